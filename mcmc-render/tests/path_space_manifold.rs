//! The manifold perturbation (`path_space::manifold_perturbation`): its
//! transition density against a histogram of its proposals, its ratio
//! against the lens perturbation's where the two moves coincide, and the
//! mixture's refusals.
//!
//! # Density: method
//!
//! Scene: a point light 1 above the centre of a glass sphere (radius 0.5,
//! η 1.5), a diffuse floor 0.1 below the sphere, a camera seeing the floor
//! directly at a low angle. From one fixed path `x` = light → sphere →
//! sphere → floor → camera (`L S S D E`, entering the sphere within 0.05
//! of its axis), the move `(a, b, c)` = (light, floor, camera) is made
//! `N` times: a von Mises–Fisher direction at the light (κ = 2π λ²/4π =
//! 1250), traced through the sphere to a new floor point `x_b'`. Each
//! valid proposal is binned by `x_b'` on a 6×6 grid spanning ±2 standard
//! deviations of a pilot run (another seed) around its mean; the rest
//! (failed proposals, points outside the grid) is one more cell.
//!
//! A cell's expected count is `N ∫_cell T(x→y) dA` with `T` the density
//! the code reports (`log_proposal_density`: direction density times the
//! generalised geometry term over the cosine at the light), evaluated at
//! 8×8 midpoints per cell on the path `y` whose chain the manifold walk
//! (anchored at the light) brings to that point. The light is close, so
//! the sphere's focus lies far below the floor: every floor point of the
//! grid has one chain, no caustic fold crosses it (with the light 3.3
//! away a fold did, and the midpoint rule failed there). Pearson's
//! chi-square with the pooled helper (`common::chi_square_p_value`) must
//! give p > 1e-4 (fixed seeds; measured χ² = 34.4 on 36 cells, p = 0.54).
//! Control: the density with the chain's Jacobian determinant dropped
//! (`G(x_a ↔ x_1)` in place of the generalised term) must give p < 1e-4
//! (measured p = 0).
//!
//! # Ratio: method
//!
//! When `x_a` is the camera, `x_b` the first non-specular vertex seen
//! through specular ones and `x_c` its light-side neighbour, the manifold
//! move is the lens perturbation's (same raster kernel, nothing to walk).
//! On the glass scene seen through the sphere (`L D S S E`), the manifold
//! perturbation's `log_ratio` for lens-perturbation proposals must equal
//! the lens perturbation's reported ratio (its densities are histogram-
//! tested in `path_space_perturbations.rs`, in the path state's measure)
//! minus the lobe probabilities of the specular vertices, which the lens
//! perturbation samples and the manifold perturbation traces: this checks
//! the measure change `J` (module docs) through refraction. Within 1e-3
//! (measured 8.9e-7 over 3669 proposals); control: `J` dropped misses by
//! up to 2.05 (must exceed 1e-2).

mod common;

use common::{chi_square_p_value, load_str};
use glam::{DVec3, Vec2};
use mcmc_core::kernel::Kernel;
use mcmc_core::rng::stream_rng;
use mcmc_core::sample::Sample;
use mcmc_render::bsdf::TransportMode;
use mcmc_render::manifold::ManifoldVertex;
use mcmc_render::manifold::constraint::{generalized_geometry, geometry_term};
use mcmc_render::manifold::walk::{WalkConfig, walk};
use mcmc_render::path_space::lens_perturbation::{LensPerturbation, OffsetKernel, lens_chain};
use mcmc_render::path_space::manifold_perturbation::{ManifoldPerturbation, Selection, selections};
use mcmc_render::path_space::state::dirac_lobe;
use mcmc_render::path_space::{Path, PathFamily, PathMutations};
use mcmc_render::pss::PathSample;
use mcmc_render::scene::Scene;

const N: usize = 100_000;
const PILOT: usize = 20_000;
const GRID: usize = 6;
const QUAD: usize = 8;

/// The glass-sphere scene with the camera at `eye` looking at `target`,
/// the point light at `light`.
fn glass_scene(eye: &str, target: &str, light: &str) -> Scene {
    load_str(&format!(
        r#"<scene version="3.0.0">
        <integrator type="path"><integer name="max_depth" value="4"/></integrator>
        <sensor type="perspective">
            <float name="fov" value="40"/>
            <transform name="to_world"><lookat origin="{eye}" target="{target}" up="0, 0, 1"/></transform>
            <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="64"/></film>
        </sensor>
        <shape type="rectangle"><transform name="to_world"><scale value="5"/></transform>
            <bsdf type="diffuse"/></shape>
        <shape type="sphere"><point name="center" x="0" y="0" z="0.6"/><float name="radius" value="0.5"/>
            <bsdf type="dielectric"><float name="int_ior" value="1.5"/><float name="ext_ior" value="1"/></bsdf></shape>
        <emitter type="point"><point name="position" {light}/>
            <rgb name="intensity" value="10, 10, 10"/></emitter>
        </scene>"#
    ))
}

fn sample_of<'s>(x: &Path<'s>) -> Sample<Path<'s>, PathSample> {
    Sample {
        state: x.clone(),
        log_density: x.log_density(),
        payload: x.sample(),
    }
}

/// A visible path of `segments` segments with the Dirac flags `delta`
/// (light to camera) that `accept` likes.
fn find_path<'s>(scene: &'s Scene, delta: &[bool], accept: impl Fn(&Path) -> bool) -> Path<'s> {
    let family = PathFamily::new(scene, Some(delta.len() - 1));
    let mut rng = stream_rng(11, 0);
    let mut near = 0;
    for _ in 0..2_000_000 {
        let x = family.draw_candidate(&mut rng);
        if x.len() == delta.len()
            && x.luminance() > 0.0
            && x.vertices.iter().zip(delta).all(|(v, d)| v.delta == *d)
            && x.all_visible()
        {
            near += 1;
            if accept(&x) {
                return x;
            }
        }
    }
    eprintln!("{near} paths had the pattern");
    panic!("no path with the pattern {delta:?}");
}

/// The caustic path light → sphere → sphere → floor → camera entering the
/// sphere near its top (paraxial: far from the caustic's fold).
fn caustic_path(scene: &Scene) -> Path<'_> {
    find_path(scene, &[false, true, true, false, false], |x| {
        x.vertices[1].p().truncate().length() < 0.05
    })
}

/// Floor point of a proposal.
fn floor_point(y: &Path) -> Vec2 {
    y.vertices[3].p().truncate()
}

/// Counts the valid proposals of `n` moves from `x` per cell (last:
/// everything else) and returns the floor points too.
fn proposals(x: &Path, sel: Selection, n: usize, seed: u64) -> Vec<Option<Vec2>> {
    let kernel = ManifoldPerturbation::default();
    let mut rng = stream_rng(seed, 1);
    let mut y = x.clone();
    let mut failures = std::collections::BTreeMap::new();
    let out = (0..n)
        .map(|_| match kernel.perturb(x, &mut y, sel, &mut rng) {
            Ok(_) => Some(floor_point(&y)),
            Err(f) => {
                *failures.entry(format!("{f:?}")).or_insert(0u64) += 1;
                None
            }
        })
        .collect();
    eprintln!("failed proposals: {failures:?}");
    out
}

/// The path `x` with its chain light → sphere → sphere → floor walked
/// (anchor: the light) to the floor point `t`; `None` when the walk fails.
fn walked_to<'s>(x: &Path<'s>, chain: &[ManifoldVertex], t: Vec2) -> Option<Path<'s>> {
    let target = DVec3::new(t.x as f64, t.y as f64, 0.0);
    let w = walk(x.scene, chain, target, &WalkConfig::default()).ok()?;
    let mut y = x.clone();
    for i in 1..=3 {
        y.vertices[i].sp = w.chain[i].sp;
    }
    y.evaluate();
    (y.luminance() > 0.0 && y.edge_visible(3)).then_some(y)
}

#[test]
fn manifold_density_matches_a_histogram_of_proposals() {
    let scene = glass_scene("3, 0.3, 0.6", "0, 0, 0", r#"x="0.03" y="0.02" z="1.6""#);
    let x = caustic_path(&scene);
    let sel = Selection { a: 0, b: 3, c: 4 };
    assert!(selections(&x).contains(&sel));
    // Grid from a pilot run.
    let pilot: Vec<Vec2> = proposals(&x, sel, PILOT, 1).into_iter().flatten().collect();
    assert!(pilot.len() > PILOT * 8 / 10, "pilot: {} valid", pilot.len());
    let mean = pilot.iter().copied().sum::<Vec2>() / pilot.len() as f32;
    let var = pilot
        .iter()
        .map(|p| (*p - mean) * (*p - mean))
        .sum::<Vec2>()
        / pilot.len() as f32;
    let (lo, size) = (mean - var.sqrt() * 2.0, var.sqrt() * 4.0);
    let cell_of = |p: Vec2| {
        let u = (p - lo) / size * GRID as f32;
        (u.x >= 0.0 && u.y >= 0.0 && u.x < GRID as f32 && u.y < GRID as f32)
            .then(|| u.y as usize * GRID + u.x as usize)
    };
    let mut counts = vec![0u64; GRID * GRID + 1];
    for p in proposals(&x, sel, N, 2) {
        match p.and_then(cell_of) {
            Some(c) => counts[c] += 1,
            None => counts[GRID * GRID] += 1,
        }
    }
    // Expected masses: the code's density, and the control without the
    // chain's Jacobian determinant.
    let kernel = ManifoldPerturbation::default();
    let chain: Vec<ManifoldVertex> = (0..=3)
        .map(|i| {
            let v = &x.vertices[i];
            let other = x.vertices[if i == 0 { 1 } else { i - 1 }].p();
            ManifoldVertex::from_path_vertex(&scene, v, None, other).expect("descriptor")
        })
        .collect();
    let cell_area = (size.x as f64 / GRID as f64) * (size.y as f64 / GRID as f64);
    let (mut masses, mut control) = (vec![0.0; GRID * GRID + 1], vec![0.0; GRID * GRID + 1]);
    let mut missed = 0;
    for cy in 0..GRID {
        for cx in 0..GRID {
            for qy in 0..QUAD {
                for qx in 0..QUAD {
                    let u = Vec2::new(
                        (cx as f32 + (qx as f32 + 0.5) / QUAD as f32) / GRID as f32,
                        (cy as f32 + (qy as f32 + 0.5) / QUAD as f32) / GRID as f32,
                    );
                    let Some(y) = walked_to(&x, &chain, lo + u * size) else {
                        missed += 1;
                        continue;
                    };
                    let log_t = kernel.log_proposal_density(&x, &y, sel);
                    let ychain: Vec<ManifoldVertex> = (0..=3)
                        .map(|i| {
                            let other = y.vertices[if i == 0 { 1 } else { i - 1 }].p();
                            ManifoldVertex::from_path_vertex(&scene, &y.vertices[i], None, other)
                                .expect("descriptor")
                        })
                        .collect();
                    let log_det = generalized_geometry(&ychain).unwrap().ln()
                        - geometry_term(&ychain[0], &ychain[1]).ln();
                    let w = cell_area / (QUAD * QUAD) as f64;
                    masses[cy * GRID + cx] += log_t.exp() * w;
                    control[cy * GRID + cx] += (log_t - log_det).exp() * w;
                }
            }
        }
    }
    eprintln!(
        "{missed} quadrature points without a chain; counts {counts:?}\n masses {:?}",
        masses
            .iter()
            .map(|m| (m * N as f64) as u64)
            .collect::<Vec<_>>()
    );
    let p = chi_square_p_value(&counts, &masses, N);
    let p_control = chi_square_p_value(&counts, &control, N);
    eprintln!(
        "grid mass {:.4} (counted {:.4}); p = {p:.3e}, control p = {p_control:.3e}",
        masses.iter().sum::<f64>(),
        counts[..GRID * GRID].iter().sum::<u64>() as f64 / N as f64
    );
    assert!(
        p > 1e-4,
        "the density disagrees with the histogram: p = {p}"
    );
    assert!(
        p_control < 1e-4,
        "the control without the determinant passed: p = {p_control}"
    );
}

#[test]
fn manifold_ratio_equals_the_lens_perturbations_where_the_moves_coincide() {
    // The camera sees the floor through the sphere: L D S S E.
    let scene = glass_scene("0.3, 0.2, 3.2", "0, 0, 0.6", r#"x="2" y="1" z="1.5""#);
    let x = find_path(&scene, &[false, false, true, true, false], |x| {
        lens_chain(x) == Some(1) && (x.raster - Vec2::splat(32.0)).length() < 12.0
    });
    let sel = Selection { a: 4, b: 1, c: 0 };
    assert!(selections(&x).contains(&sel));
    let manifold = ManifoldPerturbation::default();
    // Small offsets (any kernel: p_Δ cancels in both ratios) keep most
    // proposals on the sphere.
    let mut lens = LensPerturbation::new(Some(OffsetKernel { r1: 0.05, r2: 2.0 }));
    let current = sample_of(&x);
    let mut proposal = sample_of(&x);
    let mut rng = stream_rng(3, 0);
    let (mut compared, mut worst, mut control_miss) = (0, 0.0f64, 0.0f64);
    let mut lens_failures = std::collections::BTreeMap::new();
    let mut switched = 0;
    for _ in 0..4000 {
        let p = lens.propose(&current, &mut proposal, &mut rng);
        if p.failed {
            *lens_failures.entry(p.component).or_insert(0u64) += 1;
            continue;
        }
        let y = &proposal.state;
        // The lens perturbation may switch a dielectric between reflection
        // and refraction; the manifold perturbation never does.
        let roles = |p: &Path| -> Vec<bool> {
            (1..4)
                .map(|i| {
                    let v = &p.vertices[i];
                    (v.p() - p.vertices[i - 1].p()).dot(v.sp.ng)
                        * (v.p() - p.vertices[i + 1].p()).dot(v.sp.ng)
                        > 0.0
                })
                .collect()
        };
        if roles(y) != roles(&x) {
            switched += 1;
            continue;
        }
        // The lens perturbation samples the lobes at the specular
        // vertices, the manifold perturbation traces them: its ratio lacks
        // the lobe probabilities ln P(x_i) − ln P(y_i).
        let lobes = |p: &Path| -> f64 {
            (2..4)
                .map(|i| {
                    let v = &p.vertices[i];
                    let wc = (p.vertices[i + 1].p() - v.p()).normalize();
                    let wl = (p.vertices[i - 1].p() - v.p()).normalize();
                    let (lobe, _) =
                        dirac_lobe(&scene, v, wc, wl, TransportMode::Radiance).expect("Dirac lobe");
                    (lobe as f64).ln()
                })
                .sum()
        };
        let expected = p.log_q_ratio - lobes(&x) + lobes(y);
        let ours = manifold.log_ratio(&x, y, sel).expect("ratio");
        let err = (ours - expected).abs();
        worst = worst.max(err);
        // Control: the measure change J dropped, i.e. the manifold's own
        // densities ln T(y→x) − ln T(x→y) alone.
        let t_ratio =
            manifold.log_proposal_density(y, &x, sel) - manifold.log_proposal_density(&x, y, sel);
        control_miss = control_miss.max((t_ratio - expected).abs());
        compared += 1;
    }
    eprintln!("lens failures by component {lens_failures:?}, {switched} switched lobes");
    eprintln!(
        "{compared} proposals; worst |Δ ln ratio| {worst:.2e}; control misses by up to {control_miss:.2e}"
    );
    assert!(compared > 500, "only {compared} valid lens proposals");
    assert!(worst < 1e-3, "the ratios differ by {worst}");
    assert!(
        control_miss > 1e-2,
        "the control without J passed: {control_miss}"
    );
}

#[test]
fn the_manifold_perturbation_is_accepted_by_the_mixture() {
    let m = PathMutations {
        manifold_perturbation: 1.0,
        ..PathMutations::default()
    };
    let kernel = m.kernel(Some(5)).expect("built");
    let names = kernel.component_names();
    assert!(
        names.iter().any(|n| n == "manifold perturbation"),
        "{names:?}"
    );
}
