//! The `offset` discretiser on generated families: N_R by the L_s / D_N rule, levels of
//! Eq. 21, ring areas, vanishing thin walls, islands, degenerate input, and exact tiling.

mod common;

use common::*;
use lamina_core::{Contour, Point2};

fn tube(r_out: f64, r_in: f64) -> OneFamily {
    OneFamily::new(circle(0.0, 0.0, r_out, 512), vec![circle(0.0, 0.0, r_in, 512)])
}

#[test]
fn tube_from_outer_has_int_ls_over_dn_rings_with_eq21_levels() {
    let fam = tube(10.0, 5.0);
    let regions = fam.run(&*stage("use = \"offset\"\nnozzle = 0.4\nfrom = \"outer\""));
    assert_tiles(&fam.polygon(), &regions);
    // L_s = 5 (inscribed 512-gons: 4.9998), int(5 / 0.4) = 12 rings of 5 / 12 mm.
    assert_eq!(regions.len(), 12);
    assert_eq!(indices(&regions), (0..12).collect::<Vec<_>>());
    let s = fam.polygon().holes[0].distance(Point2::new(10.0, 0.0)).min(5.0) / 12.0;
    for (j, r) in regions.iter().enumerate() {
        assert_eq!(r.count, 12);
        assert!((r.level - j as f64 / 11.0).abs() < 1e-12);
        let (a, b) = (10.0 - j as f64 * s, 10.0 - (j + 1) as f64 * s);
        let ring = std::f64::consts::PI * (a * a - b * b);
        assert!(
            (r.area() - ring).abs() / ring < 2e-3,
            "ring {j}: {} vs {ring}",
            r.area()
        );
        assert!(r.polygon.holes.len() == 1, "ring {j} is an annulus");
    }
}

#[test]
fn tube_from_all_meets_halfway() {
    let fam = tube(10.0, 5.0);
    let regions = fam.run(&*stage("use = \"offset\"\nnozzle = 0.4"));
    assert_tiles(&fam.polygon(), &regions);
    // Reach L_s / 2 = 2.5: int(2.5 / 0.4) = 6.
    assert_eq!(indices(&regions), (0..6).collect::<Vec<_>>());
    // Ring 0 touches both boundaries: two annuli (outer band and hole band).
    assert_eq!(regions.iter().filter(|r| r.index == 0).count(), 2);
}

#[test]
fn given_count_and_spacing_are_used() {
    let fam = tube(10.0, 5.0);
    let regions = fam.run(&*stage(
        "use = \"offset\"\ncount = 4\nspacing = 0.5\nfrom = \"outer\"",
    ));
    assert_tiles(&fam.polygon(), &regions);
    assert_eq!(indices(&regions), vec![0, 1, 2, 3]);
    // The core takes everything beyond 1.5 mm.
    let core = regions.iter().find(|r| r.index == 3).expect("core");
    let want = std::f64::consts::PI * (8.5f64.powi(2) - 25.0);
    assert!((core.area() - want).abs() / want < 2e-3);
}

#[test]
fn square_with_holes_tiles() {
    let holes = vec![
        rect(3.0, 3.0, 4.0, 4.0),
        rect(13.0, 3.0, 4.0, 4.0),
        rect(3.0, 13.0, 4.0, 4.0),
        circle(15.0, 15.0, 2.0, 64),
    ];
    let fam = OneFamily::new(rect(0.0, 0.0, 20.0, 20.0), holes);
    for text in [
        "use = \"offset\"\nnozzle = 0.4",
        "use = \"offset\"\ncount = 10\nspacing = 0.4",
        "use = \"offset\"\ncount = 10\nspacing = 0.4\njoin = \"miter\"",
        "use = \"offset\"\ncount = 7\nfrom = \"outer\"\njoin = \"bevel\"",
    ] {
        let regions = fam.run(&*stage(text));
        assert_tiles(&fam.polygon(), &regions);
        assert!(regions.len() > 3, "{text}");
    }
}

#[test]
fn thin_wall_vanishes_into_one_region() {
    // tube_round.stl: OD 5.08 mm, ID 4.47 mm, a 0.305 mm wall.
    let fam = tube(2.54, 2.235);
    let default = fam.run(&*stage("use = \"offset\"\nnozzle = 0.4"));
    assert_tiles(&fam.polygon(), &default);
    assert_eq!(default.len(), 1);
    assert_eq!(default[0].count, 1);
    let ten = fam.run(&*stage("use = \"offset\"\ncount = 10\nspacing = 0.4"));
    assert_tiles(&fam.polygon(), &ten);
    assert_eq!(indices(&ten), vec![0]);
    assert_eq!(ten[0].level, 0.0);
    // With a small step the wall holds a few rings before the offsets meet.
    let fine = fam.run(&*stage("use = \"offset\"\ncount = 10\nspacing = 0.05"));
    assert_tiles(&fam.polygon(), &fine);
    assert_eq!(indices(&fine), vec![0, 1, 2, 3]);
}

#[test]
fn dumbbell_splits_into_islands() {
    let outer = Contour::new(vec![
        Point2::new(0.0, 0.0),
        Point2::new(10.0, 0.0),
        Point2::new(10.0, 4.5),
        Point2::new(20.0, 4.5),
        Point2::new(20.0, 0.0),
        Point2::new(30.0, 0.0),
        Point2::new(30.0, 10.0),
        Point2::new(20.0, 10.0),
        Point2::new(20.0, 5.5),
        Point2::new(10.0, 5.5),
        Point2::new(10.0, 10.0),
        Point2::new(0.0, 10.0),
    ]);
    let fam = OneFamily::new(outer, vec![]);
    let regions = fam.run(&*stage("use = \"offset\"\ncount = 6\nspacing = 0.75"));
    assert_tiles(&fam.polygon(), &regions);
    // The 1 mm bridge is gone after the first ring: every later ring and the core are
    // two islands.
    for j in 1..6 {
        assert_eq!(regions.iter().filter(|r| r.index == j).count(), 2, "ring {j}");
    }
    // Default: reach = inradius 5, N_R = int(5 / 0.4) = 12.
    let regions = fam.run(&*stage("use = \"offset\""));
    assert_tiles(&fam.polygon(), &regions);
    assert_eq!(regions[0].count, 12);
}

#[test]
fn degenerate_families_fall_back_without_panicking() {
    let flat = OneFamily::new(
        Contour::new(vec![
            Point2::new(0.0, 0.0),
            Point2::new(1.0, 0.0),
            Point2::new(2.0, 0.0),
        ]),
        vec![],
    );
    let regions = flat.run(&*stage("use = \"offset\""));
    assert_eq!(regions.len(), 1);
    // Two squares touching at a corner, as one self-touching contour.
    let touching = OneFamily::new(
        Contour::new(vec![
            Point2::new(0.0, 0.0),
            Point2::new(1.0, 0.0),
            Point2::new(1.0, 1.0),
            Point2::new(2.0, 1.0),
            Point2::new(2.0, 2.0),
            Point2::new(1.0, 2.0),
            Point2::new(1.0, 1.0),
            Point2::new(0.0, 1.0),
        ]),
        vec![],
    );
    let regions = touching.run(&*stage("use = \"offset\"\ncount = 3\nspacing = 0.1"));
    assert_tiles(&touching.polygon(), &regions);
    let tiny = OneFamily::new(rect(0.0, 0.0, 1e-9, 1e-9), vec![]);
    assert!(!tiny.run(&*stage("use = \"offset\"")).is_empty());
}

#[test]
fn bad_options_are_refused() {
    assert!(build_error("use = \"offset\"\nnozzle = -1.0").contains("nozzle"));
    assert!(build_error("use = \"offset\"\ncount = 0").contains("count"));
    assert!(!build_error("use = \"offset\"\nfrom = \"inner\"").is_empty());
    assert!(build_error("use = \"offset\"\nspacing = 0.0").contains("spacing"));
}

/// A circle as an STL slice delivers it: the side of a triangulated cylinder cut at a
/// quarter of its height gives a vertex on each vertical edge and one on each diagonal,
/// a quarter along the chord, all rounded to f32. The nearly straight corners at the
/// chord points are where offsets used to spike back to the boundary and cut the rings.
fn sliced_circle(r: f64, n: usize) -> Contour {
    let c = circle(0.0, 0.0, r, n);
    let f = |p: Point2| Point2::new(f64::from(p.x as f32), f64::from(p.y as f32));
    let mut points = Vec::with_capacity(2 * n);
    for (a, b) in c.edges() {
        points.push(f(a));
        points.push(f(a + (b - a) * 0.25));
    }
    Contour::new(points)
}

#[test]
fn tube_ring_split_into_pieces() {
    for n in [128, 240, 256, 1000] {
        let fam = OneFamily::new(sliced_circle(10.0, n), vec![sliced_circle(5.0, n)]);
        for (text, rings) in [
            ("use = \"offset\"\ncount = 10\nfrom = \"outer\"", 10),
            ("use = \"offset\"\ncount = 10", 10),
            ("use = \"offset\"\nnozzle = 0.4", 6),
            ("use = \"step-width\"\nstep = 0.125", 9),
        ] {
            let regions = fam.run(&*stage(text));
            assert_tiles(&fam.polygon(), &regions);
            assert_eq!(indices(&regions), (0..rings).collect::<Vec<_>>(), "{text}");
            for j in 0..rings {
                let ring: Vec<_> = regions.iter().filter(|r| r.index == j).collect();
                // From every boundary, the rings are pairs of annuli (one along the outer
                // contour, one along the bore) until they meet in the last one.
                let want = if text.contains("outer") || j + 1 == rings {
                    1
                } else {
                    2
                };
                assert!(
                    ring.len() == want && ring.iter().all(|r| r.polygon.holes.len() == 1),
                    "{n}-gon, {text}: ring {j} is {} polygons with {:?} holes",
                    ring.len(),
                    ring.iter().map(|r| r.polygon.holes.len()).collect::<Vec<_>>()
                );
            }
        }
    }
}
