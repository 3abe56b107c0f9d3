//! The wipe tower: a small block beside the parts, one layer of it on every layer
//! while tools or mixes still change, that takes the purge of each change.
//!
//! Each tower layer has a perimeter and rows of lines inside it, along X on even
//! layers and along Y on odd ones so that each layer bridges the one below. Purges fill
//! the rows in a serpentine from where the last purge of the layer stopped, exactly
//! the volume asked for; after the layer's last change the rows left are filled
//! sparsely (densely on the first layer, which must hold to the bed) so the next layer
//! has something to stand on.

use lamina_api::{BBox2, Error, Point2, Result};

/// Every how many rows a sparse tower layer lays a line.
const SPARSE_STEP: usize = 6;

/// What a stroke is, for the `;TYPE:` comment before it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Feature {
    Part,
    Skirt,
    Prime,
    Tower,
    Purge,
}

impl Feature {
    pub fn name(self) -> &'static str {
        match self {
            Feature::Part => "PART",
            Feature::Skirt => "SKIRT",
            Feature::Prime => "PRIME",
            Feature::Tower => "TOWER",
            Feature::Purge => "PURGE",
        }
    }
}

/// A polyline to extrude at the tower's line width.
#[derive(Debug, Clone, PartialEq)]
pub struct Stroke {
    pub points: Vec<Point2>,
    pub feature: Feature,
}

/// The layer of the tower being built.
#[derive(Debug, Clone)]
struct Level {
    z: f64,
    height: f64,
    /// Rows run along X (else along Y).
    along_x: bool,
    rows: usize,
    /// Row the serpentine is in, and how far along it (mm).
    row: usize,
    along: f64,
    perimeter: bool,
    finished: bool,
    dense: bool,
    /// Volume purged on this level (mm³), for messages.
    purged: f64,
}

/// The tower and the level being built.
#[derive(Debug, Clone)]
pub struct Tower {
    rect: BBox2,
    width: f64,
    level: Option<Level>,
    /// Top of the highest level begun (mm).
    top: f64,
    levels: usize,
}

impl Tower {
    /// A tower on `rect` printed with lines `width` wide.
    pub fn new(rect: BBox2, width: f64) -> Self {
        Self {
            rect,
            width,
            level: None,
            top: 0.0,
            levels: 0,
        }
    }

    pub fn rect(&self) -> BBox2 {
        self.rect
    }

    /// Levels begun so far.
    pub fn levels(&self) -> usize {
        self.levels
    }

    /// Starts the level whose top is at `z`, unless the current level is at `z` already
    /// (several deposits at one height share a level).
    pub fn begin(&mut self, z: f64) {
        if self.level.as_ref().is_some_and(|l| (l.z - z).abs() < 1e-6) || z <= self.top + 1e-6 {
            return;
        }
        let height = z - self.top;
        let along_x = self.levels.is_multiple_of(2);
        let across = if along_x {
            self.rect.height()
        } else {
            self.rect.width()
        };
        let w = self.width;
        let rows = ((across - 2.0 * w) / w).floor().max(0.0) as usize;
        self.level = Some(Level {
            z,
            height,
            along_x,
            rows,
            row: 0,
            along: 0.0,
            perimeter: false,
            finished: false,
            dense: self.levels == 0,
            purged: 0.0,
        });
        self.top = z;
        self.levels += 1;
    }

    /// Height of the current level (mm).
    pub fn height(&self) -> f64 {
        self.level.as_ref().map_or(0.0, |l| l.height)
    }

    /// Whether the current level has been begun and not yet finished.
    pub fn open(&self) -> bool {
        self.level.as_ref().is_some_and(|l| !l.finished)
    }

    /// Length of one row's line, and where row `r` starts (alternating ends).
    fn row_geometry(&self, l: &Level) -> (f64, f64, f64) {
        let w = self.width;
        let (lo, hi) = if l.along_x {
            (self.rect.min.x, self.rect.max.x)
        } else {
            (self.rect.min.y, self.rect.max.y)
        };
        (lo + 1.5 * w, hi - 1.5 * w, hi - lo - 3.0 * w)
    }

    /// The point `along` mm into row `r` of level `l`.
    fn point(&self, l: &Level, r: usize, along: f64) -> Point2 {
        let w = self.width;
        let (start, end, _) = self.row_geometry(l);
        let t = if r.is_multiple_of(2) {
            start + along
        } else {
            end - along
        };
        let across = if l.along_x {
            self.rect.min.y + w + (r as f64 + 0.5) * w
        } else {
            self.rect.min.x + w + (r as f64 + 0.5) * w
        };
        if l.along_x {
            Point2::new(t, across)
        } else {
            Point2::new(across, t)
        }
    }

    fn perimeter(&self) -> Stroke {
        let h = self.width / 2.0;
        let (a, b) = (self.rect.min, self.rect.max);
        Stroke {
            points: vec![
                Point2::new(a.x + h, a.y + h),
                Point2::new(b.x - h, a.y + h),
                Point2::new(b.x - h, b.y - h),
                Point2::new(a.x + h, b.y - h),
                Point2::new(a.x + h, a.y + h),
            ],
            feature: Feature::Tower,
        }
    }

    /// Strokes that deposit `volume` mm³ of purge on the current level (after its
    /// perimeter, on the first visit). Fails when the level is full.
    pub fn purge(&mut self, volume: f64) -> Result<Vec<Stroke>> {
        let Some(mut l) = self.level.take() else {
            return Ok(Vec::new());
        };
        let result = self.purge_level(&mut l, volume);
        self.level = Some(l);
        result
    }

    fn purge_level(&self, l: &mut Level, volume: f64) -> Result<Vec<Stroke>> {
        let mut out = Vec::new();
        if !l.perimeter {
            out.push(self.perimeter());
            l.perimeter = true;
        }
        if volume <= 0.0 {
            return Ok(out);
        }
        let w = self.width;
        let (_, _, row_length) = self.row_geometry(l);
        let mut need = volume / (w * l.height);
        let mut points = vec![self.point(l, l.row, l.along)];
        while need > 1e-9 {
            if l.row >= l.rows || row_length <= 0.0 {
                let capacity = l.rows as f64 * (row_length + w) * w * l.height;
                return Err(Error::stage(
                    crate::STAGE,
                    format!(
                        "the {:.0} x {:.0} mm wipe tower is full at z = {:.3} mm: its {:.3} mm level holds \
                         about {capacity:.0} mm³ of purge and this layer's changes need {:.0} mm³; make \
                         [machine] wipe_tower.size larger, or lower the purge volume",
                        self.rect.width(),
                        self.rect.height(),
                        l.z,
                        l.height,
                        l.purged + volume
                    ),
                ));
            }
            let left = row_length - l.along;
            if need <= left {
                l.along += need;
                need = 0.0;
                points.push(self.point(l, l.row, l.along));
            } else {
                need -= left;
                points.push(self.point(l, l.row, row_length));
                l.row += 1;
                l.along = 0.0;
                if l.row < l.rows {
                    // The step to the next row is part of the purge.
                    points.push(self.point(l, l.row, 0.0));
                    need = (need - w).max(0.0);
                }
            }
        }
        l.purged += volume;
        out.push(Stroke {
            points,
            feature: Feature::Purge,
        });
        Ok(out)
    }

    /// Completes the current level: its perimeter if no purge laid it, and the rows no
    /// purge used, sparsely (densely on the first level).
    pub fn finish(&mut self) -> Vec<Stroke> {
        let Some(mut l) = self.level.take() else {
            return Vec::new();
        };
        let mut out = Vec::new();
        if !l.finished {
            if !l.perimeter {
                out.push(self.perimeter());
                l.perimeter = true;
            }
            let first = if l.along > 0.0 { l.row + 1 } else { l.row };
            let step = if l.dense { 1 } else { SPARSE_STEP };
            let rows: Vec<usize> = (first..l.rows).step_by(step).collect();
            let (_, _, row_length) = self.row_geometry(&l);
            if !rows.is_empty() && row_length > 0.0 {
                let mut points = Vec::new();
                for (i, &r) in rows.iter().enumerate() {
                    // Serpentine over the chosen rows: every other one runs backward.
                    // `point` measures along a row from its own start, which is at the
                    // far end on odd rows.
                    let from_start = |at: f64| if r.is_multiple_of(2) { at } else { row_length - at };
                    let (a, b) = if i.is_multiple_of(2) {
                        (0.0, row_length)
                    } else {
                        (row_length, 0.0)
                    };
                    points.push(self.point(&l, r, from_start(a)));
                    points.push(self.point(&l, r, from_start(b)));
                }
                out.push(Stroke {
                    points,
                    feature: Feature::Tower,
                });
            }
            l.finished = true;
        }
        self.level = Some(l);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tower() -> Tower {
        Tower::new(
            BBox2 {
                min: Point2::new(100.0, 50.0),
                max: Point2::new(130.0, 70.0),
            },
            0.5,
        )
    }

    fn length(s: &Stroke) -> f64 {
        s.points.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
    }

    #[test]
    fn purges_deposit_exactly_their_volume_inside_the_tower() {
        let mut t = tower();
        t.begin(0.2);
        let first = t.purge(40.0).expect("fits");
        assert_eq!(first[0].feature, Feature::Tower, "perimeter first");
        let purge = &first[1];
        assert!((length(purge) * 0.5 * 0.2 - 40.0).abs() < 1e-9);
        let second = t.purge(25.0).expect("fits");
        assert_eq!(second.len(), 1, "no second perimeter");
        assert!((length(&second[0]) * 0.5 * 0.2 - 25.0).abs() < 1e-9);
        assert_eq!(
            second[0].points[0],
            *purge.points.last().expect("end"),
            "continues where it stopped"
        );
        for s in first.iter().chain(&second) {
            for p in &s.points {
                assert!(p.x > 100.0 && p.x < 130.0 && p.y > 50.0 && p.y < 70.0, "{p:?}");
            }
        }
        let rest = t.finish();
        assert_eq!(rest.len(), 1);
        assert!(t.purge(1000.0).is_err(), "a full level refuses more");
    }

    #[test]
    fn levels_alternate_and_share_a_height() {
        let mut t = tower();
        t.begin(0.2);
        t.finish();
        t.begin(0.2);
        assert_eq!(t.levels(), 1, "same height, same level");
        t.begin(0.4);
        assert_eq!(t.levels(), 2);
        assert!((t.height() - 0.2).abs() < 1e-12);
        let s = t.finish();
        // Perimeter and sparse rows along Y.
        let rows = &s[1].points;
        assert!((rows[0].x - rows[1].x).abs() < 1e-12);
    }
}
