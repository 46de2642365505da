//! Image files as textures: every accepted format decodes to the values
//! Mitsuba 3 uses (integer formats sRGB-decoded unless `raw`, float
//! formats linear, alpha dropped, grey broadcast). Expected values by
//! hand from the sRGB curve; Mitsuba 3.9 gives the same for 8- and 16-bit
//! PNGs (within its half-precision storage).

use glam::{Affine2, Vec2};
use mcmc_render::color::Rgb;
use mcmc_render::texture::{Bitmap, FilterType, WrapMode};
use std::path::{Path, PathBuf};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "mcmc-render-texfiles-{}-{name}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The value of the single-colour image `path` (nearest, at the centre).
fn value(path: &Path, raw: bool) -> Rgb {
    let b = Bitmap::load(
        path,
        raw,
        FilterType::Nearest,
        WrapMode::Repeat,
        Affine2::IDENTITY,
    )
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    b.eval(Vec2::splat(0.5))
}

/// sRGB-encoded `c` to linear, written out independently of the crate.
fn srgb(c: f64) -> f32 {
    (if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }) as f32
}

#[track_caller]
fn close(got: Rgb, want: [f32; 3], tol: f32) {
    let g = got.to_array();
    assert!(
        (0..3).all(|i| (g[i] - want[i]).abs() <= tol),
        "{got:?} != {want:?}"
    );
}

#[test]
fn every_format_decodes_to_mitsubas_values() {
    let dir = scratch("formats");
    let (r, g, b) = (200u8, 100u8, 10u8);
    let want8 = [
        srgb(r as f64 / 255.0),
        srgb(g as f64 / 255.0),
        srgb(b as f64 / 255.0),
    ];
    let raw8 = [r as f32 / 255.0, g as f32 / 255.0, b as f32 / 255.0];
    let rgb = image::RgbImage::from_pixel(3, 2, image::Rgb([r, g, b]));
    for ext in ["png", "tga", "bmp"] {
        let p = dir.join(format!("c.{ext}"));
        rgb.save(&p).unwrap();
        close(value(&p, false), want8, 1e-6);
        close(value(&p, true), raw8, 1e-6);
    }
    // RGBA: the alpha channel is dropped.
    let p = dir.join("a.png");
    image::RgbaImage::from_pixel(2, 2, image::Rgba([r, g, b, 7]))
        .save(&p)
        .unwrap();
    close(value(&p, false), want8, 1e-6);
    // Grey: the same value in all channels.
    let p = dir.join("grey.png");
    image::GrayImage::from_pixel(2, 2, image::Luma([128]))
        .save(&p)
        .unwrap();
    let v = srgb(128.0 / 255.0);
    close(value(&p, false), [v; 3], 1e-6);
    // 16 bits per channel: sRGB too (as Mitsuba treats 16-bit PNGs).
    let p = dir.join("c16.png");
    image::ImageBuffer::<image::Rgb<u16>, _>::from_pixel(2, 2, image::Rgb([32768u16, 65535, 0]))
        .save(&p)
        .unwrap();
    close(value(&p, false), [srgb(32768.0 / 65535.0), 1.0, 0.0], 1e-6);
    close(value(&p, true), [32768.0 / 65535.0, 1.0, 0.0], 1e-6);
    // Float formats are linear, values above 1 kept: EXR exactly, HDR
    // to RGBE's 8-bit mantissa.
    let hdr = image::Rgb32FImage::from_pixel(2, 2, image::Rgb([0.25f32, 3.5, 0.0625]));
    let p = dir.join("f.exr");
    hdr.save(&p).unwrap();
    close(value(&p, false), [0.25, 3.5, 0.0625], 0.0);
    let p = dir.join("f.hdr");
    hdr.save(&p).unwrap();
    close(value(&p, false), [0.25, 3.5, 0.0625], 3.5 / 128.0);
    // JPEG (lossy): a flat colour comes back close to the sRGB decode.
    let p = dir.join("c.jpg");
    rgb.save(&p).unwrap();
    close(value(&p, false), want8, 0.02);
}

#[test]
fn non_finite_texels_are_refused() {
    let dir = scratch("nan");
    let p = dir.join("nan.exr");
    image::Rgb32FImage::from_pixel(2, 1, image::Rgb([f32::NAN, 0.0, 0.0]))
        .save(&p)
        .unwrap();
    let e = Bitmap::load(
        &p,
        false,
        FilterType::Bilinear,
        WrapMode::Repeat,
        Affine2::IDENTITY,
    )
    .unwrap_err();
    assert!(e.contains("NaN or infinite"), "{e}");
}
