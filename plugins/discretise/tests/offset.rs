//! The `offset` discretiser on generated families: N_R by the L_s / D_N rule, levels of
//! Eq. 21, ring areas, vanishing thin walls, islands, degenerate input, and exact tiling.

mod common;

use common::*;
use lamina_core::{Contour, Point2};

fn tube(r_out: f64, r_in: f64) -> OneFamily {
    OneFamily::new(circle(0.0, 0.0, r_out, 512), vec![circle(0.0, 0.0, r_in, 512)])
}

/// The paper's Method 1 by default (Eq. 14-16, Fig. 5): the outer contour moves toward
/// the hole one nozzle at a time, N_R = int(L_s / D_N), and the last ring keeps what
/// is left, with the levels of Eq. 21.
#[test]
fn default_offsets_the_outer_contour_by_the_nozzle_with_int_ls_over_dn_rings() {
    let fam = tube(10.0, 5.0);
    let regions = fam.tiles("use = \"offset\"\nnozzle = 0.4");
    // L_s = 5 (inscribed 512-gons: 4.9998), N_R = int(4.9998 / 0.4) = 12; offsets at
    // 0.4, 0.8, ..., 4.4 mm, the last ring from 5.6 mm down to the bore.
    assert_eq!(regions.len(), 12);
    assert_eq!(indices(&regions), (0..12).collect::<Vec<_>>());
    let bore = fam.polygon().holes[0].area().abs();
    for (j, r) in regions.iter().enumerate() {
        assert_eq!(r.count, 12);
        assert!((r.level - j as f64 / 11.0).abs() < 1e-12);
        assert!(r.polygon.holes.len() == 1, "ring {j} is an annulus");
        let a = 10.0 - 0.4 * j as f64;
        let ring = if j < 11 {
            let b = a - 0.4;
            std::f64::consts::PI * (a * a - b * b)
        } else {
            std::f64::consts::PI * a * a - bore
        };
        // The offsetter drops vertices up to a fifth of the chord tolerance (0.0125 mm
        // by default) inside the contour it moves: a ring's area is exact to within that
        // distance along one of its circles.
        let slack = 0.2 * 0.0125 * std::f64::consts::TAU * a;
        assert!(
            (r.area() - ring).abs() < slack,
            "ring {j}: {} vs {ring} (within {slack})",
            r.area()
        );
    }
    // The same as the explicit form.
    let outer = fam.run(&*stage(
        "use = \"offset\"\nnozzle = 0.4\nfrom = \"outer\"\nspacing = 0.4",
    ));
    assert_eq!(outer.len(), regions.len());
    for (a, b) in outer.iter().zip(&regions) {
        assert!((a.area() - b.area()).abs() < 1e-9);
    }
}

/// `from = "all"`: the bore moves out as the rim moves in, one nozzle at a time, and
/// they meet halfway: N_R = int(L_s / 2 / D_N).
#[test]
fn from_all_moves_the_holes_too_and_meets_halfway() {
    let fam = tube(10.0, 5.0);
    let regions = fam.tiles("use = \"offset\"\nnozzle = 0.4\nfrom = \"all\"");
    // Reach L_s / 2 = 2.4999: int(2.4999 / 0.4) = 6.
    assert_eq!(indices(&regions), (0..6).collect::<Vec<_>>());
    // Ring 0 touches both boundaries: two annuli (outer band and hole band), each
    // 0.4 mm wide.
    let ring0: Vec<_> = regions.iter().filter(|r| r.index == 0).collect();
    assert_eq!(ring0.len(), 2);
    let want = std::f64::consts::PI * ((10.0f64.powi(2) - 9.6f64.powi(2)) + (5.4f64.powi(2) - 25.0));
    let got: f64 = ring0.iter().map(|r| r.area()).sum();
    assert!((got - want).abs() / want < 2e-3, "{got} vs {want}");
}

#[test]
fn given_count_and_spacing_are_used() {
    let fam = tube(10.0, 5.0);
    let regions = fam.tiles("use = \"offset\"\ncount = 4\nspacing = 0.5\nfrom = \"outer\"");
    assert_eq!(indices(&regions), vec![0, 1, 2, 3]);
    // The core takes everything beyond 1.5 mm.
    let core = regions.iter().find(|r| r.index == 3).expect("core");
    let want = std::f64::consts::PI * (8.5f64.powi(2) - 25.0);
    assert!((core.area() - want).abs() / want < 2e-3);
}

/// A band of three corners is a region: a triangle offset once is its triangle whole,
/// offset twice a smaller triangle inside a ring.
#[test]
fn a_triangle_band_is_a_region() {
    let fam = OneFamily::new(
        Contour::new(vec![
            Point2::new(0.0, 0.0),
            Point2::new(30.0, 0.0),
            Point2::new(0.0, 30.0),
        ]),
        vec![],
    );
    let one = fam.tiles("use = \"offset\"\ncount = 1");
    assert_eq!(one.len(), 1);
    assert_eq!(one[0].polygon.outer.len(), 3, "{:?}", one[0].polygon);
    let two = fam.tiles("use = \"offset\"\ncount = 2\njoin = \"miter\"");
    assert_eq!(indices(&two), vec![0, 1]);
    assert!(
        two.iter().any(|r| r.index == 1 && r.polygon.outer.len() == 3),
        "{two:?}"
    );
    // Two rings share the reach, the inradius r = (30 + 30 - 30 sqrt 2) / 2 = 8.787,
    // found to a twentieth of the nozzle: the inner one, offset by r / 2, is the
    // triangle halved about its incentre, a quarter of its 450 mm².
    let inner: f64 = two.iter().filter(|r| r.index == 1).map(|r| r.area()).sum();
    assert!((inner - 112.5).abs() < 0.5, "{inner}");
    // Without a count, N_R = int(8.787 / 0.4) = int(21.97) = 21 rings, by the nozzle
    // or by a spacing as wide: the reach is found closely enough to keep the 21st.
    for text in [
        "use = \"offset\"\nnozzle = 0.4",
        "use = \"offset\"\nspacing = 0.4",
    ] {
        assert_eq!(fam.tiles(text).len(), 21, "{text}");
    }
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
        let regions = fam.tiles(text);
        assert!(regions.len() > 3, "{text}");
    }
}

#[test]
fn thin_wall_vanishes_into_one_region() {
    // tube_round.stl: OD 5.08 mm, ID 4.47 mm, a 0.305 mm wall.
    let fam = tube(2.54, 2.235);
    let default = fam.tiles("use = \"offset\"\nnozzle = 0.4");
    assert_eq!(default.len(), 1);
    assert_eq!(default[0].count, 1);
    let ten = fam.tiles("use = \"offset\"\ncount = 10\nspacing = 0.4");
    assert_eq!(indices(&ten), vec![0]);
    assert_eq!(ten[0].level, 0.0);
    // With a small step the wall holds a few rings before the offsets reach the bore
    // (0.305 / 0.05: six rings and the remainder), or meet halfway from both sides.
    let fine = fam.tiles("use = \"offset\"\ncount = 10\nspacing = 0.05");
    assert_eq!(indices(&fine), (0..7).collect::<Vec<_>>());
    let both = fam.tiles("use = \"offset\"\ncount = 10\nspacing = 0.05\nfrom = \"all\"");
    assert_eq!(indices(&both), vec![0, 1, 2, 3]);
}

#[test]
fn dumbbell_splits_into_islands() {
    let outer = dumbbell();
    let fam = OneFamily::new(outer, vec![]);
    let regions = fam.tiles("use = \"offset\"\ncount = 6\nspacing = 0.75");
    // The 1 mm bridge is gone after the first ring: every later ring and the core are
    // two islands.
    for j in 1..6 {
        assert_eq!(regions.iter().filter(|r| r.index == j).count(), 2, "ring {j}");
    }
    // Default: reach = inradius 5, N_R = int(5 / 0.4) = 12.
    let regions = fam.tiles("use = \"offset\"");
    assert_eq!(regions[0].count, 12);
}

#[test]
fn degenerate_families_fall_back_without_panicking() {
    let flat = flat_family();
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
    touching.tiles("use = \"offset\"\ncount = 3\nspacing = 0.1");
    let tiny = OneFamily::new(rect(0.0, 0.0, 1e-9, 1e-9), vec![]);
    assert!(!tiny.run(&*stage("use = \"offset\"")).is_empty());
}

#[test]
fn bad_options_are_refused() {
    assert_refused(&[
        ("use = \"offset\"\nnozzle = -1.0", "nozzle"),
        ("use = \"offset\"\ncount = 0", "count"),
        ("use = \"offset\"\nspacing = 0.0", "spacing"),
        ("use = \"offset\"\nnozzle = 0.0", "nozzle"),
        ("use = \"offset\"\nnozzle = nan", "nozzle"),
        ("use = \"offset\"\ntolerance = 0.00001", "tolerance"),
        ("use = \"offset\"\ncount = 1001", "count"),
    ]);
    assert!(!build_error("use = \"offset\"\nfrom = \"inner\"").is_empty());
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
            ("use = \"offset\"\ncount = 10", 10),
            ("use = \"offset\"\ncount = 10\nfrom = \"all\"", 10),
            ("use = \"offset\"\nnozzle = 0.4\nfrom = \"all\"", 6),
            ("use = \"offset\"\nnozzle = 0.4", 12),
            ("use = \"step-width\"\nstep = 0.125", 9),
        ] {
            let regions = fam.tiles(text);
            assert_eq!(indices(&regions), (0..rings).collect::<Vec<_>>(), "{text}");
            for j in 0..rings {
                let ring: Vec<_> = regions.iter().filter(|r| r.index == j).collect();
                // From every boundary, the rings are pairs of annuli (one along the outer
                // contour, one along the bore) until they meet in the last one.
                let pairs = text.contains("all") || text.contains("step-width");
                let want = if !pairs || j + 1 == rings { 1 } else { 2 };
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
