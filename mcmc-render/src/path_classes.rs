//! Veach's path classes of one BDPT sample (Kitaoka et al. 2009, §4.2.1):
//! every technique `(s, t)` of a sample lands in exactly one of six
//! classes, so that the classes' MIS-weighted contributions `L0 … L5` sum
//! to the sample's BDPT contribution.
//!
//! The paper's index ranges overlap (spec seed002 §3); the partition used
//! here, for techniques with `t ≥ 1` (a pinhole camera is never hit):
//!
//! | class | techniques |
//! |---|---|
//! | `L0` specular implicit | `s = 0`, `t ≥ 2`, some camera-subpath vertex before the emitter sampled a Dirac delta |
//! | `L1` implicit | `s = 0`, `t ≥ 2`, no such vertex |
//! | `L2` explicit | `s = 1`, `t ≥ 2` |
//! | `L3` implicit caustic | `t = 0` (empty with a pinhole camera) |
//! | `L4` explicit caustic | `t = 1` (light tracing to the camera; BDPT skips `(1, 1)`) |
//! | `L5` indirect | `s ≥ 2`, `t ≥ 2` |

use crate::color::Rgb;
use crate::integrators::bdpt::{Bdpt, Connection, SubpathBuffers, generate_camera_subpath};
use crate::pss::{PATH_CLASSES, PssPathSampler, PssSource, Splat, raster_of};
use crate::sampling::{RandomSource, Stream};
use crate::scene::Scene;
use mcmc_core::space::TorusPoint;
use std::cell::RefCell;

/// The class of a technique.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PathClass {
    /// `L0`: the camera subpath hits the emitter after a specular bounce.
    SpecularImplicit = 0,
    /// `L1`: the camera subpath hits the emitter, no specular bounce.
    Implicit = 1,
    /// `L2`: next-event estimation (`s = 1`).
    Explicit = 2,
    /// `L3`: the light subpath hits the lens (`t = 0`).
    ImplicitCaustic = 3,
    /// `L4`: the light subpath connected to the camera (`t = 1`).
    ExplicitCaustic = 4,
    /// `L5`: interior connections (`s, t ≥ 2`).
    Indirect = 5,
}

impl PathClass {
    /// Every class, in index order.
    pub const ALL: [PathClass; PATH_CLASSES] = [
        PathClass::SpecularImplicit,
        PathClass::Implicit,
        PathClass::Explicit,
        PathClass::ImplicitCaustic,
        PathClass::ExplicitCaustic,
        PathClass::Indirect,
    ];

    /// The class of technique `(s, t)`; `specular`: whether a camera
    /// subpath vertex between the camera and the emitter sampled a Dirac
    /// delta (only read for `s = 0`).
    pub fn of(s: usize, t: usize, specular: bool) -> PathClass {
        match (s, t) {
            (_, 0) => PathClass::ImplicitCaustic,
            (_, 1) => PathClass::ExplicitCaustic,
            (0, _) if specular => PathClass::SpecularImplicit,
            (0, _) => PathClass::Implicit,
            (1, _) => PathClass::Explicit,
            _ => PathClass::Indirect,
        }
    }
}

crate::choice! {
    /// The scalar a path class's contribution is measured by.
    pub enum ClassScalar {
        /// X + Y + Z of the contribution (Kitaoka et al.: luminance
        /// under-samples non-yellow light).
        XyzSum = "xyz_sum",
        /// Luminance (Y).
        Luminance = "luminance",
    }
}

impl ClassScalar {
    /// The scalar of a linear sRGB contribution.
    pub fn of(self, l: Rgb) -> f64 {
        match self {
            // Column sums of the linear-sRGB-to-XYZ (D65) matrix.
            ClassScalar::XyzSum => {
                0.644_463_3 * f64::from(l.r)
                    + 1.191_920_3 * f64::from(l.g)
                    + 1.202_943_2 * f64::from(l.b)
            }
            ClassScalar::Luminance => f64::from(l.luminance()),
        }
    }
}

/// The class values `(L0 … L5)` of a sample's splats; NaN in every entry
/// when a splat is not finite.
pub fn class_values(splats: &[Splat], scalar: ClassScalar) -> [f64; PATH_CLASSES] {
    let mut v = [0.0; PATH_CLASSES];
    for s in splats {
        if !s.l.is_finite() {
            return [f64::NAN; PATH_CLASSES];
        }
        v[usize::from(s.class)] += scalar.of(s.l);
    }
    v
}

/// Whether a camera-subpath vertex strictly between the camera (vertex 0)
/// and vertex `t − 1` sampled a Dirac delta.
fn camera_subpath_is_specular(buffers: &SubpathBuffers, t: usize) -> bool {
    buffers.camera[1..t.saturating_sub(1).max(1)]
        .iter()
        .any(|v| v.delta)
}

/// BDPT over primary sample space with every technique's splat tagged by
/// its [`PathClass`]: the sample is [`Bdpt`]'s (same numbers, same
/// contributions), only the tags are added.
#[derive(Clone, Copy, Debug)]
pub struct ClassifiedBdpt(pub Bdpt);

thread_local! {
    /// Per-thread subpath storage.
    static BUFFERS: RefCell<SubpathBuffers> = RefCell::new(SubpathBuffers::default());
}

impl PssPathSampler for ClassifiedBdpt {
    fn streams(&self) -> usize {
        Stream::COUNT
    }

    fn trace(&self, scene: &Scene, source: &mut PssSource<'_>, out: &mut Vec<Splat>) -> u32 {
        source.set_stream(Stream::Camera);
        let raster = raster_of(scene, source);
        BUFFERS.with_borrow_mut(|buffers| {
            // The camera subpath is only readable once `sample_all` is
            // done with the buffers: keep the techniques, then classify.
            let mut techniques: Vec<Connection> = Vec::new();
            self.0
                .sample_all(scene, raster, source, buffers, |c| techniques.push(*c));
            for c in &techniques {
                let specular = c.s == 0 && camera_subpath_is_specular(buffers, c.t);
                out.push(Splat {
                    p: c.raster,
                    l: c.l,
                    class: PathClass::of(c.s, c.t, specular) as u8,
                });
            }
            (buffers.camera.len() + buffers.light.len()).saturating_sub(1) as u32
        })
    }
}

impl ClassifiedBdpt {
    /// Whether the sample at `point` can carry `L0`: its camera subpath,
    /// traced alone exactly as [`PssPathSampler::trace`] traces it (same
    /// stream, same numbers; no light subpath, no connections), reaches an
    /// emitter after a Dirac-delta bounce. When this is false the sample's
    /// `L0` is exactly 0, so a search for `L0` paths need only trace the
    /// others in full (RELT's start-up, `docs/relt.md`).
    pub fn may_carry_specular_implicit(&self, scene: &Scene, point: &TorusPoint) -> bool {
        let mut source = PssSource::new(point, Stream::COUNT);
        source.set_stream(Stream::Camera);
        let raster = raster_of(scene, &mut source);
        BUFFERS.with_borrow_mut(|buffers| {
            generate_camera_subpath(
                scene,
                raster,
                &mut source,
                self.0.max_camera_vertices(),
                Some(self.0.rr_depth),
                &mut buffers.camera,
            );
            // Technique (0, t) reads vertex t − 1 (t ≥ 2), as `connect_in`.
            (2..=buffers.camera.len())
                .any(|t| buffers.camera[t - 1].is_light() && camera_subpath_is_specular(buffers, t))
        })
    }
}
