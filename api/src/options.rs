//! Stage options declared once: [`stage_options!`](crate::stage_options) turns one
//! declaration per option (name, Rust type, doc comment, default as a TOML literal)
//! into both the options struct a stage deserialises its table into and the
//! [`OptionSpec`] list its [`StageInfo`](crate::stage::StageInfo) documents, so the
//! two cannot drift: the documented default is parsed and used as the value.
//!
//! ```
//! use lamina_api::stage_options;
//!
//! stage_options! {
//!     #[derive(Debug)]
//!     struct Options {
//!         /// layer thickness (mm)
//!         thickness: f64 = "0.2",
//!         /// thickness of the first layer (mm); unset: `thickness`
//!         first_layer: Option<f64>,
//!         /// the file to read
//!         file: String,
//!     }
//! }
//!
//! assert_eq!(Options::SPECS[0].default, Some("0.2"));
//! assert_eq!(Options::SPECS[0].ty, "float");
//! assert!(Options::SPECS[2].required && !Options::SPECS[1].required);
//! let o: Options = toml::from_str("file = \"a.stl\"").unwrap();
//! assert_eq!((o.thickness, o.first_layer), (0.2, None));
//! ```
//!
//! A field is one of:
//! - `name: T = "literal"`: optional, the TOML literal is its default;
//! - `name: Option<T>`: optional without a value (its doc says what absence means);
//! - `name: T`: required;
//! - `name: T = use PATH`: an option several stages share, whose default and doc are
//!   the [`SharedOption`] at `PATH`.
//!
//! A field may carry a physical range, `#[range(min, max)]` after its doc comment
//! (both ends included; a shared option carries its own): every number of the value,
//! given or default, must lie in it, and one outside is refused with the key, the value
//! and the range, at the value's place in the file.
//!
//! ```
//! lamina_api::stage_options! {
//!     #[derive(Debug)]
//!     struct Options {
//!         /// layer thickness (mm)
//!         #[range(0.001, 100.0)]
//!         thickness: f64 = "0.2",
//!     }
//! }
//! assert_eq!(Options::SPECS[0].range, Some((0.001, 100.0)));
//! let e = toml::from_str::<Options>("thickness = 1e-4").unwrap_err();
//! assert!(e.message().contains("`thickness` = 0.0001 is outside its range 0.001 to 100"));
//! ```
//!
//! The TOML type shown in the documentation comes from [`OptionType`], implemented
//! here for the usual Rust types; a plugin's own types implement it with
//! [`option_type!`](crate::option_type).

use std::collections::{BTreeMap, HashMap};
use std::marker::PhantomData;
use std::path::PathBuf;

use serde::de::{self, DeserializeOwned, Visitor};

#[doc(hidden)]
pub use crate::stage::OptionSpec;

/// The TOML type of an option's Rust type, as the documentation names it.
pub trait OptionType {
    /// E.g. `float`, `integer`, `string`, `bool`, `array of float`.
    const TOML: &'static str;
    /// True for `Option<T>`: absent means no value rather than an error.
    const OPTIONAL: bool = false;

    /// The first number of the value outside `min..=max`, if any. Types without
    /// numbers have none.
    fn out_of_range(&self, _min: f64, _max: f64) -> Option<f64> {
        None
    }
}

/// A type whose `Vec` is an option: names the TOML type of that array.
pub trait ArrayItem {
    /// E.g. `array of float`.
    const ARRAY: &'static str;
}

impl<T: OptionType> OptionType for Option<T> {
    const TOML: &'static str = T::TOML;
    const OPTIONAL: bool = true;

    fn out_of_range(&self, min: f64, max: f64) -> Option<f64> {
        self.as_ref().and_then(|v| v.out_of_range(min, max))
    }
}

impl<T: ArrayItem + OptionType> OptionType for Vec<T> {
    const TOML: &'static str = T::ARRAY;

    fn out_of_range(&self, min: f64, max: f64) -> Option<f64> {
        self.iter().find_map(|v| v.out_of_range(min, max))
    }
}

impl<K, V> OptionType for BTreeMap<K, V> {
    const TOML: &'static str = "table";
}

impl<K, V, S> OptionType for HashMap<K, V, S> {
    const TOML: &'static str = "table";
}

impl<const N: usize> OptionType for [f64; N] {
    const TOML: &'static str = "array of float";

    fn out_of_range(&self, min: f64, max: f64) -> Option<f64> {
        self.iter().find_map(|v| v.out_of_range(min, max))
    }
}

impl<const N: usize> ArrayItem for [f64; N] {
    const ARRAY: &'static str = "array of array of float";
}

impl ArrayItem for Vec<f64> {
    const ARRAY: &'static str = "array of array of float";
}

/// Implements [`OptionType`] (and, with `array "..."`, [`ArrayItem`]) for a type:
/// `option_type!(CutAt = "string or float");`,
/// `option_type!(SubRegion = "table", array "array of table");`.
#[macro_export]
macro_rules! option_type {
    ($($t:ty = $toml:literal $(, array $array:literal)?);+ $(;)?) => {
        $(
            impl $crate::options::OptionType for $t {
                const TOML: &'static str = $toml;
            }
            $(
                impl $crate::options::ArrayItem for $t {
                    const ARRAY: &'static str = $array;
                }
            )?
        )+
    };
}

/// Numbers: their value is checked against a declared range.
macro_rules! numeric_option {
    ($($t:ty = $toml:literal, array $array:literal);+ $(;)?) => {
        $(
            impl OptionType for $t {
                const TOML: &'static str = $toml;

                #[allow(clippy::cast_lossless, clippy::cast_precision_loss)]
                fn out_of_range(&self, min: f64, max: f64) -> Option<f64> {
                    let v = *self as f64;
                    (!(min..=max).contains(&v)).then_some(v)
                }
            }
            impl ArrayItem for $t {
                const ARRAY: &'static str = $array;
            }
        )+
    };
}

numeric_option! {
    f64 = "float", array "array of float";
    f32 = "float", array "array of float";
    usize = "integer", array "array of integer";
    u64 = "integer", array "array of integer";
    u32 = "integer", array "array of integer";
    u16 = "integer", array "array of integer";
    u8 = "integer", array "array of integer";
    i64 = "integer", array "array of integer";
    i32 = "integer", array "array of integer";
}

option_type! {
    bool = "bool", array "array of bool";
    String = "string", array "array of string";
    PathBuf = "string", array "array of string";
    crate::machine::Flavor = "string";
    lamina_geom::offset::Join = "string";
}

/// Default and doc of an option that several stages accept alike; each stage names
/// it in its [`stage_options!`](crate::stage_options) with `name: T = use PATH`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SharedOption {
    /// The default as a TOML literal; `None` when the option has none.
    pub default: Option<&'static str>,
    pub doc: &'static str,
    /// The physical range of its numbers, both ends included.
    pub range: Option<(f64, f64)>,
}

impl SharedOption {
    /// An option whose default is the TOML literal `default`.
    pub const fn new(default: &'static str, doc: &'static str) -> Self {
        Self {
            default: Some(default),
            doc,
            range: None,
        }
    }

    /// An option without a default: required, or absent when its type is an `Option`.
    pub const fn without_default(doc: &'static str) -> Self {
        Self {
            default: None,
            doc,
            range: None,
        }
    }

    /// The option, its numbers held to `min..=max`.
    pub const fn within(self, min: f64, max: f64) -> Self {
        Self {
            range: Some((min, max)),
            ..self
        }
    }
}

/// A doc comment's text: its lines joined, without the leading space.
#[doc(hidden)]
pub const fn doc_text(s: &'static str) -> &'static str {
    s.trim_ascii()
}

/// True when an option declared with `default` and Rust type `T` must be given.
#[doc(hidden)]
pub const fn required<T: OptionType>(default: Option<&'static str>) -> bool {
    default.is_none() && !T::OPTIONAL
}

/// Parses a documented default, a TOML literal, into the option's type.
pub fn parse_default<T: DeserializeOwned>(name: &str, literal: &str) -> Result<T, String> {
    let table: toml::Table = toml::from_str(&format!("v = {literal}")).map_err(|e| {
        format!(
            "the default of `{name}`, {literal}, is not a TOML value: {}",
            e.message()
        )
    })?;
    let value = table
        .get("v")
        .cloned()
        .ok_or_else(|| format!("the default of `{name}`, {literal}, is not a TOML value"))?;
    value
        .try_into()
        .map_err(|e: toml::de::Error| format!("the default of `{name}`, {literal}: {}", e.message()))
}

/// The value of one option: what the table gave, else its parsed default, else
/// `None` for an `Option` and a "missing field" error for a required one.
#[doc(hidden)]
pub fn resolve<T: DeserializeOwned, E: de::Error>(
    given: Option<T>,
    name: &'static str,
    default: Option<&'static str>,
) -> Result<T, E> {
    match (given, default) {
        (Some(v), _) => Ok(v),
        (None, Some(literal)) => parse_default(name, literal).map_err(E::custom),
        (None, None) => T::deserialize(Absent(name, PhantomData)),
    }
}

/// A field's name and declared range, for [`Checked`]: `stage_options!` makes one
/// for each field.
#[doc(hidden)]
pub trait Bounds {
    const NAME: &'static str;
    const RANGE: Option<(f64, f64)>;
}

/// An option's value as the table gave it, its range checked while it is read, so
/// that an error points at the value.
#[doc(hidden)]
pub struct Checked<T, B>(pub Option<T>, PhantomData<B>);

impl<T, B> Default for Checked<T, B> {
    fn default() -> Self {
        Self(None, PhantomData)
    }
}

impl<'de, T: OptionType + serde::Deserialize<'de>, B: Bounds> serde::Deserialize<'de> for Checked<T, B> {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let v = T::deserialize(deserializer)?;
        check_range::<T, B>(&v).map_err(de::Error::custom)?;
        Ok(Self(Some(v), PhantomData))
    }
}

/// Refuses a value with a number outside the range `B` declares.
#[doc(hidden)]
pub fn check_range<T: OptionType, B: Bounds>(v: &T) -> Result<(), String> {
    match B::RANGE.and_then(|(min, max)| v.out_of_range(min, max).map(|got| (got, min, max))) {
        Some((got, min, max)) => Err(format!(
            "`{}` = {} is outside its range {}",
            B::NAME,
            number(got),
            range_text((min, max))
        )),
        None => Ok(()),
    }
}

/// A range as messages and documentation write it: `0.001 to 100`.
pub fn range_text((min, max): (f64, f64)) -> String {
    format!("{} to {}", number(min), number(max))
}

/// A number as a user would write it: `0.25`, `100`, `1e300`, `5e-324`.
fn number(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-4..1e9).contains(&a) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// Deserialises an option that is absent: `None` for an `Option`, else the error a
/// derived struct gives for a missing field.
struct Absent<E>(&'static str, PhantomData<E>);

impl<'de, E: de::Error> de::Deserializer<'de> for Absent<E> {
    type Error = E;

    fn deserialize_any<V: Visitor<'de>>(self, _visitor: V) -> Result<V::Value, E> {
        Err(E::missing_field(self.0))
    }

    fn deserialize_option<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, E> {
        visitor.visit_none()
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string
        bytes byte_buf unit unit_struct newtype_struct seq tuple
        tuple_struct map struct enum identifier ignored_any
    }
}

/// Declares a stage's options once, generating the options struct (deserialised from
/// the stage's table with `deny_unknown_fields`, defaults parsed from their TOML
/// literals) and its `SPECS: &'static [OptionSpec]` for
/// [`StageInfo::options`](crate::stage::StageInfo). See [the module](crate::options).
///
/// The crate using it must depend on `serde`.
#[macro_export]
macro_rules! stage_options {
    (
        $(#[$attr:meta])*
        $vis:vis struct $name:ident { $($body:tt)* }
    ) => {
        $crate::stage_options!(@field [$(#[$attr])*] [$vis] $name [] $($body)*);
    };

    // An option shared with other stages: its default, doc and range are elsewhere.
    (@field $attrs:tt $vis:tt $name:ident [$($done:tt)*]
        $(#[doc = $doc:literal])* $fvis:vis $field:ident : $ty:ty = use $shared:path
        $(, $($rest:tt)*)?
    ) => {
        $crate::stage_options!(@field $attrs $vis $name [$($done)*
            { [$fvis] $field [$ty] [$shared.default] [$shared.doc] [$shared.range] [] }
        ] $($($rest)*)?);
    };

    // A default written as a TOML literal. `#[formerly("old")]`: the name the option
    // had before, still read.
    (@field $attrs:tt $vis:tt $name:ident [$($done:tt)*]
        $(#[doc = $doc:literal])* $(#[range($min:expr, $max:expr)])? $(#[formerly($old:literal)])?
        $fvis:vis $field:ident : $ty:ty = $default:literal
        $(, $($rest:tt)*)?
    ) => {
        $crate::stage_options!(@field $attrs $vis $name [$($done)*
            { [$fvis] $field [$ty] [::core::option::Option::Some($default)]
              [$crate::options::doc_text(::core::concat!($($doc),*))]
              [$crate::stage_options!(@range $($min, $max)?)] [$($old)?] }
        ] $($($rest)*)?);
    };

    // No default: required, or absent when the type is an `Option`.
    (@field $attrs:tt $vis:tt $name:ident [$($done:tt)*]
        $(#[doc = $doc:literal])* $(#[range($min:expr, $max:expr)])? $(#[formerly($old:literal)])?
        $fvis:vis $field:ident : $ty:ty
        $(, $($rest:tt)*)?
    ) => {
        $crate::stage_options!(@field $attrs $vis $name [$($done)*
            { [$fvis] $field [$ty] [::core::option::Option::None]
              [$crate::options::doc_text(::core::concat!($($doc),*))]
              [$crate::stage_options!(@range $($min, $max)?)] [$($old)?] }
        ] $($($rest)*)?);
    };

    (@range) => { ::core::option::Option::None };
    (@range $min:expr, $max:expr) => { ::core::option::Option::Some(($min as f64, $max as f64)) };

    (@field [$($attr:tt)*] [$vis:vis] $name:ident [$(
        { [$fvis:vis] $field:ident [$ty:ty] [$default:expr] [$doc:expr] [$range:expr] [$($old:literal)?] }
    )*]) => {
        $($attr)*
        $vis struct $name {
            $($fvis $field: $ty,)*
        }

        impl $name {
            /// The options as the stage's `StageInfo::options` documents them.
            #[allow(dead_code, clippy::unnecessary_cast)]
            pub const SPECS: &'static [$crate::options::OptionSpec] = &[$(
                $crate::options::OptionSpec {
                    name: ::core::stringify!($field),
                    ty: <$ty as $crate::options::OptionType>::TOML,
                    default: $default,
                    doc: $doc,
                    required: $crate::options::required::<$ty>($default),
                    range: $range,
                },
            )*];
        }

        const _: () = {
            // One type a field, naming it and its range for `Checked`.
            $(
                #[allow(non_camel_case_types)]
                struct $field {}

                #[allow(clippy::unnecessary_cast)]
                impl $crate::options::Bounds for $field {
                    const NAME: &'static str = ::core::stringify!($field);
                    const RANGE: ::core::option::Option<(f64, f64)> = $range;
                }
            )*

            #[derive(::serde::Deserialize)]
            #[serde(deny_unknown_fields)]
            struct Given {
                $(
                    #[serde(default $(, alias = $old)?)]
                    $field: $crate::options::Checked<$ty, $field>,
                )*
            }

            impl<'de> ::serde::Deserialize<'de> for $name {
                fn deserialize<D: ::serde::Deserializer<'de>>(
                    deserializer: D,
                ) -> ::core::result::Result<Self, D::Error> {
                    let given = <Given as ::serde::Deserialize<'de>>::deserialize(deserializer)?;
                    ::core::result::Result::Ok($name {
                        $($field: {
                            let defaulted = given.$field.0.is_none();
                            let value: $ty = $crate::options::resolve(
                                given.$field.0,
                                ::core::stringify!($field),
                                $default,
                            )?;
                            // A given value was checked as it was read; a default
                            // outside its range is refused here.
                            if defaulted {
                                $crate::options::check_range::<$ty, $field>(&value)
                                    .map_err(<D::Error as ::serde::de::Error>::custom)?;
                            }
                            value
                        },)*
                    })
                }
            }
        };
    };
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::SharedOption;

    const SHARED: SharedOption = SharedOption::new("\"round\"", "offset corners");

    #[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
    #[serde(rename_all = "lowercase")]
    enum Join {
        Round,
        Miter,
    }
    crate::option_type!(Join = "string");

    crate::stage_options! {
        #[derive(Debug)]
        struct Options {
            /// layer thickness (mm)
            thickness: f64 = "0.2",
            /// first layer;
            /// unset: `thickness`
            first_layer: Option<f64>,
            /// file
            file: String,
            join: Join = use SHARED,
            point: [f64; 3] = "[0.0, 0.0, 1.0]",
            layers: Vec<usize> = "[]",
        }
    }

    crate::stage_options! {
        #[derive(Debug)]
        struct Renamed {
            /// samples (formerly `cells`)
            #[range(8, 64)]
            #[formerly("cells")]
            samples: usize = "16",
        }
    }

    #[test]
    fn a_renamed_option_is_read_by_its_former_name_too() {
        let read = |text: &str| toml::from_str::<Renamed>(text).map(|r| r.samples);
        assert_eq!(read("samples = 32").unwrap(), 32);
        assert_eq!(read("cells = 32").unwrap(), 32);
        assert_eq!(read("").unwrap(), 16);
        // The former name is checked as the option is: its range, once.
        let e = read("cells = 4").unwrap_err().to_string();
        assert!(e.contains("`samples` = 4 is outside its range 8 to 64"), "{e}");
        let e = read("cells = 32\nsamples = 32").unwrap_err().to_string();
        assert!(e.contains("duplicate field `samples`"), "{e}");
        assert_eq!(Renamed::SPECS[0].name, "samples");
    }

    #[test]
    fn specs_follow_the_declaration() {
        let s = Options::SPECS;
        let names: Vec<_> = s.iter().map(|o| o.name).collect();
        assert_eq!(
            names,
            ["thickness", "first_layer", "file", "join", "point", "layers"]
        );
        let tys: Vec<_> = s.iter().map(|o| o.ty).collect();
        assert_eq!(
            tys,
            [
                "float",
                "float",
                "string",
                "string",
                "array of float",
                "array of integer"
            ]
        );
        assert_eq!(s[0].doc, "layer thickness (mm)");
        assert_eq!(s[1].doc, "first layer; unset: `thickness`");
        assert_eq!(s[3].doc, "offset corners");
        assert_eq!(s[3].default, Some("\"round\""));
        let required: Vec<_> = s.iter().map(|o| o.required).collect();
        assert_eq!(required, [false, false, true, false, false, false]);
    }

    #[test]
    fn defaults_are_parsed_and_given_values_win() {
        let o: Options = toml::from_str("file = \"a\"").unwrap();
        assert_eq!(o.thickness, 0.2);
        assert_eq!(o.first_layer, None);
        assert_eq!(o.join, Join::Round);
        assert_eq!(o.point, [0.0, 0.0, 1.0]);
        assert!(o.layers.is_empty() && o.file == "a");
        let o: Options =
            toml::from_str("file = \"a\"\nthickness = 0.3\nfirst_layer = 0.1\njoin = \"miter\"").unwrap();
        assert_eq!(
            (o.thickness, o.first_layer, o.join),
            (0.3, Some(0.1), Join::Miter)
        );
    }

    #[test]
    fn errors_are_those_of_a_derived_struct() {
        let e = toml::from_str::<Options>("thickness = 0.3").unwrap_err();
        assert!(e.message().contains("missing field `file`"), "{e}");
        let e = toml::from_str::<Options>("file = \"a\"\nthikness = 0.3").unwrap_err();
        assert!(
            e.message().contains("unknown field `thikness`, expected one of"),
            "{e}"
        );
        let e = toml::from_str::<Options>("file = \"a\"\nthickness = \"x\"").unwrap_err();
        assert!(e.message().contains("invalid type"), "{e}");
    }

    #[test]
    fn a_default_that_is_not_toml_is_an_error() {
        assert!(super::parse_default::<f64>("span", "1.5 * chord").is_err());
        assert!(super::parse_default::<f64>("x", "none").is_err());
        assert_eq!(super::parse_default::<f64>("x", "1e-5"), Ok(1e-5));
    }

    const SPACING: SharedOption = SharedOption::new("0.5", "spacing (mm)").within(0.01, 10.0);

    crate::stage_options! {
        #[derive(Debug)]
        struct Ranged {
            /// a length (mm)
            #[range(0.001, 100.0)]
            length: f64 = "0.2",
            /// a count
            #[range(1, 64)]
            count: usize = "4",
            /// an optional share
            #[range(0.0, 1.0)]
            share: Option<f64>,
            /// weights
            #[range(0.0, 10.0)]
            weights: Vec<f64> = "[]",
            /// a point
            #[range(-5.0, 5.0)]
            point: [f64; 2] = "[0.0, 0.0]",
            /// points
            #[range(-5.0, 5.0)]
            points: Vec<[f64; 2]> = "[]",
            spacing: f64 = use SPACING,
            /// no range
            name: String = "\"a\"",
        }
    }

    fn refusal(text: &str) -> String {
        toml::from_str::<Ranged>(text)
            .err()
            .map(|e| e.message().to_string())
            .unwrap_or_else(|| panic!("{text} accepted"))
    }

    #[test]
    fn ranges_are_declared_in_the_specs() {
        let ranges: Vec<_> = Ranged::SPECS.iter().map(|o| o.range).collect();
        assert_eq!(
            ranges,
            [
                Some((0.001, 100.0)),
                Some((1.0, 64.0)),
                Some((0.0, 1.0)),
                Some((0.0, 10.0)),
                Some((-5.0, 5.0)),
                Some((-5.0, 5.0)),
                Some((0.01, 10.0)),
                None
            ]
        );
    }

    #[test]
    fn every_number_inside_its_range_is_accepted_ends_included() {
        let o: Ranged = toml::from_str("").unwrap();
        assert_eq!((o.length, o.count, o.share, o.spacing), (0.2, 4, None, 0.5));
        assert_eq!(o.name, "a");
        let o: Ranged = toml::from_str(
            "length = 100.0\ncount = 1\nshare = 0.0\nweights = [0.0, 10.0]\npoint = [-5.0, 5.0]\n\
             points = [[5.0, -5.0]]\nspacing = 0.01",
        )
        .unwrap();
        assert_eq!((o.length, o.count, o.share), (100.0, 1, Some(0.0)));
        assert_eq!(
            (o.weights, o.point, o.points),
            (vec![0.0, 10.0], [-5.0, 5.0], vec![[5.0, -5.0]])
        );
    }

    #[test]
    fn a_number_outside_its_range_is_refused_with_the_key_the_value_and_the_range() {
        for (text, message) in [
            (
                "length = 1e-4",
                "`length` = 0.0001 is outside its range 0.001 to 100",
            ),
            (
                "length = 100.5",
                "`length` = 100.5 is outside its range 0.001 to 100",
            ),
            ("length = nan", "`length` = NaN is outside its range 0.001 to 100"),
            ("count = 0", "`count` = 0 is outside its range 1 to 64"),
            ("count = 65", "`count` = 65 is outside its range 1 to 64"),
            ("share = 1.5", "`share` = 1.5 is outside its range 0 to 1"),
            (
                "weights = [1.0, -1.0]",
                "`weights` = -1 is outside its range 0 to 10",
            ),
            (
                "point = [0.0, 1e300]",
                "`point` = 1e300 is outside its range -5 to 5",
            ),
            (
                "points = [[0.0, 0.0], [5e-324, -6.0]]",
                "`points` = -6 is outside its range -5 to 5",
            ),
            ("spacing = 0.0", "`spacing` = 0 is outside its range 0.01 to 10"),
        ] {
            let e = refusal(text);
            assert!(e.contains(message), "{text}: {e}");
        }
    }

    #[test]
    fn a_default_outside_its_range_is_refused() {
        const TIGHT: SharedOption = SharedOption::new("5.0", "a bad default").within(0.0, 1.0);
        crate::stage_options! {
            #[derive(Debug)]
            struct Bad {
                v: f64 = use TIGHT,
            }
        }
        let e = toml::from_str::<Bad>("").unwrap_err();
        assert!(e.message().contains("`v` = 5 is outside its range 0 to 1"), "{e}");
        assert_eq!(toml::from_str::<Bad>("v = 0.5").unwrap().v, 0.5);
    }

    #[test]
    fn a_range_on_a_value_without_numbers_refuses_nothing() {
        crate::stage_options! {
            #[derive(Debug)]
            struct Words {
                #[range(0.0, 1.0)]
                word: String = "\"five\"",
            }
        }
        assert_eq!(toml::from_str::<Words>("word = \"ten\"").unwrap().word, "ten");
        assert_eq!(toml::from_str::<Words>("").unwrap().word, "five");
    }

    #[test]
    fn numbers_are_written_as_a_user_would() {
        assert_eq!(super::range_text((0.001, 100.0)), "0.001 to 100");
        assert_eq!(super::range_text((1e-6, 1e9)), "1e-6 to 1e9");
        assert_eq!(super::range_text((-1e300, 0.0)), "-1e300 to 0");
        assert_eq!(super::range_text((0.0001, 999_999_999.0)), "0.0001 to 999999999");
        assert_eq!(super::range_text((5e-324, 0.5)), "5e-324 to 0.5");
    }
}
