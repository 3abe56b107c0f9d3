//! Layer thicknesses from the material (cmpm-process-planning 4.1): a periodic
//! microstructure is sprayed in layers of 1/10 to 1/20 of its base cell, usually under
//! 0.1 mm; an FGM or a composite in layers of 0.5 to 2 mm, thinner where its
//! composition changes faster along the build direction.

/// Thinnest and thickest layers of a graded or composite region (mm).
pub const GRADED_RANGE: (f64, f64) = (0.5, 2.0);

/// The layer of a microstructure whose base cell measures `base_cell` mm, in micrometres,
/// with the rule in words: a tenth of the cell where that is at most 0.1 mm, else a
/// twentieth (but no less than 0.1 mm). Whole tens of micrometres where the rule's
/// range holds one, so that work cycles stay short (a tenth rounded down, a twentieth
/// up, which stays within a tenth), whole micrometres for a tenth under 10 µm; `None`
/// for a cell under 10 µm, where no whole micrometre is a tenth of it or less.
pub fn microstructure_um(base_cell: f64) -> Option<(u64, String)> {
    let tenth_um = base_cell * 100.0;
    if tenth_um.is_nan() || tenth_um < 1.0 - 1e-9 {
        return None;
    }
    let (um, why) = if tenth_um <= 100.0 + 1e-9 {
        let um = (tenth_um + 1e-9).floor() as u64;
        (if um >= 10 { um / 10 * 10 } else { um }, "1/10")
    } else {
        // Rounded up to tens, a twentieth (at least 100 µm) stays within the tenth:
        // the tenth is over 100 µm here, and over the twentieth by more than 10 µm
        // once the twentieth is over 100.
        let twentieth = (base_cell * 50.0).max(100.0);
        (((twentieth - 1e-9) / 10.0).ceil() as u64 * 10, "1/20")
    };
    Some((um, format!("auto: {why} of the {base_cell} mm base cell")))
}

/// The layer of a graded region whose fractions change by at most `gradient` per mm
/// (`None`: not sampled, as for one material) when a layer may hold a change of
/// `step`: `step / gradient` within 0.5 to 2 mm, in whole tenths of a millimetre.
pub fn graded_um(gradient: Option<f64>, step: f64) -> (u64, String) {
    let g = gradient.unwrap_or(0.0);
    let (lo, hi) = GRADED_RANGE;
    let t = if g > 0.0 { (step / g).clamp(lo, hi) } else { hi };
    let um = ((t * 1000.0 + 1e-9).floor() as u64) / 100 * 100;
    let why = if g > 0.0 {
        format!("auto: fractions change by up to {g:.4} per mm, {step} per layer")
    } else {
        "auto: constant composition".to_string()
    };
    (um, why)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn microstructure_layers_are_a_tenth_or_a_twentieth_of_the_cell() {
        let um = |cell: f64| microstructure_um(cell).expect("a thickness").0;
        assert_eq!(um(1.0), 100);
        assert_eq!(um(0.6), 60);
        // A tenth of 3 mm is over 0.1 mm: a twentieth, 0.15 mm.
        assert_eq!(um(3.0), 150);
        // A twentieth of 1.5 mm is under 0.1 mm: 0.1 mm.
        assert_eq!(um(1.5), 100);
        assert_eq!(um(0.05), 5);
        // Within the rule's range: 2.1 mm takes 0.11 (1/19.1), not 0.10 (1/21).
        assert_eq!(um(2.1), 110);
        let t = um(3.9) as f64 / 1000.0;
        assert!((3.9 / 20.0..=3.9 / 10.0).contains(&t), "{t}");
        // A cell under 10 µm has no whole micrometre within a tenth of it; one of
        // exactly 10 µm has its tenth.
        assert!(microstructure_um(0.005).is_none());
        assert_eq!(um(0.01), 1);
        // Rounded up, a twentieth stays within the tenth from just over 1 mm on.
        for cell in [1.0001, 1.05, 1.99, 2.0, 2.01, 2.5, 7.3, 40.0] {
            let t = um(cell) as f64 / 1000.0;
            assert!(
                (cell / 20.0 - 1e-12..=cell / 10.0).contains(&t) && t >= 0.1,
                "{cell}: {t}"
            );
        }
        // The rule says which share it took: a tenth of exactly 1 mm is 0.1 mm.
        let rule = |cell: f64| microstructure_um(cell).expect("a thickness").1;
        assert_eq!(rule(1.0), "auto: 1/10 of the 1 mm base cell");
        assert_eq!(rule(1.0001), "auto: 1/20 of the 1.0001 mm base cell");
    }

    #[test]
    fn graded_layers_thin_where_the_composition_changes_faster() {
        // z / 6: a sixth per mm, 0.1 per layer: 0.6 mm.
        assert_eq!(graded_um(Some(1.0 / 6.0), 0.1).0, 600);
        // Faster: clamped at 0.5 mm; constant: 2 mm.
        assert_eq!(graded_um(Some(0.5), 0.1).0, 500);
        assert_eq!(graded_um(Some(0.0), 0.1).0, 2000);
        assert_eq!(graded_um(None, 0.1).0, 2000);
        // Slower: 1/16 per mm gives 1.6 mm.
        assert_eq!(graded_um(Some(1.0 / 16.0), 0.1).0, 1600);
    }
}
