//! Nested bands: a shape cut into the rings between successive inner sets. Band k is
//! `S_k - S_{k+1}` where `S_0` is the shape and `S_{k+1}` is the k+1-th inner set
//! intersected with `S_k`, both read from one overlay graph. The bands are therefore
//! disjoint and their union is the shape, whatever the inner sets are (offsets that
//! poke out by a grid unit, iso-contours that cross the boundary). Where each inner set
//! is an erosion of the one before by more than the offsetter's rounding (offsets from
//! every boundary), no boolean is needed: the band is the outer set's contours with the
//! inner set's reversed ([`band_between`]), and the bands tile the shape exactly.

use i_overlay::core::extract::BooleanExtractionBuffer;
use i_overlay::core::fill_rule::FillRule;
use i_overlay::core::overlay::{Overlay, ShapeType};
use i_overlay::core::overlay_rule::OverlayRule;
use i_overlay::i_float::int::point::IntPoint;
use i_overlay::i_shape::int::shape::{IntContour, IntShapes};
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
        let margin = (2.0 * raw.eps(scale) + CLEAR) / scale;
        return eroded_bands(
            base,
            count,
            |k| depth(k) - depth(k - 1),
            margin,
            |set, step, overlay| raw.add_loops(overlay, set, -step, scale, &mut scratch),
        )
        .map_or_else(
            || {
                nested_bands(base, count, FillRule::Positive, |k, current, overlay| {
                    let step = depth(k) - depth(k - 1);
                    Ok(raw.add_loops(overlay, current, -step, scale, &mut scratch))
                })
            },
            Ok,
        );
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

/// How far (grid units) an offset must reach past the offsetter's own simplification
/// (`eps`, each side) for its raw loops to stay off the set they erode: beyond the
/// points' rounding and a round join's chords.
const CLEAR: f64 = 8.0;

/// [`offset_bands`] for sets that each erode the one before (outer contours and holes
/// moving together): `add(set, step, overlay)` adds the raw loops of `set` eroded by
/// `step` mm as clip paths, with the offsetter's simplification `eps` grid units.
/// Each inner set is then resolved on its own, and the band between two sets is built
/// from their contours (the inner set's reversed, [`band_between`]) without a boolean
/// difference: erosion keeps the inner set off the outer one by the step, which the
/// loops miss by at most the simplification and the rounding. `None` (the caller then
/// cuts the bands with booleans) when a step is too short for that margin or the
/// nesting does not close.
fn eroded_bands(
    base: &IntShapes<i32>,
    count: usize,
    step: impl Fn(usize) -> f64,
    margin: f64,
    mut add: impl FnMut(&IntShapes<i32>, f64, &mut Overlay<i32>) -> bool,
) -> Option<Vec<IntShapes<i32>>> {
    let mut bands = Vec::with_capacity(count);
    let mut current = base.clone();
    let mut overlay = Overlay::new_custom(0, options(), solver());
    for k in 1..count {
        if current.is_empty() {
            break;
        }
        let d = step(k);
        if d.is_nan() || d <= margin {
            return None;
        }
        overlay.clear();
        if !add(&current, d, &mut overlay) {
            break;
        }
        let inner = overlay.overlay(OverlayRule::Clip, FillRule::Positive);
        bands.push(band_between(&current, &inner)?);
        current = inner;
    }
    if !current.is_empty() {
        bands.push(current);
    }
    while bands.last().is_some_and(|b| b.is_empty()) {
        bands.pop();
    }
    Some(bands)
}

/// `outer − inner` for an `inner` set strictly inside `outer` whose contours touch none
/// of `outer`'s: `outer`'s contours as they are and `inner`'s reversed (its outer
/// contours become holes of the band, its holes outer contours), each hole in the
/// smallest outer contour around it. `None` when a hole has no contour around it.
pub fn band_between(outer: &IntShapes<i32>, inner: &IntShapes<i32>) -> Option<IntShapes<i32>> {
    let reversed = |c: &IntContour<i32>| c.iter().rev().copied().collect::<IntContour<i32>>();
    let mut shapes: IntShapes<i32> = Vec::new();
    let mut holes: Vec<IntContour<i32>> = Vec::new();
    for shape in outer {
        let mut rings = shape.iter();
        shapes.extend(rings.next().map(|c| vec![c.clone()]));
        holes.extend(rings.cloned());
    }
    for shape in inner {
        let mut rings = shape.iter();
        holes.extend(rings.next().map(reversed));
        shapes.extend(rings.map(|c| vec![reversed(c)]));
    }
    let boxes: Vec<Bounds> = shapes.iter().map(|s| Bounds::of(&s[0])).collect();
    let areas: Vec<i128> = shapes.iter().map(|s| twice_area(&s[0]).abs()).collect();
    for hole in holes {
        let p = *hole.first()?;
        let home = (0..shapes.len())
            .filter(|&i| boxes[i].holds(p) && winds(&shapes[i][0], p))
            .min_by_key(|&i| areas[i])?;
        shapes[home].push(hole);
    }
    Some(shapes)
}

/// The bounding box of a contour.
struct Bounds {
    lo: IntPoint<i32>,
    hi: IntPoint<i32>,
}

impl Bounds {
    fn of(c: &IntContour<i32>) -> Self {
        let mut b = Self {
            lo: IntPoint::new(i32::MAX, i32::MAX),
            hi: IntPoint::new(i32::MIN, i32::MIN),
        };
        for p in c {
            b.lo = IntPoint::new(b.lo.x.min(p.x), b.lo.y.min(p.y));
            b.hi = IntPoint::new(b.hi.x.max(p.x), b.hi.y.max(p.y));
        }
        b
    }

    fn holds(&self, p: IntPoint<i32>) -> bool {
        (self.lo.x..=self.hi.x).contains(&p.x) && (self.lo.y..=self.hi.y).contains(&p.y)
    }
}

/// Twice the signed area of a contour (positive counter-clockwise), exact.
fn twice_area(c: &IntContour<i32>) -> i128 {
    (0..c.len())
        .map(|i| {
            let (a, b) = (c[i], c[(i + 1) % c.len()]);
            i128::from(a.x) * i128::from(b.y) - i128::from(b.x) * i128::from(a.y)
        })
        .sum()
}

/// Whether `p` (not on the contour) lies inside it: crossings of a ray toward +x,
/// exact.
fn winds(c: &IntContour<i32>, p: IntPoint<i32>) -> bool {
    let mut inside = false;
    for i in 0..c.len() {
        let (a, b) = (c[i], c[(i + 1) % c.len()]);
        if (a.y > p.y) != (b.y > p.y) {
            // The crossing's x is right of p when (x - p.x) has the sign of (b.y - a.y).
            let lhs = (i64::from(p.x) - i64::from(a.x)) * (i64::from(b.y) - i64::from(a.y));
            let rhs = (i64::from(b.x) - i64::from(a.x)) * (i64::from(p.y) - i64::from(a.y));
            if (b.y > a.y) == (rhs > lhs) {
                inside = !inside;
            }
        }
    }
    inside
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Grid;
    use crate::inset::Join;
    use lamina_api::{Contour, Point2, Polygon};

    fn square(x0: i32, y0: i32, x1: i32, y1: i32) -> IntContour<i32> {
        [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
            .iter()
            .map(|&(x, y)| IntPoint::new(x, y))
            .collect()
    }

    fn hole(x0: i32, y0: i32, x1: i32, y1: i32) -> IntContour<i32> {
        let mut c = square(x0, y0, x1, y1);
        c.reverse();
        c
    }

    fn area(shapes: &IntShapes<i32>) -> i128 {
        shapes.iter().flatten().map(twice_area).sum()
    }

    #[test]
    fn a_band_is_the_outer_sets_contours_and_the_inner_ones_reversed() {
        // A 100-square with a 20-square hole; inside it a 80-square with a 40-square
        // hole: a ring outside and a ring about the hole.
        let outer = vec![vec![square(0, 0, 100, 100), hole(40, 40, 60, 60)]];
        let inner = vec![vec![square(10, 10, 90, 90), hole(30, 30, 70, 70)]];
        let band = band_between(&outer, &inner).expect("nested");
        assert_eq!(band.len(), 2);
        assert_eq!(band[0], vec![square(0, 0, 100, 100), hole(10, 10, 90, 90)]);
        assert_eq!(band[1], vec![square(30, 30, 70, 70), hole(40, 40, 60, 60)]);
        assert_eq!(area(&band), area(&outer) - area(&inner));
        assert_eq!(area(&band), 2 * (10_000 - 400 - (6_400 - 1_600)));
        // The inner set split in two about a hole that stays in the outer band: one
        // shape with three holes, the hole in the smallest contour around it.
        let outer = vec![vec![square(0, 0, 100, 100), hole(45, 45, 55, 55)]];
        let inner = vec![vec![square(10, 10, 40, 90)], vec![square(60, 10, 90, 90)]];
        let band = band_between(&outer, &inner).expect("nested");
        assert_eq!(
            band,
            vec![vec![
                square(0, 0, 100, 100),
                hole(45, 45, 55, 55),
                hole(10, 10, 40, 90),
                hole(60, 10, 90, 90)
            ]]
        );
        // An island in a hole of the inner set takes the hole's own contour, not the
        // outer set's, though both are around it.
        let outer = vec![
            vec![square(0, 0, 100, 100), hole(20, 20, 80, 80)],
            vec![square(40, 40, 60, 60)],
        ];
        let inner = vec![vec![square(5, 5, 95, 95), hole(15, 15, 85, 85)]];
        let band = band_between(&outer, &inner).expect("nested");
        assert_eq!(
            band,
            vec![
                vec![square(0, 0, 100, 100), hole(5, 5, 95, 95)],
                vec![square(40, 40, 60, 60)],
                vec![square(15, 15, 85, 85), hole(20, 20, 80, 80)],
            ]
        );
        // A hole outside every contour is no band.
        assert!(
            band_between(
                &vec![vec![square(0, 0, 10, 10)]],
                &vec![vec![square(20, 20, 30, 30)]]
            )
            .is_none()
        );
    }

    /// A star of `n` points with two round holes, on its family's grid.
    fn star_family(n: usize) -> (Grid, IntShapes<i32>) {
        let star = Contour::new(
            (0..2 * n)
                .map(|i| {
                    let a = std::f64::consts::PI * i as f64 / n as f64;
                    let r = if i % 2 == 0 { 20.0 } else { 12.0 };
                    Point2::new(r * a.cos(), r * a.sin())
                })
                .collect(),
        );
        let holes = vec![
            Contour::circle(Point2::new(-4.0, 0.0), 2.5, 40).oriented(false),
            Contour::circle(Point2::new(5.0, 1.0), 3.0, 7).oriented(false),
        ];
        Grid::family(&Polygon::new(star, holes), "test").expect("a grid")
    }

    #[test]
    fn eroded_bands_are_the_boolean_ones() {
        // The bands built from the sets' contours and those cut by booleans are the
        // same areas, band by band, exactly, at every join and for steps down to the
        // margin; below it the booleans cut them.
        let (grid, base) = star_family(7);
        for join in [Join::Round, Join::Miter, Join::Bevel] {
            let inset = Inset {
                from: From::All,
                join,
                tolerance: 0.01,
            };
            let raw = inset.raw();
            let margin = (2.0 * raw.eps(grid.scale()) + CLEAR) / grid.scale();
            for spacing in [0.45, 0.1, 1.7] {
                let depth = |k: usize| k as f64 * spacing;
                let mut scratch = Scratch::default();
                let eroded = eroded_bands(
                    &base,
                    40,
                    |_| spacing,
                    margin,
                    |set, step, overlay| raw.add_loops(overlay, set, -step, grid.scale(), &mut scratch),
                )
                .expect("steps above the margin");
                let cut = nested_bands(&base, 40, FillRule::Positive, |k, current, overlay| {
                    let step = depth(k) - depth(k - 1);
                    Ok(raw.add_loops(overlay, current, -step, grid.scale(), &mut scratch))
                })
                .expect("bands");
                assert_eq!(eroded.len(), cut.len(), "{join:?} {spacing}");
                for (k, (a, b)) in eroded.iter().zip(&cut).enumerate() {
                    // The inner set resolved alone and in one graph with the outer one
                    // is rounded alike to within a few grid units at the raw loops'
                    // detours through the outer set's corners.
                    assert_eq!(a.len(), b.len(), "{join:?} {spacing}: band {k}");
                    let (a, b) = (area(a) as f64, area(b) as f64);
                    assert!(
                        (a - b).abs() <= 1e-6 * b,
                        "{join:?} {spacing}: band {k}: {a} vs {b}"
                    );
                }
                assert_eq!(eroded.iter().map(area).sum::<i128>(), area(&base));
                // The public entry takes the same path.
                let bands = offset_bands(&base, grid.scale(), 40, &inset, depth).expect("bands");
                assert_eq!(bands, eroded);
            }
            // A step within the margin is refused, and `offset_bands` cuts it instead.
            let short = margin * 0.9;
            assert!(
                eroded_bands(
                    &base,
                    3,
                    |_| short,
                    margin,
                    |set, step, overlay| {
                        raw.add_loops(overlay, set, -step, grid.scale(), &mut Scratch::default())
                    }
                )
                .is_none()
            );
            let bands = offset_bands(&base, grid.scale(), 3, &inset, |k| k as f64 * short).expect("bands");
            assert_eq!(bands.len(), 3);
            // The booleans drop rounding slivers from either side of a cut: the bands
            // tile the family to their area, where the eroded ones do so exactly.
            let (sum, whole) = (bands.iter().map(area).sum::<i128>() as f64, area(&base) as f64);
            assert!((sum - whole).abs() <= 1e-8 * whole, "{sum} vs {whole}");
        }
    }

    #[test]
    fn steps_within_the_offsetters_reach_are_cut_with_booleans() {
        // The margin is twice the simplification plus 8 grid units: a step 4 units
        // short of it is cut with booleans (the same bands as `nested_bands`, with the
        // same steps), one 4 units past it is built from the contours.
        let (grid, base) = star_family(7);
        let inset = Inset {
            from: From::All,
            join: Join::Round,
            tolerance: 0.01,
        };
        let scale = grid.scale();
        let margin = 2.0 * (0.01 * 0.2 * scale).max(2.0) + 8.0;
        for (units, boolean) in [(margin - 4.0, true), (margin + 4.0, false)] {
            let spacing = units / scale;
            let depth = |k: usize| k as f64 * spacing;
            let bands = offset_bands(&base, scale, 3, &inset, depth).expect("bands");
            let raw = inset.raw();
            let mut scratch = Scratch::default();
            let expected = if boolean {
                nested_bands(&base, 3, FillRule::Positive, |k, current, overlay| {
                    Ok(raw.add_loops(overlay, current, -(depth(k) - depth(k - 1)), scale, &mut scratch))
                })
                .expect("bands")
            } else {
                eroded_bands(
                    &base,
                    3,
                    |_| spacing,
                    units / scale * 0.5,
                    |set, step, overlay| raw.add_loops(overlay, set, -step, scale, &mut scratch),
                )
                .expect("contours")
            };
            assert_eq!(bands, expected, "{units} units");
        }
    }
}
