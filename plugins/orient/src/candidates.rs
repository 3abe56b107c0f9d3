//! `candidates`: weighs build directions and picks the one that minimises the chosen
//! criterion: the summed area x angle of the surfaces with the build direction (the
//! CMPM paper's sum A_i alpha_i: walls parallel to the build direction take thick layers
//! without stair steps), the same sum over the main surfaces of a microstructure's base
//! cells (`base-cell`: the paper's Σ∫ A_i α_i, the cells' faces parallel to the build
//! direction let its layers be thicker), or the build height (fewer layers).
//!
//! Candidates are the six axis directions, the normals of the largest flat faces (both
//! ways), an even Fibonacci sampling of the sphere, and any the pipeline lists. Ties
//! go to the lower build height or the smaller surface angle, then to the larger flat
//! base on the bed, then to the earlier candidate (+z first: no turn at all).

use lamina_api::stage::{AnyStage, Orienter, StageConfig, StageInfo, StageKind};
use lamina_api::{Error, Mesh, Orientation, OrientationCandidate, Result, StageFactory};
use nalgebra::{Rotation3, Unit, Vector3};
use serde::Deserialize;

use crate::surfaces::{Facet, bed_contact, facets, flat_faces, height, surface_angle};
use lamina_fgm::microstructure::{BaseCellSpec, Microstructure};

lamina_api::option_type!(Criterion = "string");

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
enum Criterion {
    SurfaceAngle,
    BaseCell,
    Height,
}

impl Criterion {
    fn name(self) -> &'static str {
        match self {
            Criterion::SurfaceAngle => "surface-angle",
            Criterion::BaseCell => "base-cell",
            Criterion::Height => "height",
        }
    }
}

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// what to minimise: "surface-angle" (sum A_i alpha_i over the object's surfaces), "base-cell" (the same over the faces of the microstructure's base cells) or "height"
        criterion: Criterion = r#""surface-angle""#,
        /// the base cell for "base-cell", in the model's own coordinates (as `engrave` and `bitmap` read theirs: the cells turn with the model): `{ shape = "box" | "cylinder", size, aspect, turn, lean, insert, period, origin, tilt }` (formerly `cell`)
        #[formerly("cell")]
        base_cell: Option<BaseCellSpec>,
        /// most base cells weighed for "base-cell" (every n-th inserting point in the model's box beyond that) (formerly `cells`)
        #[range(1, 1e6)]
        #[formerly("cells")]
        base_cells: usize = "2000",
        /// directions sampled evenly over the sphere
        #[range(0, MAX_SAMPLES)]
        samples: usize = "64",
        /// the largest flat faces whose normals are candidates (both ways)
        #[range(0, 1000)]
        faces: usize = "8",
        /// share of the area, largest flat faces first, that the surface angle counts
        #[range(0.001, 1.0)]
        main_surfaces: f64 = "1.0",
        /// more candidate directions
        #[range(-1e6, 1e6)]
        directions: Vec<[f64; 3]> = "[]",
    }
}

struct Candidates {
    criterion: Criterion,
    base_cells: Option<(Microstructure, usize)>,
    samples: usize,
    faces: usize,
    main_surfaces: f64,
    directions: Vec<Vector3<f64>>,
}

/// Directions closer than this (radians, about 0.06°) are one candidate.
const SAME_DIRECTION: f64 = 1e-3;

/// `n` directions spread evenly over the sphere (a Fibonacci lattice).
fn fibonacci_sphere(n: usize) -> Vec<Vector3<f64>> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = golden * i as f64;
            Vector3::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect()
}

/// The rotation that takes `d` to +z (half a turn about x when `d` points down).
fn rotation_to_up(d: &Vector3<f64>) -> Rotation3<f64> {
    let up = Vector3::z();
    Rotation3::rotation_between(d, &up).unwrap_or_else(|| {
        if d.z > 0.0 {
            Rotation3::identity()
        } else {
            Rotation3::from_axis_angle(&Unit::new_unchecked(Vector3::x()), std::f64::consts::PI)
        }
    })
}

impl Candidates {
    /// Every candidate direction with its label, duplicates merged (first label kept).
    fn directions(&self, faces: &[Facet]) -> Vec<(Vector3<f64>, String)> {
        let mut out: Vec<(Vector3<f64>, String)> = Vec::new();
        let mut push = |d: Vector3<f64>, label: String| {
            let len = d.norm();
            if !(len.is_finite() && len > 0.0) {
                return;
            }
            let d = d / len;
            if out.iter().all(|(e, _)| e.angle(&d) > SAME_DIRECTION) {
                out.push((d, label));
            }
        };
        for (d, l) in [
            (Vector3::z(), "+z"),
            (-Vector3::z(), "-z"),
            (Vector3::x(), "+x"),
            (-Vector3::x(), "-x"),
            (Vector3::y(), "+y"),
            (-Vector3::y(), "-y"),
        ] {
            push(d, l.to_string());
        }
        for (i, d) in self.directions.iter().enumerate() {
            push(*d, format!("directions.{i}"));
        }
        for (i, f) in faces.iter().take(self.faces).enumerate() {
            // Standing on the face (its normal down) and the other way up.
            push(-f.normal, format!("face {i} down"));
            push(f.normal, format!("face {i} up"));
        }
        for (i, d) in fibonacci_sphere(self.samples).into_iter().enumerate() {
            push(d, format!("sample {i}"));
        }
        out
    }
}

impl Orienter for Candidates {
    fn orient(&self, meshes: &[&Mesh]) -> Result<Orientation> {
        let all = facets(meshes);
        if all.is_empty() {
            return Err(Error::stage(
                "orient:candidates",
                "the model has no facet with an area",
            ));
        }
        // The base cells' faces, over the cells inserted in the model's box.
        let cell_faces: Vec<Facet> = match &self.base_cells {
            Some((m, limit)) => {
                let b = meshes
                    .iter()
                    .fold(lamina_api::BBox3::EMPTY, |b, m| b.union(&m.bbox()));
                let (lo, hi) = (b.min.coords, b.max.coords);
                let cells = m.cells_in([lo.x, lo.y, lo.z], [hi.x, hi.y, hi.z], *limit)?;
                if cells.is_empty() {
                    return Err(Error::stage(
                        "orient:candidates",
                        "the base-cell criterion found no cell in the model's box (is the lattice's \
                         origin or the inserting function right?): nothing to weigh",
                    ));
                }
                cells
                    .iter()
                    .flat_map(|c| c.facets())
                    .map(|(area, normal)| Facet { area, normal })
                    .collect()
            }
            None => Vec::new(),
        };
        let mut faces = flat_faces(&all);
        if self.criterion == Criterion::BaseCell {
            // The cells' main faces are the natural directions.
            faces = flat_faces(&cell_faces);
        }
        // The main surfaces: all facets, or the largest flat faces that make up the
        // asked share of the area.
        let surfaces: Vec<Facet> = if self.main_surfaces >= 1.0 {
            all
        } else {
            let total: f64 = faces.iter().map(|f| f.area).sum();
            let mut acc = 0.0;
            faces
                .iter()
                .take_while(|f| {
                    let take = acc < self.main_surfaces * total;
                    acc += f.area;
                    take
                })
                .copied()
                .collect()
        };
        let size = meshes
            .iter()
            .fold(lamina_api::BBox3::EMPTY, |b, m| b.union(&m.bbox()))
            .size()
            .norm();
        let tol = (size * 1e-6).max(1e-9);
        struct Scored {
            candidate: OrientationCandidate,
            contact: f64,
        }
        let mut scored: Vec<Scored> = self
            .directions(&faces)
            .into_iter()
            .map(|(d, label)| {
                let sa = surface_angle(&surfaces, &d);
                let h = height(meshes, &d);
                let cost = match self.criterion {
                    Criterion::SurfaceAngle => sa,
                    Criterion::BaseCell => surface_angle(&cell_faces, &d),
                    Criterion::Height => h,
                };
                Scored {
                    candidate: OrientationCandidate {
                        direction: [d.x, d.y, d.z],
                        label,
                        cost,
                        height: h,
                        surface_angle: sa,
                    },
                    contact: 0.0,
                }
            })
            .collect();
        // Costs equal to a relative 1e-9 are ties.
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1e-12);
        let best_cost = scored
            .iter()
            .map(|s| s.candidate.cost)
            .fold(f64::INFINITY, f64::min);
        for s in scored.iter_mut().filter(|s| close(s.candidate.cost, best_cost)) {
            let [x, y, z] = s.candidate.direction;
            s.contact = bed_contact(meshes, &Vector3::new(x, y, z), tol);
        }
        let criterion = self.criterion;
        // A stable sort keeps the candidates' order among full ties.
        scored.sort_by(|a, b| {
            let (ca, cb) = (&a.candidate, &b.candidate);
            if !close(ca.cost, cb.cost) {
                return ca.cost.total_cmp(&cb.cost);
            }
            let (sa, sb) = match criterion {
                Criterion::SurfaceAngle | Criterion::BaseCell => (ca.height, cb.height),
                Criterion::Height => (ca.surface_angle, cb.surface_angle),
            };
            if !close(sa, sb) {
                return sa.total_cmp(&sb);
            }
            b.contact.total_cmp(&a.contact)
        });
        let candidates: Vec<OrientationCandidate> = scored.into_iter().map(|s| s.candidate).collect();
        let [x, y, z] = candidates[0].direction;
        let r = rotation_to_up(&Vector3::new(x, y, z));
        let m = r.matrix();
        Ok(Orientation {
            criterion: criterion.name().to_string(),
            direction: [x, y, z],
            rotation: [
                [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
                [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
                [m[(2, 0)], m[(2, 1)], m[(2, 2)]],
            ],
            candidates,
        })
    }
}

/// Most directions sampled: each is measured over every triangle, and 4096 directions
/// lie about 3 degrees apart, finer than any criterion here tells apart.
const MAX_SAMPLES: usize = 4096;

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    // `samples` and `main_surfaces` are held to their declared ranges as they are read.
    let o: Options = config.parse()?;
    let mut directions = Vec::new();
    for d in &o.directions {
        let v = Vector3::new(d[0], d[1], d[2]);
        let len = v.norm();
        if !(len.is_finite() && len > 0.0) {
            return Err(config.error("directions", format!("{d:?} is not a direction")));
        }
        directions.push(v / len);
    }
    let cells = match (&o.base_cell, o.criterion) {
        (Some(spec), Criterion::BaseCell) => {
            if spec.shape == "sphere" {
                return Err(config.error(
                    "base_cell",
                    "a sphere weighs every build direction the same: the base-cell criterion needs a box or a cylinder",
                ));
            }
            if o.base_cells == 0 {
                return Err(config.error("base_cells", "must be at least 1"));
            }
            Some((Microstructure::new(spec, config, "base_cell")?, o.base_cells))
        }
        (None, Criterion::BaseCell) => {
            return Err(config.error(
                "base_cell",
                "the base-cell criterion needs the `base_cell` it weighs",
            ));
        }
        (Some(_), _) => {
            return Err(config.error("base_cell", "only the base-cell criterion reads a `base_cell`"));
        }
        (None, _) => None,
    };
    Ok(AnyStage::Orient(Box::new(Candidates {
        criterion: o.criterion,
        base_cells: cells,
        samples: o.samples,
        faces: o.faces,
        main_surfaces: o.main_surfaces,
        directions,
    })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Orient,
        name: "candidates",
        doc: "Turns the object to the candidate build direction with the least surface angle (sum of area x angle to the build direction, over the object's surfaces or its microstructure's base cells) or build height, and reports the alternatives weighed.",
        options: Options::SPECS,
        example: "use = \"candidates\"\ncriterion = \"height\"\nsamples = 16",
    },
    build,
});

#[cfg(test)]
mod tests {
    use super::*;
    use crate::surfaces::tests::cuboid;

    fn orienter(criterion: Criterion) -> Candidates {
        Candidates {
            criterion,
            base_cells: None,
            samples: 64,
            faces: 8,
            main_surfaces: 1.0,
            directions: vec![],
        }
    }

    fn apply(o: &Orientation, v: [f64; 3]) -> [f64; 3] {
        let r = o.rotation;
        [0, 1, 2].map(|i| r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2])
    }

    #[test]
    fn a_plate_is_stood_on_its_end_for_the_least_surface_angle() {
        let m = cuboid(10.0, 2.0, 1.0);
        let o = orienter(Criterion::SurfaceAngle).orient(&[&m]).expect("orients");
        assert_eq!(o.criterion, "surface-angle");
        assert!(o.direction[0].abs() > 1.0 - 1e-12, "{:?}", o.direction);
        let up = apply(&o, o.direction);
        assert!((up[2] - 1.0).abs() < 1e-12);
        // +x and -x tie on every count; +x comes first.
        assert!(o.candidates[0].label.contains('x'));
        assert!((o.candidates[0].cost - 2.0 * 2.0 * std::f64::consts::FRAC_PI_2).abs() < 1e-9);
        assert!(o.candidates.windows(2).all(|w| w[0].cost <= w[1].cost + 1e-9));
        assert!(o.candidates.len() > 6 + 64 / 2, "{}", o.candidates.len());
    }

    #[test]
    fn least_height_lays_the_plate_flat() {
        let m = cuboid(10.0, 2.0, 1.0);
        let o = orienter(Criterion::Height).orient(&[&m]).expect("orients");
        assert!(o.direction[2].abs() > 1.0 - 1e-12, "{:?}", o.direction);
        assert!((o.candidates[0].height - 1.0).abs() < 1e-12);
        assert_eq!(o.candidates[0].label, "+z", "no turn when +z is as good");
    }

    #[test]
    fn pointing_down_is_half_a_turn() {
        let r = rotation_to_up(&-Vector3::z());
        let v = r * Vector3::new(0.0, 0.0, -1.0);
        assert!((v.z - 1.0).abs() < 1e-12);
        assert!((r.matrix().determinant() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn fibonacci_directions_are_unit_and_spread() {
        let d = fibonacci_sphere(100);
        assert!(d.iter().all(|v| (v.norm() - 1.0).abs() < 1e-12));
        let mean: Vector3<f64> = d.iter().sum::<Vector3<f64>>() / 100.0;
        assert!(mean.norm() < 0.02);
    }
}
