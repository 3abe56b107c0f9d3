//! Work cycles and blocks in exact integer micrometres.
//!
//! A cycle's height is the least common multiple of its regions' thicknesses. With
//! floating-point millimetres, 0.2, 0.5 and 1.5 have no exact common multiple; in
//! micrometres (200, 500, 1500) the answer is exactly 3000.

use lamina_api::{Block, CycleStep, Deposit, MaterialRegion, WorkCycle};

/// Greatest common divisor.
pub fn gcd(mut a: u64, mut b: u64) -> u64 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// Least common multiple, or `None` when it does not fit in a `u64` (or an input is 0).
pub fn lcm(a: u64, b: u64) -> Option<u64> {
    if a == 0 || b == 0 {
        return None;
    }
    (a / gcd(a, b)).checked_mul(b)
}

/// Least common multiple of all thicknesses; `None` for an empty list, a zero or an
/// overflow.
pub fn lcm_all(values: impl IntoIterator<Item = u64>) -> Option<u64> {
    let mut it = values.into_iter();
    let first = it.next()?;
    if first == 0 {
        return None;
    }
    it.try_fold(first, lcm)
}

/// The work cycle of regions with thicknesses `thickness_um[i]` (`regions[i]` names
/// them): one step per height in `(0, lcm]` that is a multiple of some thickness; at
/// each step every region whose thickness divides the height deposits one layer, in
/// the given order. `None` when the least common multiple overflows or exceeds
/// `max_um`: checked before a step is built, since a cycle of a metre in micrometre
/// thicknesses has hundreds of thousands of steps.
pub fn work_cycle(regions: &[(usize, u64)], max_um: u64) -> Option<WorkCycle> {
    let height = lcm_all(regions.iter().map(|&(_, t)| t)).filter(|&h| h <= max_um)?;
    let steps = steps_up_to(regions, height);
    Some(WorkCycle {
        height_um: height,
        steps,
    })
}

/// Every deposition step over a height `top` (micrometres): each region deposits at the
/// multiples of its thickness below `top` and a last layer ending exactly at `top`.
pub fn steps_up_to(regions: &[(usize, u64)], top: u64) -> Vec<CycleStep> {
    // Next deposit height of each region; a k-way merge visits each height once, so a
    // block costs its number of layers, not its height in micrometres.
    let mut last = vec![0u64; regions.len()];
    let mut steps = Vec::new();
    let next = |last: &[u64], i: usize| -> u64 { last[i].saturating_add(regions[i].1).min(top) };
    while let Some(h) = (0..regions.len())
        .filter(|&i| last[i] < top)
        .map(|i| next(&last, i))
        .min()
    {
        let mut deposits = Vec::new();
        for (i, &(region, _)) in regions.iter().enumerate() {
            if last[i] < top && next(&last, i) == h {
                deposits.push(Deposit {
                    region,
                    thickness_um: h - last[i],
                });
                last[i] = h;
            }
        }
        steps.push(CycleStep {
            height_um: h,
            deposits,
        });
    }
    steps
}

/// Micrometres of a height in millimetres, rounded to the nearest micrometre.
pub fn mm_to_um(mm: f64) -> i64 {
    (mm * 1000.0).round() as i64
}

/// Cuts the object into blocks at every region boundary: each block holds whole region
/// heights, and its regions deposit in the block's work cycle. Heights between regions
/// that nothing occupies make no block. `None` when a cycle's height overflows or
/// exceeds `max_cycle_um`.
pub fn blocks(regions: &[MaterialRegion], max_cycle_um: u64) -> Option<Vec<Block>> {
    let spans: Vec<(i64, i64)> = regions
        .iter()
        .map(|r| (mm_to_um(r.z_start), mm_to_um(r.z_end)))
        .collect();
    let mut planes: Vec<i64> = spans.iter().flat_map(|&(a, b)| [a, b]).collect();
    planes.sort_unstable();
    planes.dedup();
    // Every block's regions and cycle height first: a cycle over the limit refuses
    // the whole sequence before any block's steps are built.
    let mut pending = Vec::new();
    for w in planes.windows(2) {
        let (lo, hi) = (w[0], w[1]);
        let present: Vec<(usize, u64)> = spans
            .iter()
            .enumerate()
            .filter(|&(_, &(a, b))| a <= lo && b >= hi)
            .map(|(i, _)| (i, regions[i].thickness_um))
            .collect();
        if present.is_empty() {
            continue;
        }
        lcm_all(present.iter().map(|&(_, t)| t)).filter(|&h| h <= max_cycle_um)?;
        pending.push((lo, hi, present));
    }
    let mut out = Vec::new();
    for (lo, hi, present) in pending {
        let cycle = work_cycle(&present, max_cycle_um)?;
        let height = u64::try_from(hi - lo).ok()?;
        out.push(Block {
            z_start: lo as f64 / 1000.0,
            z_end: hi as f64 / 1000.0,
            regions: present.iter().map(|&(i, _)| i).collect(),
            cycle,
            steps: steps_up_to(&present, height),
        });
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn region(name: &str, t: u64, z: (f64, f64)) -> MaterialRegion {
        MaterialRegion {
            name: name.into(),
            parts: vec![],
            thickness_um: t,
            z_start: z.0,
            z_end: z.1,
            rule: None,
        }
    }

    #[test]
    fn lcm_of_the_papers_thicknesses_is_three_millimetres() {
        assert_eq!(lcm_all([200, 500, 1500]), Some(3000));
        assert_eq!(lcm(4, 6), Some(12));
        assert_eq!(lcm(0, 6), None);
        assert_eq!(lcm(u64::MAX, u64::MAX - 1), None);
        assert_eq!(lcm_all([]), None);
    }

    /// cmpm-process-planning 4.1.2, Fig. 4: microstructure 0.2 mm, FGM 0.5 mm and
    /// composite 1.5 mm give a 3.0 mm cycle of 18 steps; the worktable moves down
    /// 0.1 or 0.2 mm between steps; M is sprayed every 0.2 mm, F every 0.5 mm, C every
    /// 1.5 mm, ties one after another.
    #[test]
    fn the_papers_work_cycle_has_eighteen_steps() {
        let c = work_cycle(&[(0, 200), (1, 500), (2, 1500)], u64::MAX).expect("cycle");
        assert_eq!(c.height_um, 3000);
        assert_eq!(c.steps.len(), 18);
        let heights: Vec<u64> = c.steps.iter().map(|s| s.height_um).collect();
        assert_eq!(
            heights,
            [
                200, 400, 500, 600, 800, 1000, 1200, 1400, 1500, 1600, 1800, 2000, 2200, 2400, 2500, 2600,
                2800, 3000
            ]
        );
        let mut prev = 0;
        for h in &heights {
            assert!(matches!(h - prev, 100 | 200), "table moves {} µm", h - prev);
            prev = *h;
        }
        let count = |r: usize| -> usize {
            c.steps
                .iter()
                .flat_map(|s| &s.deposits)
                .filter(|d| d.region == r)
                .count()
        };
        assert_eq!((count(0), count(1), count(2)), (15, 6, 2));
        // At 1.5 mm the FGM and the composite are both due: FGM first, then composite.
        let at_1500 = &c.steps[8];
        assert_eq!(at_1500.height_um, 1500);
        let order: Vec<usize> = at_1500.deposits.iter().map(|d| d.region).collect();
        assert_eq!(order, [1, 2]);
        // At 3.0 mm all three: M, F, C.
        let last: Vec<usize> = c.steps[17].deposits.iter().map(|d| d.region).collect();
        assert_eq!(last, [0, 1, 2]);
        for s in &c.steps {
            for d in &s.deposits {
                assert_eq!(d.thickness_um, [200, 500, 1500][d.region]);
            }
        }
    }

    #[test]
    fn blocks_cut_at_region_heights_and_trim_the_last_layers() {
        // Inner region over 0..6.1 mm at 0.2 mm, outer over 2..6.1 mm at 1.5 mm.
        let regions = [
            region("inner", 200, (0.0, 6.1)),
            region("outer", 1500, (2.0, 6.1)),
        ];
        let b = blocks(&regions, u64::MAX).expect("blocks");
        assert_eq!(b.len(), 2);
        assert_eq!((b[0].z_start, b[0].z_end), (0.0, 2.0));
        assert_eq!(b[0].regions, [0]);
        assert_eq!(b[0].steps.len(), 10);
        assert_eq!(b[1].regions, [0, 1]);
        assert_eq!(b[1].cycle.height_um, 3000);
        // Every region fills its block exactly: thicknesses sum to the block height.
        for block in &b {
            let h = mm_to_um(block.z_end - block.z_start) as u64;
            for &r in &block.regions {
                let sum: u64 = block
                    .steps
                    .iter()
                    .flat_map(|s| &s.deposits)
                    .filter(|d| d.region == r)
                    .map(|d| d.thickness_um)
                    .sum();
                assert_eq!(sum, h, "region {r} in block {block:?}");
            }
            assert!(block.steps.windows(2).all(|w| w[0].height_um < w[1].height_um));
        }
        // 4.1 mm of 1.5 mm layers: 1.5, 3.0 and a trimmed 1.1.
        let outer: Vec<u64> = b[1]
            .steps
            .iter()
            .flat_map(|s| &s.deposits)
            .filter(|d| d.region == 1)
            .map(|d| d.thickness_um)
            .collect();
        assert_eq!(outer, [1500, 1500, 1100]);
    }

    #[test]
    fn empty_gaps_make_no_block() {
        let regions = [region("a", 500, (0.0, 1.0)), region("b", 500, (2.0, 3.0))];
        let b = blocks(&regions, u64::MAX).expect("blocks");
        assert_eq!(b.len(), 2);
        assert_eq!((b[1].z_start, b[1].z_end), (2.0, 3.0));
    }
}
