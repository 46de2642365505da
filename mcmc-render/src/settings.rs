//! Plain-data integrator settings, filled by parameter name from text.
//!
//! Every integrator keeps its settings in one struct of plain fields with
//! documented defaults (as Tungsten and Mitsuba do). The struct is declared
//! with [`settings!`](crate::settings!), which also generates the table of
//! parameters and a setter by name, so that the same names and the same
//! validation serve all three places a value can come from:
//!
//! - the scene file's `<integrator type="NAME">` element
//!   (`<float name="sigma" value="0.02"/>`),
//! - the command line (`--set sigma=0.02`, and the older named flags such
//!   as `--sigma 0.02`, which are spelled as the same assignment),
//! - the JSON sidecar that records what ran (`"settings": {"sigma": 0.02}`).
//!
//! Values travel as text: a JSON number is read back through its shortest
//! round-trip decimal form, so scene → settings → JSON → settings gives the
//! same struct, bit for bit.

use serde_json::{Map, Value};

/// What kind of value a parameter takes (for listings and generated tests).
#[derive(Clone, Debug, PartialEq)]
pub enum ParamKind {
    /// A finite floating-point number.
    Float,
    /// An integer (signed or not; the parameter's check gives the range).
    Integer,
    /// `true` or `false`.
    Boolean,
    /// One of a fixed list of names.
    Choice(&'static [&'static str]),
    /// `auto` (chosen at run time, see the parameter's description) or a value.
    Auto(Box<ParamKind>),
}

/// One parameter of a settings struct: its name, kind, current value and
/// description.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamDoc {
    /// The name used in scene files, `--set` and JSON.
    pub name: &'static str,
    /// What it takes.
    pub kind: ParamKind,
    /// Its value (the default, for a default-constructed struct).
    pub value: Value,
    /// What it means (the field's doc comment).
    pub doc: String,
}

/// A type a parameter can have.
pub trait ParamValue: Sized {
    /// The kind, for listings.
    fn kind() -> ParamKind;
    /// What the text must be, for error messages.
    fn expected() -> String;
    /// Parses the text form (`None`: not a value of this type).
    fn parse(text: &str) -> Option<Self>;
    /// The JSON form (whose text form [`ParamValue::parse`] reads back).
    fn to_json(&self) -> Value;
}

impl ParamValue for f64 {
    fn kind() -> ParamKind {
        ParamKind::Float
    }
    fn expected() -> String {
        "a finite number".into()
    }
    fn parse(text: &str) -> Option<Self> {
        text.trim().parse::<f64>().ok().filter(|v| v.is_finite())
    }
    fn to_json(&self) -> Value {
        Value::from(*self)
    }
}

macro_rules! integer_param {
    ($($t:ty => $what:literal),*) => {$(
        impl ParamValue for $t {
            fn kind() -> ParamKind {
                ParamKind::Integer
            }
            fn expected() -> String {
                format!(concat!($what, " (at most {})"), <$t>::MAX)
            }
            fn parse(text: &str) -> Option<Self> {
                text.trim().parse::<$t>().ok()
            }
            fn to_json(&self) -> Value {
                Value::from(*self)
            }
        }
    )*};
}
integer_param!(u32 => "a non-negative integer", u64 => "a non-negative integer",
    usize => "a non-negative integer", i64 => "an integer");

impl ParamValue for bool {
    fn kind() -> ParamKind {
        ParamKind::Boolean
    }
    fn expected() -> String {
        "true or false".into()
    }
    fn parse(text: &str) -> Option<Self> {
        match text.trim() {
            "true" => Some(true),
            "false" => Some(false),
            _ => None,
        }
    }
    fn to_json(&self) -> Value {
        Value::Bool(*self)
    }
}

/// `None` is written `auto` (JSON `null`).
impl<T: ParamValue> ParamValue for Option<T> {
    fn kind() -> ParamKind {
        ParamKind::Auto(Box::new(T::kind()))
    }
    fn expected() -> String {
        format!("`auto` or {}", T::expected())
    }
    fn parse(text: &str) -> Option<Self> {
        if text.trim() == "auto" {
            Some(None)
        } else {
            T::parse(text).map(Some)
        }
    }
    fn to_json(&self) -> Value {
        self.as_ref().map_or(Value::Null, T::to_json)
    }
}

/// The text form of a JSON value, as [`ParamValue::parse`] reads it.
pub fn json_text(value: &Value) -> String {
    match value {
        Value::String(s) => s.clone(),
        Value::Null => "auto".into(),
        other => other.to_string(),
    }
}

/// A settings struct: parameters by name (declare it with
/// [`settings!`](crate::settings!)).
pub trait Settings {
    /// Every parameter with its current value, flattened groups included.
    fn params(&self) -> Vec<ParamDoc>;
    /// Sets parameter `name` from its text form. `Ok(false)`: no parameter
    /// of that name; `Err`: the value is not valid (the message names the
    /// parameter, the value and what it must be).
    fn set(&mut self, name: &str, text: &str) -> Result<bool, String>;

    /// The parameters as a JSON object (name → value).
    fn to_json(&self) -> Map<String, Value> {
        self.params()
            .into_iter()
            .map(|p| (p.name.to_string(), p.value))
            .collect()
    }
}

/// The field's doc comment lines as one paragraph.
pub fn doc_text(lines: &[&str]) -> String {
    lines.iter().map(|l| l.trim()).collect::<Vec<_>>().join(" ")
}

/// The message for a value that does not parse.
pub fn bad_value(name: &str, text: &str, expected: &str) -> String {
    format!("`{name}` must be {expected}, got `{text}`")
}

/// Range checks for [`settings!`](crate::settings!) fields: each returns
/// what the value must be when it is not.
pub mod check {
    /// `> 0`.
    pub fn positive(v: &f64) -> Result<(), String> {
        if *v > 0.0 {
            Ok(())
        } else {
            Err("must be > 0".into())
        }
    }
    /// `≥ 1`.
    pub fn at_least_one(v: &f64) -> Result<(), String> {
        if *v >= 1.0 {
            Ok(())
        } else {
            Err("must be ≥ 1".into())
        }
    }
    /// `≥ 0`.
    pub fn non_negative(v: &f64) -> Result<(), String> {
        if *v >= 0.0 {
            Ok(())
        } else {
            Err("must be ≥ 0".into())
        }
    }
    /// Within `[0, 1]`.
    pub fn probability(v: &f64) -> Result<(), String> {
        if (0.0..=1.0).contains(v) {
            Ok(())
        } else {
            Err("must lie in [0, 1]".into())
        }
    }
    /// `≥ 1` for counts.
    pub fn count(v: &usize) -> Result<(), String> {
        if *v >= 1 {
            Ok(())
        } else {
            Err("must be at least 1".into())
        }
    }
    /// `≥ 1` for a 32-bit count.
    pub fn positive_count(v: &u32) -> Result<(), String> {
        if *v >= 1 {
            Ok(())
        } else {
            Err("must be at least 1".into())
        }
    }
    /// `≥ 1` for a count that may be `auto`.
    pub fn auto_or_at_least_one(v: &Option<u64>) -> Result<(), String> {
        match v {
            Some(0) => Err("must be `auto` or at least 1".into()),
            _ => Ok(()),
        }
    }
    /// A path depth in Mitsuba's convention: `-1` (unbounded) or `0 ..= 2^32 − 2`.
    pub fn depth(v: &i64) -> Result<(), String> {
        if (-1..i64::from(u32::MAX)).contains(v) {
            Ok(())
        } else {
            Err(format!(
                "must be -1 (unbounded) or between 0 and {}",
                u32::MAX - 1
            ))
        }
    }
}

/// A path depth in Mitsuba's convention (`-1` unbounded, checked by
/// [`check::depth`]) as the integrators take it (`u32::MAX` unbounded).
pub fn depth_limit(max_depth: i64) -> u32 {
    u32::try_from(max_depth).unwrap_or(u32::MAX)
}

/// Declares a fieldless enum whose values are written as names.
///
/// ```
/// mcmc_render::choice! {
///     /// How to split.
///     pub enum Split { Even = "even", Odd = "odd" }
/// }
/// use mcmc_render::settings::ParamValue;
/// assert_eq!(<Split as ParamValue>::parse("odd"), Some(Split::Odd));
/// assert_eq!(Split::Even.name(), "even");
/// ```
#[macro_export]
macro_rules! choice {
    (
        $(#[$meta:meta])*
        pub enum $name:ident { $( $(#[doc = $doc:literal])* $variant:ident = $text:literal ),+ $(,)? }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum $name { $( $(#[doc = $doc])* $variant ),+ }

        impl $name {
            /// Every value's name, in declaration order.
            pub const NAMES: &'static [&'static str] = &[$($text),+];
            /// This value's name.
            pub fn name(self) -> &'static str {
                match self { $( $name::$variant => $text ),+ }
            }
        }

        impl $crate::settings::ParamValue for $name {
            fn kind() -> $crate::settings::ParamKind {
                $crate::settings::ParamKind::Choice(Self::NAMES)
            }
            fn expected() -> String {
                format!("one of {}", Self::NAMES.join(", "))
            }
            fn parse(text: &str) -> Option<Self> {
                match text.trim() { $( $text => Some($name::$variant), )+ _ => None }
            }
            fn to_json(&self) -> serde_json::Value {
                serde_json::Value::from(self.name())
            }
        }
    };
}

/// Declares a settings struct: plain public fields with defaults and
/// optional range checks, plus flattened groups of parameters (settings
/// structs themselves, whose parameters appear under their own names).
///
/// ```
/// mcmc_render::settings! {
///     /// Example settings.
///     pub struct Example {
///         /// Standard deviation of the step.
///         pub sigma: f64 = 0.01, check mcmc_render::settings::check::positive;
///         /// Number of chains.
///         pub chains: usize = 1000;
///     }
/// }
/// use mcmc_render::settings::Settings;
/// let mut s = Example::default();
/// assert_eq!(s.set("sigma", "0.02"), Ok(true));
/// assert!(s.set("sigma", "-1").is_err());
/// assert_eq!(s.set("nonsense", "1"), Ok(false));
/// assert_eq!(s.sigma, 0.02);
/// ```
#[macro_export]
macro_rules! settings {
    (
        $(#[$meta:meta])*
        pub struct $name:ident {
            $(
                $(#[doc = $doc:literal])+
                pub $field:ident : $ty:ty = $default:expr $(, check $check:path)? ;
            )*
            $(
                flatten {
                    $( $(#[doc = $fdoc:literal])+ pub $ffield:ident : $fty:ty = $fdefault:expr ; )*
                }
            )?
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Debug, PartialEq)]
        pub struct $name {
            $( $(#[doc = $doc])+ pub $field: $ty, )*
            $($( $(#[doc = $fdoc])+ pub $ffield: $fty, )*)?
        }

        impl Default for $name {
            fn default() -> Self {
                $name {
                    $( $field: $default, )*
                    $($( $ffield: $fdefault, )*)?
                }
            }
        }

        impl $crate::settings::Settings for $name {
            fn params(&self) -> Vec<$crate::settings::ParamDoc> {
                #[allow(unused_mut)]
                let mut all = vec![$(
                    $crate::settings::ParamDoc {
                        name: stringify!($field),
                        kind: <$ty as $crate::settings::ParamValue>::kind(),
                        value: $crate::settings::ParamValue::to_json(&self.$field),
                        doc: $crate::settings::doc_text(&[$($doc),+]),
                    }
                ),*];
                $($( all.extend($crate::settings::Settings::params(&self.$ffield)); )*)?
                all
            }

            fn set(&mut self, name: &str, text: &str) -> Result<bool, String> {
                match name {
                    $(
                        stringify!($field) => {
                            let value = <$ty as $crate::settings::ParamValue>::parse(text)
                                .ok_or_else(|| $crate::settings::bad_value(
                                    name,
                                    text,
                                    &<$ty as $crate::settings::ParamValue>::expected(),
                                ))?;
                            $( $check(&value).map_err(|why| format!("`{name}` {why}, got `{text}`"))?; )?
                            self.$field = value;
                            Ok(true)
                        }
                    )*
                    _ => {
                        $($(
                            if $crate::settings::Settings::set(&mut self.$ffield, name, text)? {
                                return Ok(true);
                            }
                        )*)?
                        Ok(false)
                    }
                }
            }
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    crate::choice! {
        /// Test choice.
        pub enum Colour { Red = "red", Blue = "blue" }
    }

    crate::settings! {
        /// Inner group.
        pub struct Inner {
            /// Inner probability.
            pub p: f64 = 0.3, check check::probability;
        }
    }

    crate::settings! {
        /// Outer settings.
        pub struct Outer {
            /// Depth.
            pub max_depth: i64 = -1, check check::depth;
            /// A count that may be automatic.
            pub count: Option<u64> = None, check check::auto_or_at_least_one;
            /// A colour.
            pub colour: Colour = Colour::Red;
            /// A switch.
            pub on: bool = false;
            flatten {
                /// The group.
                pub inner: Inner = Inner::default();
            }
        }
    }

    #[test]
    fn set_by_name_checks_and_reaches_flattened_groups() {
        let mut s = Outer::default();
        assert_eq!(s.set("p", "0.5"), Ok(true));
        assert_eq!(s.inner.p, 0.5);
        assert!(s.set("p", "1.5").unwrap_err().contains("[0, 1]"));
        assert_eq!(s.set("colour", "blue"), Ok(true));
        let e = s.set("colour", "green").unwrap_err();
        assert!(e.contains("red, blue") && e.contains("green"), "{e}");
        assert!(s.set("max_depth", "4294967296").is_err());
        assert!(s.set("max_depth", "-2").is_err());
        assert_eq!(s.set("max_depth", "7"), Ok(true));
        assert!(s.set("count", "0").is_err());
        assert_eq!(s.set("count", "auto"), Ok(true));
        assert_eq!(s.set("on", "true"), Ok(true));
        assert!(s.set("on", "yes").is_err());
        assert_eq!(s.set("unknown", "1"), Ok(false));
        assert!(s.set("p", "nan").is_err());
    }

    #[test]
    fn json_round_trip_restores_the_struct() {
        let mut s = Outer::default();
        for (k, v) in [
            ("p", "0.1"),
            ("count", "12"),
            ("colour", "blue"),
            ("max_depth", "3"),
        ] {
            s.set(k, v).unwrap();
        }
        let json = s.to_json();
        let mut back = Outer::default();
        for (k, v) in &json {
            assert_eq!(back.set(k, &json_text(v)), Ok(true), "{k}");
        }
        assert_eq!(back, s);
        let names: Vec<&str> = Outer::default().params().iter().map(|p| p.name).collect();
        assert_eq!(names, ["max_depth", "count", "colour", "on", "p"]);
    }
}
