//! The meshes of a run: loaded from their sources, checked for units and size, placed
//! on the bed, turned by an orienter, merged per part, and checked against the
//! machine's bed.

use std::sync::Arc;

use crate::diagnostic::Warning;
use crate::error::{Error, Result};
use crate::geom::{BBox2, Point2, Vector2};
use crate::mesh::{BBox3, Mesh, Vector3};
use crate::model::{ModelFrame, Orientation, PartInfo};
use crate::pipeline::{ModelSpec, Placement};
use crate::stage::{Orienter, StageKind};

use super::copies::{Instance, PartCopy};
use super::engine::Engine;
use super::report::Timings;

impl Engine {
    /// Loads and places the meshes, one entry per model stage.
    pub(super) fn load_models(&self, timings: &Timings) -> Result<Vec<Vec<Mesh>>> {
        let mut out = Vec::new();
        for m in &self.models {
            let mut meshes = timings.time(StageKind::Model, || m.source.load(&self.pipeline.base_dir))?;
            if meshes.is_empty() || meshes.iter().all(|m| m.triangles.is_empty()) {
                return Err(Error::config(format!("model {} holds no triangles", m.label)));
            }
            if !m.spec.size_given() {
                check_units(&meshes, &m.spec, &m.label)?;
            }
            place(&mut meshes, m.spec.factor(), m.spec.place);
            let bbox = meshes.iter().fold(BBox3::EMPTY, |b, m| b.union(&m.bbox()));
            let corners = [
                bbox.min.x, bbox.min.y, bbox.min.z, bbox.max.x, bbox.max.y, bbox.max.z,
            ];
            if !corners.into_iter().all(crate::limits::is_coordinate) {
                return Err(Error::config(format!(
                    "model {} reaches ({}, {}, {}) to ({}, {}, {}) mm once scaled and placed: \
                     Lamina works within ±{} mm (a kilometre) of the origin",
                    m.label,
                    short(bbox.min.x),
                    short(bbox.min.y),
                    short(bbox.min.z),
                    short(bbox.max.x),
                    short(bbox.max.y),
                    short(bbox.max.z),
                    crate::limits::MAX_COORDINATE
                )));
            }
            out.push(meshes);
        }
        Ok(out)
    }
}

/// The meshes a run slices, loaded, oriented, made once per part and checked against
/// the machine's bed.
pub(super) struct PartMeshes {
    pub meshes: Vec<Arc<Mesh>>,
    /// Each part's mesh, by index into `meshes`.
    pub part_mesh: Vec<usize>,
    pub parts_info: Vec<PartInfo>,
    pub bbox: BBox3,
    pub xy_bounds: BBox2,
    pub orientation: Option<Orientation>,
    pub model_frame: Option<ModelFrame>,
    /// What the readers repaired, for the run's diagnostics.
    pub warnings: Vec<Warning>,
    /// The parts' copies on the plate, part by part; copy `k` is part
    /// `parts_info.len() + k` of the run.
    pub copies: Vec<PartCopy>,
}

impl Engine {
    /// Every part's mesh as the run slices it: what `run` starts with and what `check`
    /// reads of the model.
    pub(super) fn part_meshes(&self, timings: &Timings) -> Result<PartMeshes> {
        let mut loaded = self.load_models(timings)?;
        let (orientation, model_frame) = match &self.orienter {
            Some(o) => {
                let (orientation, frame) =
                    timings.time(StageKind::Orient, || orient(o.as_ref(), &mut loaded))?;
                (Some(orientation), frame)
            }
            None => (None, None),
        };
        let warnings: Vec<Warning> = loaded
            .iter()
            .flatten()
            .flat_map(|m| m.warnings.iter().cloned())
            .collect();
        // Each model's box in X-Y, before its meshes are moved out: copies are laid out
        // by it, so the parts of one model move together.
        let model_boxes: Vec<BBox2> = loaded
            .iter()
            .map(|model| {
                let b = model.iter().fold(BBox3::EMPTY, |b, m| b.union(&m.bbox()));
                flat(&b)
            })
            .collect();
        // Parts taking the same mesh of the same model (told apart by `family_at`)
        // share it: it is cut once per layer. Each distinct mesh is made once, moved out
        // of the loaded models when nothing else needs it, and the loaded models are
        // dropped: a run holds each mesh once.
        let mut mesh_keys: Vec<(usize, Option<usize>)> = Vec::new();
        for p in &self.parts {
            let model = &loaded[p.model];
            if let Some(i) = p.mesh
                && i >= model.len()
            {
                return Err(Error::config(format!(
                    "part `{}` asks for mesh {i}, but its model holds {} meshes",
                    p.name,
                    model.len()
                )));
            }
            if !mesh_keys.contains(&(p.model, p.mesh)) {
                mesh_keys.push((p.model, p.mesh));
            }
        }
        let meshes: Vec<Arc<Mesh>> = (0..mesh_keys.len())
            .map(|k| {
                let (m, which) = mesh_keys[k];
                // Another key still to be made that reads this model's meshes.
                let needed_later = mesh_keys[k + 1..].iter().any(|&(o, _)| o == m);
                let mesh = match which {
                    Some(i) if needed_later => loaded[m][i].clone(),
                    Some(i) => std::mem::take(&mut loaded[m][i]),
                    None if needed_later => merge(&loaded[m], &self.models[m].label),
                    None => merge_owned(std::mem::take(&mut loaded[m]), &self.models[m].label),
                };
                Arc::new(mesh)
            })
            .collect();
        drop(loaded);
        let mut part_mesh = Vec::new();
        let mut parts_info = Vec::new();
        for p in &self.parts {
            let idx = mesh_keys
                .iter()
                .position(|&k| k == (p.model, p.mesh))
                .unwrap_or_default();
            let bb = meshes[idx].bbox();
            part_mesh.push(idx);
            parts_info.push(PartInfo {
                name: p.name.clone(),
                materials: p.materials.clone(),
                mesh: idx,
                z_min: bb.min.z,
                z_max: bb.max.z,
                z_gradient: None,
            });
        }
        let bbox = meshes.iter().fold(BBox3::EMPTY, |b, m| b.union(&m.bbox()));
        let (copies, instances) = self.plate(&model_boxes, &meshes, &part_mesh)?;
        let xy_bounds =
            instances.iter().fold(
                flat(&bbox),
                |b, i| if i.bbox.is_empty() { b } else { b.union(&i.bbox) },
            );
        if let Some(machine) = &self.pipeline.machine {
            if !copies.is_empty() {
                self.check_plate_on_bed(machine, &copies, &xy_bounds)?;
            }
            for (p, &mi) in self.parts.iter().zip(&part_mesh) {
                check_on_bed(machine, &p.name, &meshes[mi], Vector2::zeros(), &xy_bounds)?;
            }
            for c in &copies {
                let name = format!("{}#{}", self.parts[c.of].name, c.number);
                check_on_bed(machine, &name, &meshes[part_mesh[c.of]], c.offset, &xy_bounds)?;
            }
        }
        Ok(PartMeshes {
            meshes,
            part_mesh,
            parts_info,
            bbox,
            xy_bounds,
            orientation,
            model_frame,
            warnings,
            copies,
        })
    }

    /// Refuses a plate of copies larger than a rectangular bed as a whole, before any
    /// one part is found off it: the count or the gap is what to change.
    fn check_plate_on_bed(
        &self,
        machine: &crate::machine::Machine,
        copies: &[PartCopy],
        plate: &BBox2,
    ) -> Result<()> {
        let bed = &machine.bed;
        if !matches!(bed.shape, crate::machine::BedShape::Rectangle { .. }) {
            return Ok(());
        }
        let placed = super::copies::moved_box(plate, machine.placement_offset(plate));
        if bed.contains_box(&placed, 0.0) {
            return Ok(());
        }
        let mut asking: Vec<String> = Vec::new();
        for (pi, p) in self.parts.iter().enumerate() {
            let n = copies.iter().filter(|c| c.of == pi).count();
            if n > 0 {
                asking.push(format!("part `{}` and {n} copies", p.name));
            }
        }
        Err(machine.error(format!(
            "the plate ({}, {} x {} mm) does not fit the {} bed: ask for fewer copies or a smaller `copy_gap`",
            asking.join(", "),
            short(plate.width()),
            short(plate.height()),
            bed.describe()
        )))
    }

    /// The copies the parts ask for, laid out beside their models, and every instance
    /// on the plate; refuses a plate where a copy overlaps another instance.
    fn plate(
        &self,
        model_boxes: &[BBox2],
        meshes: &[Arc<Mesh>],
        part_mesh: &[usize],
    ) -> Result<(Vec<PartCopy>, Vec<Instance>)> {
        let mut copies = Vec::new();
        let mut instances: Vec<Instance> = Vec::new();
        for (pi, p) in self.parts.iter().enumerate() {
            let own = flat(&meshes[part_mesh[pi]].bbox());
            let places = super::copies::grid(&model_boxes[p.model], p.copies, p.copy_gap, p.copy_columns);
            for (k, &offset) in places.iter().enumerate() {
                let label = match k {
                    0 => format!("part `{}`", p.name),
                    _ => format!("part `{}`'s copy {}", p.name, k + 1),
                };
                let bbox = super::copies::moved_box(&own, offset);
                match instances
                    .iter_mut()
                    .find(|i| i.model == p.model && i.offset == offset)
                {
                    Some(i) => {
                        i.bbox = i.bbox.union(&bbox);
                        i.label = format!("{} and {label}", i.label);
                    }
                    None => instances.push(Instance {
                        model: p.model,
                        offset,
                        label,
                        bbox,
                    }),
                }
                if k > 0 {
                    copies.push(PartCopy {
                        of: pi,
                        number: k + 1,
                        offset,
                    });
                }
            }
        }
        super::copies::check_apart(&instances)?;
        Ok((copies, instances))
    }

    /// Reads the model as a run would (every file parsed, the meshes placed, oriented
    /// and checked against the machine's bed) without slicing: `lamina check`'s view of
    /// the parts, a line each.
    pub fn check_models(&self) -> Result<Vec<String>> {
        let m = self.part_meshes(&Timings::default())?;
        let mut lines: Vec<String> = m
            .parts_info
            .iter()
            .zip(&m.part_mesh)
            .enumerate()
            .map(|(pi, (p, &i))| {
                let mesh = &m.meshes[i];
                let size = mesh.bbox().size();
                let copies = m.copies.iter().filter(|c| c.of == pi).count();
                format!(
                    "part `{}`: {} triangles, {} x {} x {} mm{}",
                    p.name,
                    mesh.triangles.len(),
                    short(size.x),
                    short(size.y),
                    short(size.z),
                    match copies {
                        0 => String::new(),
                        n => format!(", and {n} copies on the plate"),
                    }
                )
            })
            .collect();
        if !m.warnings.is_empty() {
            let said: Vec<&str> = m.warnings.iter().map(|w| w.message.as_str()).collect();
            lines.push(format!("model repairs: {}", said.join("; ")));
        }
        Ok(lines)
    }
}

/// Merges the meshes of a model into one, keeping per-triangle materials: the names
/// of all meshes, each triangle's index moved to that list (`u32::MAX` for the
/// triangles of a mesh without materials).
pub(super) fn merge(meshes: &[Mesh], name: &str) -> Mesh {
    if meshes.len() == 1 {
        return meshes[0].clone();
    }
    let mut out = Mesh::new(name, Vec::new(), Vec::new());
    let with_materials = meshes.iter().any(|m| !m.triangle_materials.is_empty());
    for m in meshes {
        let base = out.vertices.len() as u32;
        out.vertices.extend_from_slice(&m.vertices);
        out.triangles.extend(
            m.triangles
                .iter()
                .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
        );
        if with_materials {
            let index: Vec<u32> = m
                .material_names
                .iter()
                .map(|n| match out.material_names.iter().position(|o| o == n) {
                    Some(i) => i as u32,
                    None => {
                        out.material_names.push(n.clone());
                        (out.material_names.len() - 1) as u32
                    }
                })
                .collect();
            out.triangle_materials.extend((0..m.triangles.len()).map(|t| {
                m.triangle_materials
                    .get(t)
                    .and_then(|&k| index.get(k as usize).copied())
                    .unwrap_or(u32::MAX)
            }));
        }
    }
    out
}

/// [`merge`] of meshes nothing else needs: a model of one mesh is moved, not copied.
pub(super) fn merge_owned(mut meshes: Vec<Mesh>, name: &str) -> Mesh {
    if meshes.len() == 1 {
        return meshes.pop().unwrap_or_default();
    }
    merge(&meshes, name)
}

/// Turns every mesh of every model by the orienter's choice, rotating about the
/// object's centre and putting the object back on the bed: the models keep their
/// places relative to each other.
pub(super) fn orient(
    orienter: &dyn Orienter,
    models: &mut [Vec<Mesh>],
) -> Result<(Orientation, Option<ModelFrame>)> {
    let all: Vec<&Mesh> = models.iter().flatten().collect();
    let orientation = orienter.orient(&all)?;
    let r = &orientation.rotation;
    let m = nalgebra::Matrix3::from_fn(|i, j| r[i][j]);
    let det = m.determinant();
    if !((det - 1.0).abs() < 1e-6 && (m.transpose() * m - nalgebra::Matrix3::identity()).norm() < 1e-6) {
        return Err(Error::stage(
            "orient",
            format!("the orienter returned a matrix that is not a rotation: {r:?}"),
        ));
    }
    let bbox = models
        .iter()
        .flatten()
        .fold(BBox3::EMPTY, |b, m| b.union(&m.bbox()));
    if bbox.is_empty() {
        return Ok((orientation, None));
    }
    let centre = (bbox.min.coords + bbox.max.coords) * 0.5;
    for mesh in models.iter_mut().flatten() {
        mesh.transform(1.0, -centre);
        mesh.rotate(r);
        mesh.transform(1.0, centre);
    }
    let after = models
        .iter()
        .flatten()
        .fold(BBox3::EMPTY, |b, m| b.union(&m.bbox()));
    for mesh in models.iter_mut().flatten() {
        mesh.transform(1.0, Vector3::new(0.0, 0.0, -after.min.z));
    }
    // build = R (model - c) + c - (0, 0, lowest) = R model + (c - R c - lowest).
    let offset = centre - m * centre - Vector3::new(0.0, 0.0, after.min.z);
    let frame = ModelFrame {
        rotation: *r,
        offset: [offset.x, offset.y, offset.z],
    };
    Ok((orientation, Some(frame)))
}

/// Applies a model table's `scale` and `place` to all meshes of the model together, so
/// the meshes of an assembly keep their relative positions.
pub fn place(meshes: &mut [Mesh], scale: f64, placement: Placement) {
    for m in meshes.iter_mut() {
        m.transform(scale, Vector3::zeros());
    }
    let bbox = meshes.iter().fold(BBox3::EMPTY, |b, m| b.union(&m.bbox()));
    if bbox.is_empty() {
        return;
    }
    let offset = match placement {
        Placement::Keep => return,
        Placement::Bed => Vector3::new(0.0, 0.0, -bbox.min.z),
        Placement::Centre => {
            let c = Vector2::new(bbox.min.x + bbox.max.x, bbox.min.y + bbox.max.y) * 0.5;
            Vector3::new(-c.x, -c.y, -bbox.min.z)
        }
    };
    for m in meshes.iter_mut() {
        m.transform(1.0, offset);
    }
}

/// A model whose extents are all under this (mm) is most likely in metres.
const SMALLEST_PLAUSIBLE_MM: f64 = 1.0;
/// A model with an extent over this (mm) is most likely in micrometres (or tenths).
const LARGEST_PLAUSIBLE_MM: f64 = 2000.0;

/// Refuses a model whose size says its file is not in millimetres (a mesh in metres
/// slices to a single layer and an empty file), unless the pipeline gives `scale` or
/// `units`.
fn check_units(meshes: &[Mesh], spec: &ModelSpec, label: &str) -> Result<()> {
    let bbox = meshes.iter().fold(BBox3::EMPTY, |b, m| b.union(&m.bbox()));
    if bbox.is_empty() {
        return Ok(());
    }
    let size = bbox.size();
    let extents = [("wide", size.x), ("deep", size.y), ("tall", size.z)];
    let (word, largest) = extents
        .into_iter()
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or(("tall", size.z));
    let (guess, fix) = if largest < SMALLEST_PLAUSIBLE_MM {
        ("is it in metres?", "scale = 1000 or units = \"m\"")
    } else if largest > LARGEST_PLAUSIBLE_MM {
        ("is it in micrometres?", "scale = 0.001")
    } else {
        return Ok(());
    };
    let table = spec.table.path_string();
    let table = if table.is_empty() {
        "model".to_string()
    } else {
        table
    };
    let message = format!(
        "the model `{label}` is {} mm {word} ({} x {} x {} mm): {guess} set [{table}] {fix}",
        short(largest),
        short(size.x),
        short(size.y),
        short(size.z)
    );
    let help = format!(
        "Lamina works in millimetres; `scale` or `units` (\"mm\", \"cm\", \"m\", \"in\") in [{table}] says what the file's numbers mean, and turns this check off"
    );
    Err(match spec
        .table
        .location_of(Some("file"))
        .filter(|_| !spec.table.is_overridden())
    {
        Some(loc) => Error::config_at(loc, message),
        None => Error::config(message),
    }
    .with_help(help))
}

/// A length for messages: three significant digits, no trailing zeros.
pub(super) fn short(v: f64) -> String {
    if v.abs() >= 1e7 {
        return format!("{v:.2e}");
    }
    let digits = if v == 0.0 {
        0
    } else {
        (2 - v.abs().log10().floor() as i32).max(0) as usize
    };
    let s = format!("{v:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// Refuses a part that does not fit the machine: placed as the machine says, every
/// vertex must lie on the bed and below the machine's build height.
pub(super) fn check_on_bed(
    machine: &crate::machine::Machine,
    part: &str,
    mesh: &Mesh,
    shift: Vector2,
    all: &crate::geom::BBox2,
) -> Result<()> {
    let offset = machine.placement_offset(all) + shift;
    let bbox = mesh.bbox();
    if bbox.is_empty() {
        return Ok(());
    }
    let bed = &machine.bed;
    let on_bed = match bed.shape {
        crate::machine::BedShape::Rectangle { .. } => bed.contains_box(
            &crate::geom::BBox2::from_points([
                Point2::new(bbox.min.x, bbox.min.y) + offset,
                Point2::new(bbox.max.x, bbox.max.y) + offset,
            ]),
            0.0,
        ),
        crate::machine::BedShape::Circle { .. } => mesh
            .vertices
            .iter()
            .all(|v| bed.contains(Point2::new(v.x, v.y) + offset, 0.0)),
    };
    if !on_bed {
        return Err(machine.error(format!(
            "part `{part}` ({} x {} mm, placed at X {:.1}..{:.1}, Y {:.1}..{:.1}) does not fit the {} bed",
            short(bbox.max.x - bbox.min.x),
            short(bbox.max.y - bbox.min.y),
            bbox.min.x + offset.x,
            bbox.max.x + offset.x,
            bbox.min.y + offset.y,
            bbox.max.y + offset.y,
            bed.describe()
        )));
    }
    if bbox.max.z > bed.max_height {
        return Err(machine.error(format!(
            "part `{part}` is {} mm tall, the machine builds up to {} mm",
            short(bbox.max.z),
            bed.max_height
        )));
    }
    Ok(())
}

/// A box's extent in X-Y (empty for an empty box).
fn flat(b: &BBox3) -> BBox2 {
    if b.is_empty() {
        return BBox2::EMPTY;
    }
    BBox2::from_points([Point2::new(b.min.x, b.min.y), Point2::new(b.max.x, b.max.y)])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn triangle(names: &[&str], materials: Vec<u32>) -> Mesh {
        let v = vec![
            crate::mesh::Point3::new(0.0, 0.0, 0.0),
            crate::mesh::Point3::new(1.0, 0.0, 0.0),
            crate::mesh::Point3::new(0.0, 1.0, 0.0),
        ];
        let mut m = Mesh::new("t", v, vec![[0, 1, 2]]);
        m.material_names = names.iter().map(|s| s.to_string()).collect();
        m.triangle_materials = materials;
        m
    }

    #[test]
    fn merging_keeps_each_triangles_material_by_name() {
        let a = triangle(&["skin", "core"], vec![1]);
        let b = triangle(&["core"], vec![0]);
        let c = triangle(&[], vec![]);
        let m = merge(&[a, b, c], "all");
        assert_eq!(m.triangles, vec![[0, 1, 2], [3, 4, 5], [6, 7, 8]]);
        assert_eq!(m.material_names, vec!["skin", "core"]);
        assert_eq!(m.triangle_materials, vec![1, 1, u32::MAX]);
        let plain = merge(&[triangle(&[], vec![]), triangle(&[], vec![])], "plain");
        assert!(plain.triangle_materials.is_empty() && plain.material_names.is_empty());
    }
}
