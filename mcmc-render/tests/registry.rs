//! The integrator registry: settings filled from a scene's `<integrator>`
//! element, written to JSON and read back give the same struct for every
//! registered integrator; every bad parameter is refused in one line; the
//! scene's integrator is used unless the command line names another.

mod cli_support;

use cli_support::{assert_clean_failure, floor_scene, json, run, run_ok, scratch, write};
use mcmc_render::integrators::registry::{self, Configured, REGISTRY};
use mcmc_render::scene::Scene;
use mcmc_render::settings::ParamKind;
use proptest::prelude::*;
use std::path::Path;

/// A tiny scene whose `<integrator>` element is `element`.
fn scene_with(element: &str) -> String {
    floor_scene(4, 3).replace(
        r#"<integrator type="path"><integer name="max_depth" value="4"/></integrator>"#,
        element,
    )
}

fn load(text: &str) -> Result<Scene, String> {
    Scene::load_str(text, Path::new("scene.xml"), Path::new(".")).map_err(|e| e.to_string())
}

/// An XML parameter element for `value` of a parameter of `kind`.
fn xml_param(name: &str, kind: &ParamKind, value: &str) -> String {
    let tag = match kind {
        ParamKind::Float => "float",
        ParamKind::Integer => "integer",
        ParamKind::Boolean => "boolean",
        ParamKind::Choice(_) => "string",
        ParamKind::Auto(inner) if value != "auto" => return xml_param(name, inner, value),
        ParamKind::Auto(_) => "string",
    };
    format!(r#"<{tag} name="{name}" value="{value}"/>"#)
}

/// A text value of `kind` from the random numbers `(u, i, b)`.
fn value_of(kind: &ParamKind, u: f32, i: i64, b: bool) -> String {
    match kind {
        // As the scene file's <float> is read (f32), so the element's text.
        ParamKind::Float => u.to_string(),
        ParamKind::Integer => i.to_string(),
        ParamKind::Boolean => b.to_string(),
        ParamKind::Choice(names) => names[i.unsigned_abs() as usize % names.len()].to_string(),
        ParamKind::Auto(_) if b && i % 3 == 0 => "auto".into(),
        ParamKind::Auto(inner) => value_of(inner, u, i, b),
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Scene element → settings → JSON → settings is the identity, for
    /// every registered integrator, over generated values. Values a
    /// parameter's own check refuses are left out of the element (the test
    /// below covers refusals); an element whose combination is invalid
    /// (e.g. `s1 > s2`) must fail the load instead.
    #[test]
    fn element_to_json_and_back_gives_the_same_settings(
        draws in proptest::collection::vec((-3.0f32..3.0, -2i64..300_000, any::<bool>()), 32),
        which in 0usize..64,
    ) {
        let entry = &REGISTRY[which % REGISTRY.len()];
        let mut expected = (entry.new)();
        let mut params = String::new();
        for (p, &(u, i, b)) in expected.params().iter().zip(draws.iter().cycle()) {
            let text = value_of(&p.kind, u, i, b);
            // A refused value leaves the settings as they were.
            if expected.set(p.name, &text).is_ok() {
                params.push_str(&xml_param(p.name, &p.kind, &text));
            }
        }
        let element = format!(r#"<integrator type="{}">{params}</integrator>"#, entry.name);
        let loaded = load(&scene_with(&element));
        match expected.validate() {
            Err(why) => {
                let e = loaded.err().expect("an invalid combination must fail the load");
                prop_assert!(e.contains("scene.xml:2") && e.contains(&why), "{e} / {why}");
            }
            Ok(()) => {
                let scene = loaded.map_err(|e| TestCaseError::fail(format!("{e}\n{element}")))?;
                let from_scene = registry::configure(scene.integrator_element.as_ref(), None, &[])
                    .map_err(TestCaseError::fail)?;
                prop_assert!(from_scene.same_as(expected.as_ref()), "{element}");
                let json = serde_json::Value::Object(from_scene.settings_json()).to_string();
                let map: serde_json::Map<String, serde_json::Value> =
                    serde_json::from_str(&json).expect("valid JSON");
                let back = registry::from_json(entry.name, &map).map_err(TestCaseError::fail)?;
                prop_assert!(back.same_as(from_scene.as_ref()), "{json}");
            }
        }
    }
}

/// `--set NAME=VALUE` fills the same settings as the scene element.
#[test]
fn flags_and_scene_elements_fill_the_same_settings() {
    for entry in REGISTRY {
        let defaults = (entry.new)();
        let mut params = String::new();
        let mut sets = Vec::new();
        for p in defaults.params() {
            // Each parameter's default, written out, must be accepted and
            // leave the settings unchanged.
            let text = mcmc_render::settings::json_text(&p.value);
            params.push_str(&xml_param(p.name, &p.kind, &text));
            sets.push((p.name.to_string(), text));
        }
        let element = format!(r#"<integrator type="{}">{params}</integrator>"#, entry.name);
        match defaults.validate() {
            Ok(()) => {
                let scene = load(&scene_with(&element)).expect("defaults load");
                let a = registry::configure(scene.integrator_element.as_ref(), None, &[]).unwrap();
                let b = registry::configure(None, Some(entry.name), &sets).unwrap();
                assert!(a.same_as(defaults.as_ref()), "{}", entry.name);
                assert!(b.same_as(defaults.as_ref()), "{}", entry.name);
            }
            // mmlt has no default depth: the element must name one.
            Err(why) => assert!(
                load(&scene_with(&element))
                    .err()
                    .expect("refused")
                    .contains(&why)
            ),
        }
    }
}

/// A bad value for each parameter of each integrator, an unknown
/// parameter and an unknown integrator: one line naming the problem and
/// what is allowed.
#[test]
fn every_bad_parameter_is_refused_in_one_line() {
    for entry in REGISTRY {
        for p in (entry.new)().params() {
            let bad = match p.kind {
                ParamKind::Float => "x1",
                ParamKind::Integer => "1.5",
                ParamKind::Boolean => "yes",
                ParamKind::Choice(_) | ParamKind::Auto(_) => "nonsense",
            };
            let e = registry::configure(None, Some(entry.name), &[(p.name.into(), bad.into())])
                .err()
                .unwrap_or_else(|| panic!("{}: {} = {bad} accepted", entry.name, p.name));
            assert!(!e.contains('\n'), "{e}");
            assert!(e.contains(p.name) && e.contains(bad), "{e}");
            if let ParamKind::Choice(names) = p.kind {
                assert!(names.iter().all(|n| e.contains(n)), "{e}");
            }
        }
        let e = registry::configure(None, Some(entry.name), &[("bogus".into(), "1".into())])
            .err()
            .expect("unknown parameter refused");
        assert!(e.contains("bogus") && e.contains(entry.name), "{e}");
        let e = load(&scene_with(&format!(
            r#"<integrator type="{}"><float name="bogus" value="1"/></integrator>"#,
            entry.name
        )))
        .err()
        .expect("unknown parameter in a scene refused");
        assert!(e.contains("scene.xml:2") && e.contains("bogus"), "{e}");
    }
    // Range checks name the range.
    for (name, param, value, needle) in [
        ("pssmlt", "sigma", "-0.1", "> 0"),
        ("pssmlt", "large_step_probability", "1.5", "[0, 1]"),
        ("mmlt", "chains", "0", "at least 1"),
        ("pt", "max_depth", "4294967296", "-1 (unbounded)"),
        ("pt", "rr_depth", "0", "at least 1"),
        ("pssmlt", "mutations_per_pixel", "0", "at least 1"),
        // Were clamped to 2^32 − 1 silently (issue 23, class 1).
        (
            "mlt",
            "direct_samples",
            "4294967296",
            "between 1 and 4294967295",
        ),
        (
            "mlt",
            "specular_samples",
            "1000000000000000",
            "between 1 and",
        ),
    ] {
        let e = registry::configure(None, Some(name), &[(param.into(), value.into())])
            .err()
            .unwrap_or_else(|| panic!("{name}: {param} = {value} accepted"));
        assert!(e.contains(needle) && e.contains(value), "{e}");
    }
    // Combinations: s1 above s2; mmlt without a finite depth.
    let e = registry::configure(
        None,
        Some("pssmlt"),
        &[("s1".into(), "0.5".into()), ("s2".into(), "0.1".into())],
    )
    .err()
    .expect("s1 > s2 refused");
    assert!(e.contains("s1") || e.contains("s2"), "{e}");
    let e = registry::configure(None, Some("mmlt"), &[])
        .err()
        .expect("no depth");
    assert!(e.contains("max_depth"), "{e}");
    let e = registry::configure(None, Some("vcm2"), &[])
        .err()
        .expect("unknown");
    assert!(e.contains("vcm2") && e.contains(&registry::names()), "{e}");
    let e = load(&scene_with(r#"<integrator type="volpath"/>"#))
        .err()
        .expect("refused");
    assert!(
        e.contains("scene.xml:2") && e.contains("volpath") && e.contains("pssmlt"),
        "{e}"
    );
}

/// The scene's integrator runs without a flag; `--integrator` overrides
/// it and keeps the scene's path depth; the sidecar records the settings,
/// and they read back as what ran.
#[test]
fn the_scene_chooses_the_integrator_unless_the_flag_does() {
    let dir = scratch("registry-choice");
    write(
        &dir,
        "s.xml",
        &scene_with(
            r#"<integrator type="pssmlt">
                <integer name="max_depth" value="3"/>
                <integer name="mutations_per_pixel" value="2"/>
                <integer name="bootstrap" value="2000"/>
                <integer name="chains" value="16"/>
                <string name="small_step" value="gaussian"/>
                <float name="sigma" value="0.02"/>
            </integrator>"#,
        ),
    );
    run_ok(&["render", "s.xml", "--out", "a.exr", "--quiet"], &dir);
    let a = json(&dir.join("a.json"));
    assert_eq!(a["integrator"], "pssmlt");
    assert!(a["mutations"].as_u64().unwrap() > 0);
    assert_eq!(a["settings"]["sigma"], 0.02);
    assert_eq!(a["settings"]["small_step"], "gaussian");
    let back = registry::from_json("pssmlt", a["settings"].as_object().unwrap()).unwrap();
    let scene = Scene::load(&dir.join("s.xml"), &Default::default()).unwrap();
    let ran = registry::configure(scene.integrator_element.as_ref(), None, &[]).unwrap();
    assert!(back.same_as(ran.as_ref()));

    run_ok(
        &[
            "render",
            "s.xml",
            "--integrator",
            "pt",
            "--spp",
            "2",
            "--out",
            "b.exr",
            "--quiet",
        ],
        &dir,
    );
    let b = json(&dir.join("b.json"));
    assert_eq!(b["integrator"], "pt");
    assert_eq!(b["settings"]["max_depth"], 3);
    assert_eq!(b["spp"], 2);

    // `--set` overrides the scene's value; a parameter the chosen
    // integrator lacks is refused in one line.
    run_ok(
        &[
            "render",
            "s.xml",
            "--set",
            "sigma=0.05",
            "--out",
            "c.exr",
            "--quiet",
        ],
        &dir,
    );
    assert_eq!(json(&dir.join("c.json"))["settings"]["sigma"], 0.05);
    let out = run(
        &[
            "render",
            "s.xml",
            "--integrator",
            "pt",
            "--set",
            "sigma=0.05",
            "--out",
            "d.exr",
        ],
        &dir,
    );
    assert_clean_failure(&out, &["pt has no parameter `sigma`"]);
}

#[test]
fn integrators_lists_every_parameter_with_its_default() {
    let dir = scratch("registry-list");
    let text = run_ok(&["integrators"], &dir);
    for entry in REGISTRY {
        assert!(text.contains(entry.description), "{text}");
        for p in (entry.new)().params() {
            assert!(text.contains(p.name), "{} missing", p.name);
        }
    }
    assert!(text.contains("normalization") && text.contains("\"running\""));
}

/// A configured integrator is a plain value: its JSON names every
/// parameter exactly once.
#[test]
fn settings_json_names_each_parameter_once() {
    for entry in REGISTRY {
        let i: Box<dyn Configured> = (entry.new)();
        let names: Vec<&str> = i.params().iter().map(|p| p.name).collect();
        let mut unique = names.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(names.len(), unique.len(), "{}: {names:?}", entry.name);
        assert_eq!(i.settings_json().len(), names.len());
    }
}
