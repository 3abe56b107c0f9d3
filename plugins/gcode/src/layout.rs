//! Where things go on the bed: the parts (moved by the machine's placement), the wipe
//! tower beside them, the skirt around both, and a prime line per head along the
//! front (or back) edge, each checked to lie on the bed and clear of the others.
//!
//! Without a machine there is no bed: the parts keep the plan's coordinates unless
//! some are negative, in which case they move so that their bounding box starts at
//! [`UNPLACED_MARGIN`] on both axes, and the header says so.

use lamina_api::machine::{Bed, BedShape, PrimeLine, Skirt, WipeTower};
use lamina_api::{BBox2, Error, Point2, Result, RunInfo, Vector2};

use crate::setup::Setup;
use crate::text::clean;

/// Without a machine, negative plans move here (mm from the origin on X and Y).
pub const UNPLACED_MARGIN: f64 = 10.0;
/// Gap between the parts and the wipe tower (mm).
const TOWER_GAP: f64 = 5.0;
/// Prime lines keep this far from the bed's edges (mm).
const PRIME_EDGE: f64 = 5.0;
/// Room kept between the prime lines and anything else (mm).
const CLEARANCE: f64 = 2.0;

/// Everything placed on the bed, in machine coordinates.
#[derive(Debug, Clone)]
pub struct Layout {
    /// Added to the plan's coordinates.
    pub offset: Vector2,
    /// The parts' XY bounding box, placed.
    pub parts: BBox2,
    pub tower: Option<BBox2>,
    /// Skirt loops, innermost first, each closed (last point = first).
    pub skirt: Vec<Vec<Point2>>,
    /// One line per head to prime, in priming order.
    pub prime_lines: Vec<(Point2, Point2)>,
    /// What was done to the coordinates, for the header.
    pub note: String,
}

impl Layout {
    /// Bounding box of everything printed.
    pub fn printed(&self) -> BBox2 {
        let mut b = self.parts;
        if let Some(t) = self.tower {
            b = b.union(&t);
        }
        for l in &self.skirt {
            b = b.union(&BBox2::from_points(l.iter().copied()));
        }
        for (a, c) in &self.prime_lines {
            b = b.union(&BBox2::from_points([*a, *c]));
        }
        b
    }
}

fn grow(b: &BBox2, d: f64) -> BBox2 {
    BBox2 {
        min: b.min - Vector2::new(d, d),
        max: b.max + Vector2::new(d, d),
    }
}

fn describe(b: &BBox2) -> String {
    format!(
        "X {:.1}..{:.1}, Y {:.1}..{:.1}",
        b.min.x, b.max.x, b.min.y, b.max.y
    )
}

/// Places the parts, and the tower, skirt and prime lines the setup asks for;
/// `tower` says whether the run needs a tower, `primed` how many heads are primed.
pub fn plan(
    setup: &Setup,
    info: &RunInfo,
    machine_error: &dyn Fn(String) -> Error,
    tower: bool,
    primed: usize,
) -> Result<Layout> {
    let bounds = info.xy_bounds;
    let Some(bed) = setup.bed.filter(|_| setup.placed) else {
        return Ok(unplaced(bounds));
    };
    let machine = setup.machine.as_deref().unwrap_or("?");
    let offset = match &info.machine {
        Some(m) => m.placement_offset(&bounds),
        None => Vector2::zeros(),
    };
    let parts = moved(&bounds, offset);
    let w = setup.line_width();
    let skirt_reach = setup.skirt.map_or(0.0, |s| s.distance + s.loops as f64 * w);
    let room = Room {
        bed: &bed,
        parts,
        skirt_reach,
        machine_error,
    };

    // Prime lines first: along the front edge, or the back one if the parts are there.
    let prime_lines = match setup.prime_line.filter(|_| primed > 0) {
        None => Vec::new(),
        Some(p) => room.prime_lines(p, primed)?,
    };
    let prime_box = (!prime_lines.is_empty()).then(|| {
        grow(
            &band_box(&prime_lines, setup.prime_line.map_or(0.0, |p| p.width)),
            CLEARANCE,
        )
    });

    let tower_box = match setup.wipe_tower.filter(|_| tower) {
        None => None,
        Some(t) => Some(room.tower(t, prime_box)?),
    };

    let mut around = parts;
    if let Some(t) = tower_box {
        around = around.union(&t);
    }
    let skirt: Vec<Vec<Point2>> = match setup.skirt {
        None => Vec::new(),
        Some(s) => skirt_loops(s, &around, w),
    };
    if let Some(outer) = skirt.last() {
        let b = BBox2::from_points(outer.iter().copied());
        if !bed.contains_box(&b, 0.0) || prime_box.is_some_and(|p| p.overlaps(&b)) {
            return Err(machine_error(format!(
                "the skirt ({}) does not fit on the {} bed beside the prime lines: lower skirt.distance or \
                 switch it off with `skirt = false` in [machine]",
                describe(&b),
                bed.describe()
            )));
        }
    }
    if let Some(t) = tower_box
        && !bed.contains_box(&t, 0.0)
    {
        return Err(machine_error(format!(
            "the wipe tower ({}) is not on the {} bed",
            describe(&t),
            bed.describe()
        )));
    }
    Ok(Layout {
        offset,
        parts,
        tower: tower_box,
        skirt,
        prime_lines,
        note: format!(
            "placed on the bed of machine `{}` by X{:+.3} Y{:+.3}",
            clean(machine),
            offset.x,
            offset.y
        ),
    })
}

/// Without a machine: the plan's coordinates, moved only off negative ones.
fn unplaced(bounds: BBox2) -> Layout {
    let offset = if bounds.is_empty() || (bounds.min.x >= 0.0 && bounds.min.y >= 0.0) {
        Vector2::zeros()
    } else {
        Vector2::new(
            (UNPLACED_MARGIN - bounds.min.x).max(0.0),
            (UNPLACED_MARGIN - bounds.min.y).max(0.0),
        )
    };
    let note = if offset == Vector2::zeros() {
        "the plan's coordinates (no machine profile)".to_string()
    } else {
        format!(
            "the plan's coordinates moved by X{:+.3} Y{:+.3} so that none is negative (no machine profile)",
            offset.x, offset.y
        )
    };
    Layout {
        offset,
        parts: moved(&bounds, offset),
        tower: None,
        skirt: Vec::new(),
        prime_lines: Vec::new(),
        note,
    }
}

/// The bed with the parts placed on it: what the prime lines and the tower are fitted
/// around, and how a misfit is reported.
struct Room<'a> {
    bed: &'a Bed,
    /// The parts' bounding box, placed.
    parts: BBox2,
    /// How far the skirt reaches beyond what it surrounds (mm).
    skirt_reach: f64,
    machine_error: &'a dyn Fn(String) -> Error,
}

impl Room<'_> {
    /// A prime line per primed head, along the front edge, or the back one if the parts
    /// (and their skirt) take the front.
    fn prime_lines(&self, p: PrimeLine, primed: usize) -> Result<Vec<(Point2, Point2)>> {
        let (bed, parts) = (self.bed, &self.parts);
        let keep_clear = grow(parts, self.skirt_reach + CLEARANCE);
        let front = prime_band(bed, p.length, p.width, primed, false);
        let back = prime_band(bed, p.length, p.width, primed, true);
        let fits = |lines: &Option<Vec<(Point2, Point2)>>| {
            lines.as_ref().is_some_and(|l| {
                !band_box(l, p.width).overlaps(&keep_clear)
                    && l.iter()
                        .all(|(a, b)| bed.contains(*a, 0.0) && bed.contains(*b, 0.0))
            })
        };
        if fits(&front) {
            Ok(front.unwrap_or_default())
        } else if fits(&back) {
            Ok(back.unwrap_or_default())
        } else {
            Err((self.machine_error)(format!(
                "no room for the prime lines along the front or back of the {} bed, the parts take {}: \
                 switch them off with `prime_line = false` in [machine]",
                bed.describe(),
                describe(parts)
            )))
        }
    }

    /// The wipe tower's footprint: where the profile puts it (clear of the parts), or
    /// the first side of the parts where it fits on the bed, with its skirt, clear of
    /// the prime lines (`prime_box`).
    fn tower(&self, t: WipeTower, prime_box: Option<BBox2>) -> Result<BBox2> {
        let (bed, parts, skirt_reach) = (self.bed, &self.parts, self.skirt_reach);
        let [tw, td] = t.size;
        let inside = |b: &BBox2| {
            bed.contains_box(&grow(b, skirt_reach), 0.0)
                && prime_box.is_none_or(|p| !grow(b, skirt_reach).overlaps(&p))
        };
        match t.position {
            Some([x, y]) => {
                let b = BBox2 {
                    min: Point2::new(x, y),
                    max: Point2::new(x + tw, y + td),
                };
                if b.overlaps(&grow(parts, CLEARANCE)) {
                    return Err((self.machine_error)(format!(
                        "the wipe tower at {} overlaps the parts placed at {}: move wipe_tower.position, \
                         or leave it out to place the tower beside the parts",
                        describe(&b),
                        describe(parts)
                    )));
                }
                Ok(b)
            }
            None => {
                let c = parts.center();
                let candidates = [
                    Point2::new(parts.max.x + TOWER_GAP, c.y - td / 2.0),
                    Point2::new(c.x - tw / 2.0, parts.max.y + TOWER_GAP),
                    Point2::new(parts.min.x - TOWER_GAP - tw, c.y - td / 2.0),
                    Point2::new(c.x - tw / 2.0, parts.min.y - TOWER_GAP - td),
                ];
                let found = candidates
                    .iter()
                    .map(|p| BBox2 {
                        min: *p,
                        max: *p + Vector2::new(tw, td),
                    })
                    .find(|b| inside(b));
                found.ok_or_else(|| {
                    (self.machine_error)(format!(
                        "no room for the {tw} x {td} mm wipe tower beside the parts ({}) on the {} bed: \
                         give wipe_tower.position, make the tower smaller, or place the parts elsewhere",
                        describe(parts),
                        bed.describe()
                    ))
                })
            }
        }
    }
}

/// The skirt's loops around `around` (the parts and the tower), innermost first, each
/// closed, a line width `w` apart.
fn skirt_loops(s: Skirt, around: &BBox2, w: f64) -> Vec<Vec<Point2>> {
    (0..s.loops)
        .map(|i| {
            let b = grow(around, s.distance + (i as f64 + 0.5) * w);
            vec![
                b.min,
                Point2::new(b.max.x, b.min.y),
                b.max,
                Point2::new(b.min.x, b.max.y),
                b.min,
            ]
        })
        .collect()
}

fn moved(b: &BBox2, offset: Vector2) -> BBox2 {
    if b.is_empty() {
        return *b;
    }
    BBox2 {
        min: b.min + offset,
        max: b.max + offset,
    }
}

/// Bounding box of prime lines with their width.
fn band_box(lines: &[(Point2, Point2)], width: f64) -> BBox2 {
    grow(
        &BBox2::from_points(lines.iter().flat_map(|(a, b)| [*a, *b])),
        width / 2.0,
    )
}

/// `count` parallel prime lines along the front (or back) edge of the bed, each as long
/// as `length` or the bed allows; `None` when the bed is too small.
fn prime_band(bed: &Bed, length: f64, width: f64, count: usize, back: bool) -> Option<Vec<(Point2, Point2)>> {
    let b = bed.bounds();
    let pitch = width + 1.0;
    (0..count)
        .map(|k| {
            let inset = PRIME_EDGE + k as f64 * pitch;
            let y = if back { b.max.y - inset } else { b.min.y + inset };
            let (x0, x1) = match bed.shape {
                BedShape::Rectangle { .. } => {
                    let x0 = b.min.x + PRIME_EDGE * 2.0;
                    (x0, (x0 + length).min(b.max.x - PRIME_EDGE * 2.0))
                }
                BedShape::Circle { diameter } => {
                    let r = diameter / 2.0;
                    let dy = y - b.center().y;
                    let half = (r * r - dy * dy).max(0.0).sqrt() - PRIME_EDGE;
                    let half = half.min(length / 2.0);
                    (b.center().x - half, b.center().x + half)
                }
            };
            // Alternate directions so that each line starts where the last ended.
            (x1 - x0 >= 10.0).then(|| {
                if k.is_multiple_of(2) {
                    (Point2::new(x0, y), Point2::new(x1, y))
                } else {
                    (Point2::new(x1, y), Point2::new(x0, y))
                }
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prime_lines_stay_on_a_round_bed() {
        let bed = Bed {
            shape: BedShape::Circle { diameter: 200.0 },
            origin: lamina_api::machine::BedOrigin::Centre,
            max_height: 200.0,
        };
        let lines = prime_band(&bed, 80.0, 0.6, 2, false).expect("room");
        for (a, b) in &lines {
            assert!(bed.contains(*a, 0.0) && bed.contains(*b, 0.0));
            assert!(a.y < -90.0);
        }
        assert!(
            prime_band(
                &Bed {
                    shape: BedShape::Rectangle { size: [12.0, 100.0] },
                    ..bed
                },
                80.0,
                0.6,
                1,
                false
            )
            .is_none()
        );
    }
}
