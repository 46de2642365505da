//! Mitsuba `.serialized` meshes: shapes 0, 1 and 2 of the input (index 0
//! reads from the start; the others go through the end-of-file
//! dictionary), then the mesh validation, as `<shape type="serialized">`.
#![no_main]
use libfuzzer_sys::fuzz_target;
use mcmc_render::scene::serialized::serialized_from_bytes;

fuzz_target!(|data: &[u8]| {
    for index in 0..3 {
        if let Ok(s) = serialized_from_bytes(data, index) {
            let _ = s.mesh.finish(&glam::Mat4::IDENTITY, s.face_normals);
        }
    }
});
