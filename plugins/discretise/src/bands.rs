//! Nested bands: a shape cut into the rings between successive inner sets. Band k is
//! `S_k - S_{k+1}` where `S_0` is the shape and `S_{k+1}` is the k+1-th inner set
//! intersected with `S_k`, both read from one overlay graph. The bands are therefore
//! disjoint and their union is the shape, whatever the inner sets are (offsets that
//! poke out by a grid unit, iso-contours that cross the boundary).

use i_overlay::core::extract::BooleanExtractionBuffer;
use i_overlay::core::fill_rule::FillRule;
use i_overlay::core::overlay::{Overlay, ShapeType};
use i_overlay::core::overlay_rule::OverlayRule;
use i_overlay::i_shape::int::shape::IntShapes;
use lamina_api::Result;
use lamina_geom::offset::Scratch;
/// The offset engine's overlay settings (OGC-valid output, rounding slivers dropped, on
/// the caller's thread), which every overlay of a family shares.
pub use lamina_geom::offset::{overlay_options as options, solver};

use crate::inset::{From, Inset};

/// Resolves arbitrary contours (self-touching, slightly crossing, any orientation)
/// into valid shapes under the non-zero rule.
pub fn clean(shapes: &IntShapes<i32>) -> IntShapes<i32> {
    let mut overlay = Overlay::from_subj_custom(shapes, options(), solver());
    overlay.overlay(OverlayRule::Subject, FillRule::NonZero)
}

/// Cuts `base` (valid shapes) into at most `count` nested bands. `inner(k, current,
/// overlay)` adds to `overlay` (as clip paths, read with `fill`) the k-th inner set for
/// `k` in `1..count`, given the current set S_k; it returns `false` when that set is
/// empty, and is not called again once the sets vanish. One overlay and one extraction
/// buffer serve every step. Returns the bands in order, outermost first, without the
/// trailing empty ones.
pub fn nested_bands(
    base: &IntShapes<i32>,
    count: usize,
    fill: FillRule,
    mut inner: impl FnMut(usize, &IntShapes<i32>, &mut Overlay<i32>) -> Result<bool>,
) -> Result<Vec<IntShapes<i32>>> {
    let mut bands = Vec::with_capacity(count);
    let mut current = base.clone();
    let mut buffer = BooleanExtractionBuffer::default();
    let mut overlay = Overlay::new_custom(0, options(), solver());
    for k in 1..count {
        if current.is_empty() {
            break;
        }
        overlay.clear();
        overlay.add_source(&current, ShapeType::Subject);
        if !inner(k, &current, &mut overlay)? {
            bands.push(std::mem::take(&mut current));
            break;
        }
        match overlay.build_graph_view(fill) {
            Some(graph) => {
                let ring = graph.extract_shapes(OverlayRule::Difference, &mut buffer);
                let rest = graph.extract_shapes(OverlayRule::Intersect, &mut buffer);
                bands.push(ring);
                current = rest;
            }
            None => {
                bands.push(std::mem::take(&mut current));
                break;
            }
        }
    }
    if !current.is_empty() {
        bands.push(current);
    }
    while bands.last().is_some_and(|b| b.is_empty()) {
        bands.pop();
    }
    Ok(bands)
}

/// Bands between inward offsets at the cumulative distances `depth(k)` (mm, `depth(0)`
/// = 0) of the family `base` on a grid of `scale` units per mm. Each set is offset from
/// the previous one by the difference (erosions by discs add up, and the sets shrink,
/// where offsetting the first set by the whole depth would make ever larger raw loops
/// with ever more self-crossings). From the outer contour alone, the eroded outer
/// contours (without the holes, which must not move) are carried along as a set of
/// their own, and each band's inner set is the family's set clipped by it.
pub fn offset_bands(
    base: &IntShapes<i32>,
    scale: f64,
    count: usize,
    inset: &Inset,
    depth: impl Fn(usize) -> f64,
) -> Result<Vec<IntShapes<i32>>> {
    let mut scratch = Scratch::default();
    let raw = inset.raw();
    let holes = base.iter().any(|s| s.len() > 1);
    if inset.from == From::All || !holes {
        return nested_bands(base, count, FillRule::Positive, |k, current, overlay| {
            let step = depth(k) - depth(k - 1);
            Ok(raw.add_loops(overlay, current, -step, scale, &mut scratch))
        });
    }
    let mut outer: IntShapes<i32> = base
        .iter()
        .filter_map(|s| s.first())
        .map(|c| vec![c.clone()])
        .collect();
    let mut resolve = Overlay::new_custom(0, options(), solver());
    nested_bands(base, count, FillRule::Positive, |k, _, overlay| {
        resolve.clear();
        let step = depth(k) - depth(k - 1);
        if !raw.add_loops(&mut resolve, &outer, -step, scale, &mut scratch) {
            return Ok(false);
        }
        outer = resolve.overlay(OverlayRule::Clip, FillRule::Positive);
        if outer.is_empty() {
            return Ok(false);
        }
        overlay.add_source(&outer, ShapeType::Clip);
        Ok(true)
    })
}
