//! A Markov-chain run as the registry reports it: the image, the JSON
//! statistics of the sidecar, the NaN dump and the terminal line.

use super::MltResult;
use crate::integrators::Rendered;
use crate::pss_dump::{DumpSampler, PssDump};
use serde_json::{Value, json};

fn rate(n: u64, seconds: f64) -> f64 {
    if seconds > 0.0 {
        n as f64 / seconds
    } else {
        0.0
    }
}

/// Each member's share of the image's mean luminance (NaN for a black
/// image).
fn image_shares(result: &MltResult) -> Vec<f64> {
    let means: Vec<f64> = result
        .families
        .iter()
        .map(|f| f.image().iter().map(|c| f64::from(c.luminance())).sum())
        .collect();
    let total: f64 = means.iter().sum();
    means.iter().map(|m| m / total).collect()
}

/// The report of `result`. `sampler` and `max_depth` go into the NaN dump;
/// with `members_are_depths` member `d` is labelled path depth `d + 1`
/// (MMLT), else 0.
pub fn rendered(
    result: &MltResult,
    sampler: DumpSampler,
    max_depth: u32,
    members_are_depths: bool,
) -> Rendered {
    let cs = &result.chain_stats;
    let image_shares = image_shares(result);
    let mutations_per_second = rate(result.mutations, result.seconds - result.bootstrap_seconds);
    let statistics = json!({
        "bootstrap_seconds": result.bootstrap_seconds,
        "bootstrap_candidates": result.bootstrap_candidates,
        // Stopped before the chains moved: the image is the candidates'.
        "image_from_start_up": result.startup_image.is_some(),
        "mutations": result.mutations,
        "mutations_per_second": mutations_per_second,
        "mutations_per_pixel": result.mutations_per_pixel,
        "b_bootstrap": result.bootstrap_b.0,
        "b_bootstrap_standard_error": result.bootstrap_b.1,
        "b_running": result.running_b.0,
        "b_running_standard_error": result.running_b.1,
        "scale": result.scale,
        "scale_standard_error": result.scale_standard_error,
        "acceptance": cs.acceptance_rate(),
        "acceptance_per_component": cs.components.iter().map(|c| json!({
            "name": c.name,
            "proposed": c.proposed,
            "accepted": c.accepted,
            "acceptance": c.acceptance_rate(),
        })).collect::<Vec<_>>(),
        "acceptance_per_depth": result.per_depth,
        "families": result.families.iter().enumerate().map(|(d, f)| {
            let mut family = json!({
                "depth": if members_are_depths { d + 1 } else { 0 },
                "chains": f.chains,
                "mutations": f.mutations,
                "acceptance": result.member_stats[d].as_ref().map(|s| s.acceptance_rate()),
                "image_share": image_shares[d],
                "b_bootstrap": f.bootstrap_b.0,
                "b_bootstrap_standard_error": f.bootstrap_b.1,
                "b_running": f.running_b.0,
                "b_running_standard_error": f.running_b.1,
                "scale": f.scale,
                "scale_standard_error": f.scale_standard_error,
            });
            // normalization=filmed: the filmed part's b̃ and the chains'
            // share of it (the running scale's excess is b·share/b̃ − 1).
            if let Some(((b, b_se), (share, share_se))) = f.filmed {
                family["b_filmed"] = json!(b);
                family["b_filmed_standard_error"] = json!(b_se);
                family["filmed_share"] = json!(share);
                family["filmed_share_standard_error"] = json!(share_se);
            }
            family
        }).collect::<Vec<_>>(),
        "nonfinite_contributions": cs.invalid_density,
        "nonfinite_bootstrap_candidates": result.bootstrap_invalid,
    });
    let mut statistics = match statistics {
        Value::Object(m) => m,
        _ => unreachable!("json! of an object literal is an object"),
    };
    if let Some(exchange) = &result.exchange {
        statistics.insert("exchange".into(), json!(exchange));
    }
    if result.searches.iter().any(Option::is_some) {
        statistics.insert("searches".into(), json!(result.searches));
    }
    if let Some(annealing) = &result.annealing {
        statistics.insert("annealing".into(), json!(annealing));
    }
    if !result.ranks.is_empty() {
        statistics.insert("ranks".into(), json!(result.ranks));
    }
    if let Some((resumed, error)) = &result.checkpoint {
        statistics.insert(
            "checkpoint".into(),
            // `total_mutations`: where the run ended, as
            // `crate::checkpoint::Checkpoint::statistics` has it.
            json!({
                "resumed_from_mutations": resumed,
                "total_mutations": result.mutations,
                "error": error,
            }),
        );
    }
    Rendered {
        image: result.image(),
        seconds: result.seconds,
        samples: result.mutations,
        interrupted: result.interrupted,
        statistics,
        nonfinite_dump: result.first_nonfinite.as_ref().map(|coords| PssDump {
            sampler,
            max_depth: Some(max_depth),
            coords: coords.clone(),
        }),
        layers: Vec::new(),
        summary: format!(
            "{} mutations in {:.2} s ({:.3} M mutations/s, bootstrap {:.2} s), b = {:.5} ± {:.5}{}",
            result.mutations,
            result.seconds,
            mutations_per_second / 1e6,
            result.bootstrap_seconds,
            result.scale,
            result.scale_standard_error,
            match (result.interrupted, &result.startup_image) {
                (true, Some(_)) => format!(
                    ", stopped early: the image is the start-up's {} independent candidates per member",
                    result.bootstrap_candidates
                ),
                (true, None) => ", stopped early".into(),
                (false, _) => String::new(),
            },
        ),
    }
}

/// Adds `result`'s sample-count image to `rendered` as the `samples` layer
/// (`<out>.samples.exr`, the image `smcmc` writes too) and its max/median
/// ratio to the statistics (`samples_per_pixel_max_over_median`).
pub fn with_sample_counts(result: &MltResult, mut rendered: Rendered) -> Rendered {
    let (layer, ratio) = result.sample_count_layer();
    rendered.layers.push(("samples".into(), layer));
    rendered
        .statistics
        .insert("samples_per_pixel_max_over_median".into(), json!(ratio));
    rendered
}
