//! Marching squares: the closed boundary loops of `{v >= t}` on a field whose border
//! samples are below every level. Loops keep the set on their left (outer loops
//! counter-clockwise, holes clockwise); saddles are resolved by the cell's mean.

use lamina_core::{Contour, Point2};

use crate::field::Field;

/// The loops of `{v >= t}` over `values` (laid out as `field`'s samples).
pub fn iso_loops(field: &Field, values: &[f64], t: f64) -> Vec<Contour> {
    let (nx, ny) = (field.nx, field.ny);
    // Edge ids: horizontal edge (i, j)-(i+1, j) is j * (nx - 1) + i; vertical edge
    // (i, j)-(i, j+1) is horizontal count + j * nx + i.
    let horizontal = (nx - 1) * ny;
    let mut next = vec![u32::MAX; horizontal + nx * (ny - 1)];
    let mut starts = Vec::new();
    let above = |k: usize| values[k] >= t;
    for j in 0..ny - 1 {
        for i in 0..nx - 1 {
            let k00 = j * nx + i;
            let (k10, k01, k11) = (k00 + 1, k00 + nx, k00 + nx + 1);
            let case = usize::from(above(k00))
                | usize::from(above(k10)) << 1
                | usize::from(above(k11)) << 2
                | usize::from(above(k01)) << 3;
            if case == 0 || case == 15 {
                continue;
            }
            // The cell's edges counter-clockwise: bottom, right, top, left, each with
            // the corner it starts from.
            let edges = [
                (j * (nx - 1) + i, case & 1 != 0),
                (horizontal + j * nx + i + 1, case & 2 != 0),
                ((j + 1) * (nx - 1) + i, case & 4 != 0),
                (horizontal + j * nx + i, case & 8 != 0),
            ];
            // Walking counter-clockwise, an edge from an inside corner to an outside
            // one is an exit; a segment runs from an exit to an entry.
            let mut exits = [0usize; 2];
            let mut entries = [0usize; 2];
            let (mut ne, mut nn) = (0, 0);
            for e in 0..4 {
                let from_in = edges[e].1;
                let to_in = edges[(e + 1) % 4].1;
                if from_in && !to_in {
                    exits[ne] = e;
                    ne += 1;
                } else if !from_in && to_in {
                    entries[nn] = e;
                    nn += 1;
                }
            }
            let mut link = |a: usize, b: usize| {
                next[edges[a].0] = edges[b].0 as u32;
                starts.push(edges[a].0);
            };
            if ne == 1 {
                link(exits[0], entries[0]);
            } else {
                let mean = 0.25 * (values[k00] + values[k10] + values[k11] + values[k01]);
                // Inside corners joined through the centre: an exit meets the next
                // entry counter-clockwise; apart: the previous one.
                let joined = mean >= t;
                for &x in &exits {
                    let after = entries.iter().copied().min_by_key(|&n| (n + 4 - x) % 4);
                    let before = entries.iter().copied().min_by_key(|&n| (x + 4 - n) % 4);
                    if let Some(n) = if joined { after } else { before } {
                        link(x, n);
                    }
                }
            }
        }
    }
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
    let mut loops = Vec::new();
    for s in starts {
        if next[s] == u32::MAX {
            continue;
        }
        let mut points = Vec::new();
        let mut e = s;
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::circle;

    #[test]
    fn a_disc_level_is_one_counter_clockwise_circle() {
        let c = circle(0.0, 0.0, 10.0, 200);
        let mut f = Field::over(&c.bbox(), 100);
        f.distance_to(&[&c]);
        let inside = f.inside(&[&c]);
        let values: Vec<f64> = f
            .values
            .iter()
            .zip(&inside)
            .map(|(&d, &i)| if i { d } else { -d })
            .collect();
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
        let mut f = Field::over(&c.bbox(), 100);
        f.distance_to(&[&c, &hole]);
        let inside = f.inside(&[&c, &hole]);
        let values: Vec<f64> = f
            .values
            .iter()
            .zip(&inside)
            .map(|(&d, &i)| if i { d } else { -d })
            .collect();
        let ring = iso_loops(&f, &values, 1.0);
        let area: f64 = ring.iter().map(Contour::signed_area).sum();
        let want = std::f64::consts::PI * (81.0 - 16.0);
        assert!(
            ring.len() == 2 && (area - want).abs() / want < 2e-2,
            "{} loops, area {area}",
            ring.len()
        );
    }
}
