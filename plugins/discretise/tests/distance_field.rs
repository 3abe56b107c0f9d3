//! The `distance-field` discretiser: iso-contours of the normalised distance to a
//! feature, clipped to the family, tile it; levels equal or step-width.

mod common;

use common::*;

#[test]
fn tube_field_from_outer_gives_rings_close_to_the_exact_ones() {
    let fam = OneFamily::new(circle(0.0, 0.0, 10.0, 512), vec![circle(0.0, 0.0, 5.0, 512)]);
    let regions = fam.run(&*stage(
        "use = \"distance-field\"\nfeature = \"outer\"\ncount = 5\ncells = 256",
    ));
    assert_tiles(&fam.polygon(), &regions);
    assert_eq!(indices(&regions), vec![0, 1, 2, 3, 4]);
    // r = d / 5 from the outer: band j is the ring 10 - j .. 9 - j.
    for r in &regions {
        let a = 10.0 - r.index as f64;
        let want = std::f64::consts::PI * (a * a - (a - 1.0) * (a - 1.0));
        assert!(
            (r.area() - want).abs() / want < 1e-2,
            "band {}: {} vs {want}",
            r.index,
            r.area()
        );
        assert!((r.level - r.index as f64 / 4.0).abs() < 1e-12);
    }
}

#[test]
fn step_width_levels_on_the_field() {
    let fam = OneFamily::new(rect(0.0, 0.0, 30.0, 20.0), vec![circle(20.0, 10.0, 4.0, 128)]);
    let regions = fam.run(&*stage("use = \"distance-field\"\nstep = 0.25"));
    assert_tiles(&fam.polygon(), &regions);
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
        "use = \"distance-field\"\nfeature = \"point\"\npoint = [0.0, 20.0]\ncell_size = 0.1",
    ] {
        let regions = fam.run(&*stage(text));
        assert_tiles(&fam.polygon(), &regions);
        assert!(regions.len() >= 4, "{text}: {}", regions.len());
    }
    // Thin wall: still tiles, with whatever bands the grid resolves.
    let thin = OneFamily::new(circle(0.0, 0.0, 2.54, 256), vec![circle(0.0, 0.0, 2.235, 256)]);
    assert_tiles(&thin.polygon(), &thin.run(&*stage("use = \"distance-field\"")));
}

#[test]
fn bad_field_options_are_refused() {
    assert!(build_error("use = \"distance-field\"\nfeature = \"point\"").contains("point"));
    assert!(build_error("use = \"distance-field\"\ncells = 2").contains("cells"));
    assert!(build_error("use = \"distance-field\"\nstep = 1.5").contains("step"));
}
