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

// ---------------------------------------------------------------------
// Through a Dirac vertex.
//
// A diffuse floor under a smooth glass ceiling (a dielectric rectangle
// facing down), a small spherical lamp between them. The start path is
// `x_0` (lamp) `x_1` (floor) `x_2` (ceiling, reflection: Dirac) `x_3`
// (floor) `x_4` (camera). The fixed-length move that deletes `x_1 x_2`
// (start `l = 1`, three edges deleted and added) can make a path of this
// pattern only one way: the camera walk from `x_3` hits the ceiling,
// reflects (the lobe chosen with probability `F`, Fresnel) and lands on
// `y_1`, which connects to `x_0`; a split with a light-walk vertex would
// connect at the Dirac vertex (`NotConnectible`). The reported `T(x→y)`
// is then `P(record) · (1/#s) · p_ω(x_3→y_2) cos_2/d²_32 · F cos_1/d²_21`:
// after the Dirac vertex the camera walk's density is the lobe
// probability `F` turned into area at `y_1`, as BDPT turns it.
//
// The histogram bins the direction `x_3 → y_2` about `x_3`'s normal (the
// move's one continuous choice) over the proposals of that record whose
// `y_2` is on the ceiling and whose `y_1` is a floor point visible from
// `x_0` (failed connections at Dirac vertices and ended walks excluded);
// the expectation integrates `T · d²/|cos θ_y2|` over each cell with the
// same conditions. Controls, which the chi-square must reject: `T / F`
// (the lobe's selection probability dropped, the Dirac vertex taken as
// certain) and `T` without the Dirac segment's area factor.
// ---------------------------------------------------------------------

/// Floor, glass ceiling, small lamp; 32×32, paths of up to 4 segments.
fn glass_ceiling() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| {
        common::load_str(
            r#"<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="4"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="50"/>
        <transform name="to_world"><lookat origin="0, 0.8, 2.5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
        <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/><rfilter type="box"/></film>
    </sensor>
    <shape type="rectangle">
        <transform name="to_world"><scale x="5" y="5" z="1"/><rotate x="1" y="0" z="0" angle="-90"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><scale x="5" y="5" z="1"/><rotate x="1" y="0" z="0" angle="90"/><translate x="0" y="1.2" z="0"/></transform>
        <bsdf type="dielectric"><float name="int_ior" value="1.5"/><float name="ext_ior" value="1.0"/></bsdf>
    </shape>
    <shape type="sphere">
        <transform name="to_world"><scale x="0.05" y="0.05" z="0.05"/><translate x="-0.3" y="0.6" z="-0.2"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0, 0, 0"/></bsdf>
        <emitter type="area"><rgb name="radiance" value="50, 50, 50"/></emitter>
    </shape>
</scene>"#,
        )
    })
}

/// A start path `L D S D E` with the Dirac vertex on the ceiling (the
/// first such start-up candidate of a fixed seed).
fn dirac_start_path(scene: &Scene) -> Path<'_> {
    let family = PathFamily::new(scene, Some(4));
    let mut rng = stream_rng(5, 0);
    for _ in 0..200_000 {
        let x = family.draw_candidate(&mut rng);
        let v = &x.vertices;
        if x.segments() == 4
            && x.luminance() > 0.0
            && x.all_visible()
            && v[2].delta
            && [1, 3]
                .iter()
                .all(|&i| v[i].kind == VertexKind::Surface && !v[i].delta && !v[i].is_light())
        {
            return x;
        }
    }
    panic!("no L D S D E path found");
}

/// The regrowth of `x_1 x_2`.
const DIRAC_RECORD: MutationRecord = MutationRecord {
    l: 1,
    deleted: 3,
    added: 3,
    s: 0,
};

/// Whether a proposal with new vertices `y1`, `y2` is counted: `y2` on a
/// Dirac surface, `y1` on a non-Dirac, non-emitting one visible from `x0`.
fn dirac_counted(scene: &Scene, x0: &Vertex, y1: &Vertex, y2: &Vertex) -> bool {
    scene.bsdf_at(&y2.sp).is_delta()
        && !scene.bsdf_at(&y1.sp).is_delta()
        && !y1.is_light()
        && scene.geometry.visible(&x0.sp, &y1.sp)
}

/// Which `T` the Dirac expectation integrates.
#[derive(Clone, Copy, PartialEq)]
enum DiracDensity {
    /// The code's `T`.
    Reported,
    /// Control: `T / F`, the lobe's selection probability dropped.
    LobeDropped,
    /// Control: `T` taken as a density in `x_3`'s solid angle times the
    /// lobe probability alone (the area factor of the Dirac segment
    /// `y_2 y_1` forgotten).
    SegmentFactorDropped,
}

/// Expected probability of each cell of the direction `x_3 → y_2`, by
/// midpoint quadrature of `T` in `(cos θ, φ)`. `T` is a density in the
/// area at `y_2` and, through the Dirac vertex, in the area at `y_1`
/// (`pdf_rev(y_1) = F |cos θ_1| / d²_21`, BDPT's convention), so the
/// density of the proposal's one continuous choice, the direction at
/// `x_3`, is `T · d²_32/|cos θ_2| · d²_21/|cos θ_1|`.
fn dirac_expected_masses(kernel: &Bidirectional, x: &Path<'_>, density: DiracDensity) -> Vec<f64> {
    use mcmc_render::bsdf::TransportMode;
    use mcmc_render::path_space::state::dirac_lobe;
    let scene = x.scene;
    let (x0, x3) = (&x.vertices[0], &x.vertices[3]);
    let frame = Frame::from_normal(x3.sp.ng);
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
            let Some(hit2) = scene.intersect(&x3.sp.spawn_ray(w)) else {
                continue;
            };
            let mut y2 = Vertex::surface(scene, hit2.sp, -w, Rgb::WHITE);
            y2.delta = true;
            // The mirror direction about the ceiling's normal.
            let n = hit2.sp.ng;
            let wr = (w - 2.0 * w.dot(n) * n).normalize();
            let Some(hit1) = scene.intersect(&hit2.sp.spawn_ray(wr)) else {
                continue;
            };
            let y1 = Vertex::surface(scene, hit1.sp, -wr, Rgb::WHITE);
            if !dirac_counted(scene, x0, &y1, &y2) {
                continue;
            }
            let mut y = x.clone();
            y.vertices[1] = y1;
            y.vertices[2] = y2;
            y.normalize_ends();
            y.evaluate();
            let mut ln_t = kernel.log_transition_density(x, &y, &DIRAC_RECORD);
            if ln_t == f64::NEG_INFINITY {
                continue;
            }
            if density == DiracDensity::LobeDropped {
                let (p, _) = dirac_lobe(scene, &y2, -w, wr, TransportMode::Radiance)
                    .expect("a reflection lobe");
                ln_t -= (p as f64).ln();
            }
            let d2 = (hit2.sp.p - x3.p()).length_squared() as f64;
            let cos_y = (n.dot(w) as f64).abs();
            let segment = if density == DiracDensity::SegmentFactorDropped {
                1.0
            } else {
                let d2_21 = (hit1.sp.p - hit2.sp.p).length_squared() as f64;
                d2_21 / (hit1.sp.ng.dot(wr) as f64).abs()
            };
            let cell = cell_of(&frame, w).expect("upper hemisphere");
            masses[cell] += ln_t.exp() * d2 / cos_y * segment * dz * dphi;
        }
    }
    masses
}

/// Histogram of the direction `x_3 → y_2` over `n` proposals from `x`
/// (module comment above for which are counted).
fn dirac_histogram(x: &Path<'_>, n: usize, seed: u64) -> Vec<u64> {
    let scene = x.scene;
    let mut kernel = Bidirectional::new(1, Some(4), true);
    let current = sample_of(x);
    let mut proposal = sample_of(x);
    let mut rng = stream_rng(seed, 0);
    let (x0, x3) = (&x.vertices[0], &x.vertices[3]);
    let frame = Frame::from_normal(x3.sp.ng);
    let mut counts = vec![0u64; NZ * NPHI];
    for _ in 0..n {
        let p = kernel.propose(&current, &mut proposal, &mut rng);
        let Some(rec) = kernel.last_record() else {
            continue;
        };
        if (rec.l, rec.deleted, rec.added) != (1, 3, 3) {
            continue;
        }
        if p.failed
            && (p.component == Invalid::WalkEnded as usize
                || p.component == Invalid::NotConnectible as usize)
        {
            continue;
        }
        let y = &proposal.state;
        let (y1, y2) = (&y.vertices[1], &y.vertices[2]);
        if !dirac_counted(scene, x0, y1, y2) {
            continue;
        }
        let Some(w) = (y2.p() - x3.p()).try_normalize() else {
            continue;
        };
        if let Some(c) = cell_of(&frame, w) {
            counts[c] += 1;
        }
    }
    counts
}

#[test]
fn bidirectional_density_through_a_dirac_vertex_matches_its_proposals() {
    let scene = glass_ceiling();
    let x = dirac_start_path(scene);
    let kernel = Bidirectional::new(1, Some(4), true);
    let n = 1_000_000;
    let counts = dirac_histogram(&x, n, 31);
    let counted: u64 = counts.iter().sum();
    let masses = dirac_expected_masses(&kernel, &x, DiracDensity::Reported);
    eprintln!(
        "counted {counted} of {n}; expected {:.0}",
        masses.iter().sum::<f64>() * n as f64
    );
    // Enough proposals in the cells for the test to have power (a
    // factor 2 off in one cell of ~25 expected is then ≥ 3σ).
    assert!(counted > 1500, "only {counted} proposals counted");
    let p = common::chi_square_p_value(&counts, &masses, n);
    assert!(
        p > 1e-4,
        "T(x→·) through the Dirac vertex disagrees with the proposals: p = {p:.2e}"
    );
    for control in [
        DiracDensity::LobeDropped,
        DiracDensity::SegmentFactorDropped,
    ] {
        let wrong = dirac_expected_masses(&kernel, &x, control);
        let p_wrong = common::chi_square_p_value(&counts, &wrong, n);
        assert!(
            p_wrong < 1e-4,
            "a control density passed (lobe dropped: {}): p = {p_wrong:.2e}",
            control == DiracDensity::LobeDropped
        );
    }
}

// ---------------------------------------------------------------------
// At infinity.
//
// `common::sky_scene` (a constant sky and a directional sun over a
// diffuse floor, a diffuse and a mirror sphere), 16×16, paths of 3
// segments. (A constant sky, not an environment map with a sun: the
// quadrature below must resolve the light walk's direction density, and
// the map's own sampling density is tested with BDPT's, `bdpt_mis.rs`.) The start path is `x_0` (the environment,
// at infinity) `x_1` `x_2` (diffuse, non-emitting) `x_3` (camera). From it
// the fixed-length move is run `N_INF` (500 000) times; two of its records are
// histogrammed from the same proposals:
//
// - `l = 0`, one edge pair deleted and added: `x_0` alone is regrown, by
//   the light walk (the environment's direction sampling, `pdf_fwd(y_0) =
//   P_env · p_env(ω)`) or by the camera walk from `x_1` escaping
//   (`pdf_rev(y_0)`, the BSDF's solid-angle density at `x_1`): `T` is a
//   density in the solid angle of `ω = y_0.wo`, the path state's measure
//   at infinity, so the histogram bins `ω` in cells uniform in `(cos θ,
//   φ)` about `x_1`'s normal and a cell's expectation is `N ∫_cell T dω`
//   (no Jacobian). Counted: `y_0` on the environment (not the directional
//   light, a Dirac direction of its own), seen from `x_1`.
// - `l = 1`: `x_1` alone is regrown with `x_0` at infinity kept, by the
//   light walk from `x_0`'s disk (`pdf_fwd(y_1) = |ng_1·ω| / (πR²)`) or
//   the camera walk from `x_2`; `y_1` on the floor is binned by position
//   in 12×12 cells of the floor, whose expectation is `N ∫_cell T dA` (`T`
//   is an area density there; 16×16 midpoint points per cell). Counted:
//   `y_1` on the floor, visible from `x_2` and seeing the sky along
//   `x_0`'s `ω`. (Binning by direction from `x_2`, as the Cornell test
//   does, fails here for the wrong reason: the floor's far edge, seen at
//   grazing angles, holds much of the disk walk's mass per solid angle
//   in slivers that a cell's quadrature does not resolve.)
//
// Controls, which the chi-square must reject: for `l = 0`, the light
// walk's density taken per projected solid angle (times `|cos θ_1|`, the
// cosine a disk-area or area-like measure at infinity would add) and the
// camera walk's way alone (the sum over ways dropped); for `l = 1`, the
// disk walk's cosine at `y_1` dropped. The ratio `T(x→y)/T(y→x)` of the
// `l = 0` move: the same histogram from an accepted proposal `y`, the
// counts' ratio in the cells of `y_0` and `x_0` against the code's
// integrals, within 4σ.
// ---------------------------------------------------------------------

/// Proposals per histogram at infinity: the disk-cosine control changes
/// the light walk's share by `1/|ng·ω|` ≈ 13% on the floor (nearly
/// constant there), so it takes this many (≈ 25 000 counted `l = 1`
/// proposals) to reject it at p < 1e-4 with room (χ² excess ≈ 100 on 60
/// dof; 200 000 gave p ≈ 1e-3).
const N_INF: usize = 500_000;

/// The sky scene, 16×16.
fn environment_scene() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| {
        let scene = common::sky_scene(16, 3, true);
        assert!(scene.lights.environment().is_some());
        scene
    })
}

/// True when `v` lies on a surface that is neither Dirac nor emitting.
fn plain_surface(scene: &Scene, v: &Vertex) -> bool {
    v.kind == VertexKind::Surface && !v.delta && !v.is_light() && !scene.bsdf_at(&v.sp).is_delta()
}

/// A three-segment path from the environment over two plain surfaces
/// (the first such start-up candidate of a fixed seed).
fn infinite_start_path(scene: &Scene) -> Path<'_> {
    let env = scene.lights.environment().expect("an environment");
    let family = PathFamily::new(scene, Some(3));
    let mut rng = stream_rng(3, 0);
    for _ in 0..100_000 {
        let x = family.draw_candidate(&mut rng);
        let v = &x.vertices;
        if x.segments() == 3
            && x.luminance() > 0.0
            && x.all_visible()
            && v[0].kind == VertexKind::Infinite
            && v[0].light == env
            && plain_surface(scene, &v[1])
            && plain_surface(scene, &v[2])
        {
            return x;
        }
    }
    panic!("no three-segment path from the environment found");
}

/// The regrowth of `x_0` alone, and of `x_1` alone.
const REGROW_X0: MutationRecord = MutationRecord {
    l: 0,
    deleted: 2,
    added: 2,
    s: 0,
};
const REGROW_X1: MutationRecord = MutationRecord {
    l: 1,
    deleted: 2,
    added: 2,
    s: 0,
};

/// Which `T` the expectations at infinity integrate.
#[derive(Clone, Copy, PartialEq)]
enum InfiniteDensity {
    /// The code's `T`.
    Reported,
    /// Control (`l = 0`): the light walk's term times `|cos θ_1|`.
    ProjectedLightWay,
    /// Control (`l = 0`): the camera walk's way alone.
    CameraWayOnly,
    /// Control (`l = 1`): the disk walk's cosine at `y_1` dropped.
    DiskCosineDropped,
}

/// `ln T(x→y)` of `record` (one new vertex at `record.l`), or a control.
fn infinite_log_t(
    kernel: &Bidirectional,
    x: &Path<'_>,
    y: &Path<'_>,
    record: &MutationRecord,
    density: InfiniteDensity,
) -> f64 {
    let full = kernel.log_transition_density(x, y, record);
    if full == f64::NEG_INFINITY || density == InfiniteDensity::Reported {
        return full;
    }
    let i = record.l;
    let ways = [
        y.log_regrowth_density(i, i, 0),
        y.log_regrowth_density(i, i, 1),
    ];
    let changed = match density {
        InfiniteDensity::ProjectedLightWay => {
            let cos = (y.vertices[1].sp.ng.dot(y.vertices[0].wo) as f64).abs();
            [ways[0], ways[1] + cos.ln()]
        }
        InfiniteDensity::CameraWayOnly => [ways[0], f64::NEG_INFINITY],
        InfiniteDensity::DiskCosineDropped => {
            let cos = (y.vertices[1].sp.ng.dot(y.vertices[0].wo) as f64).abs();
            [ways[0], ways[1] - cos.ln()]
        }
        InfiniteDensity::Reported => ways,
    };
    full - mcmc_core::math::log_sum_exp(&ways) + mcmc_core::math::log_sum_exp(&changed)
}

/// True when `x_1`'s environment direction `w` is counted for `l = 0`.
fn sees_environment(scene: &Scene, from: &Vertex, w: glam::Vec3) -> bool {
    !scene.geometry.occluded(&from.sp.spawn_ray(w))
}

/// Expected probability per cell of `ω = y_0.wo` about `x_1`'s normal.
fn x0_masses(kernel: &Bidirectional, x: &Path<'_>, density: InfiniteDensity) -> Vec<f64> {
    let scene = x.scene;
    let env = x.vertices[0].light;
    let x1 = &x.vertices[1];
    let frame = Frame::from_normal(x1.sp.ng);
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
            if !sees_environment(scene, x1, w) {
                continue;
            }
            let mut y = x.clone();
            y.vertices[0] = Vertex::infinite(env, w, Rgb::WHITE, 0.0);
            y.evaluate();
            let ln_t = infinite_log_t(kernel, x, &y, &REGROW_X0, density);
            if ln_t == f64::NEG_INFINITY {
                continue;
            }
            let cell = cell_of(&frame, w).expect("upper hemisphere");
            masses[cell] += ln_t.exp() * dz * dphi;
        }
    }
    masses
}

/// Cells of the floor `[−3, 3]²` (the `l = 1` histogram), per axis.
const FLOOR_CELLS: usize = 12;
/// Midpoint-rule points per floor cell and axis.
const FLOOR_QUAD: usize = 16;

/// The floor cell of `v` (`None` off the floor's top).
fn floor_cell(v: &Vertex) -> Option<usize> {
    let p = v.p();
    if v.kind != VertexKind::Surface || v.sp.ng.y < 0.99 || p.y.abs() > 1e-3 {
        return None;
    }
    let cell = |c: f32| ((c + 3.0) / 6.0 * FLOOR_CELLS as f32).floor();
    let (ix, iz) = (cell(p.x), cell(p.z));
    let range = 0.0..FLOOR_CELLS as f32;
    (range.contains(&ix) && range.contains(&iz)).then(|| iz as usize * FLOOR_CELLS + ix as usize)
}

/// True when a regrown `y_1` is counted for `l = 1`: on the floor, seeing
/// the sky along `x_0`'s `ω` and visible from `x_2`.
fn x1_counted(x: &Path<'_>, y1: &Vertex) -> bool {
    let scene = x.scene;
    floor_cell(y1).is_some()
        && sees_environment(scene, y1, x.vertices[0].wo)
        && scene.geometry.visible(&x.vertices[2].sp, &y1.sp)
}

/// Expected probability per floor cell of `y_1` (`T` is an area density
/// there: midpoint rule over the floor, no Jacobian).
fn x1_masses(kernel: &Bidirectional, x: &Path<'_>, density: InfiniteDensity) -> Vec<f64> {
    let scene = x.scene;
    let n = FLOOR_CELLS * FLOOR_QUAD;
    let h = 6.0 / n as f64;
    let mut masses = vec![0.0; FLOOR_CELLS * FLOOR_CELLS];
    for iz in 0..n {
        for ix in 0..n {
            let (px, pz) = (-3.0 + (ix as f64 + 0.5) * h, -3.0 + (iz as f64 + 0.5) * h);
            // The floor point from below (nothing lies under the floor).
            let up = glam::Vec3::Y;
            let ray =
                mcmc_render::geometry::Ray::new(glam::Vec3::new(px as f32, -1.0, pz as f32), up);
            let Some(hit) = scene.intersect(&ray) else {
                continue;
            };
            let v = Vertex::surface(scene, hit.sp, up, Rgb::WHITE);
            let Some(cell) = floor_cell(&v) else {
                continue;
            };
            if !x1_counted(x, &v) {
                continue;
            }
            let y = moved(x, v);
            let ln_t = infinite_log_t(kernel, x, &y, &REGROW_X1, density);
            if ln_t > f64::NEG_INFINITY {
                masses[cell] += ln_t.exp() * h * h;
            }
        }
    }
    masses
}

/// Histograms of `N_INF` proposals from `x`: the `l = 0` and `l = 1` records'
/// counted proposals (see above), and one valid `l = 0` proposal.
fn infinite_histograms<'s>(x: &Path<'s>, seed: u64) -> (Vec<u64>, Vec<u64>, Option<Path<'s>>) {
    let scene = x.scene;
    let env = x.vertices[0].light;
    let mut kernel = Bidirectional::new(1, Some(3), true);
    let current = sample_of(x);
    let mut proposal = sample_of(x);
    let mut rng = stream_rng(seed, 0);
    let x1 = &x.vertices[1];
    let frame1 = Frame::from_normal(x1.sp.ng);
    let mut counts0 = vec![0u64; NZ * NPHI];
    let mut counts1 = vec![0u64; FLOOR_CELLS * FLOOR_CELLS];
    let mut some_y = None;
    for _ in 0..N_INF {
        let p = kernel.propose(&current, &mut proposal, &mut rng);
        let Some(rec) = kernel.last_record() else {
            continue;
        };
        if p.failed && p.component == Invalid::WalkEnded as usize {
            continue;
        }
        let y = &proposal.state;
        let key = (rec.l, rec.deleted, rec.added);
        if key == (REGROW_X0.l, REGROW_X0.deleted, REGROW_X0.added) {
            let y0 = &y.vertices[0];
            if y0.kind != VertexKind::Infinite || y0.light != env {
                continue;
            }
            if !sees_environment(scene, x1, y0.wo) {
                continue;
            }
            if let Some(c) = cell_of(&frame1, y0.wo) {
                counts0[c] += 1;
            }
            if some_y.is_none() && !p.failed && y.luminance() > 0.0 {
                some_y = Some(y.clone());
            }
        } else if key == (REGROW_X1.l, REGROW_X1.deleted, REGROW_X1.added) {
            let y1 = &y.vertices[1];
            if x1_counted(x, y1)
                && let Some(c) = floor_cell(y1)
            {
                counts1[c] += 1;
            }
        }
    }
    (counts0, counts1, some_y)
}

#[test]
fn bidirectional_density_at_infinity_matches_its_proposals() {
    let scene = environment_scene();
    let x = infinite_start_path(scene);
    let kernel = Bidirectional::new(1, Some(3), true);
    let (counts0, counts1, y) = infinite_histograms(&x, 41);
    eprintln!(
        "counted: l = 0 {}, l = 1 {} of {N_INF}",
        counts0.iter().sum::<u64>(),
        counts1.iter().sum::<u64>()
    );
    let masses0 = x0_masses(&kernel, &x, InfiniteDensity::Reported);
    let p0 = common::chi_square_p_value(&counts0, &masses0, N_INF);
    assert!(p0 > 1e-4, "regrowing x_0 at infinity: p = {p0:.2e}");
    let masses1 = x1_masses(&kernel, &x, InfiniteDensity::Reported);
    let p1 = common::chi_square_p_value(&counts1, &masses1, N_INF);
    assert!(
        p1 > 1e-4,
        "regrowing x_1 from x_0 at infinity: p = {p1:.2e}"
    );
    for control in [
        InfiniteDensity::ProjectedLightWay,
        InfiniteDensity::CameraWayOnly,
    ] {
        let wrong = x0_masses(&kernel, &x, control);
        let p = common::chi_square_p_value(&counts0, &wrong, N_INF);
        assert!(
            p < 1e-4,
            "a control density of x_0 passed (projected light way: {}): p = {p:.2e}",
            control == InfiniteDensity::ProjectedLightWay
        );
    }
    let wrong = x1_masses(&kernel, &x, InfiniteDensity::DiskCosineDropped);
    let p = common::chi_square_p_value(&counts1, &wrong, N_INF);
    assert!(
        p < 1e-4,
        "the disk walk without its cosine passed: p = {p:.2e}"
    );

    // From the proposal y back: the ratio over the cells of y_0 and x_0.
    let y = y.expect("a valid proposal regrowing x_0");
    let masses0_y = x0_masses(&kernel, &y, InfiniteDensity::Reported);
    let (counts0_y, _, _) = infinite_histograms(&y, 42);
    let p_y = common::chi_square_p_value(&counts0_y, &masses0_y, N_INF);
    assert!(p_y > 1e-4, "T(y→·) at infinity: p = {p_y:.2e}");
    let frame = Frame::from_normal(x.vertices[1].sp.ng);
    let by = cell_of(&frame, y.vertices[0].wo).expect("y_0 above x_1");
    let bx = cell_of(&frame, x.vertices[0].wo).expect("x_0 above x_1");
    let (oa, ob) = (counts0[by] as f64, counts0_y[bx] as f64);
    assert!(oa > 100.0 && ob > 100.0, "cells not resolved: {oa}, {ob}");
    let observed = (oa / ob).ln();
    let reported = (masses0[by] / masses0_y[bx]).ln();
    let sigma = (1.0 / oa + 1.0 / ob).sqrt();
    eprintln!("ln ratio at infinity: histograms {observed:.4}, code {reported:.4}, σ {sigma:.4}");
    assert!(
        (observed - reported).abs() < 4.0 * sigma,
        "T(x→y)/T(y→x) at infinity: histograms {observed}, code {reported} (σ {sigma})"
    );
}
