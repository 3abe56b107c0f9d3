//! The `distance-field` discretiser: iso-contours of the normalised distance to a
//! feature, clipped to the family, tile it; levels equal or step-width.

mod common;

use common::*;

#[test]
fn tube_field_from_outer_gives_rings_close_to_the_exact_ones() {
    let fam = OneFamily::new(circle(0.0, 0.0, 10.0, 512), vec![circle(0.0, 0.0, 5.0, 512)]);
    let regions = fam.tiles("use = \"distance-field\"\nfeature = \"outer\"\ncount = 5\nsamples = 256");
    assert_eq!(indices(&regions), vec![0, 1, 2, 3, 4]);
    // r = d / 5 from the outer: band j is the ring 10 - j .. 9 - j, with Eq. 2's
    // f = d / max(d) where it starts: j / 5.
    assert_ring_areas(&regions, 10.0, 1.0, 1e-2);
    for r in &regions {
        assert!(
            (r.level - r.index as f64 / 5.0).abs() < 1e-12,
            "{}: {}",
            r.index,
            r.level
        );
    }
}

/// The samples follow `sample_spacing` (mm) when it is given: 0.05 mm on the tube's
/// 20 mm is 403 samples, and gives the rings 256 samples give.
#[test]
fn sample_spacing_sets_the_fields_resolution() {
    let fam = OneFamily::new(circle(0.0, 0.0, 10.0, 512), vec![circle(0.0, 0.0, 5.0, 512)]);
    let regions =
        fam.tiles("use = \"distance-field\"\nfeature = \"outer\"\ncount = 5\nsample_spacing = 0.05");
    assert_eq!(indices(&regions), vec![0, 1, 2, 3, 4]);
    assert_ring_areas(&regions, 10.0, 1.0, 1e-2);
}

/// The distance from the centre (the family's pole) and from a given point: a disc's
/// bands from its centre are rings of equal width, and a square's bands from its
/// corner are quarter rings about that corner.
#[test]
fn centre_and_point_features_measure_from_where_they_say() {
    let disc = OneFamily::new(circle(0.0, 0.0, 10.0, 512), vec![]);
    let regions = disc.tiles("use = \"distance-field\"\nfeature = \"centre\"\ncount = 5\nsamples = 256");
    assert_eq!(indices(&regions), vec![0, 1, 2, 3, 4]);
    for r in &regions {
        let (a, b) = (2.0 * r.index as f64, 2.0 * (r.index + 1) as f64);
        let want = std::f64::consts::PI * (b * b - a * a);
        assert!(
            (r.area() - want).abs() / want < 2e-2,
            "ring {}: {} vs {want}",
            r.index,
            r.area()
        );
    }
    // 20 x 20 from the corner (0, 0): the largest distance is the far corner's,
    // 28.28, so band 0 is the quarter disc of radius 7.07 about the origin.
    let square = OneFamily::new(rect(0.0, 0.0, 20.0, 20.0), vec![]);
    let regions =
        square.tiles("use = \"distance-field\"\nfeature = \"point\"\npoint = [0.0, 0.0]\ncount = 4");
    let near: Vec<_> = regions.iter().filter(|r| r.index == 0).collect();
    let area: f64 = near.iter().map(|r| r.area()).sum();
    let want = std::f64::consts::PI * 50.0 / 4.0;
    assert!((area - want).abs() / want < 2e-2, "{area} vs {want}");
    assert!(near.iter().all(|r| r.reference.coords.norm() < 7.1), "{near:?}");
}

/// Iso-contours every 5 um over a largest distance of 10 mm (9.96 as sampled) would be
/// about 2,000 bands: refused by the limit on sub-regions, before the field is cut.
#[test]
fn a_spacing_finer_than_the_regions_limit_allows_is_refused() {
    let fam = OneFamily::new(rect(0.0, 0.0, 40.0, 20.0), vec![]);
    let e = fam
        .try_run(&*stage("use = \"distance-field\"\nspacing = 0.005"))
        .expect_err("about 2,000 bands")
        .to_string();
    assert!(
        e.contains("needs 1993 sub-regions") && e.contains("limits.regions"),
        "{e}"
    );
    assert!(
        fam.try_run(&*stage("use = \"distance-field\"\nspacing = 0.5"))
            .is_ok()
    );
}

/// A `sample_spacing` grid is counted against `grid_samples` before it is made: on a
/// 20 x 10 mm family every 0.5 mm, ceil(20 / 0.5) + 3 = 43 samples along the longer
/// side and 43 x 43 x 10 / 20 = 924.5 samples in all.
#[test]
fn a_sample_spacing_grid_is_counted_against_the_limit() {
    let fam = OneFamily::new(rect(0.0, 0.0, 20.0, 10.0), vec![]);
    let text = "use = \"distance-field\"\nsample_spacing = 0.5";
    let with = |grid_samples: u64| {
        let limits = lamina_core::Limits {
            grid_samples,
            ..Default::default()
        };
        fam.try_run(&*stage_with_limits(text, limits))
    };
    // The 256 `samples` it does not use are not counted (256² = 65,536 would be
    // refused here).
    assert!(with(925).is_ok());
    let e = with(924).expect_err("924.5 samples").to_string();
    assert!(e.contains("grid_samples") && e.contains("20.0 x 10.0 mm"), "{e}");
    // Without a spacing, `samples` squared is counted when the stage is built.
    let limits = lamina_core::Limits {
        grid_samples: 1000,
        ..Default::default()
    };
    let built = |samples: usize| {
        try_stage_with_limits(&format!("use = \"distance-field\"\nsamples = {samples}"), limits)
    };
    assert!(built(31).is_ok());
    let e = built(32).err().expect("1,024 samples").to_string();
    assert!(e.contains("samples") && e.contains("grid_samples"), "{e}");
}

#[test]
fn step_width_levels_on_the_field() {
    let fam = OneFamily::new(rect(0.0, 0.0, 30.0, 20.0), vec![circle(20.0, 10.0, 4.0, 128)]);
    let regions = fam.tiles("use = \"distance-field\"\nstep = 0.25");
    let mut levels: Vec<f64> = regions.iter().map(|r| r.level).collect();
    levels.dedup();
    assert_eq!(levels, vec![0.0, 0.25, 0.5, 0.75, 1.0]);
}

#[test]
fn every_feature_tiles() {
    let fam = OneFamily::new(
        rect(0.0, 0.0, 20.0, 20.0),
        vec![rect(2.0, 2.0, 5.0, 5.0), circle(14.0, 14.0, 3.0, 64)],
    );
    for text in [
        "use = \"distance-field\"",
        "use = \"distance-field\"\nfeature = \"holes\"\ncount = 6",
        "use = \"distance-field\"\nfeature = \"centre\"\ncount = 4",
        "use = \"distance-field\"\nfeature = \"point\"\npoint = [0.0, 20.0]\nsample_spacing = 0.1",
    ] {
        let regions = fam.tiles(text);
        assert!(regions.len() >= 4, "{text}: {}", regions.len());
    }
    // A sliver between the samples has no inside to measure: it is one region.
    let sliver = OneFamily::new(rect(0.0, 0.0, 10.0, 0.05), vec![]);
    for feature in ["outer", "boundary", "centre"] {
        let regions = sliver.tiles(&format!(
            "use = \"distance-field\"\nfeature = \"{feature}\"\nsamples = 8"
        ));
        assert_eq!(regions.len(), 1, "{feature}");
    }
    // Thin wall: still tiles, with whatever bands the grid resolves.
    let thin = OneFamily::new(circle(0.0, 0.0, 2.54, 256), vec![circle(0.0, 0.0, 2.235, 256)]);
    thin.tiles("use = \"distance-field\"");
}

#[test]
fn bad_field_options_are_refused() {
    assert_refused(&[
        ("use = \"distance-field\"\nfeature = \"point\"", "point"),
        ("use = \"distance-field\"\nsamples = 2", "samples"),
        ("use = \"distance-field\"\nsamples = 7", "samples"),
        ("use = \"distance-field\"\nsample_spacing = 0.0", "sample_spacing"),
        ("use = \"distance-field\"\nsample_spacing = inf", "sample_spacing"),
        ("use = \"distance-field\"\nsample_spacing = nan", "sample_spacing"),
        (
            "use = \"distance-field\"\nfeature = \"line\"\npoints = [[0.0, 0.0], [1.0, nan]]",
            "points",
        ),
        ("use = \"distance-field\"\nfeature = \"polyline\"", "points"),
        (
            "use = \"distance-field\"\nfeature = \"polyline\"\npoints = [[0.0, 0.0]]",
            "points",
        ),
        ("use = \"distance-field\"\nstep = 1.5", "step"),
        ("use = \"distance-field\"\nspacing = -1.0", "spacing"),
        ("use = \"distance-field\"\nwidth = 0.0", "width"),
        ("use = \"distance-field\"\ncount = 0", "count"),
        ("use = \"distance-field\"\ncount = 1001", "count"),
        ("use = \"distance-field\"\nspacing = 1.0\nstep = 0.5", "spacing"),
    ]);
}

/// Fig. 7 of the distance-field paper: a section whose largest distance from its
/// boundary is 11.76 (at the centre), iso-contours C1-C8 at the distances 0, 1.5, ...,
/// 10.5, the sub-regions R1-R7 between them (and the centre beyond C8), each with
/// Eq. 2's composition f1 = d / max(d).
#[test]
fn fig_7_iso_contours_every_one_and_a_half_over_a_maximum_of_11_76() {
    use lamina_discretise::distance_field::Levels;
    let a = 11.76;
    let fam = OneFamily::new(rect(-a, -a, 2.0 * a, 2.0 * a), vec![]);
    let df = lamina_test_support::boundary_field(Levels::Spacing(1.5), 256);
    let iso = df.iso_sets(&fam.polygon(), None).expect("a field");
    assert!((iso.max - 11.76).abs() < 0.05, "max(d) = {}", iso.max);
    // C2-C8 (C1 is the boundary, d = 0).
    assert_eq!(iso.cut.thresholds.len(), 7);
    for (k, t) in iso.cut.thresholds.iter().enumerate() {
        assert!((t * iso.max - 1.5 * (k + 1) as f64).abs() < 1e-9);
    }
    let regions = fam.tiles("use = \"distance-field\"\nspacing = 1.5\nsamples = 256");
    assert_eq!(indices(&regions), (0..8).collect::<Vec<_>>());
    for r in &regions {
        let j = r.index as f64;
        // Eq. 2 at the contour the region starts from.
        assert!(
            (r.level - 1.5 * j / iso.max).abs() < 1e-9,
            "R{}: {}",
            r.index + 1,
            r.level
        );
        // The iso-contours of a square's distance field are squares.
        let (outer, inner) = (2.0 * (a - 1.5 * j), 2.0 * (a - 1.5 * (j + 1.0)).max(0.0));
        let want = outer * outer - inner * inner;
        assert!(
            (r.area() - want).abs() / want < 1e-2,
            "R{}: {} vs {want}",
            r.index + 1,
            r.area()
        );
    }
    // Fractions of the maximum stay available: eight equal parts of r, each with
    // Eq. 2 where it starts, as the spacing's regions: 0, 0.125, ..., 0.875 (not
    // j / 7, which would give the band 0.875-1 f = 1 and band 1 0.1429).
    let parts = fam.run(&*stage("use = \"distance-field\"\ncount = 8"));
    assert_eq!(indices(&parts), (0..8).collect::<Vec<_>>());
    for r in &parts {
        assert!(
            (r.level - r.index as f64 / 8.0).abs() < 1e-12,
            "{}: {}",
            r.index,
            r.level
        );
    }
}

/// Material features beyond the boundary, centre and point: a straight line (the
/// bottom edge's line: d = y), a polyline (the mid-line: d = |y - 10|), and chosen
/// faces of the part's mesh (its x = 0 side: d = x in space).
#[test]
fn line_polyline_and_surface_features() {
    let fam = OneFamily::new(rect(0.0, 0.0, 40.0, 20.0), vec![]);
    let strips = |regions: &[lamina_core::SubRegion], want: &[f64]| {
        assert_tiles(&fam.polygon(), regions);
        assert_eq!(indices(regions), (0..want.len()).collect::<Vec<_>>());
        for (j, w) in want.iter().enumerate() {
            let got: f64 = regions.iter().filter(|r| r.index == j).map(|r| r.area()).sum();
            assert!((got - w).abs() / w < 1e-2, "band {j}: {got} vs {w}");
        }
    };
    // d = y, every 5 mm: four strips of 40 x 5. The line runs across the family
    // whichever two of its points are given, from its middle or its corner.
    for points in ["[[10.0, 0.0], [11.0, 0.0]]", "[[0.0, 0.0], [1.0, 0.0]]"] {
        let line = fam.run(&*stage(&format!(
            "use = \"distance-field\"\nfeature = \"line\"\npoints = {points}\nspacing = 5.0"
        )));
        strips(&line, &[200.0; 4]);
    }
    // From the family's centre too: d = |y - 10|, the middle band |y - 10| < 5 and
    // the rest, not a stadium about the 1 mm between the two points.
    let middle = fam.run(&*stage(
        "use = \"distance-field\"\nfeature = \"line\"\npoints = [[20.0, 10.0], [21.0, 10.0]]\ncount = 2",
    ));
    strips(&middle, &[400.0, 400.0]);
    // A polyline of two points is that segment, not a line: within half the largest
    // distance (the corner's, 18.03) of the segment from (15, 10) to (25, 10) lies a
    // stadium of 2 x 10 r + pi r^2 with r = 9.01.
    let segment = fam.run(&*stage(
        "use = \"distance-field\"\nfeature = \"polyline\"\npoints = [[15.0, 10.0], [25.0, 10.0]]\ncount = 2",
    ));
    let r = 325f64.sqrt() / 2.0;
    let want = 20.0 * r + std::f64::consts::PI * r * r;
    let got: f64 = segment.iter().filter(|s| s.index == 0).map(|s| s.area()).sum();
    assert!((got - want).abs() / want < 2e-2, "{got} vs {want}");
    // d = |y - 10|, two equal parts of r: the middle band |y - 10| < 5, then the rest.
    let mid = fam.run(&*stage(
        "use = \"distance-field\"\nfeature = \"polyline\"\npoints = [[0.0, 10.0], [20.0, 10.0], [40.0, 10.0]]\ncount = 2",
    ));
    strips(&mid, &[400.0, 400.0]);
    // The box's x = 0 face (outward normal -x): d = x, four equal parts.
    let mut solid = OneFamily::new(rect(0.0, 0.0, 40.0, 20.0), vec![]);
    solid.mesh = Some(box_mesh(40.0, 20.0, 10.0));
    let side = solid.run(&*stage(
        "use = \"distance-field\"\nfeature = \"surface\"\nfaces = { normal = [-1.0, 0.0, 0.0], within = 10.0 }\ncount = 4",
    ));
    strips(&side, &[200.0; 4]);
    assert!(side[0].reference.x < 10.0 && side[3].reference.x > 30.0);
    // Only a surface feature reads the mesh: the runtime gives it to those alone.
    assert!(stage("use = \"distance-field\"\nfeature = \"surface\"").reads_mesh());
    assert!(!stage("use = \"distance-field\"").reads_mesh());
    // Without a mesh, or with faces that select nothing, the stage says so.
    let d = stage("use = \"distance-field\"\nfeature = \"surface\"");
    let ctx_error = |fam: &OneFamily| fam.try_run(&*d).expect_err("refused").to_string();
    assert!(
        ctx_error(&fam).contains("needs the part's mesh"),
        "{}",
        ctx_error(&fam)
    );
    let none = stage(
        "use = \"distance-field\"\nfeature = \"surface\"\nfaces = { normal = [1.0, 1.0, 1.0], within = 1.0 }",
    );
    assert!(
        solid
            .try_run(&*none)
            .expect_err("refused")
            .to_string()
            .contains("no face")
    );
    assert!(
        build_error("use = \"distance-field\"\nfeature = \"line\"\npoints = [[0.0, 0.0]]").contains("points")
    );
    assert!(
        build_error("use = \"distance-field\"\nfeature = \"surface\"\nfaces = { normal = [0.0, 0.0, 0.0] }")
            .contains("faces")
    );
}

/// The distance in space is taken at the layer's mid-height: from the top face of a
/// 10 x 20 x 10 box, a layer 2 mm thick whose top is at z = 6 measures from z = 5, so
/// over the box the distance is 5, and beyond its x = 10 side it is
/// sqrt((x - 10)^2 + 25). Band 0 of four on a family 40 mm long then ends where that
/// reaches a quarter of the largest, sqrt(30^2 + 25) / 4.
#[test]
fn a_surface_feature_measures_at_the_layers_mid_height() {
    let mut fam = OneFamily::new(rect(0.0, 0.0, 40.0, 20.0), vec![]);
    fam.mesh = Some(box_mesh(10.0, 20.0, 10.0));
    (fam.layer.z, fam.layer.thickness) = (6.0, 2.0);
    let regions = fam.run(&*stage(
        "use = \"distance-field\"\nfeature = \"surface\"\nfaces = { normal = [0.0, 0.0, 1.0], within = 10.0 }\ncount = 4",
    ));
    assert_tiles(&fam.polygon(), &regions);
    let quarter = (900.0f64 + 25.0).sqrt() / 4.0;
    let want = 20.0 * (10.0 + (quarter * quarter - 25.0).sqrt());
    let got: f64 = regions.iter().filter(|r| r.index == 0).map(|r| r.area()).sum();
    assert!((got - want).abs() / want < 1e-2, "{got} vs {want}");
}

/// An axis-aligned box from the origin, outward winding.
fn box_mesh(x: f64, y: f64, z: f64) -> lamina_core::Mesh {
    use lamina_core::Point3;
    let vertices = vec![
        Point3::new(0.0, 0.0, 0.0),
        Point3::new(x, 0.0, 0.0),
        Point3::new(x, y, 0.0),
        Point3::new(0.0, y, 0.0),
        Point3::new(0.0, 0.0, z),
        Point3::new(x, 0.0, z),
        Point3::new(x, y, z),
        Point3::new(0.0, y, z),
    ];
    let triangles = vec![
        [0, 2, 1],
        [0, 3, 2],
        [4, 5, 6],
        [4, 6, 7],
        [0, 1, 5],
        [0, 5, 4],
        [2, 3, 7],
        [2, 7, 6],
        [1, 2, 6],
        [1, 6, 5],
        [0, 4, 7],
        [0, 7, 3],
    ];
    lamina_core::Mesh::new("box", vertices, triangles)
}
