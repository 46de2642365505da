//! Agreement of the BSDF wrappers `normalmap`, `bumpmap` and `mask` with
//! Mitsuba 3 (`scalar_rgb`) on a grid of directions, at three known
//! surface points, on reference values that
//! `data/gen_mitsuba_wrapper_reference.py` produced with Mitsuba itself (as
//! `bsdf_mitsuba.rs` does for the other BSDFs).
//!
//! Setup, identical in both renderers: 4×4 bilinear, repeating, raw bitmaps
//! (a coloured height field for `bumpmap` with `scale` 0.5, a field of
//! normals for `normalmap`), whose texels the CSV carries; each point's UV
//! (one outside [0, 1]), geometric and shading normals (different at one
//! point, as with interpolated normals) and ∂p/∂u, ∂p/∂v in world
//! coordinates; directions in world coordinates, which each renderer takes
//! to its own shading frame. We evaluate what every integrator evaluates:
//! `BsdfAt::Wrapped` with the `Wrap` that `Scene::bsdf_at` builds
//! (`Perturbation::normal`, `Perturbation::at`, the opacity). The nested
//! models are isotropic, so the two renderers' different tangent axes about
//! the perturbed normal do not matter.
//!
//! What is compared:
//! - radiance mode: `eval · |cos θ_i|` and `pdf` against Mitsuba's `eval`
//!   and `pdf` (`si.wi` = our `wo`);
//! - importance mode: our wrapper transports the adjoint of the radiance
//!   function (`f_imp(a, b) = f_rad(b, a)`, see `src/bsdf/perturb.rs`), so
//!   `eval_imp(wo, wi) · |cos θ_o|` is compared with Mitsuba's radiance
//!   value with the two directions swapped; its density is ½ of the nested
//!   one in the frame `wi` selects (the two frames are drawn ½ each), which
//!   equals ½ Mitsuba's radiance `pdf(wo → wi)` wherever both directions
//!   select the same frame and lie on the valid side of it (checked on
//!   those rows). Mitsuba's own importance-mode values are recorded too:
//!   Mitsuba applies the flip and the terminator term to `si.wi` and `wo`
//!   in both modes, so its light tracing is not the adjoint of its path
//!   tracing; the test prints on how many rows they differ from ours;
//! - `mask`: the null lobe's sample (straight through, weight 1, density
//!   1 − opacity).
//!
//! Tolerances as in `bsdf_mitsuba.rs`: relative 2e-5 (plus 1e-6 absolute)
//! for f32 evaluations of the same formulas, 5e-3 / 1e-2 for the rough
//! plastic's tabulated diffuse lobe; where f32 cannot resolve the value
//! (a direction within rounding of a tilted plane, deep tails), the local
//! sensitivity to 4-ulp perturbations of the directions is added.
//!
//! Controls that must fail: the unperturbed nested BSDF in place of
//! `normalmap`/`bumpmap`, and opacity `1 − α` in place of `α` for `mask`,
//! each on most rows with a non-zero value.

mod bsdf_common;

use bsdf_common::*;
use glam::{Affine2, Vec2, Vec3};
use mcmc_render::bsdf::perturb::{PerturbKind, Perturbation};
use mcmc_render::bsdf::textured::BsdfAt;
use mcmc_render::bsdf::wrapped::Wrap;
use mcmc_render::bsdf::{Bsdf, BsdfDesc, MicrofacetKind, TransportMode};
use mcmc_render::color::Rgb;
use mcmc_render::frame::Frame;
use mcmc_render::texture::{Bitmap, FilterType, Texture, WrapMode};
use std::collections::HashMap;
use std::sync::Arc;

/// A surface point of the generator script.
struct Point {
    uv: Vec2,
    ng: Vec3,
    ns: Vec3,
    dp_du: Vec3,
    dp_dv: Vec3,
}

/// The nested models of the script.
fn nested(name: &str) -> Bsdf {
    build(&match name {
        "diffuse" => BsdfDesc::Diffuse {
            reflectance: Rgb::new(0.2, 0.5, 0.8),
        },
        "roughplastic" => BsdfDesc::RoughPlastic {
            distribution: MicrofacetKind::Ggx,
            alpha: 0.3,
            sample_visible: true,
            diffuse_reflectance: Rgb::new(0.2, 0.5, 0.8),
            specular_reflectance: Rgb::WHITE,
            int_ior: 1.49,
            ext_ior: 1.000_277,
            nonlinear: false,
        },
        "roughconductor" => rough_conductor(MicrofacetKind::Ggx, (0.2, 0.2)),
        "roughdielectric" => rough_dielectric(MicrofacetKind::Ggx, (0.3, 0.3), 1.5),
        other => panic!("unknown nested model {other}"),
    })
}

/// The reference file, parsed.
struct Reference {
    points: Vec<Point>,
    bitmaps: HashMap<String, Arc<Bitmap>>,
    bump_scale: f32,
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

fn parse() -> Reference {
    let text = include_str!("data/mitsuba_wrapper_reference.csv");
    let mut points = Vec::new();
    let mut texels: HashMap<String, Vec<(usize, usize, Rgb)>> = HashMap::new();
    let mut bump_scale = None;
    let mut header = Vec::new();
    let mut rows = Vec::new();
    for line in text.lines() {
        if let Some(s) = line.strip_prefix("# bump scale ") {
            bump_scale = Some(s.parse().unwrap());
            continue;
        }
        if line.starts_with('#') {
            continue;
        }
        let v: Vec<String> = line.split(',').map(str::to_string).collect();
        let f = |i: usize| v[i].parse::<f32>().unwrap();
        let v3 = |i: usize| Vec3::new(f(i), f(i + 1), f(i + 2));
        match v[0].as_str() {
            "point" => points.push(Point {
                uv: Vec2::new(f(2), f(3)),
                ng: v3(4),
                ns: v3(7),
                dp_du: v3(10),
                dp_dv: v3(13),
            }),
            "texel" => texels.entry(v[1].clone()).or_default().push((
                v[2].parse().unwrap(),
                v[3].parse().unwrap(),
                Rgb::new(f(4), f(5), f(6)),
            )),
            "config" => header = v,
            _ => rows.push(v),
        }
    }
    let bitmaps = texels
        .into_iter()
        .map(|(name, t)| {
            let w = t.iter().map(|t| t.0).max().unwrap() + 1;
            let h = t.iter().map(|t| t.1).max().unwrap() + 1;
            let mut px = vec![Rgb::BLACK; w * h];
            for (x, y, c) in t {
                px[y * w + x] = c;
            }
            let b = Bitmap::new(
                w as u32,
                h as u32,
                px,
                FilterType::Bilinear,
                WrapMode::Repeat,
                Affine2::IDENTITY,
            )
            .unwrap();
            (name, Arc::new(b))
        })
        .collect();
    Reference {
        points,
        bitmaps,
        bump_scale: bump_scale.expect("bump scale"),
        header,
        rows,
    }
}

/// A configuration of the script: the nested model, the perturbation (if
/// any) and the opacity.
fn config(r: &Reference, name: &str) -> (Bsdf, Option<Perturbation>, f32) {
    let (opacity, rest) = match name {
        "mask_diffuse" => (0.3, "diffuse"),
        "mask_roughplastic" => (0.7, "roughplastic"),
        "mask_bumpmap_roughplastic" => (0.6, "bumpmap_roughplastic"),
        other => (1.0, other),
    };
    let perturbation = |kind| Perturbation {
        kind,
        flip_invalid_normals: true,
        use_shadowing_function: true,
    };
    if let Some(m) = rest.strip_prefix("normalmap_") {
        let t = Texture::Bitmap(r.bitmaps["normal"].clone());
        (
            nested(m),
            Some(perturbation(PerturbKind::Normal(t))),
            opacity,
        )
    } else if let Some(m) = rest.strip_prefix("bumpmap_") {
        let kind = PerturbKind::Bump {
            height: r.bitmaps["bump"].clone(),
            scale: r.bump_scale,
        };
        (nested(m), Some(perturbation(kind)), opacity)
    } else {
        (nested(rest), None, opacity)
    }
}

/// What `Scene::bsdf_at` makes of the configuration at `p`: the wrapped
/// BSDF, the shading frame, and the perturbed normal in that frame.
fn at<'a>(
    model: Bsdf,
    perturbation: &Option<Perturbation>,
    opacity: f32,
    p: &Point,
) -> (BsdfAt<'a>, Frame, Option<Vec3>) {
    let frame = Frame::from_normal(p.ns);
    let n = perturbation
        .as_ref()
        .map(|pt| pt.normal(p.ns, p.ng, p.uv, (p.dp_du, p.dp_dv)));
    let wrap = Wrap {
        perturbed: perturbation.as_ref().zip(n).map(|(pt, n)| pt.at(&frame, n)),
        opacity,
    };
    (
        BsdfAt::Wrapped(model, wrap),
        frame,
        n.map(|n| frame.to_local(n)),
    )
}

/// The local perturbed normal that direction `w` (camera side) selects:
/// `n` or its mirror image (Mitsuba's `flip_invalid_normals`).
fn normal_for(n: Vec3, w: Vec3) -> Vec3 {
    if w.z * w.dot(n) <= 0.0 {
        Vec3::new(-n.x, -n.y, n.z)
    } else {
        n
    }
}

/// Largest relative change of `eval(wo, wi)·|cos|` under 4-ulp moves of
/// either direction.
fn sensitivity(b: &BsdfAt, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
    let g = |a: Vec3, c: Vec3| {
        let cos = if mode == TransportMode::Radiance {
            c.z
        } else {
            a.z
        };
        b.eval(a, c, mode).r * cos.abs()
    };
    let f0 = g(wo, wi);
    let eps = 4.0 * f32::EPSILON;
    let mut worst = 0.0f32;
    for axis in [Vec3::X, Vec3::Y, Vec3::Z, -Vec3::X, -Vec3::Y, -Vec3::Z] {
        for (a, c) in [
            ((wo + axis * eps).normalize(), wi),
            (wo, (wi + axis * eps).normalize()),
        ] {
            worst = worst.max(rel_diff(g(a, c), f0, 1e-6));
        }
    }
    worst
}

fn rgb_ok(a: Rgb, w: Rgb, tol: f32) -> bool {
    a.to_array()
        .into_iter()
        .zip(w.to_array())
        .all(|(a, w)| (a - w).abs() <= tol * w.abs() + 1e-6)
}

#[test]
fn wrappers_agree_with_mitsuba3() {
    let r = parse();
    let col = |n: &str| r.header.iter().position(|h| h == n).unwrap();
    let mut cache: HashMap<String, (Bsdf, Option<Perturbation>, f32)> = HashMap::new();
    let (mut checked, mut nonzero, mut loose, mut imp_pdf_rows, mut nulls) = (0, 0, 0, 0, 0);
    let (mut flat_rows, mut flat_caught, mut mask_rows, mut mask_caught) = (0, 0, 0, 0);
    let (mut mitsuba_importance_differs, mut perturbed_rows) = (0, 0);
    let mut failures = Vec::new();
    for v in &r.rows {
        let x = |n: &str| v[col(n)].parse::<f32>().unwrap();
        let v3 = |a: &str, b: &str, c: &str| Vec3::new(x(a), x(b), x(c));
        let name = v[0].as_str();
        let (model, perturbation, opacity) = cache
            .entry(name.to_string())
            .or_insert_with(|| config(&r, name))
            .clone();
        let p = &r.points[v[1].parse::<usize>().unwrap()];
        let (b, frame, n) = at(model, &perturbation, opacity, p);
        let wo = frame.to_local(v3("wo_x", "wo_y", "wo_z"));
        let wi = frame.to_local(v3("wi_x", "wi_y", "wi_z"));
        let (f_tol, pdf_tol) = if name.contains("roughplastic") {
            (5e-3, 1e-2)
        } else {
            (2e-5, 2e-5)
        };
        let ok = |a: f32, w: f32, tol: f32| (a - w).abs() <= tol * w.abs() + 1e-6;

        // Radiance mode.
        let rad = TransportMode::Radiance;
        let want = Rgb::new(x("f_r"), x("f_g"), x("f_b"));
        let want_pdf = x("pdf");
        let (f, pdf) = b.eval_pdf(wo, wi, rad);
        let got = f * wi.z.abs();
        // Importance mode: the radiance function with swapped arguments.
        let imp = TransportMode::Importance;
        let want_imp = Rgb::new(x("sw_f_r"), x("sw_f_g"), x("sw_f_b"));
        let (fi, pdf_i) = b.eval_pdf(wo, wi, imp);
        let got_imp = fi * wo.z.abs();
        let good = |extra: f32| {
            rgb_ok(got, want, f_tol + extra)
                && ok(pdf, want_pdf, pdf_tol + extra)
                && rgb_ok(got_imp, want_imp, f_tol + extra)
        };
        let mut pass = good(0.0);
        if !pass {
            loose += 1;
            let s = sensitivity(&b, wo, wi, rad).max(sensitivity(&b, wo, wi, imp));
            pass = good(4.0 * s);
        }
        if !pass {
            failures.push(format!(
                "{name} point {} wo={wo:?} wi={wi:?}: radiance {got:?} vs {want:?}, pdf {pdf} vs {want_pdf}; \
                 importance {got_imp:?} vs {want_imp:?}",
                v[1]
            ));
        }
        // Importance density, where both directions select the same frame
        // and lie on its valid side (see the module docs).
        let same_frame = n.is_none_or(|n| {
            let m = normal_for(n, wo);
            m == normal_for(n, wi) && wo.z * wo.dot(m) > 0.0 && wi.z * wi.dot(m) > 0.0
        });
        if same_frame && want_pdf > 0.0 {
            imp_pdf_rows += 1;
            let want_i = if n.is_some() { 0.5 } else { 1.0 } * want_pdf;
            if !ok(pdf_i, want_i, pdf_tol) {
                failures.push(format!(
                    "{name} point {} wo={wo:?} wi={wi:?}: importance pdf {pdf_i} vs {want_i}",
                    v[1]
                ));
            }
        }
        // Mitsuba's importance-mode value carries the cosine of its `wo`
        // (our `wi`), like our importance `eval` times |cos θ_i|.
        let mitsuba_imp = Rgb::new(x("imp_f_r"), x("imp_f_g"), x("imp_f_b"));
        if perturbation.is_some() && !(want_imp.is_black() && mitsuba_imp.is_black()) {
            perturbed_rows += 1;
            mitsuba_importance_differs += usize::from(!rgb_ok(fi * wi.z.abs(), mitsuba_imp, f_tol));
        } else {
            // Without a perturbation the two definitions coincide.
            assert!(
                rgb_ok(fi * wi.z.abs(), mitsuba_imp, f_tol + 1e-4),
                "{name}: importance {:?} vs Mitsuba's {mitsuba_imp:?}",
                fi * wi.z.abs()
            );
        }

        // Controls, on rows with a clearly non-zero value.
        if want.g > 1e-3 {
            nonzero += 1;
            if perturbation.is_some() {
                let flat = BsdfAt::Shared(&model);
                flat_rows += 1;
                flat_caught += usize::from(!rgb_ok(
                    flat.eval(wo, wi, rad) * (wi.z.abs() * opacity),
                    want,
                    f_tol,
                ));
            }
            if opacity < 1.0 {
                let (wrong, _, _) = at(model, &perturbation, 1.0 - opacity, p);
                mask_rows += 1;
                mask_caught +=
                    usize::from(!rgb_ok(wrong.eval(wo, wi, rad) * wi.z.abs(), want, f_tol));
            }
        }

        // The mask's null lobe.
        if opacity < 1.0 {
            nulls += 1;
            let s = b.sample(wo, 0.999, (0.3, 0.6), rad).expect("null sample");
            let want_wi = frame.to_local(v3("null_x", "null_y", "null_z"));
            let want_w = Rgb::new(x("null_w_r"), x("null_w_g"), x("null_w_b"));
            assert!(
                s.is_delta
                    && (s.wi - want_wi).length() < 1e-5
                    && rgb_ok(s.weight, want_w, 1e-5)
                    && ok(s.pdf, x("null_pdf"), 1e-5),
                "{name}: null sample {s:?} vs wi {want_wi:?} weight {want_w:?} pdf {}",
                x("null_pdf")
            );
        }
        checked += 1;
    }
    eprintln!(
        "checked {checked} rows ({nonzero} non-zero), conditioning allowance {loose}, \
         importance pdf on {imp_pdf_rows}, null samples {nulls}; controls: unperturbed caught \
         {flat_caught}/{flat_rows}, opacity 1 − α caught {mask_caught}/{mask_rows}; Mitsuba's own \
         importance-mode value differs from ours on {mitsuba_importance_differs} of \
         {perturbed_rows} perturbed rows where either is non-zero"
    );
    assert!(
        failures.is_empty(),
        "{} of {checked} rows disagree:\n{}",
        failures.len(),
        failures.join("\n")
    );
    assert!(
        checked >= 700 && nonzero * 3 > checked,
        "{nonzero}/{checked}"
    );
    assert!(
        loose * 20 < checked,
        "{loose}/{checked} needed the allowance"
    );
    assert!(imp_pdf_rows > 100, "{imp_pdf_rows} importance-pdf rows");
    assert!(
        flat_caught * 10 > flat_rows * 9,
        "control: the unperturbed BSDF passed on {}/{flat_rows} rows",
        flat_rows - flat_caught
    );
    assert!(
        mask_caught == mask_rows && mask_rows > 20,
        "control: opacity 1 − α passed on {}/{mask_rows} rows",
        mask_rows - mask_caught
    );
}
