//! The machine profile as written: every key optional, so that one schema checks the
//! types of each layer (a base profile, a file extending it, an inline table) with the
//! spans of its own file, and then reads the merged result. What is required, and
//! every value's range, is checked afterwards by `load`.

use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::{Deserialize, de::value::MapAccessDeserializer};

use super::{Firmware, Flavor};

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMachine {
    /// Consumed while resolving; present here so the schema accepts it.
    #[expect(dead_code, reason = "read from the table while resolving bases")]
    pub base: Option<String>,
    pub name: Option<String>,
    pub description: Option<String>,
    pub flavor: Option<Flavor>,
    pub firmware: Option<Firmware>,
    pub placement: Option<RawPlacement>,
    pub motion_systems: Option<usize>,
    pub nozzle_diameter: Option<f64>,
    pub max_layer_height: Option<f64>,
    pub filament_diameter: Option<f64>,
    pub bed_temperature: Option<f64>,
    pub first_layer_bed_temperature: Option<f64>,
    pub travel_speed: Option<f64>,
    pub bed: Option<RawBed>,
    pub tools: Option<Vec<RawTool>>,
    pub fan: Option<RawFan>,
    pub first_layer: Option<RawFirstLayer>,
    pub retraction: Option<RawRetraction>,
    pub motion: Option<RawMotion>,
    pub skirt: Option<Switch<RawSkirt>>,
    pub prime_line: Option<Switch<RawPrimeLine>>,
    pub wipe_tower: Option<Switch<RawWipeTower>>,
    pub mixer: Option<RawMixer>,
    pub heating: Option<RawHeating>,
    pub kinematics: Option<RawKinematics>,
    pub tool_change_time: Option<f64>,
    pub gcode: Option<RawTemplates>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawKinematics {
    pub class: Option<super::HeadClass>,
    pub margin: Option<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawHeating {
    pub nozzle_rate: Option<f64>,
    pub nozzle_cooling: Option<f64>,
    pub bed_rate: Option<f64>,
    pub residency: Option<f64>,
    pub bed_residency: Option<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawBed {
    pub shape: Option<RawShape>,
    pub size: Option<[f64; 2]>,
    pub diameter: Option<f64>,
    pub origin: Option<super::BedOrigin>,
    pub max_height: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(crate) enum RawShape {
    Rectangle,
    Circle,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawTool {
    pub material: Option<String>,
    pub nozzle_temperature: Option<f64>,
    pub first_layer_temperature: Option<f64>,
    pub standby_temperature: Option<f64>,
    pub name: Option<String>,
    pub axis: Option<String>,
    pub y_axis: Option<String>,
    pub home: Option<[f64; 2]>,
    pub envelope: Option<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawFan {
    pub speed: Option<f64>,
    pub first_layer: Option<bool>,
    pub full_speed_layer: Option<usize>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawFirstLayer {
    pub height: Option<f64>,
    pub speed: Option<f64>,
    pub speed_factor: Option<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRetraction {
    pub length: Option<f64>,
    pub tool_change_length: Option<f64>,
    pub speed: Option<f64>,
    pub z_hop: Option<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMotion {
    pub print_acceleration: Option<f64>,
    pub travel_acceleration: Option<f64>,
    pub retract_acceleration: Option<f64>,
    pub junction_deviation: Option<f64>,
    pub jerk: Option<RawAxes>,
    pub max_speed: Option<RawAxes>,
    pub max_acceleration: Option<RawAxes>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawAxes {
    pub x: Option<f64>,
    pub y: Option<f64>,
    pub z: Option<f64>,
    pub e: Option<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSkirt {
    pub loops: Option<usize>,
    pub distance: Option<f64>,
    pub layers: Option<usize>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawPrimeLine {
    pub length: Option<f64>,
    pub width: Option<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawWipeTower {
    pub position: Option<[f64; 2]>,
    pub size: Option<[f64; 2]>,
    pub purge_volume: Option<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMixer {
    pub transition_volume: Option<f64>,
    pub blend_below: Option<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawTemplates {
    pub start: Option<String>,
    pub end: Option<String>,
    pub tool_change: Option<String>,
}

/// `placement = "centre"` or `placement = [x, y]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum RawPlacement {
    Centre,
    At([f64; 2]),
}

impl<'de> Deserialize<'de> for RawPlacement {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = RawPlacement;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("\"centre\" or a point [x, y] on the bed")
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<Self::Value, E> {
                match v {
                    "centre" | "center" => Ok(RawPlacement::Centre),
                    _ => Err(E::custom(format!(
                        "placement `{v}`: expected \"centre\" or a point [x, y] on the bed"
                    ))),
                }
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
                let x: f64 = seq
                    .next_element()?
                    .ok_or_else(|| de::Error::invalid_length(0, &self))?;
                let y: f64 = seq
                    .next_element()?
                    .ok_or_else(|| de::Error::invalid_length(1, &self))?;
                if seq.next_element::<f64>()?.is_some() {
                    return Err(de::Error::invalid_length(3, &self));
                }
                Ok(RawPlacement::At([x, y]))
            }
        }
        d.deserialize_any(V)
    }
}

/// A feature table that an override may switch off with `false` (`skirt = false`).
#[derive(Debug)]
pub(crate) enum Switch<T> {
    Off,
    /// `true`: keep what the base says.
    On,
    Table(T),
}

impl<'de, T: Deserialize<'de>> Deserialize<'de> for Switch<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V<T>(std::marker::PhantomData<T>);
        impl<'de, T: Deserialize<'de>> Visitor<'de> for V<T> {
            type Value = Switch<T>;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a table, or false to switch the feature off")
            }
            fn visit_bool<E: de::Error>(self, v: bool) -> Result<Self::Value, E> {
                Ok(if v { Switch::On } else { Switch::Off })
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
                T::deserialize(MapAccessDeserializer::new(map)).map(Switch::Table)
            }
        }
        d.deserialize_any(V(std::marker::PhantomData))
    }
}
