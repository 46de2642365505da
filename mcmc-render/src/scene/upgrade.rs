//! Mitsuba 0.x scene files (`<scene version="0.5.0">`, `"0.6.0"`, any
//! version below 2.0.0), upgraded on load as Mitsuba 3's XML reader
//! upgrades them in memory:
//!
//! - every `name` attribute (except on `<default>`) from camelCase to
//!   snake_case (`intIOR` → `int_ior`, `maxDepth` → `max_depth`,
//!   `toWorld` → `to_world`), with Mitsuba's exact rule ([`snake_case`]);
//! - `<lookAt>` → `<lookat>` (as Mitsuba 3.0–3.5's `xml.cpp` did; the
//!   parser of Mitsuba 3.9 refuses `<lookAt>`, but 0.6 scenes use it);
//! - `diffuse_reflectance` of a `diffuse` BSDF → `reflectance`;
//! - texture `uoffset`, `voffset`, `uscale`, `vscale` → one `to_uv`
//!   transform (scale after translation, as Mitsuba composes it).
//!
//! Beyond Mitsuba 3, which refuses them, two value forms of Mitsuba 0.6
//! are read with 0.6's meaning: `<srgb>` (gamma-encoded sRGB, also
//! `#rrggbb`), converted to linear RGB, and `<spectrum>` with three
//! numbers, which 0.6's default (RGB) build read as linear RGB. What has no
//! Mitsuba 3 equivalent (a spectrum as wavelength:value pairs or from a
//! file, parameters and plugins Mitsuba 3 dropped) is refused by the
//! reader and loader with its file and line.

use crate::color::Rgb;
use glam::{Mat4, Vec3};

/// Whether a root `version` attribute ("major.minor.patch") names a
/// Mitsuba 0.x/1.x file, which is upgraded.
pub fn is_legacy(version: &str) -> Result<bool, String> {
    let parts: Vec<&str> = version.trim().split('.').collect();
    let numbers: Option<Vec<u32>> = parts.iter().map(|p| p.trim().parse().ok()).collect();
    match numbers.as_deref() {
        Some([major, _, _]) => Ok(*major < 2),
        _ => Err(format!(
            "version \"{version}\" is not of the form major.minor.patch"
        )),
    }
}

/// Mitsuba 3's camelCase-to-snake_case rule: where a lowercase letter is
/// followed by an uppercase one, insert `_` and lowercase the run of
/// uppercase letters (`intIOR` → `int_ior`, `aBcD` → `a_bc_d`, as
/// Mitsuba 3.9 names them; other letters are kept).
pub fn snake_case(name: &str) -> String {
    let mut out = String::with_capacity(name.len() + 4);
    let mut in_run = false;
    let mut prev_lower = false;
    for c in name.chars() {
        if c.is_ascii_uppercase() && (prev_lower || in_run) {
            if prev_lower {
                out.push('_');
            }
            out.push(c.to_ascii_lowercase());
            in_run = true;
        } else {
            out.push(c);
            in_run = false;
        }
        prev_lower = c.is_ascii_lowercase();
    }
    out
}

/// The sRGB transfer function inverted: gamma-encoded `c` to linear.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// A 0.6 `<srgb>` value: `#rrggbb`, or one or three gamma-encoded numbers,
/// as linear RGB.
pub fn srgb(text: &str) -> Result<Rgb, String> {
    let t = text.trim();
    let encoded = if let Some(hex) = t.strip_prefix('#') {
        let byte = |k: usize| {
            hex.get(2 * k..2 * k + 2)
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .map(|b| f32::from(b) / 255.0)
        };
        match (hex.len(), byte(0), byte(1), byte(2)) {
            (6, Some(r), Some(g), Some(b)) => [r, g, b],
            _ => return Err(format!("<srgb> value \"{t}\" is not #rrggbb")),
        }
    } else {
        match numbers(t)?.as_slice() {
            [x] => [*x; 3],
            [r, g, b] => [*r, *g, *b],
            _ => return Err("<srgb> needs one or three numbers, or #rrggbb".into()),
        }
    };
    let [r, g, b] = encoded.map(srgb_to_linear);
    Ok(Rgb::new(r, g, b))
}

/// A `<spectrum value>`: one number (a constant, in any version), or, in a
/// 0.x file, three numbers (linear RGB in Mitsuba 0.6's RGB build).
pub fn spectrum(text: &str, legacy: bool) -> Result<Rgb, String> {
    if text.contains(':') {
        return Err(
            "a <spectrum> of wavelength:value pairs is not supported (give an <rgb>)".into(),
        );
    }
    match numbers(text)?.as_slice() {
        [x] => Ok(Rgb::splat(*x)),
        [r, g, b] if legacy => Ok(Rgb::new(*r, *g, *b)),
        _ if legacy => Err("a <spectrum> needs one or three numbers".into()),
        _ => Err("a <spectrum> value needs one number (or wavelength:value pairs)".into()),
    }
}

/// Mitsuba 0.x texture coordinates parameters that become `to_uv`.
pub const UV_PARAMS: [&str; 4] = ["uoffset", "voffset", "uscale", "vscale"];

/// The `to_uv` transform of `uoffset`, `voffset`, `uscale`, `vscale`
/// (absent ones 0, 0, 1, 1): translate, then scale.
pub fn to_uv(offset: [f32; 2], scale: [f32; 2]) -> Mat4 {
    Mat4::from_scale(Vec3::new(scale[0], scale[1], 1.0))
        * Mat4::from_translation(Vec3::new(offset[0], offset[1], 0.0))
}

fn numbers(s: &str) -> Result<Vec<f32>, String> {
    s.split(|c: char| c == ',' || c.is_whitespace())
        .filter(|t| !t.is_empty())
        .map(|t| {
            t.parse::<f32>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("'{t}' is not a finite number"))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snake_case_follows_mitsuba() {
        for (camel, snake) in [
            ("intIOR", "int_ior"),
            ("extIOR", "ext_ior"),
            ("maxDepth", "max_depth"),
            ("rrDepth", "rr_depth"),
            ("sampleCount", "sample_count"),
            ("fovAxis", "fov_axis"),
            ("toWorld", "to_world"),
            ("specularReflectance", "specular_reflectance"),
            ("alphaU", "alpha_u"),
            ("cropOffsetX", "crop_offset_x"),
            ("highQualityEdges", "high_quality_edges"),
            ("reflectance", "reflectance"),
            ("max_depth", "max_depth"),
            ("uvscale", "uvscale"),
            ("Ka", "Ka"),
            // Every hump, as Mitsuba 3.9 converts it.
            ("aBcD", "a_bc_d"),
            ("fooBARBaz", "foo_barbaz"),
            ("xY1Z", "x_y1Z"),
            ("a1B", "a1B"),
            ("uvScaleX2", "uv_scale_x2"),
            ("", ""),
        ] {
            assert_eq!(snake_case(camel), snake, "{camel}");
        }
    }

    #[test]
    fn versions() {
        assert!(is_legacy("0.5.0").unwrap());
        assert!(is_legacy("0.6.0").unwrap());
        assert!(is_legacy("1.9.9").unwrap());
        assert!(!is_legacy("2.0.0").unwrap());
        assert!(!is_legacy("3.0.0").unwrap());
        assert!(is_legacy("0.6").is_err());
        assert!(is_legacy("x.y.z").is_err());
    }

    #[test]
    fn srgb_decodes_to_linear() {
        // The sRGB curve's fixed points and its linear segment.
        assert_eq!(srgb("0").unwrap(), Rgb::splat(0.0));
        assert_eq!(srgb("1").unwrap(), Rgb::splat(1.0));
        assert_eq!(srgb("0.02").unwrap(), Rgb::splat(0.02 / 12.92));
        // 0.5 encoded is 0.21404 linear (((0.5 + 0.055) / 1.055)^2.4).
        let half = srgb("0.5, 0.5, 0.5").unwrap();
        assert!((half.r - 0.214_041).abs() < 1e-6, "{half:?}");
        // #ff8000: 1, 128/255 encoded (0.21586 linear), 0.
        let c = srgb("#ff8000").unwrap();
        assert_eq!((c.r, c.b), (1.0, 0.0));
        assert!((c.g - 0.215_861).abs() < 1e-6, "{c:?}");
        assert!(srgb("#ff80").is_err());
        assert!(srgb("#gg0000").is_err());
        assert!(srgb("0.1 0.2").is_err());
    }

    #[test]
    fn spectra() {
        assert_eq!(spectrum("0.25", false).unwrap(), Rgb::splat(0.25));
        assert_eq!(spectrum("0.25", true).unwrap(), Rgb::splat(0.25));
        assert_eq!(
            spectrum("0.1, 0.2, 0.3", true).unwrap(),
            Rgb::new(0.1, 0.2, 0.3)
        );
        assert!(spectrum("0.1, 0.2, 0.3", false).is_err());
        assert!(spectrum("400:0.1, 700:0.5", true).is_err());
        assert!(spectrum("0.1 0.2", true).is_err());
    }

    #[test]
    fn to_uv_translates_then_scales() {
        // As Mitsuba 3.9 builds it: uscale 2 with uoffset 0.5 gives the
        // to_uv matrix row (2, 0, 1), i.e. u' = 2 (u + 0.5).
        assert_eq!(
            to_uv([0.5, 0.0], [2.0, 1.0]).transform_point3(Vec3::ZERO).x,
            1.0
        );
        let m = to_uv([0.5, 0.25], [2.0, 4.0]);
        let p = m.transform_point3(Vec3::new(1.0, 1.0, 0.0));
        assert_eq!(p, Vec3::new(3.0, 5.0, 0.0));
    }
}
