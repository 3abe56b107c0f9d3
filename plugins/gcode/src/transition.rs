//! Where the transition after a change of tool or mix goes.
//!
//! A mixing head does not change its mix at once: after `M163`/`M164` the nozzle's
//! chamber still holds the old mix, and what comes out approaches the new one as the
//! chamber is flushed. Modelled as a stirred chamber, the share of the old mix left
//! after `v` mm³ is `exp(-v / tau)`, with `tau` a third of the head's
//! `transition_volume` V_t (the volume after which 95 % of the chamber is the new mix).
//! The model follows the nozzle's actual composition from bead to bead, so a change
//! that comes before the last one was flushed starts from what the nozzle holds.
//!
//! On a graded part that transition does no harm where the design wants a composition
//! between the old and the new one. The beads after a change (design composition B,
//! `V_B` mm³ of them up to the next change) may take it as long as the composition they
//! receive, on average, stays within half the family's design step `s` of B (the step:
//! the largest difference between the compositions of neighbouring sub-regions, see
//! [`design_step`]). Starting from a nozzle that differs from B by a share `m` and
//! purging `P` mm³ first (on the wipe tower), the beads receive on average
//! `m (tau / V_B) exp(-P / tau) (1 - exp(-V_B / tau))` of the difference:
//! [`tower_volume`] gives the least `P` that keeps this within `s / 2`, and at most
//! V_t (a full flush) when nothing smaller does.
//!
//! A tool changer's tools each carry one material: the new tool's prime is that
//! material, and the beads the plan gives that tool are that material too, so its
//! first beads take the prime whole and the composition of no sub-region changes.

use serde::Deserialize;

/// Where transitions go (the `gcode` exporter's `purge_into`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PurgeInto {
    /// Into the part's next beads as far as the design allows; the rest on the tower.
    Part,
    /// All of every transition on the wipe tower.
    Tower,
}

lamina_api::option_type!(PurgeInto = "string");

/// The chamber's time constant in mm³ for a head that flushes in `transition` mm³.
pub fn tau(transition: f64) -> f64 {
    transition / 3.0
}

/// What the wipe tower must take (mm³) before beads of `chain` mm³ (design
/// composition B) take the rest of a transition, when the nozzle differs from B by a
/// share `moved` and the family's design step is `step` (shares of the whole, 0 to 1):
/// see the module's notes. A head that flushes in `transition` mm³.
pub fn tower_volume(moved: f64, step: f64, chain: f64, transition: f64) -> f64 {
    if transition <= 0.0 || moved <= 0.0 {
        return 0.0;
    }
    if !(step > 0.0 && chain > 0.0) {
        return transition;
    }
    let tau = tau(transition);
    let departure = moved * (tau / chain) * (1.0 - (-chain / tau).exp());
    (tau * (2.0 * departure / step).ln()).clamp(0.0, transition)
}

/// The nozzle's composition after `volume` mm³ at the set mix `target` (fractions),
/// from `nozzle`.
pub fn flush(nozzle: &[f64], target: &[f64], volume: f64, transition: f64) -> Vec<f64> {
    if transition <= 0.0 {
        return target.to_vec();
    }
    let left = (-volume / tau(transition)).exp();
    nozzle
        .iter()
        .zip(target)
        .map(|(c, t)| t + (c - t) * left)
        .collect()
}

/// The mean departure of beads from their design, deposited in order from a nozzle
/// holding `nozzle`: each bead `(volume, set mix, design)`, stepped through the chamber
/// 32 times a bead (trapezoids; the departure is smooth along a bead).
pub fn mean_departure(nozzle: &[f64], beads: &[(f64, &[f64], &[f64])], transition: f64) -> f64 {
    const STEPS: usize = 32;
    let mut nozzle = nozzle.to_vec();
    let (mut sum, mut total) = (0.0, 0.0);
    for &(volume, set, design) in beads {
        if volume <= 0.0 {
            continue;
        }
        let dv = volume / STEPS as f64;
        for _ in 0..STEPS {
            let next = flush(&nozzle, set, dv, transition);
            sum += (departure(&nozzle, design) + departure(&next, design)) / 2.0 * dv;
            nozzle = next;
        }
        total += volume;
    }
    if total > 0.0 { sum / total } else { 0.0 }
}

/// The share of the material that differs between two compositions given as fractions
/// (half the sum of the differences).
pub fn departure(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>() / 2.0
}

/// The share of the material that moves between two mixes in percent (half the sum of
/// the channels' differences): 0 for the same mix, 1 from one pure channel to another.
pub fn moved(a: &[u32], b: &[u32]) -> f64 {
    let sum: u32 = a.iter().zip(b).map(|(x, y)| x.abs_diff(*y)).sum();
    f64::from(sum) / 200.0
}

/// The design step of a family: the largest difference ([`moved`]) between the mixes
/// of neighbouring sub-regions, where neighbours are sub-regions of the same level or
/// of consecutive levels (each discretiser numbers its sub-regions' levels from the
/// grading reference outward: rings, iso-bands, truncation steps, and the cells of one
/// ring or of the next). `regions` are the family's sub-regions as (level, mix).
pub fn design_step(regions: &[(f64, Vec<u32>)]) -> f64 {
    let mut levels: Vec<f64> = regions.iter().map(|r| r.0).collect();
    levels.sort_by(f64::total_cmp);
    levels.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    let rank = |level: f64| levels.partition_point(|l| *l < level - 1e-9);
    let mut step: f64 = 0.0;
    for (i, (la, a)) in regions.iter().enumerate() {
        for (lb, b) in &regions[i + 1..] {
            if rank(*la).abs_diff(rank(*lb)) <= 1 {
                step = step.max(moved(a, b));
            }
        }
    }
    step
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The mean departure from B of beads of `chain` mm³ after a purge of `purge`,
    /// starting `moved` away, by stepping the chamber through the beads (independent
    /// of the closed form).
    fn mean_departure(moved: f64, purge: f64, chain: f64, transition: f64) -> f64 {
        let n = 20_000;
        let dv = chain / n as f64;
        let mut nozzle = flush(&[moved, 1.0 - moved], &[0.0, 1.0], purge, transition);
        let mut sum = 0.0;
        for _ in 0..n {
            let next = flush(&nozzle, &[0.0, 1.0], dv, transition);
            sum += (departure(&nozzle, &[0.0, 1.0]) + departure(&next, &[0.0, 1.0])) / 2.0;
            nozzle = next;
        }
        sum / n as f64
    }

    #[test]
    fn large_beads_take_a_one_step_transition_whole() {
        // The gear's rings: a step of 1/9 between rings of 18 mm³, 15 mm³ to flush.
        assert_eq!(tower_volume(1.0 / 9.0, 1.0 / 9.0, 18.0, 15.0), 0.0);
        assert!(mean_departure(1.0 / 9.0, 0.0, 18.0, 15.0) <= 0.5 / 9.0);
    }

    #[test]
    fn the_tower_takes_just_enough_to_stay_within_half_a_step() {
        for (moved, step, chain, transition) in [
            (0.5, 0.1, 20.0, 15.0),
            (1.0, 0.25, 8.0, 15.0),
            (0.2, 0.1, 4.0, 15.0),
            (0.3, 0.3, 2.0, 15.0),
            (0.125, 1.0 / 9.0, 9.2, 15.0),
        ] {
            let purge = tower_volume(moved, step, chain, transition);
            assert!((0.0..=transition).contains(&purge));
            let departure = mean_departure(moved, purge, chain, transition);
            assert!(
                departure <= step / 2.0 + 1e-4,
                "{moved} {step} {chain}: {departure} > half of {step}"
            );
            // And not more than needed: a purge leaves the beads half a step off.
            if purge > 0.0 {
                assert!((departure - step / 2.0).abs() < 1e-3, "{departure}");
            }
        }
    }

    #[test]
    fn the_stepped_mean_agrees_with_the_closed_form() {
        let (b, n) = ([0.0, 1.0], [0.3, 0.7]);
        let stepped = super::mean_departure(&n, &[(12.0, &b, &b)], 15.0);
        assert!(
            (stepped - mean_departure(0.3, 0.0, 12.0, 15.0)).abs() < 1e-4,
            "{stepped}"
        );
    }

    #[test]
    fn a_full_flush_is_the_most_the_tower_takes() {
        assert_eq!(tower_volume(0.5, 0.0, 100.0, 15.0), 15.0);
        assert_eq!(tower_volume(1.0, 0.001, 1.0, 15.0), 15.0);
        assert_eq!(tower_volume(0.0, 0.0, 100.0, 15.0), 0.0);
        assert_eq!(tower_volume(0.5, 0.1, 100.0, 0.0), 0.0);
        // After a full flush 5 % of the old mix is left.
        let left = flush(&[1.0, 0.0], &[0.0, 1.0], 15.0, 15.0);
        assert!((left[0] - (-3.0f64).exp()).abs() < 1e-12);
    }

    #[test]
    fn neighbours_are_regions_of_the_same_or_the_next_level() {
        let mix = |a: u32| vec![a, 100 - a];
        // Rings from 100 % to 0 % in steps of 25 %, and an outlier two levels away.
        let rings = [
            (0.0, mix(100)),
            (0.25, mix(75)),
            (0.5, mix(50)),
            (0.75, mix(25)),
            (1.0, mix(0)),
        ];
        assert!((design_step(&rings) - 0.25).abs() < 1e-12);
        // Two cells of one ring differ by 40 %: neighbours too.
        let cells = [(0.0, mix(100)), (0.0, mix(60)), (0.5, mix(70))];
        assert!((design_step(&cells) - 0.4).abs() < 1e-12);
        assert_eq!(design_step(&[(0.0, mix(50))]), 0.0);
        assert_eq!(moved(&mix(100), &mix(0)), 1.0);
    }
}
