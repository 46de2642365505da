//! The primary-sample dump of `render --replay`: the parser, then the
//! re-trace of the dump in the repository's Cornell box, as the command
//! does.
#![no_main]
use libfuzzer_sys::fuzz_target;
use mcmc_render::pss_dump::{parse_pss, replay};
use mcmc_render::scene::Scene;
use std::path::Path;
use std::sync::OnceLock;

fn cornell() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| {
        let text = include_str!("../../../scenes/cornell-box.xml");
        let name = Path::new("cornell-box.xml");
        Scene::load_str(text, name, Path::new(".")).expect("the Cornell box loads")
    })
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(dump) = parse_pss(text, Path::new("fuzz.pss")) {
        let _ = replay(cornell(), &dump);
    }
});
