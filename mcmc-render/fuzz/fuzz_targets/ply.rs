//! PLY meshes (ASCII and binary): the reader, then the validation every
//! loaded mesh goes through, as `<shape type="ply">` does.
#![no_main]
use libfuzzer_sys::fuzz_target;
use mcmc_render::scene::mesh::ply_from_bytes;

fuzz_target!(|data: &[u8]| {
    if let Ok(mesh) = ply_from_bytes(data) {
        let _ = mesh.finish(&glam::Mat4::IDENTITY, false);
    }
});
