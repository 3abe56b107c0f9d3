//! The `step-width` discretiser: t_g = 0.25 gives the five levels 0, .25, .5, .75, 1
//! with boundaries at the half steps, and the regions tile the family.

mod common;

use common::*;

#[test]
fn quarter_step_on_a_tube_gives_five_bands_at_half_steps() {
    let fam = OneFamily::new(circle(0.0, 0.0, 10.0, 512), vec![circle(0.0, 0.0, 2.0, 512)]);
    let regions = fam.tiles("use = \"step-width\"\nstep = 0.25\nfrom = \"outer\"");
    assert_eq!(indices(&regions), vec![0, 1, 2, 3, 4]);
    let levels: Vec<f64> = regions.iter().map(|r| r.level).collect();
    assert_eq!(levels, vec![0.0, 0.25, 0.5, 0.75, 1.0]);
    assert!(regions.iter().all(|r| r.count == 5));
    // d is normalised by the wall (8 mm): boundaries at 1, 3, 5 and 7 mm from the outer.
    let ring = |a: f64, b: f64| std::f64::consts::PI * (a * a - b * b);
    let want = [
        ring(10.0, 9.0),
        ring(9.0, 7.0),
        ring(7.0, 5.0),
        ring(5.0, 3.0),
        ring(3.0, 2.0),
    ];
    for (r, w) in regions.iter().zip(want) {
        assert!(
            (r.area() - w).abs() / w < 3e-3,
            "band {}: {} vs {w}",
            r.index,
            r.area()
        );
    }
}

#[test]
fn grading_width_and_power_move_the_boundaries() {
    let fam = OneFamily::new(rect(0.0, 0.0, 40.0, 40.0), vec![]);
    // f = (d / 4)^2: thresholds 0.25, 0.75 on f are d = 2 mm and d = 3.46 mm.
    let regions = fam.tiles("use = \"step-width\"\nstep = 0.5\nwidth = 4.0\npower = 2.0");
    assert_eq!(indices(&regions), vec![0, 1, 2]);
    let d1: f64 = 2.0;
    let d2 = 4.0 * 0.75f64.sqrt();
    let band0 = 1600.0 - (40.0 - 2.0 * d1).powi(2);
    assert!(
        (regions[0].area() - band0).abs() / band0 < 1e-6,
        "{}",
        regions[0].area()
    );
    let core = (40.0 - 2.0 * d2).powi(2);
    assert!((regions[2].area() - core).abs() / core < 1e-6);
}

/// Without a width, d is normalised by the inradius (with `from = "all"`), found to a
/// thousandth of the family's diagonal: a right triangle with 30 mm legs has r =
/// 8.787, so with t_g = 0.5 its core beyond 0.75 r is the triangle scaled by a
/// quarter about its incentre, 450 / 16 = 28.1 mm².
#[test]
fn without_a_width_d_is_normalised_by_the_inradius() {
    let fam = OneFamily::new(
        lamina_discretise::shapes::through(&[(0.0, 0.0), (30.0, 0.0), (0.0, 30.0)]),
        vec![],
    );
    let regions = fam.tiles("use = \"step-width\"\nstep = 0.5\nfrom = \"all\"");
    assert_eq!(indices(&regions), vec![0, 1, 2]);
    let core: f64 = regions.iter().filter(|r| r.index == 2).map(|r| r.area()).sum();
    assert!((core - 28.125).abs() / 28.125 < 0.05, "{core}");
    let rim: f64 = regions.iter().filter(|r| r.index == 0).map(|r| r.area()).sum();
    assert!((rim - 450.0 * (1.0 - 0.5625)).abs() / 196.875 < 0.01, "{rim}");
}

#[test]
fn step_width_tiles_awkward_families() {
    let fam = OneFamily::new(
        rect(0.0, 0.0, 20.0, 20.0),
        vec![
            rect(1.0, 1.0, 8.0, 18.0),
            rect(10.0, 1.0, 9.0, 9.0),
            circle(15.0, 15.0, 3.0, 40),
        ],
    );
    for text in [
        "use = \"step-width\"",
        "use = \"step-width\"\nstep = 0.1\nfrom = \"outer\"",
        "use = \"step-width\"\nstep = 1.0",
    ] {
        fam.tiles(text);
    }
}

/// A step that does not divide 1 follows the paper's rule as the `sources` stage does:
/// t_g = 0.3 gives the levels 0, 0.3, 0.6 and 1 split at f = 0.15, 0.45 and 0.75.
#[test]
fn step_that_does_not_divide_one_ends_at_one() {
    let fam = OneFamily::new(rect(0.0, 0.0, 40.0, 40.0), vec![]);
    let regions = fam.tiles("use = \"step-width\"\nstep = 0.3\nwidth = 10.0");
    assert_eq!(indices(&regions), vec![0, 1, 2, 3]);
    let levels: Vec<f64> = regions.iter().map(|r| r.level).collect();
    assert_eq!(levels, vec![0.0, 0.3, 0.6, 1.0]);
    // f = d / 10: the last boundary at d = 7.5 mm, leaving a 25 mm square core.
    assert!(
        (regions[3].area() - 625.0).abs() / 625.0 < 1e-6,
        "{}",
        regions[3].area()
    );
}

#[test]
fn bad_steps_are_refused() {
    for bad in [
        "step = 0.0",
        "step = 1.5",
        "step = 1e-9",
        "power = 0.0",
        "power = nan",
        "power = inf",
        "width = 0.0",
        "width = -2.0",
        "tolerance = 0.00001",
    ] {
        let key = bad.split(' ').next().unwrap_or_default();
        assert!(
            build_error(&format!("use = \"step-width\"\n{bad}")).contains(key),
            "{bad}"
        );
    }
}
