//! Texture images (`bitmap` textures and `envmap` emitters): the reader
//! (the `image` crate's PNG, JPEG, TGA, BMP, OpenEXR and Radiance HDR
//! decoders, then the conversion to linear texels), then what the loader
//! builds from them: the bitmap with its lookups and the environment map
//! with its light-sampling distribution.
//!
//! The first byte picks the format (a file is also read by its
//! extension, and TGA has no signature to guess from) and whether the
//! texels are `raw`; the rest is the image.
#![no_main]
use glam::{Affine2, Mat3, Vec2, Vec3};
use image::ImageFormat;
use libfuzzer_sys::fuzz_target;
use mcmc_render::environment::{EnvRadiance, Environment, LatLong};
use mcmc_render::texture::{Bitmap, FilterType, WrapMode, linear_from_bytes};

const FORMATS: [Option<ImageFormat>; 7] = [
    None,
    Some(ImageFormat::Png),
    Some(ImageFormat::Jpeg),
    Some(ImageFormat::Tga),
    Some(ImageFormat::Bmp),
    Some(ImageFormat::OpenExr),
    Some(ImageFormat::Hdr),
];

fuzz_target!(|data: &[u8]| {
    let Some((&head, image)) = data.split_first() else {
        return;
    };
    let format = FORMATS[usize::from(head & 7) % FORMATS.len()];
    let raw = head & 8 != 0;
    let Ok((w, h, texels)) = linear_from_bytes(image, format, raw) else {
        return;
    };
    if let Ok(map) = LatLong::new(w as usize, h as usize, texels.clone()) {
        if let Ok(env) = Environment::new(EnvRadiance::Map(Box::new(map)), Mat3::IDENTITY) {
            let _ = env.eval(Vec3::Z);
            if let Some((d, _, _)) = env.sample((0.3, 0.7)) {
                let _ = env.pdf(d);
            }
        }
    }
    let bitmap = Bitmap::new(
        w,
        h,
        texels,
        FilterType::Bilinear,
        WrapMode::Mirror,
        Affine2::IDENTITY,
    )
    .expect("the reader gives width × height > 0 texels");
    let _ = bitmap.mean();
    for uv in [Vec2::new(0.25, 0.75), Vec2::new(-1.5, 2.25)] {
        let _ = bitmap.eval(uv);
        let _ = bitmap.luminance_gradient(uv);
    }
});
