//! A mixing head following the gradient along a bead (`mix_along`): the composition at
//! a point of a sub-region from the compositions its grader gave at points of it.

use lamina_api::{Composition, Point2, Sample, SubRegion};

/// The composition a bead deposits at `p`, from the samples nearest to it: a
/// least-squares plane through the eight nearest (exact where the composition varies
/// linearly, as Eq. 18 does across a ring), clamped to [0, 1] and normalised; the
/// nearest sample's where they lie on a line; the region's own without samples.
pub(crate) fn composition_at(region: &SubRegion, p: Point2) -> Option<Composition> {
    const K: usize = 8;
    let mut near: Vec<(f64, &Sample)> = Vec::with_capacity(K + 1);
    for s in &region.samples {
        let d2 = (s.at - p).norm_squared();
        if near.len() < K || d2 < near[K - 1].0 {
            let at = near.partition_point(|(d, _)| *d <= d2);
            near.insert(at, (d2, s));
            near.truncate(K);
        }
    }
    let Some(&(_, first)) = near.first() else {
        return region.composition.clone();
    };
    // Normal equations of f = a + b dx + c dy, with (dx, dy) = sample - p.
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    for (_, s) in &near {
        let v = nalgebra::Vector3::new(1.0, s.at.x - p.x, s.at.y - p.y);
        m += v * v.transpose();
    }
    // Samples on (or nearly on) one line leave the plane's slope across it to
    // rounding: then the nearest sample's composition stands.
    let singular = m.singular_values();
    let well_posed = near.len() >= 3 && singular.min() > 1e-9 * singular.max();
    let Some(inverse) = m.try_inverse().filter(|_| well_posed) else {
        return Some(first.composition.clone());
    };
    let n = first.composition.fractions.len();
    let mut fractions: Vec<f64> = (0..n)
        .map(|k| {
            let mut rhs = nalgebra::Vector3::zeros();
            for (_, s) in &near {
                let v = nalgebra::Vector3::new(1.0, s.at.x - p.x, s.at.y - p.y);
                rhs += v * s.composition.fractions.get(k).copied().unwrap_or(0.0);
            }
            (inverse * rhs)[0].clamp(0.0, 1.0)
        })
        .collect();
    let total: f64 = fractions.iter().sum();
    if !(total > 0.0 && total.is_finite()) {
        return Some(first.composition.clone());
    }
    fractions.iter_mut().for_each(|f| *f /= total);
    Some(Composition { fractions })
}

#[cfg(test)]
mod tests {
    use super::*;
    use lamina_api::{Contour, Polygon};

    /// Samples of a linear field on a grid give the field exactly between them and
    /// just beyond, and a region without samples answers with its own composition.
    #[test]
    fn composition_at_follows_a_linear_field_between_samples() {
        let field = |x: f64| (0.1 + 0.08 * x).clamp(0.0, 1.0);
        let mut region = SubRegion {
            family: 0,
            index: 0,
            count: 1,
            level: 0.0,
            polygon: Polygon::new(Contour::square(Point2::new(5.0, 5.0), 5.0), vec![]),
            cell: None,
            reference: Point2::new(5.0, 5.0),
            composition: Some(Composition::binary(0.5).expect("valid")),
            samples: Vec::new(),
        };
        assert_eq!(composition_at(&region, Point2::new(1.0, 1.0)), region.composition);
        for i in 0..=10 {
            for j in 0..=10 {
                let at = Point2::new(f64::from(i), f64::from(j));
                let f = field(at.x);
                region.samples.push(Sample {
                    at,
                    composition: Composition::new(vec![f, 1.0 - f]).expect("valid"),
                });
            }
        }
        let c = composition_at(&region, Point2::new(3.3, 7.6)).expect("sampled");
        assert!((c.fractions[0] - field(3.3)).abs() < 1e-9, "{c:?}");
        assert!((c.fractions.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        // Just beyond the samples the plane goes on; far beyond, the nearest samples lie
        // on one line (x = 10) and the nearest one's composition stands.
        let c = composition_at(&region, Point2::new(10.5, 5.0)).expect("sampled");
        assert!((c.fractions[0] - field(10.5)).abs() < 1e-9, "{c:?}");
        let c = composition_at(&region, Point2::new(40.0, 5.0)).expect("sampled");
        assert!((c.fractions[0] - field(10.0)).abs() < 1e-9, "{c:?}");
    }
}
