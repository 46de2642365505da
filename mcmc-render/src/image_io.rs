//! Image files: linear EXR (the `exr` crate) and a tone-mapped sRGB PNG
//! preview (the `png` crate).

use crate::color::Rgb;
use mcmc_core::checkpoint::write_atomically;
use std::path::Path;

/// Writes a linear-RGB EXR (32-bit float channels), atomically.
pub fn write_exr(path: &Path, width: u32, height: u32, pixels: &[Rgb]) -> Result<(), String> {
    let w = width as usize;
    write_atomically(path, |tmp| {
        exr::prelude::write_rgb_file(tmp, w, height as usize, |x, y| {
            let p = pixels[y * w + x];
            (p.r, p.g, p.b)
        })
        .map_err(|e| format!("cannot write {}: {e}", path.display()))
    })
}

/// Reads the first RGB(A) layer of an EXR file as linear RGB.
pub fn read_exr(path: &Path) -> Result<(u32, u32, Vec<Rgb>), String> {
    crate::resources::regular_file(path)?;
    let file =
        std::fs::File::open(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    exr_from_reader(std::io::BufReader::new(file), path)
}

/// Reads an EXR image held in memory, as [`read_exr`] reads a file;
/// `path` names it in messages.
pub fn exr_from_bytes(bytes: &[u8], path: &Path) -> Result<(u32, u32, Vec<Rgb>), String> {
    exr_from_reader(std::io::Cursor::new(bytes), path)
}

/// Decoded bytes an EXR may claim per byte of file: ZIP, its strongest
/// compression, expands at most 1032:1 (DEFLATE), and `f16` samples
/// double as the `f32` pixels kept; 4096 leaves room above both. A header
/// claiming more is a lie (the fuzzer's 1.6 KB file claimed 309 GB).
const EXR_MAX_INFLATION: u128 = 4096;

/// Checks every header of the EXR in `input` before anything is decoded:
/// each layer's data window, as `f32` RGB pixels, must fit in what the
/// file's length can hold ([`EXR_MAX_INFLATION`]) and in the memory
/// available. Leaves `input` at its start. The error names no file.
pub(crate) fn check_exr_headers(
    input: &mut (impl std::io::Read + std::io::Seek),
) -> Result<(), String> {
    use std::io::SeekFrom;
    let file_bytes = input.seek(SeekFrom::End(0)).map_err(|e| e.to_string())?;
    input.seek(SeekFrom::Start(0)).map_err(|e| e.to_string())?;
    let meta =
        exr::meta::MetaData::read_from_unbuffered(&mut *input, false).map_err(|e| e.to_string())?;
    input.seek(SeekFrom::Start(0)).map_err(|e| e.to_string())?;
    for header in meta.headers.iter() {
        let (w, h) = (header.layer_size.width(), header.layer_size.height());
        let bytes = w as u128 * h as u128 * std::mem::size_of::<Rgb>() as u128;
        if bytes > EXR_MAX_INFLATION * u128::from(file_bytes) {
            return Err(format!(
                "the header claims {w}×{h} pixels ({bytes} bytes), more than a file of {file_bytes} bytes can hold"
            ));
        }
        crate::resources::check_memory(&format!("image {w}×{h}"), bytes)?;
    }
    Ok(())
}

fn exr_from_reader(
    mut input: impl std::io::Read + std::io::Seek + Send,
    path: &Path,
) -> Result<(u32, u32, Vec<Rgb>), String> {
    use exr::prelude::{ReadChannels, ReadLayers};
    let cannot = |e: &dyn std::fmt::Display| format!("cannot read {}: {e}", path.display());
    // Nothing is allocated on the header's word: its sizes are checked
    // against the file's length and the memory available first.
    check_exr_headers(&mut input).map_err(|e| cannot(&e))?;
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .rgba_channels(
            |res, _| (res.width(), vec![Rgb::BLACK; res.width() * res.height()]),
            |(w, px): &mut (usize, Vec<Rgb>), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                px[pos.y() * *w + pos.x()] = Rgb::new(r, g, b);
            },
        )
        .first_valid_layer()
        .all_attributes()
        .from_buffered(input)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let size = image.layer_data.size;
    let (_, pixels) = image.layer_data.channel_data.pixels;
    let side = |n: usize| {
        u32::try_from(n).map_err(|_| cannot(&format!("a side of {n} pixels is more than 2^32")))
    };
    Ok((side(size.width())?, side(size.height())?, pixels))
}

/// sRGB transfer function of a linear value clamped to [0, 1].
fn srgb_encode(v: f32) -> u8 {
    let v = if v.is_finite() {
        v.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let s = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

/// Writes an 8-bit sRGB PNG preview (linear values clamped to [0, 1]),
/// atomically.
pub fn write_png(path: &Path, width: u32, height: u32, pixels: &[Rgb]) -> Result<(), String> {
    write_atomically(path, |tmp| write_png_to(tmp, path, width, height, pixels))
}

/// The PNG encoding of [`write_png`] into `file_path` (errors name `path`).
fn write_png_to(
    file_path: &Path,
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[Rgb],
) -> Result<(), String> {
    let fail = |e: &dyn std::fmt::Display| format!("cannot write {}: {e}", path.display());
    let file = std::fs::File::create(file_path).map_err(|e| fail(&e))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
    let mut writer = enc.write_header().map_err(|e| fail(&e))?;
    let data: Vec<u8> = pixels
        .iter()
        .flat_map(|p| [srgb_encode(p.r), srgb_encode(p.g), srgb_encode(p.b)])
        .collect();
    writer.write_image_data(&data).map_err(|e| fail(&e))?;
    writer.finish().map_err(|e| fail(&e))
}
