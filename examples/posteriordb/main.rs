//! Our NUTS on reference posteriors from posteriordb; see
//! `mcmc_examples::posteriordb`.
//!
//! ```text
//! cargo run --release --example posteriordb
//! cargo run --release --example posteriordb -- --json
//! cargo run --release --example posteriordb -- --posteriors arK-arK,sblrc-blr --draws 4000
//! ```
//!
//! Flags: `--chains N` (4), `--warmup N` (1000), `--draws N` (1000),
//! `--seed N` (1), `--adapt-delta δ` (0.8), `--posteriors a,b` (all),
//! `--json`, `--out DIR` (also write each posterior's constrained draws and
//! sampler statistics as CmdStan CSV files and one `.npz`). Every posterior
//! runs with the same settings (`NutsSettings::default()`). Warm-up:
//! `--init-buffer N`, `--window N`, `--term-buffer N` (CmdStan's names;
//! defaults 75 / 25 / 150), `--step-size continuous|restart` (restart is
//! CmdStan's dual averaging, restarted at every metric update),
//! `--acceptance stan|symmetric-late` (the statistic dual averaging steers;
//! default symmetric-late, nuts-rs's from the last metric window on);
//! `--init-radius r` (initial points uniform in `[−r, r]^d` on the
//! unconstrained space, Stan's 2); `--stiff-inits redraw|keep` (default
//! redraw: a random initial point where Stan's step-size heuristic finds no
//! step ≥ 10⁻¹⁰ is drawn again; keep is Stan's rule);
//! `--metric diagonal|gradient|gradient-early|dense` (the metric the
//! warm-up estimates: `MetricAdaptation::Diagonal`, `DiagonalGradient`,
//! `DiagonalGradientEarly`, `Dense`).

use mcmc_core::adaptation::{AcceptanceStatistic, MetricAdaptation, StepSizeAdaptation};
use mcmc_core::fit::NutsSettings;
use mcmc_examples::posteriordb::{PosteriorReport, load, names, run, write_outputs};

struct Options {
    json: bool,
    settings: NutsSettings,
    posteriors: Vec<String>,
    out: Option<std::path::PathBuf>,
}

fn parse() -> Result<Options, String> {
    let mut o = Options {
        json: false,
        settings: NutsSettings::default(),
        posteriors: names().into_iter().map(String::from).collect(),
        out: None,
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = |name: &str| args.next().ok_or_else(|| format!("{name} needs a value"));
        let s = &mut o.settings;
        match a.as_str() {
            "--json" => o.json = true,
            "--out" => o.out = Some(value(&a)?.into()),
            "--chains" => s.chains = number(&a, &value(&a)?)?,
            "--warmup" => s.warmup = number(&a, &value(&a)?)?,
            "--draws" => s.draws = number(&a, &value(&a)?)?,
            "--seed" => s.seed = number(&a, &value(&a)?)?,
            "--adapt-delta" => {
                s.target_accept = number(&a, &value(&a)?)?;
                if !(s.target_accept > 0.0 && s.target_accept < 1.0) {
                    return Err("--adapt-delta must lie in (0, 1)".into());
                }
            }
            "--init-radius" => {
                s.init_radius = number(&a, &value(&a)?)?;
                if !(s.init_radius.is_finite() && s.init_radius >= 0.0) {
                    return Err("--init-radius must be finite and non-negative".into());
                }
            }
            "--stiff-inits" => {
                s.retry_stiff_inits = match value(&a)?.as_str() {
                    "redraw" => true,
                    "keep" => false,
                    other => {
                        return Err(format!(
                            "--stiff-inits: `{other}` (expected redraw or keep)"
                        ));
                    }
                }
            }
            "--metric" => {
                s.metric = match value(&a)?.as_str() {
                    "diagonal" => MetricAdaptation::Diagonal,
                    "gradient" => MetricAdaptation::DiagonalGradient,
                    "gradient-early" => MetricAdaptation::DiagonalGradientEarly,
                    "dense" => MetricAdaptation::Dense,
                    other => {
                        return Err(format!(
                            "--metric: `{other}` (expected diagonal, gradient, gradient-early or dense)"
                        ));
                    }
                }
            }
            "--init-buffer" => s.init_buffer = number(&a, &value(&a)?)?,
            "--window" => s.window = number(&a, &value(&a)?)?,
            "--term-buffer" => s.term_buffer = number(&a, &value(&a)?)?,
            "--acceptance" => {
                s.acceptance_statistic = match value(&a)?.as_str() {
                    "stan" => AcceptanceStatistic::Stan,
                    "symmetric-late" => AcceptanceStatistic::SymmetricLate,
                    other => {
                        return Err(format!(
                            "--acceptance: `{other}` (expected stan or symmetric-late)"
                        ));
                    }
                }
            }
            "--step-size" => {
                s.step_size_adaptation = match value(&a)?.as_str() {
                    "continuous" => StepSizeAdaptation::Continuous,
                    "restart" => StepSizeAdaptation::Restart,
                    other => {
                        return Err(format!(
                            "--step-size: `{other}` (expected continuous or restart)"
                        ));
                    }
                }
            }
            "--posteriors" => {
                o.posteriors = value(&a)?.split(',').map(String::from).collect();
                let known = names();
                if let Some(bad) = o.posteriors.iter().find(|p| !known.contains(&p.as_str())) {
                    return Err(format!(
                        "--posteriors: unknown posterior `{bad}` (known: {})",
                        known.join(", ")
                    ));
                }
            }
            other => {
                return Err(format!(
                    "unknown argument `{other}` (expected --json, --chains N, --warmup N, --draws N, --seed N, --adapt-delta δ, --init-radius r, --stiff-inits redraw|keep, --metric diagonal|gradient|gradient-early|dense, --init-buffer N, --window N, --term-buffer N, --step-size continuous|restart, --acceptance stan|symmetric-late, --posteriors a,b, --out DIR)"
                ));
            }
        }
    }
    if o.settings.chains == 0 || o.settings.draws < 4 {
        return Err("need at least 1 chain and 4 draws".into());
    }
    Ok(o)
}

fn number<T: std::str::FromStr>(flag: &str, v: &str) -> Result<T, String>
where
    T::Err: std::fmt::Display,
{
    v.parse().map_err(|e| format!("{flag}: `{v}`: {e}"))
}

fn main() {
    let o = parse().unwrap_or_else(|e| fail(&e));
    let mut reports = Vec::new();
    for name in &o.posteriors {
        let p = load(name).unwrap_or_else(|e| fail(&e));
        let (report, fit) = run(&p, &o.settings).unwrap_or_else(|e| fail(&e));
        if let Some(dir) = &o.out {
            write_outputs(dir, &p, &fit).unwrap_or_else(|e| fail(&e));
        }
        reports.push(report);
    }
    if o.json {
        println!(
            "{}",
            serde_json::to_string(&reports).expect("plain data serialises")
        );
        return;
    }
    for r in &reports {
        print_detail(r);
    }
    print_overview(&reports);
}

fn fail(e: &str) -> ! {
    eprintln!("error: {e}");
    std::process::exit(2);
}

fn print_detail(r: &PosteriorReport) {
    println!("{} (d = {})", r.posterior, r.dim);
    println!(
        "  {:<10} {:>11} {:>11} {:>7} {:>10} {:>10} {:>7} {:>7} {:>6}",
        "quantity", "ref mean", "mean", "z", "ref sd", "sd", "z", "ESS", "R-hat"
    );
    for q in &r.quantities {
        println!(
            "  {:<10} {:>11.4} {:>11.4} {:>7.2} {:>10.4} {:>10.4} {:>7.2} {:>7.0} {:>6.3}",
            q.name,
            q.reference_mean,
            q.mean,
            q.z_mean,
            q.reference_sd,
            q.sd,
            q.z_sd,
            q.ess_bulk,
            q.rhat
        );
    }
    for (c, ch) in r.chains.iter().enumerate() {
        let metric: Vec<String> = ch
            .inverse_metric_diagonal
            .iter()
            .map(|v| format!("{v:.3e}"))
            .collect();
        println!(
            "  chain {c}: step {:.4}, accept_stat {:.3}, leapfrog/draw {:.1}, divergences {}, M⁻¹ diag [{}]",
            ch.step_size,
            ch.accept_stat_mean,
            ch.leapfrog_mean,
            ch.divergences,
            metric.join(", ")
        );
    }
    println!();
}

fn print_overview(reports: &[PosteriorReport]) {
    println!(
        "{:<40} {:>3} {:>10} {:>8} {:>9} {:>5} {:>7} {:>6} {:>7}",
        "posterior", "d", "gradients", "ESS min", "ESS/grad", "div", "max|z|", "R-hat", "seconds"
    );
    for r in reports {
        let div = if r.divergences_expected && r.divergences > 0 {
            format!("{}*", r.divergences)
        } else {
            r.divergences.to_string()
        };
        println!(
            "{:<40} {:>3} {:>10} {:>8.0} {:>9.4} {:>5} {:>7.2} {:>6.3} {:>7.2}",
            r.posterior,
            r.dim,
            r.gradient_evaluations,
            r.ess_bulk_min,
            r.ess_per_gradient,
            div,
            r.max_abs_z,
            r.rhat_max,
            r.seconds
        );
    }
    if reports.iter().any(|r| r.divergences_expected) {
        println!("* expected: the centred eight schools' funnel (compare the non-centred run)");
    }
}
