//! `info` (what a scene file loads to) and `integrators` (the registry).

use super::stdout::{Failure, out};
use crate::integrators::registry::{self, REGISTRY};
use crate::scene::Scene;
use crate::settings::ParamKind;
use std::path::Path;

/// Prints what `s` loaded to.
pub fn print_info(path: &Path, s: &Scene) -> Result<(), Failure> {
    let mut kinds: Vec<(String, usize)> = Vec::new();
    for sh in &s.shapes {
        match kinds.iter_mut().find(|(k, _)| *k == sh.kind) {
            Some((_, n)) => *n += 1,
            None => kinds.push((sh.kind.clone(), 1)),
        }
    }
    let shapes: Vec<String> = kinds.iter().map(|(k, n)| format!("{n} {k}")).collect();
    let area = s
        .lights
        .lights
        .iter()
        .filter(|l| matches!(l, crate::light::Light::Area { .. }))
        .count();
    out!("scene               {}", path.display())?;
    out!(
        "shapes              {} ({})",
        s.shapes.len(),
        shapes.join(", ")
    )?;
    out!("triangles           {}", s.geometry.triangles)?;
    out!("dropped triangles   {} (zero area)", s.dropped_degenerate)?;
    out!("bsdfs               {}", s.bsdf_descs.len())?;
    for (i, d) in s.bsdf_descs.iter().enumerate() {
        out!("  [{i}] {d:?}")?;
    }
    out!(
        "lights              {} ({} area, {} point)",
        s.lights.lights.len(),
        area,
        s.lights.lights.len() - area
    )?;
    out!(
        "film                {}x{} {:?}, {} spp",
        s.film.width,
        s.film.height,
        s.film.filter,
        s.sample_count
    )?;
    let integ = registry::configure(s.integrator_element.as_ref(), None, &[])?;
    let settings: Vec<String> = integ
        .settings_json()
        .iter()
        .map(|(k, v)| format!("{k}={v}"))
        .collect();
    out!(
        "integrator          {} ({})",
        integ.name(),
        settings.join(", ")
    )?;
    out!(
        "bvh                 {} primitives, built in {:.3} ms, {:.2} MiB",
        s.geometry.primitive_count(),
        s.geometry.build_time.as_secs_f64() * 1e3,
        s.geometry.bvh_bytes() as f64 / (1024.0 * 1024.0)
    )?;
    Ok(())
}

fn kind_text(kind: &ParamKind) -> String {
    match kind {
        ParamKind::Float => "float".into(),
        ParamKind::Integer => "integer".into(),
        ParamKind::Boolean => "boolean".into(),
        ParamKind::Choice(names) => names.join("|"),
        ParamKind::Auto(inner) => format!("auto|{}", kind_text(inner)),
    }
}

/// Prints every registered integrator with its parameters and defaults.
pub fn print_integrators() -> Result<(), Failure> {
    for r in REGISTRY {
        let aliases = if r.aliases.is_empty() {
            String::new()
        } else {
            format!(" (also: {})", r.aliases.join(", "))
        };
        out!("{}{aliases}\n    {}", r.name, r.description)?;
        for p in (r.new)().params() {
            out!(
                "    {:<24} {:<28} default {:<10} {}",
                p.name,
                kind_text(&p.kind),
                p.value.to_string(),
                p.doc
            )?;
        }
        out!()?;
    }
    Ok(())
}
