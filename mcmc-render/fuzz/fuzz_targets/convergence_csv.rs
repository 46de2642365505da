//! The study CSV of `convergence --replot`: the parser, then the log–log
//! plot the command draws from its records (written to a temporary file).
#![no_main]
use libfuzzer_sys::fuzz_target;
use mcmc_render::cli::convergence::{integrators_of, parse_csv, write_plot};
use std::path::Path;
use std::sync::OnceLock;

fn out_dir() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| tempfile::tempdir().expect("a temporary directory"))
        .path()
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(records) = parse_csv(text, Path::new("fuzz.csv")) {
        let names = integrators_of(&records);
        let _ = write_plot(&out_dir().join("fuzz.png"), &records, &names, "fuzz");
    }
});
