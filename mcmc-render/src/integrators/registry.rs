//! The integrator registry: every integrator by name, with its settings.
//!
//! An integrator registers by implementing [`IntegratorSettings`] for its
//! settings struct (declared with [`settings!`](crate::settings!)) and
//! adding one line to [`REGISTRY`]. Its settings are then filled, with the
//! same names and checks, from the scene's `<integrator type="NAME">`
//! element, from `--set name=value` (and the older named flags), and from
//! the JSON sidecar of an earlier run ([`configure`], [`from_json`]).

use super::{RenderError, Rendered, RunSettings};
use crate::observer::Observer;
use crate::scene::{IntegratorElement, Scene};
use crate::settings::{ParamDoc, Settings, json_text};
use serde_json::{Map, Value};
use std::any::Any;
use std::sync::atomic::AtomicBool;

/// An integrator's settings struct, which knows how to render with itself.
pub trait IntegratorSettings:
    Settings + Clone + Default + PartialEq + std::fmt::Debug + Send + Sync + 'static
{
    /// The name in scene files and on the command line.
    const NAME: &'static str;
    /// Other names accepted for it (Mitsuba's plugin names).
    const ALIASES: &'static [&'static str] = &[];
    /// One line for `mcmc-render integrators`.
    const DESCRIPTION: &'static str;

    /// Checks what single parameters cannot (e.g. `s1 < s2`).
    fn validate(&self) -> Result<(), String> {
        Ok(())
    }

    /// Renders `scene`; `stop` ends the run early with what it has.
    fn render(
        &self,
        scene: &Scene,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<Rendered, RenderError>;

    /// The samples the run will report through [`Observer::progress`] (for
    /// a progress bar), or `None` when only the time budget ends it. The
    /// default is the per-pixel driver's: `spp` (or the scene's
    /// `sample_count`) per pixel.
    fn planned_samples(&self, scene: &Scene, run: &RunSettings) -> Option<u64> {
        let pixels = u64::from(scene.film.width) * u64::from(scene.film.height);
        run.samples_per_pixel(scene.sample_count)
            .map(|n| u64::from(n) * pixels)
    }
}

/// A registered integrator with its settings filled in, ready to render.
pub trait Configured: Send + Sync {
    /// The registered name.
    fn name(&self) -> &'static str;
    /// Every parameter with its current value.
    fn params(&self) -> Vec<ParamDoc>;
    /// Sets parameter `name` (see [`Settings::set`]).
    fn set(&mut self, name: &str, text: &str) -> Result<bool, String>;
    /// See [`IntegratorSettings::validate`].
    fn validate(&self) -> Result<(), String>;
    /// The settings as JSON (name → value), as the sidecar records them.
    fn settings_json(&self) -> Map<String, Value>;
    /// Renders `scene` (see [`IntegratorSettings::render`]).
    fn render(
        &self,
        scene: &Scene,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<Rendered, RenderError>;
    /// See [`IntegratorSettings::planned_samples`].
    fn planned_samples(&self, scene: &Scene, run: &RunSettings) -> Option<u64>;
    /// The settings struct, for comparisons and downcasts.
    fn as_any(&self) -> &dyn Any;
    /// Whether `other` is the same integrator with equal settings.
    fn same_as(&self, other: &dyn Configured) -> bool;
}

impl<T: IntegratorSettings> Configured for T {
    fn name(&self) -> &'static str {
        T::NAME
    }
    fn params(&self) -> Vec<ParamDoc> {
        Settings::params(self)
    }
    fn set(&mut self, name: &str, text: &str) -> Result<bool, String> {
        Settings::set(self, name, text)
    }
    fn validate(&self) -> Result<(), String> {
        IntegratorSettings::validate(self)
    }
    fn settings_json(&self) -> Map<String, Value> {
        Settings::to_json(self)
    }
    fn render(
        &self,
        scene: &Scene,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<Rendered, RenderError> {
        IntegratorSettings::render(self, scene, run, stop, observer)
    }
    fn planned_samples(&self, scene: &Scene, run: &RunSettings) -> Option<u64> {
        IntegratorSettings::planned_samples(self, scene, run)
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn same_as(&self, other: &dyn Configured) -> bool {
        other.as_any().downcast_ref::<T>() == Some(self)
    }
}

/// One entry of the registry.
pub struct Registration {
    /// The name in scene files and on the command line.
    pub name: &'static str,
    /// Other accepted names.
    pub aliases: &'static [&'static str],
    /// One line describing it.
    pub description: &'static str,
    /// Its settings at their defaults.
    pub new: fn() -> Box<dyn Configured>,
}

fn boxed_default<T: IntegratorSettings>() -> Box<dyn Configured> {
    Box::new(T::default())
}

/// The registry entry of the integrator whose settings are `T`.
pub const fn register<T: IntegratorSettings>() -> Registration {
    Registration {
        name: T::NAME,
        aliases: T::ALIASES,
        description: T::DESCRIPTION,
        new: boxed_default::<T>,
    }
}

/// Every integrator, in the order `mcmc-render integrators` lists them.
pub static REGISTRY: &[Registration] = &[
    register::<super::pt::PtSettings>(),
    register::<super::lt::LtSettings>(),
    register::<super::bdpt::BdptSettings>(),
    register::<super::guided::GuidedSettings>(),
    register::<super::pssmlt::Pssmlt>(),
    register::<super::mmlt::Mmlt>(),
    register::<super::mlt::Mlt>(),
    register::<super::relt::Relt>(),
    register::<super::vcm::VcmSettings>(),
    register::<super::tempered_pssmlt::TemperedPssmlt>(),
    register::<super::tempered_mmlt::TemperedMmlt>(),
    register::<super::mept::Mept>(),
    register::<super::erpt::Erpt>(),
    register::<super::fused::Fused>(),
    register::<super::mcmc_vcm::McmcVcmSettings>(),
    register::<super::mcmc_pg::McmcPg>(),
    register::<super::smcmc::Smcmc>(),
];

/// The registered names, comma-separated.
pub fn names() -> String {
    REGISTRY
        .iter()
        .map(|r| r.name)
        .collect::<Vec<_>>()
        .join(", ")
}

/// The entry named `name` (or one of its aliases).
pub fn find(name: &str) -> Result<&'static Registration, String> {
    REGISTRY
        .iter()
        .find(|r| r.name == name || r.aliases.contains(&name))
        .ok_or_else(|| format!("unknown integrator `{name}` (known: {})", names()))
}

/// Parameters that carry over from the scene's `<integrator>` element when
/// another integrator is chosen on the command line: the path depth
/// settings every integrator shares (Mitsuba scenes set them on `path`).
pub const SHARED_PARAMS: &[&str] = &["max_depth", "rr_depth"];

/// Sets `name = text` on `integrator`, which must know the parameter.
pub fn assign(integrator: &mut dyn Configured, name: &str, text: &str) -> Result<(), String> {
    match integrator.set(name, text) {
        Ok(true) => Ok(()),
        Ok(false) => Err(format!(
            "{} has no parameter `{name}` (parameters: {})",
            integrator.name(),
            integrator
                .params()
                .iter()
                .map(|p| p.name)
                .collect::<Vec<_>>()
                .join(", ")
        )),
        Err(e) => Err(format!("{}: {e}", integrator.name())),
    }
}

/// The integrator of a scene element alone, every parameter applied.
pub fn from_element(element: &IntegratorElement) -> Result<Box<dyn Configured>, String> {
    let mut integ = (find(&element.kind)?.new)();
    for (name, text) in &element.params {
        assign(integ.as_mut(), name, text)?;
    }
    integ.validate()?;
    Ok(integ)
}

/// The integrator to run: `chosen` (the command line's `--integrator`) or
/// else the scene's `<integrator>` element, or `pt` when neither names one.
/// Its settings start at their defaults; then come the scene element's
/// parameters (all of them when it names the same integrator, else only
/// [`SHARED_PARAMS`]), then `assignments` in order (`--set`, named flags).
pub fn configure(
    element: Option<&IntegratorElement>,
    chosen: Option<&str>,
    assignments: &[(String, String)],
) -> Result<Box<dyn Configured>, String> {
    let entry = match (chosen, element) {
        (Some(name), _) => find(name)?,
        (None, Some(e)) => find(&e.kind)?,
        (None, None) => find("pt")?,
    };
    let mut integ = (entry.new)();
    if let Some(e) = element {
        let same = find(&e.kind).is_ok_and(|r| r.name == entry.name);
        for (name, text) in &e.params {
            if same || SHARED_PARAMS.contains(&name.as_str()) {
                assign(integ.as_mut(), name, text).map_err(|m| format!("{}: {m}", e.loc))?;
            }
        }
    }
    for (name, text) in assignments {
        assign(integ.as_mut(), name, text)?;
    }
    integ.validate()?;
    Ok(integ)
}

/// The integrator a sidecar's `"integrator"` and `"settings"` record.
pub fn from_json(name: &str, settings: &Map<String, Value>) -> Result<Box<dyn Configured>, String> {
    let mut integ = (find(name)?.new)();
    for (k, v) in settings {
        assign(integ.as_mut(), k, &json_text(v))?;
    }
    integ.validate()?;
    Ok(integ)
}

/// Splits `NAME=VALUE` (a `--set` argument).
pub fn parse_assignment(text: &str) -> Result<(String, String), String> {
    match text.split_once('=') {
        Some((k, v)) if !k.trim().is_empty() => Ok((k.trim().to_string(), v.trim().to_string())),
        _ => Err(format!("--set expects NAME=VALUE, got `{text}`")),
    }
}
