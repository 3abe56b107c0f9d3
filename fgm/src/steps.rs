//! The step-wise truncation of a grading function (grading-step-width paper, 3.1), in
//! one place so that every stage that truncates a grading (the `step-width` and
//! `distance-field` discretisers, the `sources` stage) accepts the same step widths
//! and cuts at the same values.
//!
//! The paper's rule for a step width t_g in (0, 1]: f = 0 for f < t_g / 2;
//! f = t_g (u + 1) for (u + 1/2) t_g <= f < (u + 3/2) t_g, u = 0, ..., N_c - 3; and
//! f = 1 for f >= (N_c - 3/2) t_g, with N_c = 1 / t_g + 1 levels. When t_g does not
//! divide 1, N_c = int(1 / t_g) + 1: the thresholds stay at the half steps and the last
//! level, 1, starts at the last half step below 1 (t_g = 0.3: levels 0, 0.3, 0.6, 1,
//! thresholds 0.15, 0.45, 0.75).

/// More levels than any process could deposit: a guard against typos such as 1e-9.
pub const MAX_LEVELS: usize = 10_001;

/// A step width and its N_c levels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truncation {
    /// t_g.
    pub step: f64,
    /// N_c.
    pub count: usize,
}

impl Truncation {
    /// Refuses a step outside (0, 1] or one so small that it gives more than
    /// [`MAX_LEVELS`] levels.
    pub fn new(step: f64) -> std::result::Result<Self, String> {
        if step.is_nan() || step <= 0.0 || step > 1.0 {
            return Err(format!("the step width t_g must lie in (0, 1], not {step}"));
        }
        // A step that divides 1 up to rounding (0.1 * 10 = 1.0000000000000002) counts
        // as dividing it.
        let steps = (1.0 / step + 1e-9).floor();
        if steps + 1.0 > MAX_LEVELS as f64 {
            return Err(format!(
                "the step width t_g = {step} gives more than {MAX_LEVELS} levels"
            ));
        }
        Ok(Self {
            step,
            count: steps as usize + 1,
        })
    }

    /// Level of band k (0 for k = 0): k t_g, and 1 for the last band.
    pub fn level(&self, k: usize) -> f64 {
        if k + 1 >= self.count {
            1.0
        } else {
            k as f64 * self.step
        }
    }

    /// The N_c levels, 0 first and 1 last.
    pub fn levels(&self) -> Vec<f64> {
        (0..self.count).map(|k| self.level(k)).collect()
    }

    /// The values of f where band k - 1 ends and band k starts, k in 1..N_c:
    /// (k - 1/2) t_g.
    pub fn thresholds(&self) -> Vec<f64> {
        (1..self.count).map(|k| (k as f64 - 0.5) * self.step).collect()
    }

    /// The band f falls in.
    pub fn band(&self, f: f64) -> usize {
        if f.is_nan() || f < 0.5 * self.step {
            return 0;
        }
        // The estimate, then settled against the thresholds as `thresholds` computes
        // them, so that a value exactly at a threshold is in the band it starts.
        let mut k = (((f / self.step) + 0.5).floor() as usize).min(self.count - 1);
        while k + 1 < self.count && (k as f64 + 0.5) * self.step <= f {
            k += 1;
        }
        while k > 0 && (k as f64 - 0.5) * self.step > f {
            k -= 1;
        }
        k
    }

    /// The truncated value of f: the level of its band.
    pub fn truncate(&self, f: f64) -> f64 {
        self.level(self.band(f))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The paper's example: t_g = 0.25 gives N_c = 5 contours, the levels 0, 0.25, 0.5,
    /// 0.75 and 1, changing at 0.125, 0.375, 0.625 and 0.875.
    #[test]
    fn quarter_steps_give_five_levels_at_half_steps() {
        let t = Truncation::new(0.25).unwrap();
        assert_eq!(t.count, 5);
        assert_eq!(t.levels(), [0.0, 0.25, 0.5, 0.75, 1.0]);
        assert_eq!(t.thresholds(), [0.125, 0.375, 0.625, 0.875]);
        for (f, want) in [
            (-0.3, 0.0),
            (0.0, 0.0),
            (0.124, 0.0),
            (0.125, 0.25),
            (0.374, 0.25),
            (0.375, 0.5),
            (0.625, 0.75),
            (0.874, 0.75),
            (0.875, 1.0),
            (1.0, 1.0),
            (1.7, 1.0),
        ] {
            assert_eq!(t.truncate(f), want, "f = {f}");
        }
    }

    /// t_g = 1 is the plain multi-material case (Fig. 4d): two levels split at 0.5.
    #[test]
    fn whole_step_is_two_materials() {
        let t = Truncation::new(1.0).unwrap();
        assert_eq!(t.levels(), [0.0, 1.0]);
        assert_eq!(t.thresholds(), [0.5]);
        assert_eq!(Truncation::new(0.1).unwrap().count, 11);
    }

    /// A step that does not divide 1 keeps the half-step thresholds; the last level is
    /// 1 from the last half step below 1.
    #[test]
    fn step_that_does_not_divide_one_ends_at_one() {
        let t = Truncation::new(0.3).unwrap();
        assert_eq!(t.count, 4);
        assert_eq!(t.levels(), [0.0, 0.3, 0.6, 1.0]);
        let th = t.thresholds();
        for (a, b) in th.iter().zip([0.15, 0.45, 0.75]) {
            assert!((a - b).abs() < 1e-12);
        }
        assert_eq!(t.truncate(0.74), 0.6);
        assert_eq!(t.truncate(0.76), 1.0);
        assert_eq!(t.truncate(0.449), 0.3);
    }

    /// A value exactly at a threshold, as `thresholds` computes it, starts its band;
    /// the float just below it is still in the band before. Steps whose thresholds
    /// are not exact in binary (0.1, 0.3, 0.07, 1/3) put the first estimate on the
    /// wrong side, which the band must settle.
    #[test]
    fn a_value_at_a_threshold_starts_its_band() {
        for step in [0.1, 0.3, 0.07, 1.0 / 3.0, 0.013, 0.25, 0.6] {
            let t = Truncation::new(step).unwrap();
            for (i, &th) in t.thresholds().iter().enumerate() {
                let k = i + 1;
                assert_eq!(t.band(th), k, "t_g = {step}, threshold {th}");
                let below = f64::from_bits(th.to_bits() - 1);
                assert_eq!(t.band(below), k - 1, "t_g = {step}, just below {th}");
                let mid = th + 0.5 * step;
                assert_eq!(t.band(mid), k, "t_g = {step}, {mid}");
                assert_eq!(t.truncate(th), t.level(k));
            }
            assert_eq!(t.band(f64::NAN), 0);
            assert_eq!(t.band(10.0), t.count - 1);
            assert_eq!(t.band(f64::INFINITY), t.count - 1);
        }
    }

    #[test]
    fn bad_steps_are_refused() {
        for s in [0.0, -0.25, 1.5, f64::NAN, 1e-9] {
            assert!(Truncation::new(s).is_err(), "{s}");
        }
    }
}
