//! Layers that an open mesh leaves empty. Where a mesh has a hole, the cut through it
//! is a chain that does not close, and the slicer drops it (with a warning): a layer
//! whose chains were all dropped holds nothing, although the mesh crosses it, and the
//! part would be built with a gap, or upon air. Such a layer takes the contours of the
//! nearest layer that has some, below first, and says so; with none near, the run
//! fails naming the layer. A layer that no triangle crosses (a gap between two bodies)
//! stays empty.

use crate::diagnostic::Warning;
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::model::{Layer, LayerSlot};
use crate::stage::MeshSlicer;

/// How many layers away, below or above, a layer left empty may take its contours
/// from: a hole the height of a few layers is mended, a missing wall is not.
pub(super) const MEND_REACH: usize = 32;

/// The cut of `mesh` for `slots[at]` by `slicer`, mended as [`mend_empty`] says: how
/// every pass of a run cuts a layer, so that a layer is the same whichever pass cut it.
pub(super) fn slice_mended(
    slicer: &dyn MeshSlicer,
    mesh: &Mesh,
    slots: &[LayerSlot],
    at: usize,
) -> Result<Layer> {
    mend_empty(slicer.slice(&slots[at])?, mesh, slicer, slots, at)
}

/// `layer`, the cut of `mesh` for `slots[at]`, with the contours of its nearest
/// layer that has some if the mesh crosses it yet it holds none.
fn mend_empty(
    mut layer: Layer,
    mesh: &Mesh,
    slicer: &dyn MeshSlicer,
    slots: &[LayerSlot],
    at: usize,
) -> Result<Layer> {
    let slot = &slots[at];
    if !layer.contours.is_empty() || !crosses(mesh, slot.cut_z) {
        return Ok(layer);
    }
    for d in 1..=MEND_REACH {
        let near = [at.checked_sub(d), Some(at + d).filter(|&k| k < slots.len())];
        for k in near.into_iter().flatten() {
            let other = slicer.slice(&slots[k])?;
            if !other.contours.is_empty() {
                layer.contours = other.contours;
                layer.warnings.push(Warning::new(
                    "empty-layer-filled",
                    format!(
                        "the mesh crosses this layer but its cut closes no area (an open mesh): filled with the contours of layer {} (z = {:.4} mm)",
                        slots[k].index, slots[k].z
                    ),
                ));
                return Ok(layer);
            }
        }
    }
    Err(Error::stage(
        "slice",
        format!(
            "layer {} (z = {:.4} mm): mesh `{}` crosses it but its cut closes no area, nor does that of any layer within {MEND_REACH} of it: the mesh is open here; repair it, or join its open chains with [slice] close_gaps",
            slot.index, slot.z, mesh.name
        ),
    ))
}

/// Whether a triangle of `mesh` reaches both below and above the height `z`.
fn crosses(mesh: &Mesh, z: f64) -> bool {
    mesh.triangles.iter().any(|t| {
        let zs = t.map(|v| mesh.vertices[v as usize].z);
        zs.iter().any(|&a| a < z) && zs.iter().any(|&a| a > z)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::{Contour, Point2};
    use crate::mesh::Point3;

    /// Cuts that are empty where `empty` says, a square elsewhere.
    struct Holed {
        empty: Vec<bool>,
    }

    impl MeshSlicer for Holed {
        fn slice(&self, slot: &LayerSlot) -> Result<Layer> {
            let contours = if self.empty[slot.index] {
                Vec::new()
            } else {
                let s = slot.index as f64;
                vec![Contour::new(vec![
                    Point2::new(0.0, 0.0),
                    Point2::new(1.0 + s, 0.0),
                    Point2::new(1.0 + s, 1.0),
                    Point2::new(0.0, 1.0),
                ])]
            };
            Ok(Layer {
                index: slot.index,
                z: slot.z,
                thickness: slot.thickness,
                contours,
                warnings: Vec::new(),
                section_area: None,
            })
        }
    }

    /// A tall tetrahedron-like spike from z = 0 to z = `top`: it crosses every layer
    /// below its top.
    fn spike(top: f64) -> Mesh {
        Mesh {
            name: "spike".into(),
            vertices: vec![
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(1.0, 0.0, 0.0),
                Point3::new(0.0, 1.0, top),
            ],
            triangles: vec![[0, 1, 2]],
            ..Mesh::default()
        }
    }

    fn slots(n: usize) -> Vec<LayerSlot> {
        (0..n)
            .map(|i| LayerSlot {
                index: i,
                z: 0.2 * (i + 1) as f64,
                thickness: 0.2,
                cut_z: 0.2 * i as f64 + 0.1,
                material_region: None,
            })
            .collect()
    }

    fn mended(empty: &[usize], n: usize, at: usize, top: f64) -> Result<Layer> {
        let slicer = Holed {
            empty: (0..n).map(|i| empty.contains(&i)).collect(),
        };
        let slots = slots(n);
        let layer = slicer.slice(&slots[at])?;
        mend_empty(layer, &spike(top), &slicer, &slots, at)
    }

    /// The width of the square a mended layer took says which layer it came from.
    fn source(layer: &Layer) -> usize {
        (layer.contours[0].points[1].x - 1.0).round() as usize
    }

    #[test]
    fn an_empty_layer_the_mesh_crosses_takes_its_nearest_neighbours_contours() {
        let empty = [4, 5, 6, 7];
        // Below first at equal distance; the nearer above otherwise.
        for (at, from) in [(4, 3), (5, 3), (6, 8), (7, 8)] {
            let layer = mended(&empty, 10, at, 100.0).expect("mended");
            assert_eq!(source(&layer), from, "layer {at}");
            assert!(
                layer.warnings[0].code == "empty-layer-filled"
                    && layer.warnings[0]
                        .message
                        .contains(&format!("contours of layer {from}")),
                "{:?}",
                layer.warnings
            );
        }
        // The bottom layer takes the one above it.
        assert_eq!(source(&mended(&[0], 10, 0, 100.0).expect("mended")), 1);
        // A full layer is left as it is.
        let full = mended(&empty, 10, 2, 100.0).expect("full");
        assert_eq!(source(&full), 2);
        assert!(full.warnings.is_empty());
    }

    #[test]
    fn a_layer_no_triangle_crosses_stays_empty() {
        // The spike ends at z = 0.5: layer 5 (cut at 1.1) is above it.
        let layer = mended(&[5], 10, 5, 0.5).expect("left alone");
        assert!(layer.contours.is_empty() && layer.warnings.is_empty());
    }

    #[test]
    fn a_hole_taller_than_the_reach_is_an_error_naming_the_layer() {
        let n = 2 * MEND_REACH + 3;
        let empty: Vec<usize> = (0..n).collect();
        let e = mended(&empty, n, MEND_REACH, 1000.0).expect_err("nothing near");
        let text = e.to_string();
        assert!(
            text.contains(&format!("layer {MEND_REACH} ")) && text.contains("`spike`"),
            "{text}"
        );
    }
}
