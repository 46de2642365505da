//! The bidirectional mutation's transition density `T(x→y)` against the
//! histogram of its proposals.
//!
//! # Method
//!
//! On the repo's (diffuse) Cornell box, a fixed path `x` of three segments
//! `x_0 x_1 x_2 x_3` is mutated `N` times with the fixed-length mutation
//! from one state. The proposals that regrow `x_1` alone (deletion start
//! `l = 1`, two edges deleted and added) place a new vertex `y_1`, either by
//! the light walk from `x_0` or by the camera walk from `x_2`, and the code
//! reports `T(x→y)` for it summed over both ways. `y_1` is binned by its
//! direction `ω` from `x_2`, in cells uniform in `(cos θ, φ)` about `x_2`'s
//! normal. A cell's expected count is `N ∫_cell T(x→y(ω)) d²/|cos θ_y| dω`
//! (the area density turned into solid angle at `x_2`), integrated with a
//! 6×6 midpoint rule per cell, `y(ω)` the first hit from `x_2`. Only
//! points visible from both `x_0` and `x_2` are counted, in the histogram
//! and in the integral: a point hidden from `x_2` can still be proposed by
//! the light walk (its connection then fails), but no ray from `x_2` finds
//! it. Every other proposal falls in one extra cell with expectation `N`
//! minus the rest. Cells expecting fewer than 5 are pooled. The test
//! rejects at p < 1e-4 (Pearson's chi-square, fixed seeds).
//!
//! The control replaces the sum over the two ways by the camera walk's
//! term alone (the forgotten "sum over every way to produce y"): the
//! chi-square must reject it.
//!
//! The ratio check runs the same histogram from the proposal `y` (an
//! accepted one) and compares the histogram estimate of
//! `T(x→B_y) / T(y→B_x)` (cells holding `y_1` and `x_1`) with the code's
//! integrals over the same cells, within 4σ of the counts' Poisson error.
//!
//! A second test checks the discrete part of `T` for the length-changing
//! mutation: the frequencies of the drawn (length, deletion, start, split)
//! records against [`Bidirectional::log_record_probability`].

mod common;

use common::repo_scene;
use mcmc_core::kernel::Kernel;
use mcmc_core::rng::stream_rng;
use mcmc_core::sample::Sample;
use mcmc_render::color::Rgb;
use mcmc_render::frame::Frame;
use mcmc_render::integrators::path_vertex::{Vertex, VertexKind};
use mcmc_render::path_space::bidirectional::{Invalid, MutationRecord};
use mcmc_render::path_space::{Bidirectional, Path, PathFamily};
use mcmc_render::pss::PathSample;
use mcmc_render::scene::Scene;
use statrs::distribution::{ChiSquared, ContinuousCDF};
use std::collections::HashMap;
use std::f64::consts::PI;
use std::sync::OnceLock;

const NZ: usize = 6;
const NPHI: usize = 12;
const QUAD: usize = 6;
const N: usize = 200_000;

fn cornell() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| repo_scene("cornell-box.xml", 16))
}

/// A three-segment start path with interior vertices on diffuse surfaces
/// (the first such start-up candidate of a fixed seed).
fn start_path(scene: &Scene) -> Path<'_> {
    let family = PathFamily::new(scene, Some(3));
    let mut rng = stream_rng(7, 0);
    for _ in 0..100_000 {
        let x = family.draw_candidate(&mut rng);
        if x.segments() == 3
            && x.luminance() > 0.0
            && x.all_visible()
            && x.vertices[1..3]
                .iter()
                .all(|v| v.kind == VertexKind::Surface && !v.delta)
        {
            return x;
        }
    }
    panic!("no three-segment path found");
}

fn sample_of<'s>(x: &Path<'s>) -> Sample<Path<'s>, PathSample> {
    Sample {
        state: x.clone(),
        log_density: x.log_density(),
        payload: x.sample(),
    }
}

/// The regrowth of `x_1` alone.
const RECORD: MutationRecord = MutationRecord {
    l: 1,
    deleted: 2,
    added: 2,
    s: 0,
};

/// Cell of direction `w` from `x_2` (`None` below its surface).
fn cell_of(frame: &Frame, w: glam::Vec3) -> Option<usize> {
    let l = frame.to_local(w);
    if l.z <= 0.0 || l.z.is_nan() {
        return None;
    }
    let iz = ((l.z as f64 * NZ as f64) as usize).min(NZ - 1);
    let phi = (l.y as f64).atan2(l.x as f64).rem_euclid(2.0 * PI);
    let ip = ((phi / (2.0 * PI) * NPHI as f64) as usize).min(NPHI - 1);
    Some(iz * NPHI + ip)
}

/// `y` = `x` with vertex 1 moved to `sp`.
fn moved<'s>(x: &Path<'s>, v: Vertex) -> Path<'s> {
    let mut y = x.clone();
    y.vertices[1] = v;
    y.normalize_ends();
    y.evaluate();
    y
}

/// Which `ln T` the expectation integrates.
#[derive(Clone, Copy, PartialEq)]
enum Density {
    /// The code's `T`.
    Reported,
    /// Control: the camera walk's way alone (the sum over ways dropped).
    CameraWayOnly,
}

/// Expected probability of each cell for proposals from `x` (visible from
/// both kept neighbours), by midpoint quadrature in `(cos θ, φ)`.
fn expected_masses(kernel: &Bidirectional, x: &Path<'_>, density: Density) -> Vec<f64> {
    let scene = x.scene;
    let (x0, x2) = (&x.vertices[0], &x.vertices[2]);
    let frame = Frame::from_normal(x2.sp.ng);
    let mut masses = vec![0.0; NZ * NPHI];
    let dz = 1.0 / (NZ * QUAD) as f64;
    let dphi = 2.0 * PI / (NPHI * QUAD) as f64;
    for iz in 0..NZ * QUAD {
        for ip in 0..NPHI * QUAD {
            let z = (iz as f64 + 0.5) * dz;
            let phi = (ip as f64 + 0.5) * dphi;
            let r = (1.0 - z * z).sqrt();
            let local = glam::Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
            let w = frame.to_world(local).normalize();
            let Some(hit) = scene.intersect(&x2.sp.spawn_ray(w)) else {
                continue;
            };
            let sp = hit.sp;
            if !scene.geometry.visible(&x0.sp, &sp) {
                continue;
            }
            let y = moved(x, Vertex::surface(scene, sp, -w, Rgb::WHITE));
            let ln_t = match density {
                Density::Reported => kernel.log_transition_density(x, &y, &RECORD),
                Density::CameraWayOnly => {
                    let full = kernel.log_transition_density(x, &y, &RECORD);
                    let ways = [
                        y.log_regrowth_density(1, 1, 0),
                        y.log_regrowth_density(1, 1, 1),
                    ];
                    full - mcmc_core::math::log_sum_exp(&ways) + ways[0]
                }
            };
            if ln_t == f64::NEG_INFINITY {
                continue;
            }
            let d = sp.p - x2.p();
            let d2 = d.length_squared() as f64;
            let cos_y = (sp.ng.dot(w) as f64).abs();
            let t_omega = ln_t.exp() * d2 / cos_y;
            let cell = cell_of(&frame, w).expect("upper hemisphere");
            masses[cell] += t_omega * dz * dphi;
        }
    }
    masses
}

/// Histogram of `N` proposals from `x`: counts per cell of the `y_1` of
/// proposals with [`RECORD`] visible from `x_0` and `x_2`; also one
/// accepted-able proposal `y` (valid, positive contribution).
fn histogram<'s>(x: &Path<'s>, seed: u64) -> (Vec<u64>, Option<Path<'s>>) {
    let scene = x.scene;
    let mut kernel = Bidirectional::new(1, Some(3), true);
    let current = sample_of(x);
    let mut proposal = sample_of(x);
    let mut rng = stream_rng(seed, 0);
    let frame = Frame::from_normal(x.vertices[2].sp.ng);
    let (x0, x2) = (&x.vertices[0], &x.vertices[2]);
    let mut counts = vec![0u64; NZ * NPHI];
    let mut some_y = None;
    for _ in 0..N {
        let p = kernel.propose(&current, &mut proposal, &mut rng);
        let Some(rec) = kernel.last_record() else {
            continue;
        };
        if (rec.l, rec.deleted, rec.added) != (RECORD.l, RECORD.deleted, RECORD.added) {
            continue;
        }
        // A walk that ended early assembled no proposal.
        if p.failed && p.component == Invalid::WalkEnded as usize {
            continue;
        }
        let y = &proposal.state;
        let y1 = &y.vertices[1];
        let Some(w) = (y1.p() - x2.p()).try_normalize() else {
            continue;
        };
        if !(scene.geometry.visible(&x0.sp, &y1.sp) && scene.geometry.visible(&x2.sp, &y1.sp)) {
            continue;
        }
        if let Some(c) = cell_of(&frame, w) {
            counts[c] += 1;
        }
        if some_y.is_none() && !p.failed && y.luminance() > 0.0 {
            some_y = Some(y.clone());
        }
    }
    (counts, some_y)
}

#[test]
fn bidirectional_density_matches_its_proposals() {
    let scene = cornell();
    let x = start_path(scene);
    let kernel = Bidirectional::new(1, Some(3), true);
    let masses = expected_masses(&kernel, &x, Density::Reported);
    let (counts, y) = histogram(&x, 11);
    let p = common::chi_square_p_value(&counts, &masses, N);
    assert!(p > 1e-4, "T(x→·) disagrees with the proposals: p = {p:.2e}");

    // The control: the camera walk's way alone.
    let wrong = expected_masses(&kernel, &x, Density::CameraWayOnly);
    let p_wrong = common::chi_square_p_value(&counts, &wrong, N);
    assert!(
        p_wrong < 1e-4,
        "a density without the sum over ways passed: p = {p_wrong:.2e}"
    );

    // From the proposal y back: its own histogram, and the ratio of the
    // two densities over the cells holding y_1 and x_1.
    let y = y.expect("a valid proposal");
    let masses_y = expected_masses(&kernel, &y, Density::Reported);
    let (counts_y, _) = histogram(&y, 12);
    let p_y = common::chi_square_p_value(&counts_y, &masses_y, N);
    assert!(
        p_y > 1e-4,
        "T(y→·) disagrees with the proposals: p = {p_y:.2e}"
    );
    let frame = Frame::from_normal(x.vertices[2].sp.ng);
    let x2 = x.vertices[2].p();
    let by = cell_of(&frame, (y.vertices[1].p() - x2).normalize()).expect("y_1 in front");
    let bx = cell_of(&frame, (x.vertices[1].p() - x2).normalize()).expect("x_1 in front");
    let (oa, ob) = (counts[by] as f64, counts_y[bx] as f64);
    assert!(oa > 100.0 && ob > 100.0, "cells not resolved: {oa}, {ob}");
    let observed = (oa / ob).ln();
    let reported = (masses[by] / masses_y[bx]).ln();
    let sigma = (1.0 / oa + 1.0 / ob).sqrt();
    eprintln!("ln ratio: histograms {observed:.4}, code {reported:.4}, σ {sigma:.4}");
    assert!(
        (observed - reported).abs() < 4.0 * sigma,
        "T(x→y)/T(y→x): histograms {observed}, code {reported} (σ {sigma})"
    );
}

#[test]
fn length_changing_choices_match_their_probabilities() {
    // The discrete part of T: the (length, deletion, start, split) records
    // drawn from one path against `log_record_probability`, by chi-square
    // over the records (failed proposals included: the records are drawn
    // before any walk), plus one cell for the draws that found no valid
    // deletion start.
    let scene = cornell();
    let x = start_path(scene);
    let mut kernel = Bidirectional::new(1, Some(6), false);
    let current = sample_of(&x);
    let mut proposal = sample_of(&x);
    let mut rng = stream_rng(21, 0);
    let n = 100_000u64;
    let mut seen: HashMap<(usize, usize, usize, usize), u64> = HashMap::new();
    for _ in 0..n {
        kernel.propose(&current, &mut proposal, &mut rng);
        if let Some(r) = kernel.last_record() {
            *seen.entry((r.l, r.deleted, r.added, r.s)).or_default() += 1;
        }
    }
    // Every record the move can draw from x: lengths 1..=6 segments.
    let k = x.segments();
    let mut total_p = 0.0;
    let mut cells = Vec::new();
    for deleted in 1..=k + 2 {
        for added in 1..=8 + deleted {
            for l in 0..=k + 2 {
                for s in 0..added {
                    let rec = MutationRecord {
                        l,
                        deleted,
                        added,
                        s,
                    };
                    let p = kernel.log_record_probability(&x, &rec).exp();
                    if p > 0.0 {
                        total_p += p;
                        let o = seen.remove(&(l, deleted, added, s)).unwrap_or(0);
                        cells.push((p * n as f64, o as f64));
                    }
                }
            }
        }
    }
    assert!(
        seen.is_empty(),
        "records the pmf says are impossible: {seen:?}"
    );
    // The rest: drawn lengths with no valid deletion start (failed, no record).
    let recorded: f64 = cells.iter().map(|c| c.1).sum();
    cells.push(((1.0 - total_p) * n as f64, n as f64 - recorded));
    let (mut pool_e, mut pool_o) = (0.0, 0.0);
    let mut kept = Vec::new();
    for (e, o) in cells {
        if e < 5.0 {
            pool_e += e;
            pool_o += o;
        } else {
            kept.push((e, o));
        }
    }
    if pool_e > 0.0 {
        kept.push((pool_e, pool_o));
    }
    let chi2: f64 = kept.iter().map(|(e, o)| (o - e).powi(2) / e).sum();
    let p = ChiSquared::new(kept.len() as f64 - 1.0).unwrap().sf(chi2);
    assert!(
        p > 1e-4,
        "record frequencies disagree: chi2 {chi2}, p {p:.2e}"
    );
}

#[test]
fn two_tailed_geometric_is_a_pmf() {
    // Bounded and unbounded supports, centres inside, at and outside the
    // ends: the pmf sums to 1 (to 1e-12), has its mode at the centre when
    // the centre is inside, halves per step away from it, and inversion
    // returns every value with its probability on a fine grid of u.
    use mcmc_render::path_space::bidirectional::TwoTailedGeometric;
    for (center, lo, hi) in [
        (2, 1, Some(5)),
        (2, 2, Some(2)),
        (5, 3, Some(12)),
        (1, 3, Some(9)),
        (20, 3, Some(9)),
        (4, 3, None),
        (0, 1, None),
    ] {
        let d = TwoTailedGeometric { center, lo, hi };
        let top = hi.unwrap_or(lo + 80);
        let total: f64 = (lo..=top).map(|i| d.pmf(i)).sum();
        assert!((total - 1.0).abs() < 1e-12, "{d:?}: sums to {total}");
        assert_eq!(d.pmf(lo - 1), 0.0);
        if let Some(h) = hi {
            assert_eq!(d.pmf(h + 1), 0.0);
        }
        if (lo + 1..=top).contains(&center) {
            assert!((d.pmf(center - 1) / d.pmf(center) - 0.5).abs() < 1e-12);
        }
        let grid = 1 << 16;
        let mut counts = HashMap::new();
        for j in 0..grid {
            let u = (j as f64 + 0.5) / grid as f64;
            *counts
                .entry(d.sample(u).expect("non-empty"))
                .or_insert(0u64) += 1;
        }
        for (i, c) in counts {
            let p = d.pmf(i);
            assert!(p > 0.0, "{d:?}: sampled {i} outside the support");
            assert!(
                (c as f64 / grid as f64 - p).abs() <= 1.0 / grid as f64 + 1e-12,
                "{d:?}: {i} drawn {c} times, pmf {p}"
            );
        }
    }
    let empty = TwoTailedGeometric {
        center: 2,
        lo: 4,
        hi: Some(3),
    };
    assert_eq!(empty.sample(0.5), None);
    assert_eq!(empty.pmf(3), 0.0);
}

#[test]
fn degenerate_paths_are_outside_the_support() {
    // An empty path, a lone vertex and a NaN contribution: ln I is −∞,
    // −∞ and NaN (which mcmc-core rejects and counts).
    use mcmc_core::target::Target;
    use mcmc_render::path_space::PathTarget;
    let scene = cornell();
    let mut p = Path::new(scene);
    assert_eq!(
        PathTarget::default().evaluate(&p).log_density,
        f64::NEG_INFINITY
    );
    let x = start_path(scene);
    p.vertices = vec![x.vertices[0]];
    p.evaluate();
    assert_eq!(p.log_density(), f64::NEG_INFINITY);
    let mut q = x.clone();
    q.contribution = Rgb::new(f32::NAN, 1.0, 1.0);
    assert!(q.log_density().is_nan());
    q.contribution = Rgb::new(f32::INFINITY, 1.0, 1.0);
    assert!(q.log_density().is_nan());
    // The start path: finite, positive, one splat at its raster position.
    let e = PathTarget::default().evaluate(&x);
    assert!(e.log_density.is_finite());
    assert_eq!(e.payload.splats.len(), 1);
    assert_eq!(e.payload.splats[0].p, x.raster);
    assert_eq!(e.payload.depth, 3);
}
