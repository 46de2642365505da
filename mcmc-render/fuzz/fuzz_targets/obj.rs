//! OBJ meshes: the reader, then the validation every loaded mesh goes
//! through (`RawMesh::finish`), as `<shape type="obj">` does.
#![no_main]
use libfuzzer_sys::fuzz_target;
use mcmc_render::scene::mesh::obj_from_bytes;

fuzz_target!(|data: &[u8]| {
    if let Ok(mut mesh) = obj_from_bytes(data) {
        mesh.flip_tex_coords();
        let _ = mesh.finish(&glam::Mat4::IDENTITY, false);
    }
});
