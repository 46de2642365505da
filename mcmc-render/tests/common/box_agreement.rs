//! Agreement of path-space `mlt`'s image over a box of pixels with path
//! tracing's, from independent replicates, with the two controls every
//! such test runs (`tests/path_space_specular.rs`,
//! `tests/path_space_unconnectable.rs`).

use super::{MeanAgreement, masked_mean, pt_of, render_image};
use mcmc_render::integrators::RunSettings;
use mcmc_render::integrators::mlt::Mlt;
use mcmc_render::integrators::registry::IntegratorSettings;
use mcmc_render::observer::NoObserver;
use mcmc_render::scene::Scene;
use statrs::distribution::{ContinuousCDF, StudentsT};
use std::ops::Range;
use std::sync::atomic::AtomicBool;

/// The pixels `(x, y)` with `x ∈ xs`, `y ∈ ys` of a `res × res` film.
pub fn rect_mask(res: u32, xs: Range<u32>, ys: Range<u32>) -> Vec<bool> {
    (0..res * res)
        .map(|i| xs.contains(&(i % res)) && ys.contains(&(i / res)))
        .collect()
}

/// PT's box means: `k` renders of `spp` (seeds `seed0..seed0 + k`).
pub fn pt_box_reps(scene: &Scene, mask: &[bool], k: u64, spp: u32, seed0: u64) -> Vec<[f64; 3]> {
    (0..k)
        .map(|s| {
            masked_mean(
                &render_image(scene, &pt_of(scene), spp, seed0 + s),
                Some(mask),
            )
        })
        .collect()
}

/// `mlt`'s box means as the CLI runs it (seeds `0..k`, default settings
/// with `configure` applied).
pub fn mlt_box_reps(
    scene: &Scene,
    mask: &[bool],
    k: u64,
    configure: impl Fn(&mut Mlt),
) -> Vec<[f64; 3]> {
    let stop = AtomicBool::new(false);
    (0..k)
        .map(|seed| {
            let mut mlt = Mlt::default();
            configure(&mut mlt);
            let run = RunSettings {
                seed,
                ..RunSettings::default()
            };
            let out = mlt
                .render(scene, &run, &stop, &NoObserver)
                .expect("mlt runs");
            masked_mean(&out.image, Some(mask))
        })
        .collect()
}

/// Channels outside `t σ` or `bound`, whether `t σ` resolves `bound` on
/// every channel, and the comparison; `t` is Student's 0.9995 quantile on
/// the smaller replicate count less one degrees of freedom.
fn check(pt: &[[f64; 3]], test: &[[f64; 3]], bound: f64) -> (Vec<usize>, bool, MeanAgreement) {
    let a = MeanAgreement::new(pt, test);
    let dof = (pt.len().min(test.len()) - 1) as f64;
    let t = StudentsT::new(0.0, 1.0, dof)
        .expect("t distribution")
        .inverse_cdf(0.9995);
    (a.failures(t, bound), a.resolves(t, bound), a)
}

/// Asserts that `with` agrees with `pt` within `t σ` and `bound` on every
/// channel, and that `t σ` resolves `bound`; then the controls, which must
/// fail: `with` scaled by `1 + bound`, and `without` (the estimator before
/// the fix, `what` in the messages).
pub fn assert_box_agreement(
    pt: &[[f64; 3]],
    with: &[[f64; 3]],
    (what, without): (&str, &[[f64; 3]]),
    bound: f64,
) {
    let (bad, resolves, a) = check(pt, with, bound);
    eprintln!("mlt: rel {:?}\n  {a:?}", a.rel());
    assert!(bad.is_empty(), "mlt disagrees with PT: {a:?}");
    assert!(resolves, "noise too large for {bound}: {a:?}");

    let scaled: Vec<[f64; 3]> = with.iter().map(|m| m.map(|v| v * (1.0 + bound))).collect();
    let (bad, resolves, a) = check(pt, &scaled, bound);
    assert!(!bad.is_empty() || !resolves, "a {bound} bias passed: {a:?}");

    let (bad, resolves, a) = check(pt, without, bound);
    eprintln!("{what}: rel {:?}\n  {a:?}", a.rel());
    assert!(!bad.is_empty() || !resolves, "{what}: mlt passed: {a:?}");
}
