//! Primary-sample dumps: the coordinates of a path whose contribution was
//! NaN or infinite, written by the Metropolis integrators beside their
//! image (`<out>.nonfinite.pss`) and re-traced by `render --replay`.

use crate::integrators::bdpt::{Bdpt, MisHeuristic};
use crate::integrators::pt::PathTracer;
use crate::pss::{MmltDepth, PathSample, PssTarget};
use crate::scene::Scene;
use mcmc_core::rng::stream_rng;
use mcmc_core::space::TorusPoint;
use mcmc_core::target::Evaluation;
use std::path::Path;

crate::choice! {
    /// The path sampler a primary-sample dump was traced with.
    pub enum DumpSampler {
        /// PSSMLT over the path tracer.
        Pt = "pt",
        /// PSSMLT over BDPT (all techniques of one sample).
        Bdpt = "bdpt",
        /// Multiplexed MLT (one target per path depth).
        Mmlt = "mmlt",
    }
}

/// A dumped primary-sample vector and what it must be replayed with.
#[derive(Clone, Debug, PartialEq)]
pub struct PssDump {
    /// The path sampler of the run.
    pub sampler: DumpSampler,
    /// The run's longest path in segments (`None`: the scene's).
    pub max_depth: Option<u32>,
    /// The coordinates, in `[0, 1)`.
    pub coords: Vec<f64>,
}

/// Writes a primary-sample dump: `# sampler` and `# max_depth` header
/// lines, then one coordinate per line (shortest round-trip decimal form).
pub fn write_pss(path: &Path, dump: &PssDump) -> Result<(), String> {
    let mut text = String::from("# mcmc-render primary-sample vector (one coordinate per line)\n");
    text.push_str(&format!("# sampler {}\n", dump.sampler.name()));
    if let Some(d) = dump.max_depth {
        text.push_str(&format!("# max_depth {d}\n"));
    }
    for c in &dump.coords {
        text.push_str(&format!("{c:?}\n"));
    }
    mcmc_core::checkpoint::write_bytes(path, text.as_bytes())
}

/// Reads a file written by [`write_pss`]. A file without a `# sampler`
/// line is taken as a path-tracer dump at the scene's depth.
pub fn read_pss(path: &Path) -> Result<PssDump, String> {
    crate::resources::regular_file(path)?;
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    parse_pss(&text, path)
}

/// Parses the text of a dump, as [`read_pss`] reads it from a file;
/// `path` names it in messages.
pub fn parse_pss(text: &str, path: &Path) -> Result<PssDump, String> {
    let mut dump = PssDump {
        sampler: DumpSampler::Pt,
        max_depth: None,
        coords: Vec::new(),
    };
    for (n, line) in text.lines().enumerate() {
        let t = line.trim();
        let at = || format!("{}:{}", path.display(), n + 1);
        if let Some(comment) = t.strip_prefix('#') {
            let comment = comment.trim();
            if let Some(name) = comment.strip_prefix("sampler ") {
                dump.sampler = match name.trim() {
                    "pt" => DumpSampler::Pt,
                    "bdpt" => DumpSampler::Bdpt,
                    "mmlt" => DumpSampler::Mmlt,
                    other => {
                        return Err(format!(
                            "{}: unknown sampler `{other}` (pt, bdpt or mmlt)",
                            at()
                        ));
                    }
                };
            } else if let Some(d) = comment.strip_prefix("max_depth ") {
                let d: u32 = d
                    .trim()
                    .parse()
                    .map_err(|_| format!("{}: max_depth is not a count: {}", at(), d.trim()))?;
                dump.max_depth = Some(d);
            }
            continue;
        }
        if t.is_empty() {
            continue;
        }
        let v: f64 = t
            .parse()
            .map_err(|_| format!("{}: not a number: {t}", at()))?;
        if !(0.0..1.0).contains(&v) {
            return Err(format!("{}: coordinate {v} is outside [0, 1)", at()));
        }
        dump.coords.push(v);
    }
    if dump.coords.is_empty() {
        return Err(format!("{}: no coordinates", path.display()));
    }
    Ok(dump)
}

/// One re-traced evaluation of a dump.
pub struct ReplayTrace {
    /// The MMLT target depth it was traced at (`None` for PSSMLT dumps).
    pub target_depth: Option<usize>,
    /// What the path sampler returned.
    pub evaluation: Evaluation<PathSample>,
}

/// What re-tracing a dump gave.
pub struct Replay {
    /// Coordinates the traces read (beyond the file's, drawn from seed 0).
    pub coordinates_read: usize,
    /// One trace per target (one per depth for an MMLT dump).
    pub traces: Vec<ReplayTrace>,
}

/// Re-traces the path of `dump` with the sampler it records. Coordinates
/// beyond the file are drawn from a fixed seed (a NaN path reads only
/// dumped ones). An MMLT dump does not record the path depth of its chain,
/// so it is traced at every depth.
pub fn replay(scene: &Scene, dump: &PssDump) -> Result<Replay, String> {
    let point = TorusPoint::from_values(&dump.coords, stream_rng(0, 0));
    let max_depth = dump.max_depth.unwrap_or(scene.integrator.max_depth);
    let rr_depth = scene.integrator.rr_depth;
    let bdpt = Bdpt {
        max_depth,
        rr_depth,
        heuristic: MisHeuristic::Power,
    };
    let one = |evaluation| {
        vec![ReplayTrace {
            target_depth: None,
            evaluation,
        }]
    };
    let traces = match dump.sampler {
        DumpSampler::Pt => {
            let sampler = PathTracer {
                max_depth,
                rr_depth,
            };
            one(PssTarget { scene, sampler }.trace(&point))
        }
        DumpSampler::Bdpt => one(PssTarget {
            scene,
            sampler: bdpt,
        }
        .trace(&point)),
        DumpSampler::Mmlt => {
            if max_depth == u32::MAX || max_depth == 0 {
                return Err("an mmlt dump needs a finite max_depth ≥ 1".into());
            }
            let most = crate::integrators::mmlt::MAX_DEPTH;
            if max_depth > most {
                return Err(format!(
                    "an mmlt dump's max_depth must be at most {most} (mmlt's limit), got {max_depth}"
                ));
            }
            (1..=max_depth as usize)
                .map(|depth| {
                    let sampler = MmltDepth { bdpt, depth };
                    ReplayTrace {
                        target_depth: Some(depth),
                        evaluation: PssTarget { scene, sampler }.trace(&point),
                    }
                })
                .collect()
        }
    };
    Ok(Replay {
        coordinates_read: point.len(),
        traces,
    })
}
