//! Machine profiles as data: what a printer is (its bed, firmware, tools, temperatures,
//! motion limits and G-code templates), so that an exporter can write a file the
//! machine prints safely, a planner can keep its heads apart, and the runtime can place
//! the parts on its bed and refuse those that do not fit.
//!
//! This module holds the resolved, validated description that crosses the plugin
//! boundary in [`RunInfo`](crate::stage::RunInfo). Reading profiles (built-in ones,
//! TOML files, inline tables with a `base`) is lamina-machine's, with errors that name
//! the file, line and field.
//!
//! The API knows no G-code: the templates are kept as text with their variables
//! ([`template`]), and what the commands mean is the exporters' business.

pub mod template;

use serde::{Deserialize, Serialize};

use crate::geom::{BBox2, Point2, Vector2};
use crate::source::Location;

pub use template::Template;

/// A printer, as a machine profile describes it, validated.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Machine {
    pub name: String,
    /// One line for people (`lamina plugins` lists the built-in profiles with it).
    #[serde(default)]
    pub description: String,
    pub flavor: Flavor,
    pub firmware: Firmware,
    /// Motion systems that move heads independently (RepRapFirmware 3.5 runs two from
    /// one job): with two, tool `n` is the head of motion system `n` and the tools work
    /// at the same time.
    #[serde(default = "one")]
    pub motion_systems: usize,
    pub bed: Bed,
    /// Where the parts go on the bed.
    pub placement: BedPlacement,
    /// Nozzle bore (mm); the natural extrusion width is near it.
    pub nozzle_diameter: f64,
    /// Thickest layer the nozzle lays and presses down (mm): about three quarters of
    /// its bore.
    pub max_layer_height: f64,
    pub filament_diameter: f64,
    /// Tools of a tool changer or IDEX, or channels of a mixing head, in firmware order.
    pub tools: Vec<ToolSlot>,
    /// Bed temperature after the first layer (°C; 0: unheated).
    pub bed_temperature: f64,
    pub first_layer_bed_temperature: f64,
    pub fan: Fan,
    pub first_layer: FirstLayer,
    pub retraction: Retraction,
    /// Speed of moves that do not extrude (mm/s).
    pub travel_speed: f64,
    pub motion: Motion,
    pub skirt: Option<Skirt>,
    pub prime_line: Option<PrimeLine>,
    pub wipe_tower: Option<WipeTower>,
    /// What a mixing head purges after a mix change; `Some` exactly for mixing flavours.
    pub mixer: Option<Mixer>,
    /// How fast the heaters heat and cool, and how long the firmware lets them settle:
    /// what a wait for a temperature costs.
    #[serde(default)]
    pub heating: Heating,
    /// How the heads may move around each other: what a planner running several at
    /// once must respect.
    #[serde(default)]
    pub kinematics: Kinematics,
    /// What a tool change takes besides the moves the file writes for it (s): the
    /// firmware's own parking and pick-up.
    #[serde(default)]
    pub tool_change_time: f64,
    pub gcode: Templates,
    /// Where the profile came from, for messages.
    #[serde(skip)]
    pub origin: MachineOrigin,
}

fn one() -> usize {
    1
}

/// How the heads of a machine with several of them move around each other.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Kinematics {
    pub class: HeadClass,
    /// What a plan keeps beyond the heads' envelopes (mm, per head): the firmware's
    /// accelerations move each head off the plan's constant-speed timing between two
    /// synchronisations, and this is the room that leaves. The planner keeps it around
    /// every head, and the file's synchronisation points keep it too.
    pub margin: f64,
}

impl Default for Kinematics {
    fn default() -> Self {
        Kinematics {
            class: HeadClass::Free,
            margin: 1.0,
        }
    }
}

/// The mechanics that carry the heads, and so which of their relative positions exist.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum HeadClass {
    /// Heads that go anywhere around each other (robot arms, delta pairs, heads on
    /// separate frames): each keeps the disc of its envelope clear of the others'.
    #[default]
    Free,
    /// Each head on a gantry beam of its own, the beams on one pair of Y rails: the
    /// heads keep their order in Y (the one homing nearer Y = 0 is in front) and each
    /// beam is an obstacle across the whole bed, so they keep the envelopes' sum apart
    /// in Y wherever they are in X.
    DualGantry,
    /// Two carriages on one beam (IDEX): ordered in X, one Y for both. Only one works
    /// at a time unless both follow the same Y, which no plan of different materials
    /// does: one motion system, heads taking turns.
    SharedBeam,
}

impl HeadClass {
    pub fn name(self) -> &'static str {
        match self {
            HeadClass::Free => "free",
            HeadClass::DualGantry => "dual-gantry",
            HeadClass::SharedBeam => "shared-beam",
        }
    }
}

/// How the firmware is asked to change material.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Flavor {
    /// One tool per material (`T0`, `T1`, ...): tool changers and IDEX machines.
    ToolChange,
    /// One Marlin mixing extruder (`M163`/`M164`, or `M165`).
    MarlinMixing,
    /// One RepRapFirmware mixing tool (`M563`, `M567`).
    ReprapMixing,
}

impl Flavor {
    pub fn name(self) -> &'static str {
        match self {
            Flavor::ToolChange => "tool-change",
            Flavor::MarlinMixing => "marlin-mixing",
            Flavor::ReprapMixing => "reprap-mixing",
        }
    }

    /// True for one nozzle fed by several channels.
    pub fn is_mixing(self) -> bool {
        !matches!(self, Flavor::ToolChange)
    }
}

/// The firmware dialect: temperatures, accelerations and cornering are set differently.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Firmware {
    Marlin,
    #[serde(rename = "reprapfirmware")]
    RepRapFirmware,
}

impl Firmware {
    pub fn name(self) -> &'static str {
        match self {
            Firmware::Marlin => "marlin",
            Firmware::RepRapFirmware => "reprapfirmware",
        }
    }
}

/// The build plate: its shape, where its coordinate origin is, and how high the machine
/// builds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Bed {
    pub shape: BedShape,
    pub origin: BedOrigin,
    /// Highest Z the nozzle reaches over the bed (mm).
    pub max_height: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BedShape {
    /// `size` along X and Y (mm).
    Rectangle {
        size: [f64; 2],
    },
    Circle {
        diameter: f64,
    },
}

/// Where X = 0, Y = 0 is on the bed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BedOrigin {
    /// The front-left corner (of the bed's bounding square for a circle).
    FrontLeft,
    Centre,
}

impl Bed {
    /// The bed's bounding box in machine coordinates.
    pub fn bounds(&self) -> BBox2 {
        let (w, d) = match self.shape {
            BedShape::Rectangle { size } => (size[0], size[1]),
            BedShape::Circle { diameter } => (diameter, diameter),
        };
        let min = match self.origin {
            BedOrigin::FrontLeft => Point2::new(0.0, 0.0),
            BedOrigin::Centre => Point2::new(-w / 2.0, -d / 2.0),
        };
        BBox2 {
            min,
            max: min + Vector2::new(w, d),
        }
    }

    pub fn centre(&self) -> Point2 {
        self.bounds().center()
    }

    /// Whether a point (machine coordinates) lies on the bed, `margin` mm inside its edge.
    pub fn contains(&self, p: Point2, margin: f64) -> bool {
        let b = self.bounds();
        match self.shape {
            BedShape::Rectangle { .. } => {
                p.x >= b.min.x + margin
                    && p.x <= b.max.x - margin
                    && p.y >= b.min.y + margin
                    && p.y <= b.max.y - margin
            }
            BedShape::Circle { diameter } => (p - b.center()).norm() <= diameter / 2.0 - margin,
        }
    }

    /// Whether a box (machine coordinates) lies on the bed, `margin` mm inside its edge.
    pub fn contains_box(&self, b: &BBox2, margin: f64) -> bool {
        !b.is_empty()
            && [
                b.min,
                b.max,
                Point2::new(b.min.x, b.max.y),
                Point2::new(b.max.x, b.min.y),
            ]
            .into_iter()
            .all(|p| self.contains(p, margin))
    }

    /// "220 x 220 mm rectangle", "200 mm circle", for messages.
    pub fn describe(&self) -> String {
        match self.shape {
            BedShape::Rectangle { size } => format!("{} x {} mm rectangle", size[0], size[1]),
            BedShape::Circle { diameter } => format!("{diameter} mm circle"),
        }
    }
}

/// Where the parts go on the bed: the centre of the parts' XY bounding box is put on the
/// bed's centre or at a given point.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BedPlacement {
    Centre,
    At([f64; 2]),
}

/// One tool of a tool changer or IDEX, or one channel of a mixing head.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ToolSlot {
    /// The pipeline material it carries; `None`: the pipeline's material at this
    /// position, so a shipped profile serves any pipeline.
    pub material: Option<String>,
    /// Printing temperature after the first layer (°C).
    pub nozzle_temperature: f64,
    pub first_layer_temperature: f64,
    /// Temperature while another tool prints (°C); for tool changers.
    pub standby_temperature: Option<f64>,
    /// The head's name (an IDEX's `left` and `right`), for people and flavours that
    /// drive heads separately.
    pub name: Option<String>,
    /// The firmware axis that moves this head along X (`X`, `U`) on an IDEX.
    pub axis: Option<String>,
    /// The firmware axis that moves this head along Y (`Y`, `V`), when the head has a
    /// motion system of its own.
    #[serde(default)]
    pub y_axis: Option<String>,
    /// Where homing leaves the head (bed coordinates, mm).
    #[serde(default)]
    pub home: Option<[f64; 2]>,
    /// Radius of the disc around the nozzle that no other head may enter (mm).
    #[serde(default)]
    pub envelope: Option<f64>,
}

/// The part-cooling fan.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Fan {
    /// Full speed, in percent.
    pub speed: f64,
    /// Whether the fan runs on the first layer (it usually harms adhesion).
    pub first_layer: bool,
    /// Layer index from which the fan runs at `speed`; it ramps up linearly before it.
    pub full_speed_layer: usize,
}

/// How the first layer is slowed down.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FirstLayer {
    /// Thickness of the first layer (mm), when the machine wants its own: slicers
    /// that cut uniform layers start with it.
    #[serde(default)]
    pub height: Option<f64>,
    pub speed: FirstLayerSpeed,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FirstLayerSpeed {
    /// A fraction of the planned speed.
    Factor(f64),
    /// At most this speed (mm/s).
    Speed(f64),
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Retraction {
    /// Filament pulled back before a travel (mm).
    pub length: f64,
    /// Filament pulled back before a tool parks (mm).
    pub tool_change_length: f64,
    pub speed: f64,
    /// Lift of the nozzle during retracted travel (mm; 0: none).
    pub z_hop: f64,
}

/// Acceleration and cornering the firmware is configured with: they make the time a
/// file takes, so the file sets them and the time estimate uses them.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Motion {
    /// Acceleration of extruding moves (mm/s²).
    pub print_acceleration: f64,
    /// Acceleration of moves without extrusion.
    pub travel_acceleration: f64,
    /// Acceleration of extruder-only moves (retraction).
    pub retract_acceleration: f64,
    pub cornering: Cornering,
    /// Per-axis speed limits (mm/s), X, Y, Z, E.
    pub max_speed: Option<Axes>,
    /// Per-axis acceleration limits (mm/s²), X, Y, Z, E.
    pub max_acceleration: Option<Axes>,
}

/// How fast the firmware lets the head go through a corner.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Cornering {
    /// Marlin's junction deviation (mm).
    JunctionDeviation(f64),
    /// Largest instantaneous speed change per axis (mm/s): Marlin's classic jerk,
    /// RepRapFirmware's `M566`.
    Jerk(Axes),
}

/// One value per axis.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Axes {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub e: f64,
}

impl Axes {
    pub fn as_array(&self) -> [f64; 4] {
        [self.x, self.y, self.z, self.e]
    }
}

/// Loops around everything on the first layers, which primes the nozzle and shows the
/// bed is level before the part starts.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Skirt {
    pub loops: usize,
    /// Gap between the skirt and what it surrounds (mm).
    pub distance: f64,
    /// How many layers high.
    pub layers: usize,
}

/// A line along the front of the bed that each tool extrudes before its first use.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PrimeLine {
    pub length: f64,
    /// Width of the line (mm).
    pub width: f64,
}

/// The tower that takes the purge of every tool or mix change.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WipeTower {
    /// Front-left corner on the bed; `None`: beside the parts, where it fits.
    pub position: Option<[f64; 2]>,
    /// Footprint along X and Y (mm).
    pub size: [f64; 2],
    /// Volume purged after each tool change (mm³); a mixing head purges its
    /// `Mixer::transition_volume` instead, and this is 0.
    pub purge_volume: f64,
}

/// The heaters' physics, for the time a wait takes. The rates are those of the
/// temperature range a print moves in (standby to printing), where heaters run at full
/// power and cool by convection and the part fan.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Heating {
    /// °C/s a nozzle heats.
    pub nozzle_rate: f64,
    /// °C/s a nozzle cools.
    pub nozzle_cooling: f64,
    /// °C/s the bed heats.
    pub bed_rate: f64,
    /// Seconds the firmware keeps waiting once a nozzle is at temperature (Marlin's
    /// `TEMP_RESIDENCY_TIME`; RepRapFirmware's `M116` has none).
    pub residency: f64,
    /// The same for the bed (Marlin's `TEMP_BED_RESIDENCY_TIME`).
    pub bed_residency: f64,
}

impl Heating {
    /// Typical of a 40 W cartridge hotend and a 24 V bed, with the firmware's own
    /// residency defaults.
    pub fn typical(firmware: Firmware) -> Self {
        let residency = match firmware {
            Firmware::Marlin => 10.0,
            Firmware::RepRapFirmware => 0.0,
        };
        Self {
            nozzle_rate: 2.0,
            nozzle_cooling: 1.0,
            bed_rate: 0.5,
            residency,
            bed_residency: residency,
        }
    }
}

impl Default for Heating {
    fn default() -> Self {
        Self::typical(Firmware::Marlin)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Mixer {
    /// Volume that leaves the nozzle after a mix change before 95 % of what comes out
    /// is the new mix (mm³): the transition, which the part's next beads take where
    /// their design allows it and the wipe tower takes otherwise.
    pub transition_volume: f64,
    /// Share of the mix (half the sum of the channels' differences, 0..1) below which
    /// a change between beads is blended in place rather than purged: a graded part
    /// changes its mix by a few percent from one bead to the next, and the chamber's
    /// blending of such a step is the gradient itself.
    #[serde(default)]
    pub blend_below: f64,
}

/// G-code templates with `{variable}` placeholders (see [`template::START_VARIABLES`]
/// and its neighbours).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Templates {
    pub start: Template,
    pub end: Template,
    /// Selects the next tool; the exporter retracts, sets temperatures and purges
    /// around it.
    pub tool_change: Template,
}

/// Where a profile came from, for messages.
#[derive(Debug, Clone, Default)]
pub struct MachineOrigin {
    /// `built-in profile marlin-mixing-2in1`, `profiles/my.toml`, `[machine] in p.toml`.
    pub label: String,
    /// Where the pipeline names the machine.
    pub at: Option<Location>,
}

impl PartialEq for MachineOrigin {
    fn eq(&self, other: &Self) -> bool {
        self.label == other.label
    }
}

impl Machine {
    /// How far the parts move so that the centre of their XY bounding box `parts` lands
    /// where the placement says.
    pub fn placement_offset(&self, parts: &BBox2) -> Vector2 {
        if parts.is_empty() {
            return Vector2::zeros();
        }
        let target = match self.placement {
            BedPlacement::Centre => self.bed.centre(),
            BedPlacement::At([x, y]) => Point2::new(x, y),
        };
        target - parts.center()
    }

    /// The tool slot that carries pipeline material `material` (its name and position
    /// among the pipeline's materials).
    pub fn tool_of(&self, material: &str, position: usize) -> Option<usize> {
        self.tools
            .iter()
            .position(|t| t.material.as_deref() == Some(material))
            .or_else(|| {
                self.tools
                    .get(position)
                    .filter(|t| t.material.is_none())
                    .map(|_| position)
            })
    }

    /// A configuration error about this machine, at the place the pipeline names it.
    pub fn error(&self, message: impl Into<String>) -> crate::Error {
        let message = format!(
            "machine `{}` ({}): {}",
            self.name,
            self.origin.label,
            message.into()
        );
        match &self.origin.at {
            Some(at) => crate::Error::config_at(at.clone(), message),
            None => crate::Error::config(message),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bed(shape: BedShape, origin: BedOrigin) -> Bed {
        Bed {
            shape,
            origin,
            max_height: 200.0,
        }
    }

    #[test]
    fn bounds_follow_the_origin() {
        let b = bed(BedShape::Rectangle { size: [220.0, 200.0] }, BedOrigin::FrontLeft);
        assert_eq!(b.bounds().max, Point2::new(220.0, 200.0));
        assert_eq!(b.centre(), Point2::new(110.0, 100.0));
        let b = bed(BedShape::Circle { diameter: 200.0 }, BedOrigin::Centre);
        assert_eq!(b.bounds().min, Point2::new(-100.0, -100.0));
        assert!(b.contains(Point2::new(70.0, 70.0), 0.0));
        assert!(
            !b.contains(Point2::new(80.0, 80.0), 0.0),
            "outside the circle, inside its square"
        );
    }

    #[test]
    fn boxes_inside_with_a_margin() {
        let b = bed(BedShape::Rectangle { size: [100.0, 100.0] }, BedOrigin::Centre);
        let inside = BBox2::from_points([Point2::new(-40.0, -40.0), Point2::new(40.0, 40.0)]);
        assert!(b.contains_box(&inside, 5.0));
        assert!(!b.contains_box(&inside, 15.0));
        assert!(!b.contains_box(&BBox2::EMPTY, 0.0));
    }
}
