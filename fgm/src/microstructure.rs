//! The base cell of a periodic microstructure as the CAD model describes it
//! (cmpm-process-planning 4.3): an inserting function that says where cells go, and a
//! size and an orientation that may change with position, each a number or a Rhai
//! expression of `x`, `y`, `z`; cells on a lattice that may stand tilted against the
//! layers (Fig. 5). Every stage that needs a layer's voids (the `bitmap` exporter, the
//! `engrave` operation) reads the same `cell` table into a [`Microstructure`] and asks
//! it for the voids the layer's plane cuts.

use nalgebra::{Matrix3, Rotation3, Vector3};
use serde::Deserialize;

use lamina_api::error::{Error, Result};
use lamina_api::geom::{BBox2, Contour};
use lamina_api::limits::{Limit, Limits};
use lamina_api::model::ModelFrame;
use lamina_api::script::{ScriptArgs, ScriptFn};
use lamina_api::stage::StageConfig;
use lamina_geom::base_cell::{BaseCellArray, BaseCellShape, PlacedBaseCell};

/// A number, or a Rhai expression of `x`, `y` and `z` (mm) evaluated at each
/// inserting point.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum NumberOrScript {
    Number(f64),
    Script(String),
}

/// The `cell` table of a stage.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BaseCellSpec {
    /// `sphere`, `box` or `cylinder`.
    #[serde(default = "sphere")]
    pub shape: String,
    /// The cell's size (mm): a sphere's or cylinder's radius, a box's half-edge, times
    /// `aspect` along each of the cell's axes.
    pub size: NumberOrScript,
    /// Multipliers of `size` along the cell's x, y and z (a cylinder's radius is
    /// `size * aspect[0]` and its half-height `size * aspect[2]`; `aspect[1]` is not
    /// used for it).
    #[serde(default = "ones")]
    pub aspect: [f64; 3],
    /// Turn of the cell about the vertical (degrees).
    #[serde(default)]
    pub turn: Option<NumberOrScript>,
    /// Lean of the cell's z axis toward -y, about x (degrees), applied before the turn.
    #[serde(default)]
    pub lean: Option<NumberOrScript>,
    /// The inserting function: a cell goes where it is above zero; every lattice point
    /// holds one when absent.
    #[serde(default)]
    pub insert: Option<String>,
    /// Lattice spacing along the lattice's x, y and z (mm).
    pub period: [f64; 3],
    /// One inserting point (mm).
    #[serde(default)]
    pub origin: [f64; 3],
    /// Angle of the lattice's z axis from the vertical, about x (degrees): the
    /// spraying plane at an angle Φ to the lattice (Fig. 5).
    #[serde(default)]
    pub tilt: f64,
}

fn sphere() -> String {
    "sphere".into()
}

fn ones() -> [f64; 3] {
    [1.0; 3]
}

lamina_api::option_type!(BaseCellSpec = "table");

enum Value {
    Number(f64),
    Script(ScriptFn, String),
}

impl Value {
    fn new(v: &NumberOrScript, config: &StageConfig<'_>, key: &str) -> Result<Value> {
        Ok(match v {
            NumberOrScript::Number(x) => {
                if !x.is_finite() {
                    return Err(config.error(key, format!("`cell.{key}` must be a finite number")));
                }
                Value::Number(*x)
            }
            NumberOrScript::Script(s) => {
                Value::Script(config.scripts.compile(s, config.string_location(key))?, s.clone())
            }
        })
    }

    fn text(&self) -> String {
        match self {
            Value::Number(x) => x.to_string(),
            Value::Script(_, s) => format!("`{s}`"),
        }
    }

    fn at(&self, p: &Vector3<f64>, what: &str) -> Result<f64> {
        match self {
            Value::Number(x) => Ok(*x),
            Value::Script(f, _) => {
                let args = ScriptArgs {
                    x: p.x,
                    y: p.y,
                    z: p.z,
                    ..ScriptArgs::default()
                };
                let v = f.number(&args, what)?;
                if v.is_finite() {
                    Ok(v)
                } else {
                    Err(Error::stage(
                        "cell",
                        format!("`cell.{what}` is {v} at ({:.3}, {:.3}, {:.3})", p.x, p.y, p.z),
                    ))
                }
            }
        }
    }
}

/// A microstructure ready to give each layer its voids.
pub struct Microstructure {
    shape: BaseCellShape,
    size: Value,
    aspect: [f64; 3],
    turn: Option<Value>,
    lean: Option<Value>,
    insert: Option<Value>,
    lattice: BaseCellArray,
    /// How far a cell may reach from its inserting point: half the lattice's diagonal,
    /// the search band's half-width `L_max`.
    reach: f64,
    /// The lattice's tilt (degrees), for the description.
    tilt: f64,
    /// The run's limits: the lattice points a layer or a box visits are counted first.
    limits: Limits,
}

impl Microstructure {
    /// The microstructure of `spec`, read from the option `key` of `config`.
    pub fn new(spec: &BaseCellSpec, config: &StageConfig<'_>, key: &str) -> Result<Self> {
        let shape = match spec.shape.as_str() {
            "sphere" => BaseCellShape::Sphere,
            "box" => BaseCellShape::Box,
            "cylinder" => BaseCellShape::Cylinder,
            other => {
                return Err(config.error(
                    key,
                    format!("`shape` is `{other}`: use `sphere`, `box` or `cylinder`"),
                ));
            }
        };
        if spec.period.iter().any(|p| !(p.is_finite() && *p > 0.0)) {
            return Err(config.error(key, "`period`: every spacing must be a positive number of mm"));
        }
        if spec.aspect.iter().any(|a| !(a.is_finite() && *a > 0.0)) {
            return Err(config.error(key, "`aspect`: every multiplier must be positive"));
        }
        if spec.origin.iter().any(|o| !o.is_finite()) || !(spec.tilt.is_finite() && spec.tilt.abs() < 90.0) {
            return Err(config.error(key, "`origin` must be finite and `tilt` within (-90, 90) degrees"));
        }
        let script = |v: &Option<String>| -> Result<Option<Value>> {
            v.as_ref()
                .map(|s| Value::new(&NumberOrScript::Script(s.clone()), config, key))
                .transpose()
        };
        Ok(Self {
            shape,
            size: Value::new(&spec.size, config, key)?,
            aspect: spec.aspect,
            turn: spec
                .turn
                .as_ref()
                .map(|v| Value::new(v, config, key))
                .transpose()?,
            lean: spec
                .lean
                .as_ref()
                .map(|v| Value::new(v, config, key))
                .transpose()?,
            insert: script(&spec.insert)?,
            lattice: BaseCellArray::tilted_about_x(spec.period, spec.origin, spec.tilt.to_radians()),
            reach: 0.5 * Vector3::from(spec.period).norm(),
            tilt: spec.tilt,
            limits: config.limits,
        })
    }

    /// Spherical voids of `radius` on an upright lattice: the shorthand of stages that
    /// take `period`, `origin` and `void_radius`.
    pub fn spheres(period: [f64; 3], origin: [f64; 3], radius: f64, limits: Limits) -> Self {
        Self {
            shape: BaseCellShape::Sphere,
            size: Value::Number(radius),
            aspect: [1.0; 3],
            turn: None,
            lean: None,
            insert: None,
            lattice: BaseCellArray::upright(period, origin),
            reach: 0.5 * Vector3::from(period).norm(),
            tilt: 0.0,
            limits,
        }
    }

    /// The microstructure in a line, for file headers.
    pub fn describe(&self) -> String {
        let shape = match self.shape {
            BaseCellShape::Sphere => "sphere",
            BaseCellShape::Box => "box",
            BaseCellShape::Cylinder => "cylinder",
        };
        let mut s = format!(
            "{shape} cells of size {} mm x [{}, {}, {}]",
            self.size.text(),
            self.aspect[0],
            self.aspect[1],
            self.aspect[2]
        );
        if let Some(t) = &self.turn {
            s.push_str(&format!(", turned {} deg", t.text()));
        }
        if let Some(l) = &self.lean {
            s.push_str(&format!(", leaning {} deg", l.text()));
        }
        if let Some(i) = &self.insert {
            s.push_str(&format!(", inserted where {} > 0", i.text()));
        }
        let l = &self.lattice;
        s.push_str(&format!(
            " on a lattice of period [{}, {}, {}] mm from [{}, {}, {}], tilted {} deg about x",
            l.period[0], l.period[1], l.period[2], l.origin[0], l.origin[1], l.origin[2], self.tilt
        ));
        s
    }

    /// The cell at an inserting point, or `None` where the inserting function leaves
    /// it out.
    fn cell(&self, p: Vector3<f64>) -> Result<Option<PlacedBaseCell>> {
        self.cell_moved(p, p, &Matrix3::identity())
    }

    /// The cell at inserting point `p` of the model's frame, placed at `at` in the
    /// build's, turned by `turned` (the model's turn) on top of its own orientation.
    fn cell_moved(
        &self,
        p: Vector3<f64>,
        at: Vector3<f64>,
        turned: &Matrix3<f64>,
    ) -> Result<Option<PlacedBaseCell>> {
        if let Some(f) = &self.insert
            && f.at(&p, "insert")? <= 0.0
        {
            return Ok(None);
        }
        let size = self.size.at(&p, "size")?;
        if size <= 0.0 {
            return Ok(None);
        }
        let half = [
            size * self.aspect[0],
            size * self.aspect[1],
            size * self.aspect[2],
        ];
        let lean = match &self.lean {
            Some(v) => v.at(&p, "lean")?.to_radians(),
            None => 0.0,
        };
        let turn = match &self.turn {
            Some(v) => v.at(&p, "turn")?.to_radians(),
            None => 0.0,
        };
        let own: Matrix3<f64> = *(Rotation3::from_axis_angle(&Vector3::z_axis(), turn)
            * Rotation3::from_axis_angle(&Vector3::x_axis(), lean))
        .matrix();
        let cell = PlacedBaseCell {
            shape: self.shape,
            centre: at,
            half,
            // The cell turns with the lattice it sits on.
            rotation: turned * self.lattice.rotation * own,
        };
        if cell.reach() > self.reach + 1e-9 {
            return Err(Error::stage(
                "cell",
                format!(
                    "the cell at ({:.3}, {:.3}, {:.3}) reaches {:.4} mm from its inserting point, more than \
                     half the lattice's diagonal ({:.4} mm): make it smaller or the period larger",
                    p.x,
                    p.y,
                    p.z,
                    cell.reach(),
                    self.reach
                ),
            ));
        }
        Ok(Some(cell))
    }

    /// The cells whose inserting points lie in the box `lo..hi`, at most about `limit`
    /// of them (every n-th, in lattice order, when there are more): what the build
    /// direction is weighed over.
    pub fn cells_in(&self, lo: [f64; 3], hi: [f64; 3], limit: usize) -> Result<Vec<PlacedBaseCell>> {
        let (lo, hi) = (Vector3::from(lo), Vector3::from(hi));
        let count = self.lattice.count_in_box(lo, hi);
        self.limits.check(
            Limit::GridSamples,
            count,
            "the base cells' lattice over the model",
        )?;
        let stride = ((count / limit.max(1) as f64).ceil() as usize).max(1);
        let mut out = Vec::new();
        let mut seen = 0usize;
        let mut failed = None;
        self.lattice.in_box(lo, hi, |_, p| {
            seen += 1;
            if (seen - 1).is_multiple_of(stride) {
                match self.cell(p) {
                    Ok(c) => out.extend(c),
                    Err(e) => {
                        failed = Some(e);
                        return false;
                    }
                }
            }
            true
        });
        match failed {
            Some(e) => Err(e),
            None => Ok(out),
        }
    }

    /// The voids the horizontal plane at `z` cuts over the box `bbox`, counter-clockwise,
    /// in the order of their inserting points.
    ///
    /// The cells are the model's: where an `[orient]` stage turned the model (`frame`),
    /// the lattice turns and moves with it, and the functions read each inserting
    /// point's coordinates in the model's own frame.
    pub fn voids(&self, z: f64, bbox: &BBox2, frame: Option<&ModelFrame>) -> Result<Vec<Contour>> {
        let (turn, offset) = match frame {
            Some(f) => (Matrix3::from_fn(|i, j| f.rotation[i][j]), Vector3::from(f.offset)),
            None => (Matrix3::identity(), Vector3::zeros()),
        };
        let lattice = self.lattice.moved(&turn, offset);
        self.limits.check(
            Limit::GridSamples,
            lattice.count_near_plane(z, self.reach, bbox),
            "the base cells' lattice points near a layer",
        )?;
        let back = turn.transpose();
        let mut out = Vec::new();
        for (_, at) in lattice.near_plane(z, self.reach, bbox) {
            let p = back * (at - offset);
            if let Some(cell) = self.cell_moved(p, at, &turn)?
                && let Some(section) = cell.section(z)
            {
                out.push(section);
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lamina_api::geom::Point2;

    fn square(lo: f64, hi: f64) -> BBox2 {
        BBox2 {
            min: Point2::new(lo, lo),
            max: Point2::new(hi, hi),
        }
    }

    /// Centre (of the bounding box) and radius (from the area) of a circular void.
    fn circle(c: &Contour) -> (f64, f64, f64) {
        let b = c.bbox();
        (
            (b.min.x + b.max.x) / 2.0,
            (b.min.y + b.max.y) / 2.0,
            (c.area() / std::f64::consts::PI).sqrt(),
        )
    }

    /// Spheres of radius 0.5 on a 2 mm lattice: a plane 0.3 mm above a row of centres
    /// cuts circles of radius 0.4 about them, counter-clockwise, in lattice order; a
    /// plane between the rows cuts nothing.
    #[test]
    fn a_plane_cuts_each_sphere_in_the_circle_of_its_chord() {
        let m = Microstructure::spheres([2.0; 3], [0.0; 3], 0.5, Limits::default());
        let voids = m.voids(0.3, &square(-0.1, 4.1), None).unwrap();
        let mut centres = Vec::new();
        for v in &voids {
            let (x, y, r) = circle(v);
            assert!(v.area() > 0.0, "counter-clockwise");
            assert!((r - 0.4).abs() < 0.004, "{r}");
            centres.push((x.round() as i64, y.round() as i64));
        }
        let mut sorted = centres.clone();
        sorted.sort_unstable();
        assert_eq!(
            sorted,
            (0..3)
                .flat_map(|i| (0..3).map(move |j| (2 * i, 2 * j)))
                .collect::<Vec<_>>()
        );
        // Through the next row's centres the whole radius; between rows nothing.
        let through = m.voids(2.0, &square(-0.1, 4.1), None).unwrap();
        assert_eq!(through.len(), 9);
        assert!(through.iter().all(|v| (circle(v).2 - 0.5).abs() < 0.005));
        assert!(m.voids(1.0, &square(-0.1, 4.1), None).unwrap().is_empty());
        assert!(m.voids(1.45, &square(-0.1, 4.1), None).unwrap().is_empty());
        // 0.45 below the next row's centres: radius sqrt(0.25 - 0.2025).
        let edge = m.voids(1.55, &square(-0.1, 4.1), None).unwrap();
        assert_eq!(edge.len(), 9);
        assert!(
            edge.iter()
                .all(|v| (circle(v).2 - 0.0475f64.sqrt()).abs() < 0.003)
        );
        // Only the cells whose inserting points lie within a cell's reach (half the
        // lattice's diagonal, 1.73 mm) of the box.
        assert_eq!(m.voids(0.3, &square(1.9, 2.1), None).unwrap().len(), 1);
        assert_eq!(m.voids(0.3, &square(1.5, 2.5), None).unwrap().len(), 9);
    }

    /// The model turned a quarter about x and moved 0.5 along x: the lattice turns and
    /// moves with it, so its spacing along the build's z is the model's y spacing.
    #[test]
    fn the_lattice_turns_and_moves_with_the_model() {
        let m = Microstructure::spheres([2.0, 3.0, 5.0], [0.0; 3], 0.5, Limits::default());
        // (x, y, z) -> (x, -z, y): the model's y is the build's z.
        let frame = ModelFrame {
            rotation: [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]],
            offset: [0.5, 0.0, 0.0],
        };
        let at = |z: f64| m.voids(z, &square(-0.2, 10.2), Some(&frame)).unwrap();
        // Centres at build z = 0, 3, 6; x = 0.5 + 2k; y = -5j.
        for z in [0.0, 3.0, 6.0] {
            let v = at(z);
            assert!(!v.is_empty(), "{z}");
            for c in &v {
                let (x, y, r) = circle(c);
                assert!(((x - 0.5) / 2.0 - ((x - 0.5) / 2.0).round()).abs() < 1e-3, "{x}");
                assert!((y / 5.0 - (y / 5.0).round()).abs() < 1e-3, "{y}");
                assert!((r - 0.5).abs() < 0.005, "{r}");
            }
        }
        assert!(at(1.5).is_empty());
        assert!(at(5.0).is_empty());
        // Unturned, the spacing along z is 5.
        assert!(!m.voids(5.0, &square(-0.2, 10.2), None).unwrap().is_empty());
        assert!(m.voids(3.0, &square(-0.2, 10.2), None).unwrap().is_empty());
    }

    #[test]
    fn a_cell_reaching_past_half_the_lattice_diagonal_is_refused() {
        // Half the diagonal of a 2 mm lattice: 1.732 mm.
        let fits = Microstructure::spheres([2.0; 3], [0.0; 3], 1.73, Limits::default());
        assert!(fits.voids(0.0, &square(-0.1, 0.1), None).is_ok());
        // Exactly half the diagonal still fits.
        let exact = Microstructure::spheres([2.0; 3], [0.0; 3], 0.5 * 12f64.sqrt(), Limits::default());
        assert!(exact.voids(0.0, &square(-0.1, 0.1), None).is_ok());
        let big = Microstructure::spheres([2.0; 3], [0.0; 3], 1.74, Limits::default());
        let e = big.voids(0.0, &square(-0.1, 0.1), None).unwrap_err().to_string();
        assert!(
            e.contains("reaches 1.7400 mm") && e.contains("(1.7321 mm)"),
            "{e}"
        );
        // A cell of no size is no void.
        let none = Microstructure::spheres([2.0; 3], [0.0; 3], 0.0, Limits::default());
        assert!(none.voids(0.0, &square(-0.1, 4.1), None).unwrap().is_empty());
    }

    #[test]
    fn the_lattice_points_are_counted_against_the_limits_first() {
        let limits = Limits {
            grid_samples: 8,
            ..Limits::default()
        };
        let m = Microstructure::spheres([1.0; 3], [0.0; 3], 0.3, limits);
        // 3 x 3 points near the plane fit, 11 x 11 do not.
        assert_eq!(m.voids(0.0, &square(-0.1, 1.1), None).map(|v| v.len()).ok(), None);
        let small = Microstructure::spheres(
            [1.0; 3],
            [0.0; 3],
            0.3,
            Limits {
                grid_samples: 100,
                ..limits
            },
        );
        assert_eq!(small.voids(0.0, &square(-0.1, 1.1), None).unwrap().len(), 4);
        let e = m.voids(0.0, &square(-0.1, 10.1), None).unwrap_err().to_string();
        assert!(e.contains("lattice points near a layer"), "{e}");
        let e = m.cells_in([0.0; 3], [10.0; 3], 5).unwrap_err().to_string();
        assert!(e.contains("lattice over the model"), "{e}");
    }

    /// Every n-th cell of the box when it holds more than the limit asks.
    #[test]
    fn cells_in_a_box_are_thinned_to_about_the_limit() {
        let m = Microstructure::spheres([1.0; 3], [0.0; 3], 0.3, Limits::default());
        // 3 x 3 x 3 = 27 points.
        let all = m.cells_in([0.0; 3], [2.0; 3], 100).unwrap();
        assert_eq!(all.len(), 27);
        assert!(
            all.iter()
                .all(|c| c.half == [0.3; 3] && c.shape == BaseCellShape::Sphere)
        );
        // At most 10: every third.
        let some = m.cells_in([0.0; 3], [2.0; 3], 10).unwrap();
        assert_eq!(some.len(), 9);
        assert_eq!(some[0].centre, all[0].centre);
        assert_eq!(some[1].centre, all[3].centre);
        assert_eq!(m.cells_in([0.0; 3], [2.0; 3], 0).unwrap().len(), 1);
    }

    #[test]
    fn the_description_names_the_cells_and_their_lattice() {
        let m = Microstructure::spheres([2.0, 3.0, 4.0], [0.5, 0.0, -1.0], 0.25, Limits::default());
        assert_eq!(
            m.describe(),
            "sphere cells of size 0.25 mm x [1, 1, 1] on a lattice of period [2, 3, 4] mm \
             from [0.5, 0, -1], tilted 0 deg about x"
        );
    }
}
