//! Marching squares: the closed boundary loops of `{v >= t}` on a field whose border
//! samples are below every level. Loops keep the set on their left (outer loops
//! counter-clockwise, holes clockwise); saddles are resolved by the cell's mean.

use crate::field::Field;
use crate::shape::{Contour, Point2};

/// The loops of `{v >= t}` over `values` (laid out as `field`'s samples).
pub fn iso_loops(field: &Field, values: &[f64], t: f64) -> Vec<Contour> {
    iso_levels(field, values, &[t]).pop().unwrap_or_default()
}

/// The loops of `{v >= t}` for every level `t` of `levels`, in their order, from one
/// pass over the cells: a cell is looked at for the levels between its lowest and
/// highest corner only, so the cost is one scan plus the crossed cells. The links
/// between cell edges are gathered per level, then followed through one table over
/// every edge that each level fills and leaves cleared (every link is followed once).
pub fn iso_levels(field: &Field, values: &[f64], levels: &[f64]) -> Vec<Vec<Contour>> {
    let (nx, ny) = (field.nx, field.ny);
    let mut order: Vec<usize> = (0..levels.len()).filter(|&l| !levels[l].is_nan()).collect();
    order.sort_unstable_by(|&a, &b| levels[a].total_cmp(&levels[b]));
    let sorted: Vec<f64> = order.iter().map(|&l| levels[l]).collect();
    let mut links: Vec<Vec<(u32, u32)>> = vec![Vec::new(); levels.len()];
    if nx < 2 || ny < 2 || sorted.is_empty() {
        return vec![Vec::new(); levels.len()];
    }
    // Each sample's band: how many levels lie at or below it (levels s with s < band
    // have the sample inside). A cell is crossed by the levels from its lowest corner's
    // band to its highest's, and by none when they agree.
    let band: Vec<u16> = if sorted.len() <= 32 {
        // Samples below the lowest level (the outside) stop at once; the others count
        // every level without a branch (the levels are sorted, so the levels at or
        // below a sample are the first ones).
        let lowest = sorted[0];
        values
            .iter()
            .map(|&v| {
                if lowest <= v {
                    sorted.iter().map(|&t| u16::from(t <= v)).sum()
                } else {
                    0
                }
            })
            .collect()
    } else {
        values
            .iter()
            .map(|&v| sorted.partition_point(|&t| t <= v) as u16)
            .collect()
    };
    // Edge ids: horizontal edge (i, j)-(i+1, j) is j * (nx - 1) + i; vertical edge
    // (i, j)-(i, j+1) is horizontal count + j * nx + i.
    let horizontal = (nx - 1) * ny;
    // A row of cells is first flagged in one branch-free sweep (a cell is crossed
    // when its corners' bands differ); most cells are not, and only the flagged ones
    // are looked at.
    let mut crossed = vec![false; nx - 1];
    for j in 0..ny - 1 {
        let (row, up) = (&band[j * nx..(j + 1) * nx], &band[(j + 1) * nx..(j + 2) * nx]);
        for (((c, &a), &b), (&u, &w)) in crossed
            .iter_mut()
            .zip(row)
            .zip(&row[1..])
            .zip(up.iter().zip(&up[1..]))
        {
            *c = (a != b) | (a != u) | (a != w);
        }
        for i in 0..nx - 1 {
            if !crossed[i] {
                continue;
            }
            let b = [row[i], row[i + 1], up[i + 1], up[i]];
            let lo = b[0].min(b[1]).min(b[2].min(b[3]));
            let hi = b[0].max(b[1]).max(b[2].max(b[3]));
            let k = j * nx + i;
            let v = [values[k], values[k + 1], values[k + nx + 1], values[k + nx]];
            for s in usize::from(lo)..usize::from(hi) {
                cell(
                    &v,
                    sorted[s],
                    [
                        j * (nx - 1) + i,
                        horizontal + j * nx + i + 1,
                        (j + 1) * (nx - 1) + i,
                        horizontal + j * nx + i,
                    ],
                    &mut links[order[s]],
                );
            }
        }
    }
    // One table of the next edge over every edge, filled and cleared level by level,
    // and kept per thread: it is megabytes on a fine grid, and every link is followed
    // once, which leaves it cleared for the next call.
    NEXT.with(|next| {
        let mut next = next.borrow_mut();
        let Next { table, clear } = &mut *next;
        // A call that stopped half-way (a panic caught further up) left it unknown.
        if !*clear {
            table.fill(u32::MAX);
        }
        let edges = horizontal + nx * (ny - 1);
        if table.len() < edges {
            table.resize(edges, u32::MAX);
        }
        *clear = false;
        let loops = follow(field, values, levels, links, horizontal, table);
        *clear = true;
        if table.len() > KEEP_EDGES {
            *table = Vec::new();
        }
        loops
    })
}

/// The edge table of [`iso_levels`], all `u32::MAX` while `clear`.
struct Next {
    table: Vec<u32>,
    clear: bool,
}

thread_local! {
    static NEXT: std::cell::RefCell<Next> = const { std::cell::RefCell::new(Next { table: Vec::new(), clear: true }) };
}

/// Largest edge table a thread keeps for the next call (a 1024 x 1024 field's, 8 MiB).
const KEEP_EDGES: usize = 1 << 21;

/// The loops of every level from its links, through `next` (all `u32::MAX` on entry
/// and on return).
fn follow(
    field: &Field,
    values: &[f64],
    levels: &[f64],
    links: Vec<Vec<(u32, u32)>>,
    horizontal: usize,
    next: &mut [u32],
) -> Vec<Vec<Contour>> {
    let nx = field.nx;
    links
        .into_iter()
        .enumerate()
        .map(|(l, links)| {
            let t = levels[l];
            let point = |edge: usize| -> Point2 {
                let (k0, k1) = if edge < horizontal {
                    let (j, i) = (edge / (nx - 1), edge % (nx - 1));
                    (j * nx + i, j * nx + i + 1)
                } else {
                    let e = edge - horizontal;
                    (e, e + nx)
                };
                let (v0, v1) = (values[k0], values[k1]);
                let s = if v1 != v0 {
                    ((t - v0) / (v1 - v0)).clamp(0.0, 1.0)
                } else {
                    0.5
                };
                let p0 = field.point(k0 % nx, k0 / nx);
                let p1 = field.point(k1 % nx, k1 / nx);
                p0 + (p1 - p0) * s
            };
            for &(from, to) in &links {
                next[from as usize] = to;
            }
            let mut loops = Vec::new();
            for &(start, _) in &links {
                let mut e = start as usize;
                let mut points = Vec::new();
                while next[e] != u32::MAX {
                    points.push(point(e));
                    let n = next[e] as usize;
                    next[e] = u32::MAX;
                    e = n;
                }
                if points.len() >= 3 {
                    loops.push(Contour::new(points));
                }
            }
            loops
        })
        .collect()
}

/// The segments of level `t` in one cell with corner values `v` (counter-clockwise from
/// the lower left) and edge ids `ids` (bottom, right, top, left), as links from the edge
/// a segment leaves the set by to the edge it enters by.
fn cell(v: &[f64; 4], t: f64, ids: [usize; 4], links: &mut Vec<(u32, u32)>) {
    let inside = [v[0] >= t, v[1] >= t, v[2] >= t, v[3] >= t];
    // Walking counter-clockwise, an edge from an inside corner to an outside one is an
    // exit; a segment runs from an exit to an entry.
    let mut exits = [0usize; 2];
    let mut entries = [0usize; 2];
    let (mut ne, mut nn) = (0, 0);
    for e in 0..4 {
        let (from_in, to_in) = (inside[e], inside[(e + 1) % 4]);
        if from_in && !to_in && ne < 2 {
            exits[ne] = e;
            ne += 1;
        } else if !from_in && to_in && nn < 2 {
            entries[nn] = e;
            nn += 1;
        }
    }
    let mut link = |a: usize, b: usize| links.push((ids[a] as u32, ids[b] as u32));
    if ne == 1 && nn == 1 {
        link(exits[0], entries[0]);
    } else if ne == 2 && nn == 2 {
        // Saddle, resolved by the cell's mean: inside corners joined through the centre
        // make an exit meet the next entry counter-clockwise; apart, the previous one.
        let joined = 0.25 * (v[0] + v[1] + v[2] + v[3]) >= t;
        for &x in &exits {
            let after = entries.iter().copied().min_by_key(|&n| (n + 4 - x) % 4);
            let before = entries.iter().copied().min_by_key(|&n| (x + 4 - n) % 4);
            if let Some(n) = if joined { after } else { before } {
                link(x, n);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn circle(cx: f64, cy: f64, r: f64, n: usize) -> Contour {
        Contour::circle(Point2::new(cx, cy), r, n)
    }

    /// The field over the first contour's box at 100 cells: distance inside the
    /// contours, its negative outside.
    fn signed(contours: &[&Contour]) -> (Field, Vec<f64>) {
        let mut f = Field::over(&contours[0].bbox(), 100);
        f.distance_to(contours);
        let inside = f.inside(contours);
        let values = f
            .values
            .iter()
            .zip(&inside)
            .map(|(&d, &i)| if i { d } else { -d })
            .collect();
        (f, values)
    }

    #[test]
    fn a_disc_level_is_one_counter_clockwise_circle() {
        let c = circle(0.0, 0.0, 10.0, 200);
        let (f, values) = signed(&[&c]);
        let loops = iso_loops(&f, &values, 4.0);
        assert_eq!(loops.len(), 1);
        let want = std::f64::consts::PI * 36.0;
        assert!(
            (loops[0].signed_area() - want).abs() / want < 1e-2,
            "{}",
            loops[0].signed_area()
        );
        // A disc with a hole: {d >= 1} is an annulus, two loops of positive total area.
        let hole = circle(0.0, 0.0, 3.0, 100).oriented(false);
        let (f, values) = signed(&[&c, &hole]);
        let ring = iso_loops(&f, &values, 1.0);
        let area: f64 = ring.iter().map(Contour::signed_area).sum();
        let want = std::f64::consts::PI * (81.0 - 16.0);
        assert!(
            ring.len() == 2 && (area - want).abs() / want < 2e-2,
            "{} loops, area {area}",
            ring.len()
        );
    }

    /// A field of `nx` by `ny` unit cells from the origin, with `values`.
    fn grid(nx: usize, ny: usize, values: Vec<f64>) -> Field {
        assert_eq!(values.len(), nx * ny);
        Field {
            nx,
            ny,
            origin: Point2::new(0.0, 0.0),
            h: 1.0,
            values,
        }
    }

    #[test]
    fn a_saddle_joins_or_parts_by_the_cells_mean() {
        // The middle cell's high corners are (1, 1) and (2, 2), its low ones 0.2; the
        // border is 0. Its mean is 0.6.
        let mut values = vec![0.0; 16];
        values[4 + 1] = 1.0;
        values[2 * 4 + 2] = 1.0;
        values[4 + 2] = 0.2;
        values[2 * 4 + 1] = 0.2;
        let f = grid(4, 4, values.clone());
        // Below the mean the high corners are joined through the centre: one loop.
        let joined = iso_loops(&f, &values, 0.5);
        assert_eq!(joined.len(), 1, "{joined:?}");
        assert!(joined[0].signed_area() > 0.0);
        // Above it, two loops, one round each high corner.
        let apart = iso_loops(&f, &values, 0.7);
        assert_eq!(apart.len(), 2, "{apart:?}");
        for l in &apart {
            assert!(l.signed_area() > 0.0);
            assert!(l.contains(Point2::new(1.0, 1.0)) != l.contains(Point2::new(2.0, 2.0)));
        }
        // The other diagonal high: the same, turned.
        let mut turned = vec![0.0; 16];
        turned[4 + 2] = 1.0;
        turned[2 * 4 + 1] = 1.0;
        turned[4 + 1] = 0.2;
        turned[2 * 4 + 2] = 0.2;
        assert_eq!(iso_loops(&f, &turned, 0.5).len(), 1);
        assert_eq!(iso_loops(&f, &turned, 0.7).len(), 2);
    }

    #[test]
    fn loop_vertices_lie_where_the_edge_reaches_the_level() {
        // A disc with a hole, cut at several levels: every vertex is on a grid edge,
        // where the straight line between the edge's samples takes the level; outer
        // loops run counter-clockwise and holes clockwise.
        let c = circle(0.5, -0.3, 10.0, 200);
        let hole = circle(2.0, 1.0, 3.0, 90).oriented(false);
        let (f, values) = signed(&[&c, &hole]);
        for t in [0.7, 1.5, 2.2] {
            let loops = iso_loops(&f, &values, t);
            assert_eq!(loops.len(), 2, "level {t}");
            let signs: Vec<bool> = loops.iter().map(|l| l.signed_area() > 0.0).collect();
            assert!(signs.contains(&true) && signs.contains(&false), "level {t}");
            for l in &loops {
                let outer = l.signed_area() > 0.0;
                // Only the outer loop holds a point of the disc away from the hole.
                assert_eq!(l.contains(Point2::new(-5.0, -0.3)), outer);
                for p in &l.points {
                    let (u, v) = ((p.x - f.origin.x) / f.h, (p.y - f.origin.y) / f.h);
                    let on_vertical = (u - u.round()).abs() < 1e-9;
                    let (i, j) = if on_vertical {
                        (u.round() as usize, v.floor() as usize)
                    } else {
                        assert!((v - v.round()).abs() < 1e-9, "{p:?} is off the grid's edges");
                        (u.floor() as usize, v.round() as usize)
                    };
                    let k0 = j * f.nx + i;
                    let (k1, s) = if on_vertical {
                        (k0 + f.nx, v - v.floor())
                    } else {
                        (k0 + 1, u - u.floor())
                    };
                    let at = values[k0] + s * (values[k1] - values[k0]);
                    assert!((at - t).abs() < 1e-9, "level {t}: {at} at {p:?}");
                }
            }
        }
    }

    #[test]
    fn many_levels_at_once_are_each_level_alone() {
        // Levels in no order, repeated and not a number, few (one pass per level) and
        // many (over 32: the levels are searched instead of counted), all above the
        // field's border.
        let c = circle(0.0, 0.0, 10.0, 200);
        let hole = circle(3.0, 0.0, 2.5, 90).oriented(false);
        let (f, values) = signed(&[&c, &hole]);
        let few = vec![3.0, 0.5, f64::NAN, 1.5, 3.0, 0.05, 20.0];
        let many: Vec<f64> = (0..45).map(|k| 9.0 - f64::from(k) * 0.19).collect();
        for levels in [few, many] {
            let all = iso_levels(&f, &values, &levels);
            assert_eq!(all.len(), levels.len());
            for (t, loops) in levels.iter().zip(&all) {
                let alone = if t.is_nan() {
                    Vec::new()
                } else {
                    iso_loops(&f, &values, *t)
                };
                let area = |l: &[Contour]| l.iter().map(Contour::signed_area).sum::<f64>();
                assert_eq!(loops.len(), alone.len(), "level {t}");
                assert!((area(loops) - area(&alone)).abs() < 1e-9, "level {t}");
            }
            // Nothing above the top of the field, and the levels that cut it give
            // areas that shrink as the level rises.
            let mut cut: Vec<(f64, f64)> = levels
                .iter()
                .zip(&all)
                .filter(|(t, _)| !t.is_nan())
                .map(|(t, l)| (*t, l.iter().map(Contour::signed_area).sum()))
                .collect();
            cut.sort_by(|a, b| a.0.total_cmp(&b.0));
            for w in cut.windows(2) {
                assert!(w[1].1 <= w[0].1 + 1e-9, "{w:?}");
            }
        }
        assert!(iso_levels(&f, &values, &[20.0])[0].is_empty());
        assert!(iso_levels(&f, &values, &[]).is_empty());
    }

    #[test]
    fn only_usual_fields_keep_their_edge_table() {
        let kept = || NEXT.with(|n| n.borrow().table.len());
        // A cone: v = 1 - distance from the middle, cut at 0.5.
        let cone = |n: usize| {
            let c = (n as f64 - 1.0) / 2.0;
            let values: Vec<f64> = (0..n * n)
                .map(|k| {
                    let (i, j) = ((k % n) as f64, (k / n) as f64);
                    1.0 - (i - c).hypot(j - c) / c
                })
                .collect();
            (grid(n, n, values.clone()), values)
        };
        let (f, values) = cone(64);
        assert_eq!(iso_loops(&f, &values, 0.5).len(), 1);
        assert!(kept() >= 2 * 63 * 64);
        // 1100 x 1100 samples, 2.4 million edges: beyond the 2^21 kept.
        let (f, values) = cone(1100);
        assert_eq!(iso_loops(&f, &values, 0.5).len(), 1);
        assert_eq!(kept(), 0);
    }
}
