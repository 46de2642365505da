//! Textures through the `mcmc-render` binary: a missing, corrupt or
//! truncated image file is refused with one line naming the file and the
//! scene line; 1×1 and 16384-wide images load and render.

mod cli_support;

use cli_support::{assert_clean_failure, exr, run, run_ok, scratch, write};
use std::path::Path;

/// A tiny scene whose floor's reflectance is the bitmap `file`.
fn textured_scene(file: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
    <sensor type="perspective">
        <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="2"/></sampler>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="6"/></film>
    </sensor>
    <shape type="rectangle">
        <bsdf type="diffuse">
            <texture type="bitmap" name="reflectance">
                <string name="filename" value="{file}"/>
            </texture>
        </bsdf>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="0.3"/><rotate x="1" angle="180"/><translate z="2"/></transform>
        <emitter type="area"><rgb name="radiance" value="1"/></emitter>
    </shape>
</scene>"#
    )
}

/// Writes an 8-bit RGB PNG of `w`×`h` texels, all `rgb`.
fn write_png(path: &Path, w: u32, h: u32, rgb: [u8; 3]) {
    image::RgbImage::from_pixel(w, h, image::Rgb(rgb))
        .save(path)
        .unwrap();
}

#[test]
fn missing_texture_file_is_refused_with_its_name() {
    let dir = scratch("tex-missing");
    write(&dir, "s.xml", &textured_scene("nowhere.png"));
    let out = run(&["info", "s.xml"], &dir);
    assert_clean_failure(&out, &["s.xml:10", "nowhere.png", "cannot load texture"]);
}

#[test]
fn corrupt_and_truncated_images_are_refused_with_their_names() {
    let dir = scratch("tex-corrupt");
    // Not an image at all, under each extension the loader accepts.
    for name in [
        "junk.png", "junk.jpg", "junk.tga", "junk.exr", "junk.hdr", "junk.bmp",
    ] {
        std::fs::write(dir.join(name), b"this is not an image\n").unwrap();
    }
    // Valid files cut short.
    write_png(&dir.join("full.png"), 64, 64, [200, 100, 50]);
    let png = std::fs::read(dir.join("full.png")).unwrap();
    std::fs::write(dir.join("short.png"), &png[..png.len() / 2]).unwrap();
    image::RgbImage::from_pixel(64, 64, image::Rgb([1, 2, 3]))
        .save(dir.join("full.jpg"))
        .unwrap();
    let jpg = std::fs::read(dir.join("full.jpg")).unwrap();
    std::fs::write(dir.join("short.jpg"), &jpg[..jpg.len() / 3]).unwrap();
    // An empty file.
    std::fs::write(dir.join("empty.png"), b"").unwrap();
    for name in [
        "junk.png",
        "junk.jpg",
        "junk.tga",
        "junk.exr",
        "junk.hdr",
        "junk.bmp",
        "short.png",
        "short.jpg",
        "empty.png",
    ] {
        write(&dir, "s.xml", &textured_scene(name));
        let out = run(&["info", "s.xml"], &dir);
        assert_clean_failure(&out, &["s.xml:10", name, "cannot load texture"]);
    }
}

#[test]
fn one_texel_and_16k_wide_images_render() {
    let dir = scratch("tex-sizes");
    write_png(&dir.join("one.png"), 1, 1, [255, 255, 255]);
    write_png(&dir.join("wide.png"), 16384, 1, [255, 255, 255]);
    let mut means = Vec::new();
    for name in ["one.png", "wide.png"] {
        write(&dir, "s.xml", &textured_scene(name));
        run_ok(&["render", "s.xml", "--seed", "1", "--out", "r.exr"], &dir);
        let (_, _, pixels) = exr(&dir.join("r.exr"));
        means.push(pixels.iter().map(|p| p.g as f64).sum::<f64>());
    }
    // A white texture everywhere: the same seed gives the same image.
    assert!(means[0] > 0.0);
    assert_eq!(means[0], means[1]);
}
