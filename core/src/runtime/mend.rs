//! Layers that an open mesh leaves empty. Where a mesh has a hole, the cut through it
//! is a chain that does not close, and the slicer drops it (with a warning): a layer
//! whose chains were all dropped holds nothing, although the mesh crosses it, and the
//! part would be built with a gap, or upon air. Such a layer takes the contours of the
//! nearest layer that has some, below first, and says so; with none near, the run
//! fails naming the layer. A layer that no triangle crosses (a gap between two bodies)
//! stays empty.

use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};

use crate::diagnostic::Warning;
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::model::{Layer, LayerSlot};
use crate::stage::MeshSlicer;

/// How many layers away, below or above, a layer left empty may take its contours
/// from: a hole the height of a few layers is mended, a missing wall is not.
pub(super) const MEND_REACH: usize = 32;

/// The run's cuts of its layers, each mended as [`mend_empty`] says: how every pass of
/// a run cuts a layer, so that a layer is the same whichever pass cut it.
pub(super) struct LayerCuts<'a> {
    slicers: &'a [Box<dyn MeshSlicer>],
    meshes: &'a [Arc<Mesh>],
    /// The run's layers in build order, for a layer an open mesh leaves empty to take
    /// the contours of its neighbours (none: such a layer stays empty).
    slots: &'a [LayerSlot],
    /// Per mesh and slot, what is known of its cut ([`Seen`]). A layer left empty
    /// looks for its nearest layer with contours; without this record every empty
    /// layer of an open mesh would cut all its neighbours again, up to
    /// 2 x [`MEND_REACH`] cuts each (a triangle soup of ten layers took ten times its
    /// slicing to be refused), and two threads searching side by side would cut the
    /// same layers at the same time.
    seen: Vec<Vec<AtomicU8>>,
}

impl<'a> LayerCuts<'a> {
    /// The cuts of `meshes`, each prepared for slicing as `slicers` (one per mesh),
    /// through the layers `slots`.
    pub(super) fn new(
        slicers: &'a [Box<dyn MeshSlicer>],
        meshes: &'a [Arc<Mesh>],
        slots: &'a [LayerSlot],
    ) -> Self {
        let seen = slicers
            .iter()
            .map(|_| slots.iter().map(|_| AtomicU8::new(Seen::Unknown as u8)).collect())
            .collect();
        Self {
            slicers,
            meshes,
            slots,
            seen,
        }
    }

    /// How many meshes are cut.
    pub(super) fn meshes(&self) -> usize {
        self.slicers.len()
    }

    /// The run's layers.
    pub(super) fn slots(&self) -> &'a [LayerSlot] {
        self.slots
    }

    /// The cut of mesh `mi` for the run's layer `slots[at]`, mended.
    pub(super) fn at(&self, mi: usize, at: usize) -> Result<Layer> {
        let seen = self.seen.get(mi).map_or(&[][..], Vec::as_slice);
        slice_mended(&*self.slicers[mi], &self.meshes[mi], self.slots, seen, at)
    }

    /// The cut of mesh `mi` for `slot`: mended if it is one of the run's layers, as
    /// it is otherwise (a slot of a pass of its own).
    pub(super) fn of(&self, mi: usize, slot: &LayerSlot) -> Result<Layer> {
        match self.slots.iter().position(|s| s.index == slot.index) {
            Some(at) => self.at(mi, at),
            None => self.slicers[mi].slice(slot),
        }
    }
}

/// What the run knows of a layer's cut, in [`LayerCuts`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
enum Seen {
    Unknown,
    /// Being cut by some thread.
    Cutting,
    /// Cut, and it closes no area.
    Empty,
    /// Cut, and it has contours.
    Full,
}

impl Seen {
    fn of(state: &AtomicU8) -> Self {
        match state.load(Ordering::Acquire) {
            1 => Self::Cutting,
            2 => Self::Empty,
            3 => Self::Full,
            _ => Self::Unknown,
        }
    }
}

/// The cut of `mesh` for `slots[at]` by `slicer`, mended as [`mend_empty`] says.
/// `seen` is the mesh's record of [`LayerCuts`], one entry per slot (none: every
/// cut is made).
fn slice_mended(
    slicer: &dyn MeshSlicer,
    mesh: &Mesh,
    slots: &[LayerSlot],
    seen: &[AtomicU8],
    at: usize,
) -> Result<Layer> {
    let layer = cut(slicer, slots, seen, at)?;
    mend_empty(layer, mesh, slicer, slots, seen, at)
}

/// The cut for `slots[at]`, noted in `seen`: as being cut while it is (unless known
/// already), then as empty or full.
fn cut(slicer: &dyn MeshSlicer, slots: &[LayerSlot], seen: &[AtomicU8], at: usize) -> Result<Layer> {
    let state = seen.get(at);
    if let Some(state) = state {
        let _ = state.compare_exchange(
            Seen::Unknown as u8,
            Seen::Cutting as u8,
            Ordering::AcqRel,
            Ordering::Acquire,
        );
    }
    let layer = slicer.slice(&slots[at]);
    if let (Some(state), Ok(layer)) = (state, &layer) {
        let found = if layer.contours.is_empty() {
            Seen::Empty
        } else {
            Seen::Full
        };
        state.store(found as u8, Ordering::Release);
    }
    layer
}

/// `layer`, the cut of `mesh` for `slots[at]`, with the contours of its nearest
/// layer that has some if the mesh crosses it yet it holds none: the nearest below
/// first, then above, one layer farther each time, up to [`MEND_REACH`].
///
/// A layer known to be empty is passed over uncut, any other is cut (again: the
/// record keeps no contours), and one another thread is cutting is put off until
/// the layers after it in that order have been looked at; by then its cut is
/// known, or is made here. Whichever thread cuts what, the layer chosen is the first
/// in that order whose cut has contours.
fn mend_empty(
    mut layer: Layer,
    mesh: &Mesh,
    slicer: &dyn MeshSlicer,
    slots: &[LayerSlot],
    seen: &[AtomicU8],
    at: usize,
) -> Result<Layer> {
    let slot = &slots[at];
    if !layer.contours.is_empty() || !crosses(mesh, slot.cut_z) {
        return Ok(layer);
    }
    let known = |k: usize| seen.get(k).map_or(Seen::Unknown, Seen::of);
    let order = (1..=MEND_REACH).flat_map(|d| [at.checked_sub(d), Some(at + d).filter(|&k| k < slots.len())]);
    // The cut of layer `k` if it has contours.
    let full = |k: usize| -> Result<Option<(usize, Layer)>> {
        let other = cut(slicer, slots, seen, k)?;
        Ok((!other.contours.is_empty()).then_some((k, other)))
    };
    let mut put_off = Vec::new();
    let mut found = None;
    for k in order.flatten() {
        match known(k) {
            Seen::Empty => {}
            Seen::Cutting => put_off.push(k),
            Seen::Unknown | Seen::Full => {
                found = full(k)?;
                if found.is_some() {
                    break;
                }
            }
        }
    }
    // Every layer put off comes before the one found, in the order.
    for k in put_off {
        if known(k) != Seen::Empty
            && let Some(nearer) = full(k)?
        {
            found = Some(nearer);
            break;
        }
    }
    if let Some((k, other)) = found {
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
        /// How many cuts were made.
        cuts: Arc<std::sync::atomic::AtomicUsize>,
    }

    impl Holed {
        fn new(empty: &[usize], n: usize) -> Self {
            Self {
                empty: (0..n).map(|i| empty.contains(&i)).collect(),
                cuts: Default::default(),
            }
        }
    }

    impl MeshSlicer for Holed {
        fn slice(&self, slot: &LayerSlot) -> Result<Layer> {
            self.cuts.fetch_add(1, Ordering::Relaxed);
            // Other threads' cuts interleave with this one.
            std::thread::yield_now();
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

    /// Layer `at` of `n`, of which those in `empty` cut empty, mended, with no record
    /// of the cuts.
    fn mended(empty: &[usize], n: usize, at: usize, top: f64) -> Result<Layer> {
        let slicer = Holed::new(empty, n);
        slice_mended(&slicer, &spike(top), &slots(n), &[], at)
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

    #[test]
    fn a_cut_found_empty_is_not_made_again() {
        // Every layer empty: each is cut for itself, and once more by the first
        // search; the other searches find them all known. Every layer is refused.
        let n = 20;
        let mesh = [Arc::new(spike(1000.0))];
        let all: Vec<usize> = (0..n).collect();
        let slicer = Holed::new(&all, n);
        let made = slicer.cuts.clone();
        let layers = slots(n);
        let slicers: Vec<Box<dyn MeshSlicer>> = vec![Box::new(slicer)];
        let cuts = LayerCuts::new(&slicers, &mesh, &layers);
        for at in (0..n).rev() {
            let e = cuts.at(0, at).expect_err("nothing near");
            assert!(e.to_string().contains(&format!("layer {at} ")), "{e}");
        }
        assert_eq!(made.load(Ordering::Relaxed), 2 * n - 1);
        // Without the record, each layer's search cuts all of them.
        let bare = Holed::new(&all, n);
        slice_mended(&bare, &mesh[0], &layers, &[], n - 1).expect_err("nothing near");
        assert_eq!(bare.cuts.load(Ordering::Relaxed), n);

        // With contours near, the layer mended is the one found without the record,
        // whatever the record holds of the other layers.
        let holes = [4, 5, 6, 7];
        let slicer = Holed::new(&holes, 10);
        let made = slicer.cuts.clone();
        let layers = slots(10);
        let slicers: Vec<Box<dyn MeshSlicer>> = vec![Box::new(slicer)];
        let cuts = LayerCuts::new(&slicers, &mesh, &layers);
        for at in [6, 4, 7, 5] {
            let with = cuts.of(0, &layers[at]).expect("mended");
            let without = mended(&holes, 10, at, 1000.0).expect("mended");
            assert_eq!(source(&with), source(&without), "layer {at}");
        }
        // 4 own cuts; 6 then cuts 5, 7, 4 and 8; 4 cuts 3; 7 cuts 8 (6 is known);
        // 5 cuts 3 (4 and 6 are known).
        assert_eq!(made.load(Ordering::Relaxed), 4 + 4 + 1 + 1 + 1);
    }

    #[test]
    fn a_layer_another_thread_is_cutting_is_looked_at_last_and_still_chosen_if_nearest() {
        let mesh = [Arc::new(spike(1000.0))];
        let layers = slots(12);
        // Layer 5 searches 4, 6, 3, 7, 2, ...; 3 is being cut elsewhere: put off, then
        // cut here, as it is still being cut. It has contours (first case) and is
        // chosen over 2, or it has none (second) and 2 is.
        for (holes, from) in [(vec![4, 5, 6, 7], 3), (vec![3, 4, 5, 6, 7], 2)] {
            let slicers: Vec<Box<dyn MeshSlicer>> = vec![Box::new(Holed::new(&holes, 12))];
            let cuts = LayerCuts::new(&slicers, &mesh, &layers);
            cuts.seen[0][3].store(Seen::Cutting as u8, Ordering::Release);
            let layer = cuts.at(0, 5).expect("mended");
            assert_eq!(source(&layer), from, "{holes:?}");
            assert_eq!(source(&mended(&holes, 12, 5, 1000.0).expect("mended")), from);
        }
    }

    /// A slicer that notes what the record says of each layer while it cuts it.
    struct Probe {
        seen: Arc<Vec<AtomicU8>>,
        during: std::sync::Mutex<Vec<Seen>>,
    }

    impl MeshSlicer for Probe {
        fn slice(&self, slot: &LayerSlot) -> Result<Layer> {
            let state = Seen::of(&self.seen[slot.index]);
            self.during.lock().expect("probe").push(state);
            let contours = if slot.index == 1 {
                Holed::new(&[], 2).slice(slot)?.contours
            } else {
                Vec::new()
            };
            Ok(Layer {
                contours,
                ..Layer::from_slot(slot)
            })
        }
    }

    #[test]
    fn a_layer_is_noted_as_being_cut_while_it_is_then_as_what_it_holds() {
        let seen: Arc<Vec<AtomicU8>> = Arc::new((0..3).map(|_| AtomicU8::new(0)).collect());
        let probe = Probe {
            seen: seen.clone(),
            during: Default::default(),
        };
        let layers = slots(3);
        for at in 0..2 {
            cut(&probe, &layers, &seen, at).expect("cut");
        }
        assert_eq!(
            *probe.during.lock().expect("probe"),
            [Seen::Cutting, Seen::Cutting]
        );
        assert_eq!(
            [Seen::of(&seen[0]), Seen::of(&seen[1]), Seen::of(&seen[2])],
            [Seen::Empty, Seen::Full, Seen::Unknown]
        );
    }

    #[test]
    fn threads_mending_side_by_side_choose_as_one_thread_does() {
        let n = 90;
        let mesh = [Arc::new(spike(1000.0))];
        let layers = slots(n);
        // Runs of empty layers of many lengths, one too tall to mend in its middle.
        let holes: Vec<usize> = (0..n)
            .filter(|&i| (i * 7 + i / 11) % 10 < 7 || (10..80).contains(&i))
            .collect();
        let alone: Vec<Option<usize>> = (0..n)
            .map(|at| mended(&holes, n, at, 1000.0).ok().map(|l| source(&l)))
            .collect();
        assert!(alone.iter().any(Option::is_none) && alone.iter().any(Option::is_some));
        for _ in 0..20 {
            let slicers: Vec<Box<dyn MeshSlicer>> = vec![Box::new(Holed::new(&holes, n))];
            let cuts = LayerCuts::new(&slicers, &mesh, &layers);
            let next = std::sync::atomic::AtomicUsize::new(0);
            let found: Vec<(usize, Option<usize>)> = std::thread::scope(|scope| {
                let workers: Vec<_> = (0..4)
                    .map(|_| {
                        scope.spawn(|| {
                            let mut mine = Vec::new();
                            loop {
                                let at = next.fetch_add(1, Ordering::Relaxed);
                                if at >= n {
                                    return mine;
                                }
                                mine.push((at, cuts.at(0, at).ok().map(|l| source(&l))));
                            }
                        })
                    })
                    .collect();
                workers
                    .into_iter()
                    .flat_map(|w| w.join().expect("worker"))
                    .collect()
            });
            for (at, source) in found {
                assert_eq!(source, alone[at], "layer {at}");
            }
        }
    }
}
