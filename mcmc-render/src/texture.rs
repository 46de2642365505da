//! Textures with Mitsuba 3's semantics: `bitmap` (PNG, JPEG, TGA, BMP,
//! OpenEXR, Radiance HDR, decoded by the `image` crate), `checkerboard`,
//! and constants. A texture maps a surface UV to an RGB value.
//!
//! `bitmap` follows Mitsuba 3 (Dr.Jit's texture lookups): image row 0 (the
//! top of the file) is v ∈ [0, 1/height); `to_uv` applies first;
//! `bilinear` (default) interpolates the four texels around
//! `uv·size − 0.5`, `nearest` takes the texel at `floor(uv·size)`; texel
//! indices outside the image are wrapped per axis by `wrap_mode`: `repeat`
//! (default, modulo), `mirror` (period 2·size, the edge texel repeated:
//! …, 1, 0, 0, 1, …, n−1, n−1, n−2, …) or `clamp` (to the edge texel).
//! Integer images (8 or 16 bits per channel) are sRGB-encoded and turned
//! into linear values with the exact sRGB curve unless `raw` is set; float
//! images (EXR, HDR) are linear. An alpha channel is dropped; a grey image
//! gives the same value in all three channels.
//!
//! Where this differs from Mitsuba 3, on purpose: Mitsuba stores 8- and
//! 16-bit images in half precision (a relative rounding of at most
//! 2⁻¹¹ ≈ 0.05%); this stores single precision.

use crate::color::Rgb;
use glam::{Affine2, Mat4, Vec2};
use std::path::Path;
use std::sync::Arc;

/// How a bitmap is read between texel centres.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FilterType {
    /// Bilinear interpolation of the four nearest texels (Mitsuba's default).
    Bilinear,
    /// The texel the point falls in.
    Nearest,
}

/// How texel indices outside the image are brought back into it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WrapMode {
    /// Tile the image (Mitsuba's default).
    Repeat,
    /// Tile with every other copy mirrored.
    Mirror,
    /// Repeat the edge texels.
    Clamp,
}

impl WrapMode {
    /// Texel index `i` wrapped into `0..n` (`n ≥ 1`).
    #[inline]
    fn wrap(self, i: i64, n: i64) -> usize {
        (match self {
            WrapMode::Repeat => i.rem_euclid(n),
            WrapMode::Clamp => i.clamp(0, n - 1),
            WrapMode::Mirror => {
                let m = i.rem_euclid(2 * n);
                if m < n { m } else { 2 * n - 1 - m }
            }
        }) as usize
    }
}

/// An image texture (`bitmap`).
#[derive(Debug)]
pub struct Bitmap {
    width: u32,
    height: u32,
    /// Linear RGB texels, row by row from the top of the image.
    texels: Vec<Rgb>,
    filter: FilterType,
    wrap: WrapMode,
    to_uv: Affine2,
}

impl Bitmap {
    /// A bitmap from linear texels (row 0 at v = 0); `None` unless
    /// `texels.len() == width·height > 0`.
    pub fn new(
        width: u32,
        height: u32,
        texels: Vec<Rgb>,
        filter: FilterType,
        wrap: WrapMode,
        to_uv: Affine2,
    ) -> Option<Bitmap> {
        (width > 0 && height > 0 && texels.len() == width as usize * height as usize).then_some(
            Bitmap {
                width,
                height,
                texels,
                filter,
                wrap,
                to_uv,
            },
        )
    }

    /// Reads an image file: PNG, JPEG, TGA and BMP are sRGB-decoded unless
    /// `raw`; EXR and HDR are taken as linear. The error names no file (the
    /// caller does).
    pub fn load(
        path: &Path,
        raw: bool,
        filter: FilterType,
        wrap: WrapMode,
        to_uv: Affine2,
    ) -> Result<Bitmap, String> {
        let (width, height, texels) = read_linear(path, raw)?;
        Bitmap::new(width, height, texels, filter, wrap, to_uv)
            .ok_or_else(|| "the image is empty".to_string())
    }
}

/// Reads an image file as linear RGB texels, row by row from the top:
/// PNG, JPEG, TGA and BMP are sRGB-decoded unless `raw` (as Mitsuba does);
/// EXR and HDR are taken as linear. NaN or infinite texels are refused.
/// The error names no file (the caller does).
/// A path that is not a regular file (a FIFO would block, a device never
/// end) is refused before it is opened.
pub fn read_linear(path: &Path, raw: bool) -> Result<(u32, u32, Vec<Rgb>), String> {
    crate::resources::regular_file(path)?;
    let reader = image::ImageReader::open(path)
        .map_err(|e| e.to_string())?
        .with_guessed_format()
        .map_err(|e| e.to_string())?;
    decode_linear(reader, raw)
}

/// Reads an image held in memory, as [`read_linear`] reads a file: the
/// format is `format`, or guessed from the first bytes when `None` (a file
/// also falls back on its extension, which bytes do not have).
pub fn linear_from_bytes(
    bytes: &[u8],
    format: Option<image::ImageFormat>,
    raw: bool,
) -> Result<(u32, u32, Vec<Rgb>), String> {
    let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes));
    match format {
        Some(f) => reader.set_format(f),
        None => reader = reader.with_guessed_format().map_err(|e| e.to_string())?,
    }
    decode_linear(reader, raw)
}

/// Decodes an image as linear RGB texels. Nothing is allocated on the
/// header's word: the decoded image must fit the `image` crate's default
/// limit (512 MiB) and, with the texels made from it (12 bytes each, up to
/// 12 times the decoded bytes of a grey 8-bit image), the memory available.
fn decode_linear<R: std::io::BufRead + std::io::Seek>(
    reader: image::ImageReader<R>,
    raw: bool,
) -> Result<(u32, u32, Vec<Rgb>), String> {
    use image::{DynamicImage as D, ImageDecoder, ImageFormat};
    // The `image` crate sizes an EXR by its display window but decodes its
    // data window: a data window of 4·10^9 columns behind a 64×32 display
    // window passed its limit, then the `exr` crate allocated 32 GB for one
    // block and aborted (the `texture` target's finding). The data windows
    // are checked first, as `compare`'s EXR reader checks them.
    let reader = if reader.format() == Some(ImageFormat::OpenExr) {
        let mut inner = reader.into_inner();
        crate::image_io::check_exr_headers(&mut inner)?;
        image::ImageReader::with_format(inner, ImageFormat::OpenExr)
    } else {
        reader
    };
    let mut decoder = reader.into_decoder().map_err(|e| e.to_string())?;
    let (width, height) = decoder.dimensions();
    let decoded = decoder.total_bytes();
    let mut limits = image::Limits::default();
    limits.reserve(decoded).map_err(|e| e.to_string())?;
    decoder.set_limits(limits).map_err(|e| e.to_string())?;
    let texels = u128::from(width) * u128::from(height) * std::mem::size_of::<Rgb>() as u128;
    crate::resources::check_memory(
        &format!("image {width}×{height}"),
        u128::from(decoded) + texels,
    )?;
    let image = D::from_decoder(decoder).map_err(|e| e.to_string())?;
    let (width, height) = (image.width(), image.height());
    // 8-bit values through a table (exact, and 256 powers instead of
    // one per channel of every texel).
    let lut8: Vec<f32> = (0..=255u32)
        .map(|c| decode(c as f32 / 255.0, raw))
        .collect();
    let from16 = |c: u16| decode(c as f32 / 65535.0, raw);
    let texels: Vec<Rgb> = match &image {
        D::ImageLuma8(im) => im
            .pixels()
            .map(|p| Rgb::splat(lut8[p[0] as usize]))
            .collect(),
        D::ImageLumaA8(im) => im
            .pixels()
            .map(|p| Rgb::splat(lut8[p[0] as usize]))
            .collect(),
        D::ImageRgb8(im) => im
            .pixels()
            .map(|p| {
                Rgb::new(
                    lut8[p[0] as usize],
                    lut8[p[1] as usize],
                    lut8[p[2] as usize],
                )
            })
            .collect(),
        D::ImageRgba8(im) => im
            .pixels()
            .map(|p| {
                Rgb::new(
                    lut8[p[0] as usize],
                    lut8[p[1] as usize],
                    lut8[p[2] as usize],
                )
            })
            .collect(),
        D::ImageLuma16(im) => im.pixels().map(|p| Rgb::splat(from16(p[0]))).collect(),
        D::ImageLumaA16(im) => im.pixels().map(|p| Rgb::splat(from16(p[0]))).collect(),
        D::ImageRgb16(im) => im
            .pixels()
            .map(|p| Rgb::new(from16(p[0]), from16(p[1]), from16(p[2])))
            .collect(),
        D::ImageRgba16(im) => im
            .pixels()
            .map(|p| Rgb::new(from16(p[0]), from16(p[1]), from16(p[2])))
            .collect(),
        D::ImageRgb32F(im) => im.pixels().map(|p| Rgb::new(p[0], p[1], p[2])).collect(),
        D::ImageRgba32F(im) => im.pixels().map(|p| Rgb::new(p[0], p[1], p[2])).collect(),
        other => {
            return Err(format!("unsupported pixel format {:?}", other.color()));
        }
    };
    if let Some(i) = texels.iter().position(|t| !t.is_finite()) {
        return Err(format!(
            "pixel ({}, {}) is NaN or infinite",
            i % width as usize,
            i / width as usize
        ));
    }
    if width == 0 || height == 0 {
        return Err("the image is empty".to_string());
    }
    Ok((width, height, texels))
}

impl Bitmap {
    /// Width and height in texels.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Mean of the texels.
    pub fn mean(&self) -> Rgb {
        let sum = self.texels.iter().fold([0.0f64; 3], |mut acc, t| {
            for (a, c) in acc.iter_mut().zip(t.to_array()) {
                *a += c as f64;
            }
            acc
        });
        let n = self.texels.len() as f64;
        Rgb::new(
            (sum[0] / n) as f32,
            (sum[1] / n) as f32,
            (sum[2] / n) as f32,
        )
    }

    /// The texel at integer position (x, y), wrapped.
    #[inline]
    fn texel(&self, x: i64, y: i64) -> Rgb {
        let x = self.wrap.wrap(x, self.width as i64);
        let y = self.wrap.wrap(y, self.height as i64);
        self.texels[y * self.width as usize + x]
    }

    /// The value at surface UV `uv`.
    pub fn eval(&self, uv: Vec2) -> Rgb {
        let uv = self.to_uv.transform_point2(uv);
        let size = Vec2::new(self.width as f32, self.height as f32);
        match self.filter {
            FilterType::Nearest => {
                let p = (uv * size).floor();
                self.texel(p.x as i64, p.y as i64)
            }
            FilterType::Bilinear => {
                let p = uv * size - 0.5;
                let p0 = p.floor();
                let w1 = p - p0;
                let w0 = Vec2::ONE - w1;
                let (x, y) = (p0.x as i64, p0.y as i64);
                let row0 = self.texel(x, y) * w0.x + self.texel(x + 1, y) * w1.x;
                let row1 = self.texel(x, y + 1) * w0.x + self.texel(x + 1, y + 1) * w1.x;
                row0 * w0.y + row1 * w1.y
            }
        }
    }
}

impl Bitmap {
    /// The gradient (∂/∂u, ∂/∂v) of the texture's luminance at surface UV
    /// `uv`, as Mitsuba 3's `eval_1_grad` computes it for `bumpmap`: the
    /// exact derivative of the bilinear interpolation inside the texel
    /// cell `uv` falls in, through `to_uv` (chain rule); zero for the
    /// `nearest` filter, whose value is piecewise constant.
    pub fn luminance_gradient(&self, uv: Vec2) -> Vec2 {
        if self.filter == FilterType::Nearest {
            return Vec2::ZERO;
        }
        let t = self.to_uv.transform_point2(uv);
        let size = Vec2::new(self.width as f32, self.height as f32);
        let p = t * size - 0.5;
        let p0 = p.floor();
        let w1 = p - p0;
        let w0 = Vec2::ONE - w1;
        let (x, y) = (p0.x as i64, p0.y as i64);
        let f = |dx: i64, dy: i64| self.texel(x + dx, y + dy).luminance();
        let (f00, f10, f01, f11) = (f(0, 0), f(1, 0), f(0, 1), f(1, 1));
        // Partial derivatives in texel units, then in the transformed UV.
        let d_texel = Vec2::new(
            w0.y * (f10 - f00) + w1.y * (f11 - f01),
            w0.x * (f01 - f00) + w1.x * (f11 - f10),
        ) * size;
        // ∂f/∂uv = Jᵀ ∂f/∂t with J the linear part of `to_uv`.
        let j = self.to_uv.matrix2;
        Vec2::new(j.x_axis.dot(d_texel), j.y_axis.dot(d_texel))
    }
}

/// sRGB-encoded `c` ∈ [0, 1] to linear (the exact sRGB curve); `c` itself
/// when `raw`.
fn decode(c: f32, raw: bool) -> f32 {
    if raw {
        c
    } else if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// A texture: a constant, an image or a procedural pattern.
#[derive(Clone, Debug)]
pub enum Texture {
    /// The same value everywhere.
    Constant(Rgb),
    /// An image (shared: several BSDFs may name one file).
    Bitmap(Arc<Bitmap>),
    /// Mitsuba's `checkerboard`.
    Checkerboard(Box<Checkerboard>),
}

/// Mitsuba's `checkerboard`: `color0` where the fractional parts of u and
/// v are both above 1/2 or both not, `color1` elsewhere (after `to_uv`).
#[derive(Clone, Debug)]
pub struct Checkerboard {
    /// The first colour (Mitsuba's default 0.4).
    pub color0: Texture,
    /// The second colour (Mitsuba's default 0.2).
    pub color1: Texture,
    /// UV transform.
    pub to_uv: Affine2,
}

impl Texture {
    /// The value at surface UV `uv`.
    pub fn eval(&self, uv: Vec2) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
            Texture::Bitmap(b) => b.eval(uv),
            Texture::Checkerboard(c) => {
                let t = c.to_uv.transform_point2(uv);
                let high = |x: f32| x - x.floor() > 0.5;
                // Nested textures see the surface UV, not the transformed one.
                if high(t.x) == high(t.y) {
                    c.color0.eval(uv)
                } else {
                    c.color1.eval(uv)
                }
            }
        }
    }

    /// The scalar value at `uv`, as Mitsuba 3.9's `eval_1` computes it for
    /// a float parameter (roughness `alpha`, `opacity`): a constant gives
    /// the mean of its channels, a bitmap the luminance of its (linear)
    /// value, and a checkerboard its *other* colour's `eval_1`: Mitsuba
    /// 3.9.1's `checkerboard` picks `color1` in `eval_1` where its `eval`
    /// picks `color0` and vice versa (measured on a grid of UVs with
    /// Mitsuba 3.9.1, `scalar_rgb`; `texture_loader.rs` pins it).
    pub fn eval_1(&self, uv: Vec2) -> f32 {
        match self {
            Texture::Constant(c) => (c.r + c.g + c.b) / 3.0,
            Texture::Bitmap(b) => b.eval(uv).luminance(),
            Texture::Checkerboard(c) => {
                let t = c.to_uv.transform_point2(uv);
                let high = |x: f32| x - x.floor() > 0.5;
                if high(t.x) == high(t.y) {
                    c.color1.eval_1(uv)
                } else {
                    c.color0.eval_1(uv)
                }
            }
        }
    }

    /// The mean of [`Texture::eval_1`] over the unit UV square (as
    /// [`Texture::mean`]: exact for constants and bitmaps, the mean of the
    /// two colours for checkerboards).
    pub fn mean_1(&self) -> f32 {
        match self {
            Texture::Constant(_) => self.eval_1(Vec2::ZERO),
            Texture::Bitmap(b) => b.mean().luminance(),
            Texture::Checkerboard(c) => 0.5 * (c.color0.mean_1() + c.color1.mean_1()),
        }
    }

    /// The mean value over the unit UV square (exact for constants and
    /// bitmaps; checkerboards: the mean of their two colours' means, as
    /// Mitsuba's `mean()`).
    pub fn mean(&self) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
            Texture::Bitmap(b) => b.mean(),
            Texture::Checkerboard(c) => (c.color0.mean() + c.color1.mean()) * 0.5,
        }
    }
}

/// Mitsuba's `to_uv` from a scene `<transform>`: the 4×4 matrix with its
/// z row and column removed (a 3×3 homogeneous map of the UV plane, whose
/// last row must be (0, 0, 1) for an affine map).
pub fn uv_transform(m: &Mat4) -> Result<Affine2, String> {
    let affine = m.x_axis.w == 0.0 && m.y_axis.w == 0.0 && m.w_axis.w == 1.0;
    if !affine || !m.is_finite() {
        return Err("to_uv must be a finite affine transform".into());
    }
    Ok(Affine2::from_cols(
        Vec2::new(m.x_axis.x, m.x_axis.y),
        Vec2::new(m.y_axis.x, m.y_axis.y),
        Vec2::new(m.w_axis.x, m.w_axis.y),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4×2 bitmap whose red channel is x + 10·y at texel (x, y).
    fn ramp(filter: FilterType, wrap: WrapMode) -> Bitmap {
        let texels = (0..2)
            .flat_map(|y| (0..4).map(move |x| Rgb::new((x + 10 * y) as f32, 0.0, 0.0)))
            .collect();
        Bitmap::new(4, 2, texels, filter, wrap, Affine2::IDENTITY).unwrap()
    }

    fn red(b: &Bitmap, u: f32, v: f32) -> f32 {
        b.eval(Vec2::new(u, v)).r
    }

    /// Lookups along u at v = 0.25 (the centre of row 0) and along v at
    /// u = 0.125 (the centre of column 0), at u, v = 0, 1, negative and
    /// beyond 1, for every wrap mode and filter. Expected values by hand:
    /// nearest takes texel floor(4u); bilinear interpolates at 4u − 0.5
    /// between its floor and the next texel, indices wrapped per mode
    /// (repeat: mod 4; mirror: m = i mod 8, m < 4 ? m : 7 − m; clamp: to
    /// 0..=3). The same values come from Mitsuba 3.9's `bitmap` plugin
    /// on this image.
    #[test]
    fn lookups_under_every_wrap_mode_and_filter() {
        use FilterType::*;
        use WrapMode::*;
        let us = [
            -1.3f32, -0.6, -0.1, 0.0, 0.06, 0.3, 0.5, 0.99, 1.0, 1.1, 1.7, 2.6,
        ];
        let vs = [-0.3f32, 0.0, 0.1, 0.25, 0.5, 0.75, 0.9, 1.0, 1.2];
        let cases: [(WrapMode, FilterType, [f32; 12], [f32; 9]); 6] = [
            (
                Repeat,
                Nearest,
                [2., 1., 3., 0., 0., 1., 2., 3., 0., 0., 2., 2.],
                [10., 0., 0., 0., 10., 10., 10., 0., 0.],
            ),
            (
                Repeat,
                Bilinear,
                [2.3, 1.1, 2.7, 1.5, 0.78, 0.7, 1.5, 1.62, 1.5, 0.3, 2.3, 1.9],
                [9., 5., 3., 0., 5., 10., 7., 5., 1.],
            ),
            (
                Mirror,
                Nearest,
                [2., 2., 0., 0., 0., 1., 2., 3., 3., 3., 1., 2.],
                [0., 0., 0., 0., 10., 10., 10., 10., 10.],
            ),
            (
                Mirror,
                Bilinear,
                [2.3, 1.9, 0., 0., 0., 0.7, 1.5, 3., 3., 3., 0.7, 1.9],
                [1., 0., 0., 0., 5., 10., 10., 10., 10.],
            ),
            (
                Clamp,
                Nearest,
                [0., 0., 0., 0., 0., 1., 2., 3., 3., 3., 3., 3.],
                [0., 0., 0., 0., 10., 10., 10., 10., 10.],
            ),
            (
                Clamp,
                Bilinear,
                [0., 0., 0., 0., 0., 0.7, 1.5, 3., 3., 3., 3., 3.],
                [0., 0., 0., 0., 5., 10., 10., 10., 10.],
            ),
        ];
        for (wrap, filter, along_u, along_v) in cases {
            let b = ramp(filter, wrap);
            for (u, want) in us.iter().zip(along_u) {
                let got = red(&b, *u, 0.25);
                assert!(
                    (got - want).abs() < 1e-4,
                    "{wrap:?} {filter:?} u={u}: {got} != {want}"
                );
            }
            for (v, want) in vs.iter().zip(along_v) {
                let got = red(&b, 0.125, *v);
                assert!(
                    (got - want).abs() < 1e-4,
                    "{wrap:?} {filter:?} v={v}: {got} != {want}"
                );
            }
        }
    }

    /// A 1×1 image is that colour everywhere, under every mode.
    #[test]
    fn one_texel_image_is_constant() {
        let c = Rgb::new(0.2, 0.4, 0.8);
        for wrap in [WrapMode::Repeat, WrapMode::Mirror, WrapMode::Clamp] {
            for filter in [FilterType::Bilinear, FilterType::Nearest] {
                let b = Bitmap::new(1, 1, vec![c], filter, wrap, Affine2::IDENTITY).unwrap();
                for (u, v) in [
                    (0.0, 0.0),
                    (1.0, 1.0),
                    (-3.7, 0.2),
                    (1e6, -1e6),
                    (0.5, 0.999),
                ] {
                    assert_eq!(b.eval(Vec2::new(u, v)), c);
                }
            }
        }
    }

    /// A 16384-wide image: each texel is found at its centre, and bilinear
    /// lookups halfway between two texels average them, including across
    /// the wrap-around seam.
    #[test]
    fn wide_image_lookups() {
        let w = 16384u32;
        let texels: Vec<Rgb> = (0..w).map(|x| Rgb::splat(x as f32)).collect();
        let b = Bitmap::new(
            w,
            1,
            texels,
            FilterType::Bilinear,
            WrapMode::Repeat,
            Affine2::IDENTITY,
        )
        .unwrap();
        let n = Bitmap::new(
            w,
            1,
            b.texels.clone(),
            FilterType::Nearest,
            WrapMode::Repeat,
            Affine2::IDENTITY,
        )
        .unwrap();
        for x in [0u32, 1, 777, 8191, 16383] {
            let centre = (x as f64 + 0.5) / w as f64;
            assert_eq!(b.eval(Vec2::new(centre as f32, 0.5)).r, x as f32, "x={x}");
            assert_eq!(n.eval(Vec2::new(centre as f32, 0.5)).r, x as f32, "x={x}");
        }
        // Between texels 100 and 101; and at u = 0, between 16383 and 0.
        assert!((b.eval(Vec2::new(101.0 / w as f32, 0.5)).r - 100.5).abs() < 1e-2);
        assert!((b.eval(Vec2::new(0.0, 0.5)).r - 16383.0 / 2.0).abs() < 1e-2);
    }

    /// sRGB decoding: the curve's two pieces and its end points.
    #[test]
    fn srgb_curve() {
        assert_eq!(decode(0.0, false), 0.0);
        assert!((decode(1.0, false) - 1.0).abs() < 1e-6);
        assert!((decode(0.04, false) - 0.04 / 12.92).abs() < 1e-9);
        // 0.5 → ((0.555)/1.055)^2.4 = 0.214041...
        assert!((decode(0.5, false) - 0.214_041_14).abs() < 1e-6);
        assert_eq!(decode(0.5, true), 0.5);
    }

    /// Checkerboard: color0 on the cells where both fractional parts are
    /// on the same side of 1/2, through `to_uv`, and nested textures.
    #[test]
    fn checkerboard_cells_and_to_uv() {
        let (a, b) = (Rgb::splat(0.4), Rgb::splat(0.2));
        let board = |to_uv| {
            Texture::Checkerboard(Box::new(Checkerboard {
                color0: Texture::Constant(a),
                color1: Texture::Constant(b),
                to_uv,
            }))
        };
        let t = board(Affine2::IDENTITY);
        for (u, v, want) in [
            (0.25, 0.25, a),
            (0.75, 0.75, a),
            (0.75, 0.25, b),
            (0.25, 0.75, b),
            (-0.25, 0.25, b), // frac(−0.25) = 0.75
            (1.25, 2.25, a),
            (0.5, 0.5, a), // 0.5 is not above 1/2
        ] {
            assert_eq!(t.eval(Vec2::new(u, v)), want, "({u}, {v})");
        }
        // Scaled by 2: (0.3, 0.1) → (0.6, 0.2).
        let t = board(Affine2::from_scale(Vec2::splat(2.0)));
        assert_eq!(t.eval(Vec2::new(0.3, 0.1)), b);
        assert_eq!(t.mean(), Rgb::splat(0.3));
    }

    /// `to_uv` from a 4×4 transform keeps the x, y rows and the translation.
    #[test]
    fn uv_transform_from_4x4() {
        let m = Mat4::from_translation(glam::Vec3::new(0.25, -0.5, 7.0))
            * Mat4::from_scale(glam::Vec3::new(2.0, 3.0, 5.0));
        let a = uv_transform(&m).unwrap();
        assert_eq!(
            a.transform_point2(Vec2::new(1.0, 1.0)),
            Vec2::new(2.25, 2.5)
        );
        let mut p = Mat4::IDENTITY;
        p.x_axis.w = 1.0;
        assert!(uv_transform(&p).is_err());
    }

    /// `eval_1` against values Mitsuba 3.9.1 (`scalar_rgb`) printed for
    /// `checkerboard` (color0 0.1, color1 0.9, and color0 the RGB
    /// (0.2, 0.5, 0.8)) at these UVs, with `eval` beside them: the scalar
    /// lookup takes the other colour than `eval`, and an RGB constant's
    /// scalar value is its channel mean (0.5), not its luminance (0.458).
    #[test]
    fn scalar_lookups_match_mitsuba() {
        let grey = |v: f32| Texture::Constant(Rgb::splat(v));
        let board = |color0: Texture| {
            Texture::Checkerboard(Box::new(Checkerboard {
                color0,
                color1: grey(0.9),
                to_uv: Affine2::IDENTITY,
            }))
        };
        let plain = board(grey(0.1));
        let rgb = board(Texture::Constant(Rgb::new(0.2, 0.5, 0.8)));
        // (u, v, Mitsuba's eval, eval_1 of `plain`, eval_1 of `rgb`)
        let measured = [
            (0.1, 0.1, 0.1, 0.9, 0.9),
            (0.4, 0.6, 0.9, 0.1, 0.5),
            (0.6, 0.9, 0.1, 0.9, 0.9),
            (0.9, 0.4, 0.9, 0.1, 0.5),
            (1.2, 0.9, 0.9, 0.1, 0.5),
            (-0.3, 0.1, 0.9, 0.1, 0.5),
            (-0.3, 0.6, 0.1, 0.9, 0.9),
        ];
        for (u, v, eval, one, one_rgb) in measured {
            let uv = Vec2::new(u, v);
            assert_eq!(plain.eval(uv).r, eval, "eval at {uv}");
            assert!((plain.eval_1(uv) - one).abs() < 1e-6, "eval_1 at {uv}");
            assert!((rgb.eval_1(uv) - one_rgb).abs() < 1e-6, "eval_1 at {uv}");
        }
        assert!((plain.mean_1() - 0.5).abs() < 1e-6);
    }
}
