//! The EXR input of `compare` (and of `convergence --reference`): the
//! reader, then the comparison of the image with itself.
#![no_main]
use libfuzzer_sys::fuzz_target;
use mcmc_render::image_io::exr_from_bytes;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    if let Ok((_, _, pixels)) = exr_from_bytes(data, Path::new("fuzz.exr")) {
        let _ = mcmc_render::compare::compare(&pixels, &pixels);
    }
});
