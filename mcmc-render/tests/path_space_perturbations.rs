//! The perturbation mutations' transition densities against the histograms
//! of their proposals.
//!
//! # Lens perturbation: method
//!
//! Scene: the repo's Cornell box at 64×64 with its back wall a perfect
//! mirror (`conductor`, material `none`). From one fixed path `x =
//! x_0 x_1 x_2 x_3` (light, diffuse, the mirror, camera: pattern `L D S E`)
//! the lens perturbation is run `N` times. Each valid proposal `y` is
//! binned by its raster offset `Δ = y.raster − x.raster` (recomputed from
//! `y`'s geometry), in cells uniform in `(ln |Δ|, φ)`.
//!
//! A cell's expected count is `N ∫_cell q(Δ) d²Δ` where `q` is the raster
//! density implied by the density the code reports:
//!
//! ```text
//! q(Δ) = T(x→y(Δ)) · |dA(y_1)/dr| · d₁² d₂² / ((d₁+d₂)² cos_m P)
//! ```
//!
//! with `y(Δ)` traced by the test (camera ray, reflection in the mirror
//! plane, first hit), `|dA(y_1)/dr|` the raster-to-area Jacobian of `y_1`
//! computed independently of the renderer's densities (the solid angle per
//! pixel of the camera ray, by central finite differences of
//! `Camera::generate_ray`, times `(d₁+d₂)²/cos θ_1`: a planar mirror
//! unfolds the two segments into one), and `d₁² d₂² / ((d₁+d₂)² cos_m P)`
//! the change from the path state's Dirac-coefficient measure at the mirror
//! to `y_1`'s area (`d₁` camera–mirror, `d₂` mirror–`y_1`, `cos_m` at the
//! mirror, `P = 1` for the mirror's single lobe; see the module docs of
//! `path_space::state`). Only offsets whose `y` is valid (a mirror hit, then
//! a diffuse surface visible from `x_0`, non-zero contribution) count, in
//! the histogram and in the integral. Midpoint rule, 24×24 per cell (cells cut by an occlusion or mirror edge need the resolution). Cells
//! expecting fewer than 5 are pooled; the proposals outside every cell
//! (failed ones) form one more cell. Pearson's chi-square rejects at
//! p < 1e-4 (fixed seeds).
//!
//! Control: the same with the cosine at `y_1` dropped from the reported
//! density (a forgotten Jacobian factor of the area conversion): must be
//! rejected.
//!
//! The ratio: for proposals `y`, the code's `ln T(y→x) − ln T(x→y)` (both
//! from `log_transition_density`, and the kernel's own reported ratio)
//! against the independent `ln J(y) − ln J(x)` of the Jacobians above (`T(x→y) = p_Δ / J(y)`)
//! (`p_Δ` is symmetric), within 1e-4 (finite differences in f32; measured
//! 4.8e-6); the control, a symmetric kernel's ratio 0, must be off by more
//! than 1e-2.
//!
//! # Caustic perturbation: method
//!
//! Same scene. From one fixed path `x = x_0 x_1 x_2 x_3` (light, the
//! mirror, diffuse, camera: pattern `L S D E`, the chain starts at the
//! light, `l = 0`) the caustic perturbation is run `N` times. Each valid
//! proposal is binned by the direction `y_1 − x_0` in cells uniform in
//! `(ln θ, φ)` about `x_1 − x_0` (θ between the kernel's `θ₁` and `θ₂`,
//! φ in the test's own basis). A cell's expected count is `N ∫_cell
//! T(x→y(ω)) · J(y) dω` with `y(ω)` traced by the test (light ray, mirror
//! reflection, first hit) and `J = d₁² d₂² / (cos_m cos_2)` (`d₁`
//! light–mirror, `d₂` mirror–`y_2`): the planar mirror's unfolded
//! `|dA(y_2)/dω| = (d₁+d₂)²/cos_2` times the Dirac-coefficient factor of the
//! lens test. Midpoint rule, 24×24 per cell; chi-square as above; the
//! control drops the cosine at `y_2`. The ratio `ln T(y→x) − ln T(x→y)`
//! must equal `ln J(y) − ln J(x)` within 1e-4 (`p_ω` is the same both
//! ways), and a symmetric ratio must be off by more than 1e-2.

mod common;

use common::{load_str, pixel_solid_angle};
use glam::{DVec3, Vec2, Vec3};
use mcmc_core::kernel::Kernel;
use mcmc_core::rng::{stream_rng, uniform};
use mcmc_core::sample::Sample;
use mcmc_render::color::Rgb;
use mcmc_render::integrators::mlt::Mlt;
use mcmc_render::integrators::path_vertex::Vertex;
use mcmc_render::markov::{ChainFamily, ChainSettings, Normalization};
use mcmc_render::observer::NoObserver;
use mcmc_render::path_space::bidirectional::Bidirectional;
use mcmc_render::path_space::caustic_perturbation::{
    AngleKernel, CausticPerturbation, caustic_chain,
};
use mcmc_render::path_space::independent::IndependentPath;
use mcmc_render::path_space::lens_perturbation::{LensPerturbation, lens_chain};
use mcmc_render::path_space::lens_subpath::LensSubpath;
use mcmc_render::path_space::multi_chain_perturbation::{MultiChainPerturbation, multi_chain};
use mcmc_render::path_space::{Path, PathFamily, PathMutations};
use mcmc_render::pss::PathSample;
use mcmc_render::scene::Scene;
use std::f64::consts::PI;
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

const RES: u32 = 64;
const NR: usize = 8;
const NPHI: usize = 8;
const QUAD: usize = 24;
const N: usize = 100_000;

/// The Cornell box with a mirror for a back wall.
fn mirror_box() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| {
        let text = std::fs::read_to_string(common::repo_scene_path("cornell-box.xml"))
            .expect("scene file");
        let back = r#"<translate x="0" y="0" z="-1"/>
        </transform>
        <ref id="white"/>"#;
        assert!(text.contains(back), "back wall not found");
        let text = text
            .replace(
                back,
                r#"<translate x="0" y="0" z="-1"/>
        </transform>
        <bsdf type="conductor"/>"#,
            )
            .replace(
                r#"<default name="width" value="256"/>"#,
                &format!(r#"<default name="width" value="{RES}"/>"#),
            )
            .replace(
                r#"<default name="height" value="256"/>"#,
                &format!(r#"<default name="height" value="{RES}"/>"#),
            );
        load_str(&text)
    })
}

fn sample_of<'s>(x: &Path<'s>) -> Sample<Path<'s>, PathSample> {
    Sample {
        state: x.clone(),
        log_density: x.log_density(),
        payload: x.sample(),
    }
}

/// A three-segment path light → diffuse → mirror → camera whose raster
/// position is at least `margin` pixels inside the image.
fn mirror_path(scene: &Scene, margin: f32) -> Path<'_> {
    let family = PathFamily::new(scene, Some(3));
    let mut rng = stream_rng(5, 0);
    let r = RES as f32;
    for _ in 0..1_000_000 {
        let x = family.draw_candidate(&mut rng);
        if x.segments() == 3
            && x.luminance() > 0.0
            && x.all_visible()
            && x.vertices[2].delta
            && lens_chain(&x) == Some(1)
            && x.raster.min_element() > margin
            && x.raster.max_element() < r - margin
        {
            return x;
        }
    }
    panic!("no light-diffuse-mirror-camera path found");
}

/// The path `x` with its camera ray through `raster`, traced by the test:
/// mirror hit, reflection, first hit. `None` when the ray misses the
/// mirror or the reflected ray escapes.
fn traced<'s>(x: &Path<'s>, raster: Vec2) -> Option<Path<'s>> {
    let scene = x.scene;
    let ray = scene.camera.generate_ray(raster);
    let m = scene.intersect(&ray)?;
    if !scene.bsdf_at(&m.sp).is_delta() {
        return None;
    }
    let d = ray.d.normalize();
    let n = m.sp.ng;
    let r = d - 2.0 * d.dot(n) * n;
    let hit = scene.intersect(&m.sp.spawn_ray(r))?;
    let mut y = x.clone();
    let mut mirror = Vertex::surface(scene, m.sp, -d, Rgb::WHITE);
    mirror.delta = true;
    y.vertices[2] = mirror;
    y.vertices[1] = Vertex::surface(scene, hit.sp, -r, Rgb::WHITE);
    y.normalize_ends();
    y.evaluate();
    Some(y)
}

/// True when `y` is a proposal the lens perturbation accepts as valid.
fn valid(x: &Path, y: &Path) -> bool {
    let scene = x.scene;
    y.contribution.luminance() > 0.0
        && lens_chain(y) == Some(1)
        && scene.geometry.visible(&x.vertices[0].sp, &y.vertices[1].sp)
}

/// `ln` of the factor that turns the code's `T(x→y)` into a raster
/// density: `|dA(y_1)/dr| · d₁² d₂² / ((d₁+d₂)² cos_m)`, from the camera's
/// ray map by central differences (`h` = 0.25 px; the map is smooth) and the mirror geometry.
fn log_jacobian(y: &Path) -> f64 {
    let d_omega = pixel_solid_angle(y.scene, y.raster);
    let (c, m, y1) = (
        y.vertices[3].p().as_dvec3(),
        y.vertices[2].p().as_dvec3(),
        y.vertices[1].p().as_dvec3(),
    );
    let (d1, d2) = ((m - c).length(), (y1 - m).length());
    let cos_m = y.vertices[2].sp.ng.as_dvec3().dot((c - m) / d1).abs();
    let cos_1 = y.vertices[1].sp.ng.as_dvec3().dot((m - y1) / d2).abs();
    let da_dr = d_omega * (d1 + d2).powi(2) / cos_1;
    (da_dr * d1 * d1 * d2 * d2 / ((d1 + d2).powi(2) * cos_m)).ln()
}

/// `ln cos θ` at `y_1` towards the mirror.
fn log_cos_1(y: &Path) -> f64 {
    let w = (y.vertices[2].p() - y.vertices[1].p()).normalize();
    (y.vertices[1].sp.ng.dot(w).abs() as f64).ln()
}

/// Cell of an offset (`None` outside `[r1, r2]`).
fn cell_of(offset: Vec2, r1: f64, r2: f64) -> Option<usize> {
    polar_cell(offset_polar(offset), r1, r2, NR, NPHI)
}

/// `(|Δ|, φ)` of a film offset.
fn offset_polar(offset: Vec2) -> (f64, f64) {
    let phi = (offset.y as f64).atan2(offset.x as f64);
    (offset.length() as f64, phi)
}

/// Cell of polar coordinates `(r, φ)` on an `nr × nphi` grid uniform in
/// `(ln r, φ)` (`None` outside `[r1, r2]`).
fn polar_cell((r, phi): (f64, f64), r1: f64, r2: f64, nr: usize, nphi: usize) -> Option<usize> {
    if !(r >= r1 && r < r2) {
        return None;
    }
    let ir = (((r / r1).ln() / (r2 / r1).ln() * nr as f64) as usize).min(nr - 1);
    let phi = phi.rem_euclid(2.0 * PI);
    let ip = ((phi / (2.0 * PI) * nphi as f64) as usize).min(nphi - 1);
    Some(ir * nphi + ip)
}

/// Expected probability per cell from the code's `T(x→·)`; `drop_cos`
/// removes the cosine at `y_1` (the control).
fn expected_masses(kernel: &LensPerturbation, x: &Path, drop_cos: bool) -> Vec<f64> {
    let k = kernel.offsets(x.scene);
    let (lr1, lr2) = (k.r1.ln(), k.r2.ln());
    let mut masses = vec![0.0; NR * NPHI];
    let dl = (lr2 - lr1) / (NR * QUAD) as f64;
    let dphi = 2.0 * PI / (NPHI * QUAD) as f64;
    for il in 0..NR * QUAD {
        for ip in 0..NPHI * QUAD {
            let r = (lr1 + (il as f64 + 0.5) * dl).exp();
            let phi = (ip as f64 + 0.5) * dphi;
            let offset = Vec2::new((r * phi.cos()) as f32, (r * phi.sin()) as f32);
            let raster = x.raster + offset;
            let Some(y) = traced(x, raster) else {
                continue;
            };
            if !valid(x, &y) {
                continue;
            }
            let mut ln_t = kernel.log_transition_density(x, &y);
            if drop_cos {
                ln_t -= log_cos_1(&y);
            }
            if ln_t == f64::NEG_INFINITY {
                continue;
            }
            let q = (ln_t + log_jacobian(&y)).exp();
            let cell = (il / QUAD) * NPHI + ip / QUAD;
            // d²Δ = r² d(ln r) dφ.
            masses[cell] += q * r * r * dl * dphi;
        }
    }
    masses
}

/// The density test every perturbation shares (module docs): `N`
/// proposals from `x` with `kernel` (stream `seed`), binned by `cell`
/// (given the kernel) into `cells` cells, against `masses(kernel, false)` (the code's
/// density) by chi-square, and against `masses(kernel, true)` (the control
/// without `dropped`), which must be rejected; then for 200 valid
/// proposals the kernel's reported ratio against `log_t`'s (to
/// `reported_tolerance`) and against the independent `ln J(y) − ln J(x)`
/// (to 1e-4), with the symmetric control off by more than 1e-2.
#[allow(clippy::too_many_arguments)]
fn check_density<'s, K: Kernel<Path<'s>, PathSample>>(
    kernel: &mut K,
    x: &Path<'s>,
    seed: u64,
    cells: usize,
    cell: impl Fn(&K, &Path<'s>) -> Option<usize>,
    masses: impl Fn(&K, bool) -> Vec<f64>,
    dropped: &str,
    log_t: impl Fn(&K, &Path, &Path) -> f64,
    log_jacobian: fn(&Path) -> f64,
    reported_tolerance: f64,
) {
    let current = sample_of(x);
    let mut proposal = sample_of(x);
    let mut rng = stream_rng(seed, 0);
    let mut counts = vec![0u64; cells];
    let mut ys = Vec::new();
    for _ in 0..N {
        let p = kernel.propose(&current, &mut proposal, &mut rng);
        if p.failed {
            continue;
        }
        let y = &proposal.state;
        if let Some(c) = cell(kernel, y) {
            counts[c] += 1;
        }
        if ys.len() < 200 {
            ys.push((y.clone(), p.log_q_ratio));
        }
    }
    let expected = masses(kernel, false);
    let p = common::chi_square_p_value(&counts, &expected, N);
    assert!(p > 1e-4, "T(x→·) disagrees with the proposals: p = {p:.2e}");
    let wrong = masses(kernel, true);
    let p_wrong = common::chi_square_p_value(&counts, &wrong, N);
    assert!(
        p_wrong < 1e-4,
        "a density without {dropped} passed: p = {p_wrong:.2e}"
    );

    // The ratio, against the independent Jacobians.
    assert!(ys.len() == 200, "too few valid proposals: {}", ys.len());
    let (mut worst, mut worst_symmetric) = (0.0f64, 0.0f64);
    for (y, reported) in &ys {
        let forward = log_t(kernel, x, y);
        let backward = log_t(kernel, y, x);
        assert!(forward.is_finite() && backward.is_finite());
        let code = backward - forward;
        assert!(
            (code - reported).abs() < reported_tolerance,
            "kernel ratio {reported} vs densities {code}"
        );
        let independent = log_jacobian(y) - log_jacobian(x);
        worst = worst.max((code - independent).abs());
        // Control: a symmetric ratio (the re-traced densities dropped).
        worst_symmetric = worst_symmetric.max(independent.abs());
    }
    eprintln!(
        "worst |ln ratio − independent| = {worst:.2e}, symmetric control {worst_symmetric:.2e}"
    );
    assert!(worst < 1e-4, "T ratio off by {worst}");
    assert!(
        worst_symmetric > 1e-2,
        "the control (ratio 0) passed: {worst_symmetric}"
    );
}

#[test]
fn lens_perturbation_density_matches_its_proposals() {
    let scene = mirror_box();
    let mut kernel = LensPerturbation::default();
    let offsets = kernel.offsets(scene);
    // Mitsuba's sizes on a 64×64 film: r1 = 0.1 px, r2 = √(0.05·4096/π).
    assert_eq!(offsets.r1, 0.1);
    assert!((offsets.r2 - (0.05f64 * 4096.0 / PI).sqrt()).abs() < 1e-12);
    let x = mirror_path(scene, offsets.r2 as f32 + 1.0);
    check_density(
        &mut kernel,
        &x,
        13,
        NR * NPHI,
        |_, y| cell_of(y.raster - x.raster, offsets.r1, offsets.r2),
        |k, drop| expected_masses(k, &x, drop),
        "the cosine at y_1",
        |k, a, b| k.log_transition_density(a, b),
        log_jacobian,
        1e-9,
    );
}

#[test]
fn lens_perturbation_pattern() {
    // Two-segment paths: L D E matches (x_0 is the kept end), L S E (the
    // light seen in the mirror) does not: nothing before the chain to
    // reconnect to. A proposal from L D E never fails as a mismatch.
    let scene = mirror_box();
    let family = PathFamily::new(scene, Some(2));
    let mut rng = stream_rng(3, 0);
    let mut kernel = LensPerturbation::default();
    let (mut lde, mut lse) = (0, 0);
    for _ in 0..50_000 {
        let x = family.draw_candidate(&mut rng);
        if x.segments() != 2 || x.luminance() <= 0.0 {
            continue;
        }
        let current = sample_of(&x);
        let mut proposal = sample_of(&x);
        let p = kernel.propose(&current, &mut proposal, &mut rng);
        if x.vertices[1].delta {
            lse += 1;
            assert_eq!(lens_chain(&x), None);
            assert!(p.failed && p.component == 1, "L S E must mismatch");
        } else {
            lde += 1;
            assert_eq!(lens_chain(&x), Some(1));
            assert!(p.component != 1, "L D E matches the pattern");
        }
    }
    eprintln!("L D E {lde}, L S E {lse}");
    assert!(lde > 100, "too few L D E paths: {lde}");
    // Component 0 and one per failure reason.
    assert_eq!(kernel.component_names().len(), 8);
}

/// Image means of `k` path-space MLT runs with `mutation` (seeds `seed0..`).
fn path_mlt_reps(
    scene: &Scene,
    mutation: PathMutations,
    budget: common::Budget,
    k: u64,
    seed0: u64,
) -> Vec<[f64; 3]> {
    let stop = AtomicBool::new(false);
    let max = scene.integrator.max_depth;
    let family = PathFamily::new(scene, (max != u32::MAX).then_some(max as usize));
    (0..k)
        .map(|s| {
            let settings = ChainSettings {
                mutation,
                bootstrap: budget.bootstrap,
                chains: budget.chains,
                mutations_per_pixel: Some(budget.mpp),
                seed: seed0 + s,
                normalization: Normalization::Running,
                ..ChainSettings::default()
            };
            let r = mcmc_render::markov::run(scene, &family, &settings, &stop, &NoObserver)
                .expect("mlt runs");
            assert_eq!(r.chain_stats.invalid_density, 0, "NaN/inf paths");
            common::image_mean(&r.image())
        })
        .collect()
}

/// `mlt` with the lens perturbation on (weights 1 : 1, Mitsuba's sizes)
/// against PT on the tilted glossy-glass Cornell box (16×16, depth 5), as
/// `agree_mlt.rs` checks its estimators: replicate means, 4σ and 1%, with
/// 5σ < 1% required; a 1% bias on the same replicates must fail. Ignored
/// (64 s on 2 loaded cores): measured once, the means agree (rel −0.21%,
/// −0.06%, +0.10%; σ 0.21%, 0.24%, 0.32% of the mean), but the noise does
/// not yet resolve 1% at 5σ on green and blue, so the test FAILS its
/// resolution check: it needs ~2.5× the budget (not yet run).
#[test]
#[ignore]
fn mlt_with_lens_perturbation_agrees_with_pt_on_the_glass_box() {
    let scene = common::repo_scene_tilted("cornell-glossy-glass.xml", 16, 5);
    let pt = common::mc_reps(&scene, &common::pt_of(&scene), 512, 96, 1000);
    let mutation = PathMutations {
        lens_perturbation: 1.0,
        ..PathMutations::default()
    };
    let budget = common::Budget {
        bootstrap: 400_000,
        chains: 256,
        mpp: 4096,
    };
    let mlt = path_mlt_reps(&scene, mutation, budget, 48, 7000);
    let a = common::MeanAgreement::new(&pt, &mlt);
    eprintln!("mlt+lens: rel {:?}\n  {a:?}", a.rel());
    assert!(a.resolves(5.0, 0.01), "noise too large for 1%: {a:?}");
    assert!(
        a.failures(4.0, 0.01).is_empty(),
        "mlt+lens disagrees with PT: {a:?}"
    );
    let biased: Vec<[f64; 3]> = mlt.iter().map(|m| m.map(|v| v * 1.01)).collect();
    let b = common::MeanAgreement::new(&pt, &biased);
    assert!(!b.failures(4.0, 0.01).is_empty(), "a 1% bias passed: {b:?}");
}

// ---------------------------------------------------------------------------
// Caustic perturbation.

/// A three-segment path light → mirror → diffuse → camera (pattern
/// `L S D E`, the chain starts at the light) whose raster position is at
/// least `margin` pixels inside the image.
fn caustic_path(scene: &Scene, margin: f32) -> Path<'_> {
    let family = PathFamily::new(scene, Some(3));
    let mut rng = stream_rng(17, 0);
    let r = RES as f32;
    for _ in 0..1_000_000 {
        let x = family.draw_candidate(&mut rng);
        if x.segments() == 3
            && x.luminance() > 0.0
            && x.all_visible()
            && x.vertices[1].delta
            && caustic_chain(&x) == Some(0)
            && x.raster.min_element() > margin
            && x.raster.max_element() < r - margin
        {
            return x;
        }
    }
    panic!("no light-mirror-diffuse-camera path found");
}

/// An orthonormal basis `(e1, e2)` about unit `w` (the test's own, for the
/// azimuth of the histogram cells).
fn basis(w: DVec3) -> (DVec3, DVec3) {
    let helper = if w.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let e1 = w.cross(helper).normalize();
    (e1, w.cross(e1))
}

/// The direction of the ray spawned at surface vertex `from` towards `to`
/// (from the offset origin, as the walks spawn rays: the perturbations'
/// smallest angles are comparable to the offset).
fn ray_dir(from: &Vertex, to: Vec3) -> DVec3 {
    (to.as_dvec3() - from.sp.spawn_origin(to).as_dvec3()).normalize()
}

/// `(θ, φ)` of direction `d` about `w` in the basis of [`basis`].
fn polar_of(w: DVec3, d: DVec3) -> (f64, f64) {
    let (e1, e2) = basis(w);
    let theta = w.cross(d).length().atan2(w.dot(d));
    (theta, d.dot(e2).atan2(d.dot(e1)))
}

/// The path `x` with its light ray turned to `dir`, traced by the test:
/// mirror hit, reflection, first hit. `None` when the ray misses the
/// mirror or the reflected ray escapes.
fn traced_from_light<'s>(x: &Path<'s>, dir: Vec3) -> Option<Path<'s>> {
    let scene = x.scene;
    let m = scene.intersect(&x.vertices[0].sp.spawn_ray(dir))?;
    if !scene.bsdf_at(&m.sp).is_delta() {
        return None;
    }
    let n = m.sp.ng;
    let r = dir - 2.0 * dir.dot(n) * n;
    let hit = scene.intersect(&m.sp.spawn_ray(r))?;
    let mut y = x.clone();
    let mut mirror = Vertex::surface(scene, m.sp, -dir, Rgb::WHITE);
    mirror.delta = true;
    y.vertices[1] = mirror;
    y.vertices[2] = Vertex::surface(scene, hit.sp, -r, Rgb::WHITE);
    y.normalize_ends();
    y.evaluate();
    Some(y)
}

/// True when `y` is a proposal the caustic perturbation makes from `x`:
/// non-zero, pattern `L S D E`, camera visible, and the angle inside the
/// reverse move's range (the kernel's support, read from the code).
fn caustic_valid(kernel: &CausticPerturbation, x: &Path, y: &Path) -> bool {
    y.contribution.luminance() > 0.0
        && caustic_chain(y) == Some(0)
        && y.edge_visible(2)
        && kernel.log_transition_density(y, x) > f64::NEG_INFINITY
}

/// `ln` of the factor that turns the code's `T(x→y)` into a solid-angle
/// density at `x_0`: `|dA(y_2)/dω| · d₁² d₂² / ((d₁+d₂)² cos_m P)` with the
/// planar mirror unfolding `|dA(y_2)/dω| = (d₁+d₂)²/cos θ_2`, i.e.
/// `d₁² d₂² / (cos_m cos_2)` (`P = 1`), from the geometry alone.
fn caustic_log_jacobian(y: &Path) -> f64 {
    let (l, m, y2) = (
        y.vertices[0].p().as_dvec3(),
        y.vertices[1].p().as_dvec3(),
        y.vertices[2].p().as_dvec3(),
    );
    let (d1, d2) = ((m - l).length(), (y2 - m).length());
    let cos_m = y.vertices[1].sp.ng.as_dvec3().dot((l - m) / d1).abs();
    let cos_2 = y.vertices[2].sp.ng.as_dvec3().dot((m - y2) / d2).abs();
    (d1 * d1 * d2 * d2 / (cos_m * cos_2)).ln()
}

/// `ln cos θ` at `y_2` towards the mirror.
fn log_cos_2(y: &Path) -> f64 {
    let w = (y.vertices[1].p() - y.vertices[2].p()).normalize();
    (y.vertices[2].sp.ng.dot(w).abs() as f64).ln()
}

/// Expected probability per `(ln θ, φ)` cell from the code's `T(x→·)`;
/// `drop_cos` removes the cosine at `y_2` (the control).
fn caustic_masses(kernel: &CausticPerturbation, x: &Path, drop_cos: bool) -> Vec<f64> {
    let angles = kernel.angles(x, 0).expect("angle kernel");
    let (lt1, lt2) = (angles.theta1.ln(), angles.theta2.ln());
    let w = ray_dir(&x.vertices[0], x.vertices[1].p());
    let (e1, e2) = basis(w);
    let mut masses = vec![0.0; NR * NPHI];
    let dl = (lt2 - lt1) / (NR * QUAD) as f64;
    let dphi = 2.0 * PI / (NPHI * QUAD) as f64;
    for il in 0..NR * QUAD {
        for ip in 0..NPHI * QUAD {
            let theta = (lt1 + (il as f64 + 0.5) * dl).exp();
            let phi = (ip as f64 + 0.5) * dphi;
            let d = w * theta.cos() + (e1 * phi.cos() + e2 * phi.sin()) * theta.sin();
            let Some(y) = traced_from_light(x, d.as_vec3()) else {
                continue;
            };
            if !caustic_valid(kernel, x, &y) {
                continue;
            }
            let mut ln_t = kernel.log_transition_density(x, &y);
            if drop_cos {
                ln_t -= log_cos_2(&y);
            }
            if ln_t == f64::NEG_INFINITY {
                continue;
            }
            let q = (ln_t + caustic_log_jacobian(&y)).exp();
            let cell = (il / QUAD) * NPHI + ip / QUAD;
            // dω = sin θ dθ dφ = sin θ · θ d(ln θ) dφ.
            masses[cell] += q * theta.sin() * theta * dl * dphi;
        }
    }
    masses
}

#[test]
fn caustic_perturbation_density_matches_its_proposals() {
    let scene = mirror_box();
    let mut kernel = CausticPerturbation::default();
    let x = caustic_path(scene, 4.0);
    let angles = kernel.angles(&x, 0).expect("angle kernel");
    // Mitsuba's sizes: the lens perturbation's film offsets as angles
    // seen from the camera, times |x_3 − x_2| / (|x_1 − x_0| + |x_2 − x_1|).
    let p = |i: usize| x.vertices[i].p().as_dvec3();
    let factor = (p(3) - p(2)).length() / ((p(1) - p(0)).length() + (p(2) - p(1)).length());
    let per_pixel = scene.camera.radians_per_pixel() as f64;
    // Mitsuba's radPerPixel: the fields of view (here from the camera's
    // edge rays) over the pixels, the smaller of the two axes.
    let edge = |r: Vec2| scene.camera.generate_ray(r).d.normalize().as_dvec3();
    let fov = |a: Vec2, b: Vec2| polar_of(edge(a), edge(b)).0;
    let half = RES as f32 / 2.0;
    let xfov = fov(Vec2::new(0.0, half), Vec2::new(RES as f32, half));
    let yfov = fov(Vec2::new(half, 0.0), Vec2::new(half, RES as f32));
    let expected = (xfov / RES as f64).min(yfov / RES as f64);
    assert!(
        (per_pixel / expected - 1.0).abs() < 1e-5,
        "{per_pixel} vs {expected}"
    );
    let r2 = (0.05f64 * (RES * RES) as f64 / PI).sqrt();
    assert!((angles.theta1 / (per_pixel * 0.1 * factor) - 1.0).abs() < 1e-9);
    assert!((angles.theta2 / (per_pixel * r2 * factor) - 1.0).abs() < 1e-9);
    eprintln!("θ1 = {:.2e}, θ2 = {:.2e} rad", angles.theta1, angles.theta2);
    // p_ω is the same both ways: T(x→y) = p_ω(θ) / J(y).
    let w = ray_dir(&x.vertices[0], x.vertices[1].p());
    check_density(
        &mut kernel,
        &x,
        19,
        NR * NPHI,
        |_, y| {
            let (theta, phi) = polar_of(w, ray_dir(&x.vertices[0], y.vertices[1].p()));
            polar_cell((theta, phi), angles.theta1, angles.theta2, NR, NPHI)
        },
        |k, drop| caustic_masses(k, &x, drop),
        "the cosine at y_2",
        |k, a, b| k.log_transition_density(a, b),
        caustic_log_jacobian,
        1e-9,
    );
}

#[test]
fn caustic_perturbation_pattern() {
    // Two-segment paths: L D E matches (the light's direction turns, no
    // chain), L S E does not (the camera sees a mirror: no connection to
    // the camera). A proposal from L D E never fails as a mismatch.
    let scene = mirror_box();
    let family = PathFamily::new(scene, Some(2));
    let mut rng = stream_rng(23, 0);
    let mut kernel = CausticPerturbation::default();
    let (mut lde, mut lse) = (0, 0);
    for _ in 0..50_000 {
        let x = family.draw_candidate(&mut rng);
        if x.segments() != 2 || x.luminance() <= 0.0 {
            continue;
        }
        let current = sample_of(&x);
        let mut proposal = sample_of(&x);
        let p = kernel.propose(&current, &mut proposal, &mut rng);
        if x.vertices[1].delta {
            lse += 1;
            assert_eq!(caustic_chain(&x), None);
            assert!(p.failed && p.component == 1, "L S E must mismatch");
        } else {
            lde += 1;
            assert_eq!(caustic_chain(&x), Some(0));
            assert!(p.component != 1, "L D E matches the pattern");
        }
    }
    eprintln!("L D E {lde}, L S E {lse}");
    assert!(lde > 100, "too few L D E paths: {lde}");
    // Component 0 and one per failure reason.
    assert_eq!(kernel.component_names().len(), 10);
}

// ---------------------------------------------------------------------------
// Multi-chain perturbation.

/// Cells per polar axis of the multi-chain test (film offset and angle:
/// 4 × 4 each, 256 joint cells).
const NM: usize = 4;
/// Quadrature points per cell and axis: film offset, angle (the angle
/// kernel is uniform in `(ln θ, φ)`, so few points resolve it).
const QM_OFFSET: usize = 12;
const QM_ANGLE: usize = 4;

/// A four-segment path light → diffuse → mirror → diffuse → camera
/// (pattern `L D S D E`, `j = 1`) whose raster position is at least
/// `margin` pixels inside the image.
fn multi_chain_path(scene: &Scene, margin: f32) -> Path<'_> {
    let family = PathFamily::new(scene, Some(4));
    let mut rng = stream_rng(29, 0);
    let r = RES as f32;
    for _ in 0..2_000_000 {
        let x = family.draw_candidate(&mut rng);
        if x.segments() == 4
            && x.luminance() > 0.0
            && x.all_visible()
            && x.vertices[2].delta
            && multi_chain(&x) == Some(1)
            && x.raster.min_element() > margin
            && x.raster.max_element() < r - margin
        {
            return x;
        }
    }
    panic!("no light-diffuse-mirror-diffuse-camera path found");
}

/// The path `x` with its camera ray through `raster` and the direction
/// `dir` leaving the vertex the camera sees, traced by the test: diffuse
/// hit, then mirror hit, reflection, first hit.
fn traced_multi<'s>(x: &Path<'s>, raster: Vec2, dir: Vec3) -> Option<Path<'s>> {
    let scene = x.scene;
    let ray = scene.camera.generate_ray(raster);
    let seen = scene.intersect(&ray)?;
    if scene.bsdf_at(&seen.sp).is_delta() {
        return None;
    }
    let m = scene.intersect(&seen.sp.spawn_ray(dir))?;
    if !scene.bsdf_at(&m.sp).is_delta() {
        return None;
    }
    let n = m.sp.ng;
    let r = dir - 2.0 * dir.dot(n) * n;
    let hit = scene.intersect(&m.sp.spawn_ray(r))?;
    let mut y = x.clone();
    y.vertices[3] = Vertex::surface(scene, seen.sp, -ray.d.normalize(), Rgb::WHITE);
    let mut mirror = Vertex::surface(scene, m.sp, -dir, Rgb::WHITE);
    mirror.delta = true;
    y.vertices[2] = mirror;
    y.vertices[1] = Vertex::surface(scene, hit.sp, -r, Rgb::WHITE);
    y.normalize_ends();
    y.evaluate();
    Some(y)
}

/// True when `y` is a proposal the multi-chain perturbation accepts.
fn multi_valid(x: &Path, y: &Path) -> bool {
    let scene = x.scene;
    y.contribution.luminance() > 0.0
        && multi_chain(y) == Some(1)
        && y.vertices[2].delta
        && scene.geometry.visible(&x.vertices[0].sp, &y.vertices[1].sp)
}

/// `ln J(y)`, the factor that turns the code's `T(x→y)` into a density
/// over (film offset, direction at `y_3`): the camera's `|dA(y_3)/dr| =
/// |dω/dr| d_c² / cos_3` times the mirror chain's `d₁² d₂² / (cos_m
/// cos_1)` (as in the caustic test), from the geometry alone.
fn multi_log_jacobian(y: &Path) -> f64 {
    let p = |i: usize| y.vertices[i].p().as_dvec3();
    let ng = |i: usize| y.vertices[i].sp.ng.as_dvec3();
    let d_c = (p(4) - p(3)).length();
    let cos_3 = ng(3).dot((p(4) - p(3)) / d_c).abs();
    let (d1, d2) = ((p(2) - p(3)).length(), (p(1) - p(2)).length());
    let cos_m = ng(2).dot((p(3) - p(2)) / d1).abs();
    let cos_1 = ng(1).dot((p(2) - p(1)) / d2).abs();
    (pixel_solid_angle(y.scene, y.raster) * d_c * d_c / cos_3 * d1 * d1 * d2 * d2 / (cos_m * cos_1))
        .ln()
}

/// The joint cell of a proposal: film offset cell × angle cell.
fn multi_cell(
    kernel: &MultiChainPerturbation,
    x: &Path,
    offset: (f64, f64),
    angle: (f64, f64),
) -> Option<usize> {
    let o = kernel.offsets(x.scene);
    let a = kernel.angles;
    let co = polar_cell(offset, o.r1, o.r2, NM, NM)?;
    let ca = polar_cell(angle, a.theta1, a.theta2, NM, NM)?;
    Some(co * NM * NM + ca)
}

/// Expected probability per joint cell from the code's `T(x→·)`;
/// `drop_cos` removes the cosine at `y_1` (the control).
fn multi_masses(kernel: &MultiChainPerturbation, x: &Path, drop_cos: bool) -> Vec<f64> {
    let o = kernel.offsets(x.scene);
    let a = kernel.angles;
    let w = ray_dir(&x.vertices[3], x.vertices[2].p());
    let (e1, e2) = basis(w);
    let mut masses = vec![0.0; NM.pow(4)];
    let (no, na) = (NM * QM_OFFSET, NM * QM_ANGLE);
    let dlo = (o.r2 / o.r1).ln() / no as f64;
    let dla = (a.theta2 / a.theta1).ln() / na as f64;
    let (dpo, dpa) = (2.0 * PI / no as f64, 2.0 * PI / na as f64);
    for io in 0..no {
        let r = o.r1 * ((io as f64 + 0.5) * dlo).exp();
        for po in 0..no {
            let phi = (po as f64 + 0.5) * dpo;
            let raster = x.raster + Vec2::new((r * phi.cos()) as f32, (r * phi.sin()) as f32);
            for ia in 0..na {
                let theta = a.theta1 * ((ia as f64 + 0.5) * dla).exp();
                for pa in 0..na {
                    let psi = (pa as f64 + 0.5) * dpa;
                    let d = w * theta.cos() + (e1 * psi.cos() + e2 * psi.sin()) * theta.sin();
                    let Some(y) = traced_multi(x, raster, d.as_vec3()) else {
                        continue;
                    };
                    if !multi_valid(x, &y) {
                        continue;
                    }
                    let mut ln_t = kernel.log_transition_density(x, &y);
                    if drop_cos {
                        ln_t -= log_cos_1(&y);
                    }
                    if ln_t == f64::NEG_INFINITY {
                        continue;
                    }
                    let q = (ln_t + multi_log_jacobian(&y)).exp();
                    let Some(cell) = multi_cell(kernel, x, (r, phi), (theta, psi)) else {
                        continue;
                    };
                    // d²Δ dω = r² d(ln r) dφ · θ sin θ d(ln θ) dψ.
                    masses[cell] += q * r * r * dlo * dpo * theta * theta.sin() * dla * dpa;
                }
            }
        }
    }
    masses
}

#[test]
fn multi_chain_perturbation_density_matches_its_proposals() {
    let scene = mirror_box();
    let mut kernel = MultiChainPerturbation::default();
    // Mitsuba's angle sizes by default.
    assert!((kernel.angles.theta1 - 1e-4 * PI / 180.0).abs() < 1e-15);
    assert!((kernel.angles.theta2 - 0.1 * PI / 180.0).abs() < 1e-15);
    // Mitsuba's θ₁ = 1.7e-6 rad is within a few f32 ulps of the positions
    // (directions between hit points are off by up to 5e-7 rad here,
    // measured), which the histogram cannot resolve: the test runs the
    // same kernel at θ₁ = 0.01°, θ₂ = 1°.
    kernel.angles = AngleKernel {
        theta1: 0.01f64.to_radians(),
        theta2: 1f64.to_radians(),
    };
    let offsets = kernel.offsets(scene);
    let x = multi_chain_path(scene, offsets.r2 as f32 + 1.0);
    // T(x→y) = p_Δ p_ω / J(y).
    let w = ray_dir(&x.vertices[3], x.vertices[2].p());
    check_density(
        &mut kernel,
        &x,
        31,
        NM.pow(4),
        |k, y| {
            let d = ray_dir(&y.vertices[3], y.vertices[2].p());
            let offset = offset_polar(y.raster - x.raster);
            multi_cell(k, &x, offset, polar_of(w, d))
        },
        |k, drop| multi_masses(k, &x, drop),
        "the cosine at y_1",
        |k, a, b| k.log_transition_density(a, b),
        multi_log_jacobian,
        1e-6,
    );
}

#[test]
fn multi_chain_perturbation_pattern() {
    // Four-segment paths: only L D S D E matches (j = 1); L D D S E, L D S
    // S E, … do not, and their proposals fail as mismatches.
    let scene = mirror_box();
    let family = PathFamily::new(scene, Some(4));
    let mut rng = stream_rng(37, 0);
    let mut kernel = MultiChainPerturbation::default();
    let (mut matched, mut other) = (0, 0);
    for _ in 0..50_000 {
        let x = family.draw_candidate(&mut rng);
        if x.luminance() <= 0.0 {
            continue;
        }
        let ldsde = x.segments() == 4
            && (0..4).all(|i| x.vertices[i].delta == (i == 2))
            && (0..4).all(|i| x.connectible(i) == (i != 2));
        let current = sample_of(&x);
        let mut proposal = sample_of(&x);
        let p = kernel.propose(&current, &mut proposal, &mut rng);
        if ldsde {
            matched += 1;
            assert_eq!(multi_chain(&x), Some(1));
            assert!(p.component != 1, "L D S D E matches the pattern");
        } else {
            other += 1;
            assert_eq!(multi_chain(&x), None, "{x:?}");
            assert!(p.failed && p.component == 1, "only L D S D E matches");
        }
    }
    eprintln!("L D S D E {matched}, others {other}");
    assert!(matched > 20, "too few L D S D E paths: {matched}");
    assert_eq!(kernel.component_names().len(), 8);
}

// ---------------------------------------------------------------------------
// Stationarity from exact start states.

/// A kernel whose reported ratio is replaced by 0 (a perturbation treated
/// as symmetric: every Jacobian dropped). The control of the
/// stationarity test.
struct Symmetric<K>(K);

impl<'s, K: Kernel<Path<'s>, PathSample>> Kernel<Path<'s>, PathSample> for Symmetric<K> {
    fn propose(
        &mut self,
        current: &Sample<Path<'s>, PathSample>,
        proposal: &mut Sample<Path<'s>, PathSample>,
        rng: &mut mcmc_core::rng::ChainRng,
    ) -> mcmc_core::kernel::Proposal {
        let mut p = self.0.propose(current, proposal, rng);
        if !p.failed {
            p.log_q_ratio = 0.0;
        }
        p
    }

    fn component_names(&self) -> Vec<String> {
        self.0.component_names()
    }
}

/// Statistics of a path restricted to a set: `1`, raster x and y (in
/// image widths), and the squared distance from the image centre, each
/// times the set's indicator.
fn stats(x: &Path, in_set: bool) -> [f64; 4] {
    if !in_set {
        return [0.0; 4];
    }
    let (rx, ry) = (
        x.raster.x as f64 / RES as f64,
        x.raster.y as f64 / RES as f64,
    );
    [1.0, rx, ry, (rx - 0.5).powi(2) + (ry - 0.5).powi(2)]
}

/// Self-normalised importance estimate of `E_π[h | set]` from `m`
/// start-up candidates (seed `seed`), with its delta-method standard
/// error, and the candidates in the set with their log weights.
#[allow(clippy::type_complexity)]
fn reference<'s>(
    family: &PathFamily<'s>,
    set: &dyn Fn(&Path) -> bool,
    m: usize,
    seed: u64,
) -> ([f64; 4], [f64; 4], Vec<(Path<'s>, f64)>) {
    let mut rng = stream_rng(seed, 0);
    let mut kept = Vec::new();
    for _ in 0..m {
        let x = family.draw_candidate(&mut rng);
        let lw = family.weighed_candidate(0, &x).0;
        if lw.is_finite() && set(&x) {
            kept.push((x, lw));
        }
    }
    let max = kept.iter().map(|c| c.1).fold(f64::NEG_INFINITY, f64::max);
    let w: Vec<f64> = kept.iter().map(|c| (c.1 - max).exp()).collect();
    let sw: f64 = w.iter().sum();
    let mut mean = [0.0; 4];
    for (c, wi) in kept.iter().zip(&w) {
        let h = stats(&c.0, true);
        for d in 0..4 {
            mean[d] += wi * h[d] / sw;
        }
    }
    let mut se = [0.0; 4];
    for (c, wi) in kept.iter().zip(&w) {
        let h = stats(&c.0, true);
        for d in 0..4 {
            se[d] += (wi / sw).powi(2) * (h[d] - mean[d]).powi(2);
        }
    }
    (mean, se.map(f64::sqrt), kept)
}

/// Mean over `k` chains of the per-chain average of `stats` over the last
/// two thirds of `n` Metropolis–Hastings steps (`mcmc-core`'s acceptance;
/// every step's marginal is `π` for exact starts, and a wrong kernel has
/// drifted furthest at the end) of `kernel`, each
/// chain started from a candidate resampled in proportion to its weight;
/// and the standard error from the `k` independent chain averages.
fn chain_means<'s, K: Kernel<Path<'s>, PathSample>>(
    kernel: &mut K,
    starts: &[(Path<'s>, f64)],
    k: usize,
    n: usize,
    seed: u64,
) -> ([f64; 4], [f64; 4]) {
    use mcmc_core::mh::{accept, mh_log_acceptance};
    use mcmc_core::rng::uniform;
    let max = starts.iter().map(|c| c.1).fold(f64::NEG_INFINITY, f64::max);
    let mut cdf = Vec::with_capacity(starts.len());
    let mut acc = 0.0;
    for c in starts {
        acc += (c.1 - max).exp();
        cdf.push(acc);
    }
    let target = mcmc_render::path_space::PathTarget::default();
    let mut per_chain = Vec::with_capacity(k);
    for chain in 0..k {
        let mut rng = stream_rng(seed, chain as u64);
        let u = uniform(&mut rng) * acc;
        let i = cdf.partition_point(|&c| c < u).min(starts.len() - 1);
        let mut current = sample_of(&starts[i].0);
        let mut scratch = current.clone();
        let mut sum = [0.0; 4];
        for step in 0..n {
            let p = kernel.propose(&current, &mut scratch, &mut rng);
            if !p.failed {
                scratch.reevaluate(&target);
                let (log_alpha, _) =
                    mh_log_acceptance(current.log_density, scratch.log_density, p.log_q_ratio);
                if accept(log_alpha, &mut rng) {
                    std::mem::swap(&mut current, &mut scratch);
                }
            }
            if step >= n / 3 {
                let h = stats(&current.state, true);
                for d in 0..4 {
                    sum[d] += h[d] / (n - n / 3) as f64;
                }
            }
        }
        per_chain.push(sum);
    }
    let mut mean = [0.0; 4];
    for s in &per_chain {
        for d in 0..4 {
            mean[d] += s[d] / k as f64;
        }
    }
    let mut var = [0.0; 4];
    for s in &per_chain {
        for d in 0..4 {
            var[d] += (s[d] - mean[d]).powi(2) / (k as f64 - 1.0);
        }
    }
    (mean, var.map(|v| (v / k as f64).sqrt()))
}

/// The reference and the exact start states of one set of paths: two
/// independent importance estimates of `m` start-up candidates each
/// (seeds `seed`, `seed + 1`), the second's candidates the chains' start
/// pool. Built once per set and shared by a kernel and its control.
struct Pools<'s> {
    /// Seed of the first pool; the chains run on `seed + 2`.
    seed: u64,
    /// Chains run from the start pool.
    chains: usize,
    /// The reference estimate of the statistics and its standard error.
    truth: ([f64; 4], [f64; 4]),
    /// The start pool's estimate and its standard error.
    start: ([f64; 4], [f64; 4]),
    /// The start pool's candidates in the set, with their log weights.
    starts: Vec<(Path<'s>, f64)>,
}

impl<'s> Pools<'s> {
    /// Pools of 200 000 candidates for 2 000 chains.
    fn new(family: &PathFamily<'s>, set: &dyn Fn(&Path) -> bool, seed: u64) -> Self {
        Self::sized(family, set, seed, 200_000, 2_000)
    }

    /// Pools of `m` candidates for `chains` chains.
    fn sized(
        family: &PathFamily<'s>,
        set: &dyn Fn(&Path) -> bool,
        seed: u64,
        m: usize,
        chains: usize,
    ) -> Self {
        let (truth, truth_se, _) = reference(family, set, m, seed);
        let (start_mean, start_se, starts) = reference(family, set, m, seed + 1);
        Pools {
            seed,
            chains,
            truth: (truth, truth_se),
            start: (start_mean, start_se),
            starts,
        }
    }
}

/// Largest |z| over statistics 1–3 (raster x, y, radius²) between a
/// kernel's chains (from `pools`' starts, 300 steps) and `pools`'
/// reference.
fn stationarity_z<'s, K: Kernel<Path<'s>, PathSample>>(
    name: &str,
    kernel: &mut K,
    pools: &Pools<'s>,
) -> f64 {
    const STEPS: usize = 300;
    let ((truth, truth_se), (start_mean, start_se)) = (pools.truth, pools.start);
    let (mean, se) = chain_means(kernel, &pools.starts, pools.chains, STEPS, pools.seed + 2);
    let mut worst = 0.0f64;
    for d in 1..4 {
        // The chains' mean carries the start pool's error too (the starts
        // are resampled from it): three independent errors.
        let sigma = (se[d].powi(2) + truth_se[d].powi(2) + start_se[d].powi(2)).sqrt();
        let z = (mean[d] - truth[d]) / sigma;
        eprintln!(
            "{name}: stat {d}: chains {:.5} ± {:.5}, reference {:.5} ± {:.5}, starts {:.5}; z = {z:+.2}",
            mean[d], se[d], truth[d], truth_se[d], start_mean[d]
        );
        worst = worst.max(z.abs());
    }
    worst
}

/// Asserts that `kernel` keeps exact start states exact (|z| < 4) and
/// that its control, the same kernel with its ratio replaced by 0, does
/// not (|z| > 4), on the paths `pools` were drawn from.
fn assert_stationary_with_control<'s, K: Kernel<Path<'s>, PathSample>>(
    name: &str,
    mut kernel: impl FnMut() -> K,
    pools: &Pools<'s>,
) {
    let z = stationarity_z(name, &mut kernel(), pools);
    let control = stationarity_z(&format!("{name}, ratio 0"), &mut Symmetric(kernel()), pools);
    assert!(z < 4.0, "{name}: the chains drift from π: |z| = {z:.2}");
    assert!(
        control > 4.0,
        "{name}: the control (ratio 0) passed: |z| = {control:.2}"
    );
}

/// Each perturbation (and the lens subpath mutation) alone, on the paths
/// of its pattern (which it keeps, so `π` restricted to them is
/// invariant), and the mixture of all mutations at weight 1 on every
/// path, started from exact samples: importance resampling from 200 000
/// start-up candidates (the driver's MIS weights), 2 000 chains of 300
/// steps (the last 200 averaged). The chains' average of raster x, raster
/// y and squared radius must match a second, independent importance
/// estimate within 4σ (σ from the 2 000 independent chain averages, K ≥
/// 30, and both pools' delta-method errors). Controls, each asserted to
/// fail: the same kernels with their ratio replaced by 0 (all Jacobians
/// dropped). The multi-chain perturbation's control is asserted at wider
/// angles (`multi_chain_perturbation_keeps_exact_start_states_exact_at_wide_angles`):
/// at Mitsuba's (≤ 0.1°) its Jacobians barely change.
#[test]
fn perturbations_keep_exact_start_states_exact() {
    let scene = mirror_box();
    let family = PathFamily::new(scene, Some(4));
    let lens = Pools::new(&family, &|x: &Path| lens_chain(x).is_some(), 100);
    let caustic = Pools::new(&family, &|x: &Path| caustic_chain(x).is_some(), 200);
    let multi = Pools::new(&family, &|x: &Path| multi_chain(x).is_some(), 300);
    let all = Pools::new(&family, &|_: &Path| true, 400);
    assert_stationary_with_control("lens", LensPerturbation::default, &lens);
    assert_stationary_with_control("caustic", CausticPerturbation::default, &caustic);
    let z_multi = stationarity_z(
        "multi-chain",
        &mut MultiChainPerturbation::default(),
        &multi,
    );
    assert!(
        z_multi < 4.0,
        "multi-chain: the chains drift from π: |z| = {z_multi:.2}"
    );
    assert_stationary_with_control("lens subpath", LensSubpath::default, &lens);
    let mixture = || {
        PathMutations {
            lens_perturbation: 1.0,
            caustic_perturbation: 1.0,
            multi_chain_perturbation: 1.0,
            lens_subpath: 1.0,
            ..PathMutations::default()
        }
        .kernel(Some(4))
        .expect("mixture")
    };
    assert_stationary_with_control("mixture", mixture, &all);
}

/// The multi-chain perturbation alone, as above, with its angle kernel
/// widened to `θ₁ = 0.5°`, `θ₂ = 20°` (Mitsuba's: 10⁻⁴° to 0.1°, where
/// the turned segment barely changes its Jacobians and the control cannot
/// fail at this budget): the kernel's ratio holds for any sizes (its
/// density test runs at 0.01°–1°), and here its control, the ratio
/// replaced by 0, must fail. Its paths (`L D S D E`) are rare among the
/// start-up candidates, so the two pools' errors dominated σ with the
/// default test's 200 000 candidates (control |z| 2.28, the chains 0.010
/// off on the squared radius with σ 0.005, session 20): here 2 000 000
/// candidates per pool and 4 000 chains (expected σ ≈ 0.0018). Ignored
/// for its run time (≈ 10 s): `cargo test -p mcmc-render --test
/// path_space_perturbations -- --ignored wide_angles --nocapture`.
#[test]
#[ignore]
fn multi_chain_perturbation_keeps_exact_start_states_exact_at_wide_angles() {
    let scene = mirror_box();
    let family = PathFamily::new(scene, Some(4));
    let set = |x: &Path| multi_chain(x).is_some();
    let multi = Pools::sized(&family, &set, 300, 2_000_000, 4_000);
    let wide = || {
        let mut k = MultiChainPerturbation::default();
        k.angles = AngleKernel {
            theta1: 0.5f64.to_radians(),
            theta2: 20f64.to_radians(),
        };
        k
    };
    assert_stationary_with_control("multi-chain, wide angles", wide, &multi);
}

/// Veach's bidirectional mutation alone keeps exact start states exact:
/// the stationarity check above (mirror box, paths of up to 4 segments,
/// 2 000 chains of 300 steps from importance-resampled starts, the last
/// 200 averaged, |z| < 4 against the independent importance estimate),
/// for the length-changing and the fixed-length variant on all paths
/// (both keep `π` invariant on every path; the fixed-length one on each
/// length). Control: the length-changing mutation with its ratio set to 0
/// (the sum over splits, the length and deletion pmfs dropped) must fail.
#[test]
fn bidirectional_mutation_keeps_exact_start_states_exact() {
    let scene = mirror_box();
    let family = PathFamily::new(scene, Some(4));
    let all = |_: &Path| true;
    assert_stationary_with_control(
        "bidirectional",
        || Bidirectional::new(1, Some(4), false),
        &Pools::new(&family, &all, 600),
    );
    let z_fixed = stationarity_z(
        "bidirectional, fixed length",
        &mut Bidirectional::new(1, Some(4), true),
        &Pools::new(&family, &all, 700),
    );
    assert!(
        z_fixed < 4.0,
        "fixed length: the chains drift from π: |z| = {z_fixed:.2}"
    );
}

/// The independent proposal (a fresh start-up candidate, `mept`'s large
/// step) alone keeps exact start states exact: the stationarity check
/// above (mirror box, paths of up to 4 segments, 2 000 chains of 300
/// steps from importance-resampled starts, |z| < 4 against the
/// independent importance estimate). Control: its ratio `ln p₀(x) −
/// ln p₀(y)` set to 0 (the chains then target `I · p₀`) must fail.
#[test]
fn independent_proposal_keeps_exact_start_states_exact() {
    let scene = mirror_box();
    let family = PathFamily::new(scene, Some(4));
    let independent = || IndependentPath {
        min_segments: 1,
        max_segments: Some(4),
        camera_walks: false,
    };
    assert_stationary_with_control(
        "independent",
        independent,
        &Pools::new(&family, &|_: &Path| true, 800),
    );
}

/// PT's and `mlt`'s replicate image means on the tilted glossy-glass box
/// (16×16, depth 5), shared by the agreement test below and its control.
type Replicates = (Vec<[f64; 3]>, Vec<[f64; 3]>);

/// `mlt`'s default mixture (Mitsuba 0.6's selection: bidirectional, lens,
/// caustic and multi-chain at weight 1 each) against PT on the tilted
/// glossy-glass box, sized for 1% (session 20).
///
/// Why the session-9 version (48 replicates of 400 000 candidates, 256
/// chains, 4096 mutations per pixel) did not resolve 1%: variance, spent
/// in the wrong place. A replicate's noise here is its start-up pool's:
/// the chains start from candidates resampled from the pool and barely
/// leave their colours within a replicate, so the image mean's spread
/// follows the pool size, not the chains. Measured with the CLI (2 cores,
/// 12–16 seeds each, the mixture below): blue spreads 6.6% per replicate
/// with 100 000 candidates and 256 chains of 1024 mutations per pixel,
/// 6.4% with 4096 chains, 2.2% with 300 000 candidates and 512 chains
/// (≈ 1 s of CPU), 2.2% with 1 000 000 (≈ 3.5 s); session 9's budget gave
/// 2.1% for ≈ 4 s. So the budget is `path_space_mlt.rs`'s (300 000, 512,
/// 1024) and the replicates many: with PT at 128 × 2048 spp (0.07% on
/// blue) and `mlt` at 2.2–2.6% per replicate, 256 replicates give a total
/// σ of 0.15–0.18% (5σ 0.77–0.89%).
fn all_perturbations_glossy_glass() -> &'static Replicates {
    static REPS: OnceLock<Replicates> = OnceLock::new();
    REPS.get_or_init(|| {
        let scene = common::repo_scene_tilted("cornell-glossy-glass.xml", 16, 5);
        let pt = common::mc_reps(&scene, &common::pt_of(&scene), 2048, 128, 1000);
        let mutation = Mlt::default().mutations();
        // The name of the test: Mitsuba's selection is `mlt`'s default.
        assert_eq!(
            [
                mutation.bidirectional,
                mutation.lens_perturbation,
                mutation.caustic_perturbation,
                mutation.multi_chain_perturbation,
                mutation.manifold_perturbation,
                mutation.lens_subpath,
                mutation.independent,
            ],
            [1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0]
        );
        let budget = common::Budget {
            bootstrap: 300_000,
            chains: 512,
            mpp: 1024,
        };
        let mlt = path_mlt_reps(&scene, mutation, budget, 256, 19_000);
        (pt, mlt)
    })
}

/// `mlt` with every perturbation Mitsuba 0.6 turns on (its default
/// mixture) agrees with PT on the glossy-glass box to 1%: 4σ and 1%, 5σ <
/// 1% (sizing at `all_perturbations_glossy_glass`). Ignored for its run
/// time: `cargo test -p mcmc-render --profile test --test
/// path_space_perturbations -- --ignored all_perturbations --nocapture`
/// runs it with its control. Passed once (session 20, 2026-11-27, 2
/// cores, load 7–8): rel −0.07%, −0.09%, −0.005% (R/G/B), σ of the
/// difference 0.12%, 0.13%, 0.18% (5σ 0.90% on blue), the ×1.01 control
/// failing at 5.5–7.6σ; both tests 224 s of CPU, 404 s wall.
#[test]
#[ignore]
fn mlt_with_all_perturbations_agrees_with_pt_on_the_glass_box() {
    let (pt, mlt) = all_perturbations_glossy_glass();
    common::assert_agrees_to_one_percent("mlt, all perturbations", pt, mlt);
}

/// The control of the agreement above: the same replicates × 1.01 must
/// fail it. Ignored with the replicates it scales.
#[test]
#[ignore]
fn a_one_percent_bias_is_rejected_with_all_perturbations() {
    let (pt, mlt) = all_perturbations_glossy_glass();
    common::assert_one_percent_bias_is_rejected("mlt, all perturbations", pt, mlt);
}

// ---------------------------------------------------------------------------
// Lens subpath mutation.

/// Expected probability per cell of an 8×8 grid over the image from the
/// code's `T(x→·)` of the lens subpath mutation (the lens test's tracer and
/// Jacobian); `drop_cos` removes the cosine at `y_1` (the control).
fn subpath_masses(kernel: &LensSubpath, x: &Path, drop_cos: bool) -> Vec<f64> {
    // 64 points per cell and axis (1/8 px): the cells are cut by the
    // mirror's edges and the occlusion boundaries.
    let cell = RES as f64 / NR as f64;
    let n = NR * 64;
    let h = RES as f64 / n as f64;
    let mut masses = vec![0.0; NR * NR];
    for ix in 0..n {
        for iy in 0..n {
            let raster = Vec2::new(
                ((ix as f64 + 0.5) * h) as f32,
                ((iy as f64 + 0.5) * h) as f32,
            );
            let Some(y) = traced(x, raster) else {
                continue;
            };
            if !valid(x, &y) {
                continue;
            }
            let mut ln_t = kernel.log_transition_density(x, &y);
            if drop_cos {
                ln_t -= log_cos_1(&y);
            }
            if ln_t == f64::NEG_INFINITY {
                continue;
            }
            let q = (ln_t + log_jacobian(&y)).exp();
            let c = ((ix as f64 * h / cell) as usize) * NR + (iy as f64 * h / cell) as usize;
            masses[c] += q * h * h;
        }
    }
    masses
}

/// The lens subpath mutation from one `L D S E` path of the mirror box:
/// 100 000 proposals binned by raster position in 8×8 cells over the
/// image, against the code's `T` times the lens test's independent
/// Jacobian (midpoint rule, 64×64 per cell); chi-square p > 1e-4; the
/// control without the cosine at `y_1` must fail; the ratio of 200
/// proposals against the independent Jacobians within 1e-4.
#[test]
fn lens_subpath_density_matches_its_proposals() {
    let scene = mirror_box();
    let mut kernel = LensSubpath::default();
    let x = mirror_path(scene, 1.0);
    let cell = RES as f32 / NR as f32;
    check_density(
        &mut kernel,
        &x,
        41,
        NR * NR,
        |_, y| {
            let (cx, cy) = ((y.raster.x / cell) as usize, (y.raster.y / cell) as usize);
            Some(cx.min(NR - 1) * NR + cy.min(NR - 1))
        },
        |k, drop| subpath_masses(k, &x, drop),
        "the cosine at y_1",
        |k, a, b| k.log_transition_density(a, b),
        log_jacobian,
        1e-9,
    );
}

/// Suitability selection (Mitsuba 0.6): a mutation whose pattern the path
/// does not match is never selected, and the bidirectional mutation's
/// reported ratio is its own plus `ln p_b(y) − ln p_b(x)`, the selection
/// probabilities renormalised over the applicable types at each end:
/// checked exactly (to 1e-12) against the bare bidirectional mutation
/// replayed with the same random numbers (the mixture draws one uniform
/// for the selection, then the component draws its own). On the mirror
/// box of ≤ 3 segments the applicable sets differ (`L D E`: all three;
/// `L S E`: bidirectional only; `L D S E`: + lens; `L S D E`: + caustic),
/// so the bidirectional mutation often moves between them. Control: the
/// fixed-weight mixture's ratio lacks the factor and must miss it.
#[test]
fn suitability_selection_enters_the_ratio() {
    let scene = mirror_box();
    let weights = [1.0, 2.0, 3.0];
    let mutations = PathMutations {
        bidirectional: weights[0],
        lens_perturbation: weights[1],
        caustic_perturbation: weights[2],
        suitability: true,
        ..PathMutations::default()
    };
    let mut suitable = mutations.kernel(Some(3)).expect("mixture");
    let mut fixed = PathMutations {
        suitability: false,
        ..mutations
    }
    .kernel(Some(3))
    .expect("mixture");
    let mut bare = Bidirectional::new(1, Some(3), false);
    // ln p_b at x: the bidirectional weight over the applicable weights.
    let log_p_bidirectional = |x: &Path| {
        let lens = if lens_chain(x).is_some() {
            weights[1]
        } else {
            0.0
        };
        let caustic = if caustic_chain(x).is_some() {
            weights[2]
        } else {
            0.0
        };
        (weights[0] / (weights[0] + lens + caustic)).ln()
    };
    // Components: bidirectional 0–6, independent 7, lens 8–14, caustic 15–24.
    let (lens_range, caustic_range) = (8..15, 15..25);
    let family = PathFamily::new(scene, Some(3));
    let mut rng = stream_rng(71, 0);
    let (mut checked, mut moved_between_sets) = (0, 0);
    let (mut control_cases, mut control_missed) = (0, 0);
    let (mut lens_picked, mut caustic_picked) = (0, 0);
    for i in 0..4000u64 {
        let x = family.draw_candidate(&mut rng);
        if x.luminance() <= 0.0 {
            continue;
        }
        let current = sample_of(&x);
        let numbers = stream_rng(1000 + i, 0);
        let mut proposal = sample_of(&x);
        let p = suitable.propose(&current, &mut proposal, &mut numbers.clone());
        if lens_range.contains(&p.component) {
            lens_picked += 1;
            assert!(
                lens_chain(&x).is_some(),
                "lens selected where it cannot apply"
            );
        }
        if caustic_range.contains(&p.component) {
            caustic_picked += 1;
            assert!(
                caustic_chain(&x).is_some(),
                "caustic selected where it cannot apply"
            );
        }
        if p.failed || p.component != 0 {
            continue;
        }
        let mut replay = numbers.clone();
        let _selection = uniform(&mut replay);
        let mut alone = sample_of(&x);
        let q = bare.propose(&current, &mut alone, &mut replay);
        assert!(!q.failed && q.component == 0, "replay differs");
        let y = &proposal.state;
        assert_eq!(y.raster, alone.state.raster, "replay made another path");
        assert_eq!(y.len(), alone.state.len());
        let factor = log_p_bidirectional(y) - log_p_bidirectional(&x);
        if q.log_q_ratio == f64::NEG_INFINITY {
            // No reverse move: rejected with or without the selection.
            assert_eq!(p.log_q_ratio, f64::NEG_INFINITY);
            continue;
        }
        let expected = q.log_q_ratio + factor;
        assert!(
            (p.log_q_ratio - expected).abs() <= 1e-12 * (1.0 + expected.abs()),
            "ratio {} vs bidirectional {} + selection {factor}",
            p.log_q_ratio,
            q.log_q_ratio
        );
        checked += 1;
        if factor.abs() > 1e-3 {
            moved_between_sets += 1;
            // The control: the same move through the fixed mixture (same
            // numbers, same selection here as the bidirectional weight is
            // chosen first) reports the bare ratio, off by the factor.
            let mut control = sample_of(&x);
            let c = fixed.propose(&current, &mut control, &mut numbers.clone());
            if c.component == 0 && !c.failed {
                control_cases += 1;
                control_missed += usize::from((c.log_q_ratio - expected).abs() > 1e-3);
            }
        }
    }
    eprintln!(
        "{checked} bidirectional proposals checked, {moved_between_sets} between applicable sets (control missed {control_missed} of {control_cases}); lens picked {lens_picked}, caustic {caustic_picked}"
    );
    assert!(checked >= 200, "too few checked: {checked}");
    assert!(
        moved_between_sets >= 20,
        "too few set changes: {moved_between_sets}"
    );
    assert!(control_cases >= 5, "too few control cases: {control_cases}");
    assert_eq!(
        control_missed, control_cases,
        "the control passed somewhere"
    );
    assert!(lens_picked > 0 && caustic_picked > 0);
}

/// Emitters at infinity (issue 13): on `common::sky_scene` (a constant sky
/// and a directional sun, every path starting at infinity; 64×64, paths
/// of up to 4 segments) the stationarity check above for the mixture of
/// the bidirectional mutation (which regrows `x_0` at infinity by the
/// sky's direction sampling or an escaping camera walk, and continues
/// light walks from its disk) with every re-tracing mutation at weight 1:
/// the lens and multi-chain perturbations and the lens subpath mutation
/// reconnect to `x_0`'s direction, the caustic perturbation's pattern
/// refuses `x_0` at infinity as its chain's start. Control: the
/// bidirectional mutation with its ratio set to 0 must fail.
#[test]
fn mutations_keep_exact_start_states_exact_under_a_sky() {
    let scene = sky();
    let family = PathFamily::new(scene, Some(4));
    let all = |_: &Path| true;
    let mut mixture = PathMutations {
        lens_perturbation: 1.0,
        caustic_perturbation: 1.0,
        multi_chain_perturbation: 1.0,
        lens_subpath: 1.0,
        ..PathMutations::default()
    }
    .kernel(Some(4))
    .expect("mixture");
    let pools = Pools::new(&family, &all, 900);
    let z = stationarity_z("mixture under a sky", &mut mixture, &pools);
    let control = stationarity_z(
        "bidirectional under a sky, ratio 0",
        &mut Symmetric(Bidirectional::new(1, Some(4), false)),
        &pools,
    );
    assert!(z < 4.0, "the chains drift from π under a sky: |z| = {z:.2}");
    assert!(
        control > 4.0,
        "control passed under a sky: |z| = {control:.2}"
    );
}

/// The sky scene at the test resolution.
fn sky() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| common::sky_scene(RES, 4, true))
}
