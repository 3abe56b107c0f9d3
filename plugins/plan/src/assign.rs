//! Which tool lays each bead when every tool carries one material. A graded sub-region
//! of 60 % bronze and 40 % steel cannot be laid by one single-material tool: laid all
//! by the bronze tool it would be pure bronze. Under `fraction` (the default) its beads
//! are shared between the tools so that each tool lays its material's share of the
//! area; the share not met by one group (a bead is laid whole) is carried to the next
//! group of the part, so over a layer each material's area is met within one bead.
//! Consecutive beads of a group stay with one tool while it is owed at least half the
//! next bead, so each tool lays a band, not every other loop, and the tools keep out of
//! each other's way. `dominant` gives each group whole to the tool of its largest
//! fraction: coarser, but each sub-region is laid by one tool.

use lamina_api::{Composition, RunInfo};

lamina_api::option_type!(Assign = "string");

/// How the beads of a graded group are shared between single-material tools.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Assign {
    /// Each tool lays its material's share of each group's area, in whole beads.
    #[default]
    Fraction,
    /// Each group goes whole to the tool of its largest fraction.
    Dominant,
}

/// The tools of one part's materials, and what each is still owed (mm² of bead area)
/// by the groups handed out so far.
#[derive(Debug, Clone)]
pub struct Shares {
    /// `tools[i]`: the tool of the part's material `i`.
    tools: Vec<usize>,
    owed: Vec<f64>,
    mode: Assign,
}

impl Shares {
    /// Shares for part `part` of the run among `count` tools (tool `m` lays material
    /// `m`); a material beyond the last tool goes to the last.
    pub fn new(info: &RunInfo, part: usize, count: usize, mode: Assign) -> Self {
        let tools: Vec<usize> = info
            .parts
            .get(part)
            .map(|p| {
                p.materials
                    .iter()
                    .map(|&m| m.min(count.saturating_sub(1)))
                    .collect()
            })
            .unwrap_or_default();
        let owed = vec![0.0; tools.len()];
        Shares { tools, owed, mode }
    }

    /// The part's material index that tool `tool` lays, when it lays one of them.
    pub fn material_of(&self, tool: usize) -> Option<usize> {
        self.tools.iter().position(|&t| t == tool)
    }

    /// What a bead laid by `tool` deposits: its material alone.
    pub fn deposited(&self, tool: usize) -> Option<Composition> {
        self.material_of(tool)
            .map(|i| Composition::pure(i, self.tools.len()))
    }

    /// The tool of each bead of a group of `composition` whose beads fill `areas`, in
    /// the beads' order.
    pub fn hand_out(&mut self, composition: Option<&Composition>, areas: &[f64]) -> Vec<usize> {
        let n = self.tools.len();
        let fallback = self.tools.first().copied().unwrap_or(0);
        let fractions: Vec<f64> = match composition {
            Some(c) if c.fractions.len() == n && n > 0 => c.fractions.clone(),
            // No grading: the part's first material.
            _ => {
                let mut f = vec![0.0; n.max(1)];
                f[0] = 1.0;
                f
            }
        };
        if n == 0 {
            return vec![fallback; areas.len()];
        }
        if self.mode == Assign::Dominant {
            let i = dominant(&fractions);
            return vec![self.tools[i]; areas.len()];
        }
        let total: f64 = areas.iter().sum();
        for (o, f) in self.owed.iter_mut().zip(&fractions) {
            *o += f * total;
        }
        let mut current: Option<usize> = None;
        let mut out = Vec::with_capacity(areas.len());
        for &a in areas {
            let pick = match current {
                Some(i) if self.owed[i] >= a / 2.0 => i,
                _ => dominant(&self.owed),
            };
            self.owed[pick] -= a;
            current = Some(pick);
            out.push(self.tools[pick]);
        }
        out
    }
}

/// Index of the largest value (the first on a tie).
fn dominant(values: &[f64]) -> usize {
    values
        .iter()
        .enumerate()
        .fold(
            (0, f64::NEG_INFINITY),
            |a, (i, &f)| if f > a.1 { (i, f) } else { a },
        )
        .0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shares(mode: Assign) -> Shares {
        Shares {
            tools: vec![0, 1],
            owed: vec![0.0, 0.0],
            mode,
        }
    }

    fn laid(tools: &[usize], areas: &[f64], tool: usize) -> f64 {
        tools
            .iter()
            .zip(areas)
            .filter(|(t, _)| **t == tool)
            .map(|(_, a)| a)
            .sum()
    }

    #[test]
    fn a_graded_group_is_shared_by_its_fractions_in_bands() {
        let mut s = shares(Assign::Fraction);
        let areas = [1.0; 10];
        let c = Composition::binary(0.6).expect("composition");
        let tools = s.hand_out(Some(&c), &areas);
        assert_eq!(laid(&tools, &areas, 0), 6.0);
        assert_eq!(laid(&tools, &areas, 1), 4.0);
        // One band per tool, not every other bead.
        let changes = tools.windows(2).filter(|w| w[0] != w[1]).count();
        assert_eq!(changes, 1, "{tools:?}");
        // The dominant rule lays it all with the first tool.
        let tools = shares(Assign::Dominant).hand_out(Some(&c), &areas);
        assert_eq!(laid(&tools, &areas, 0), 10.0);
    }

    #[test]
    fn what_a_group_cannot_meet_in_whole_beads_is_carried_to_the_next() {
        // Ten one-bead groups at 30 % of the first material: three of them go to the
        // first tool, not none (as the dominant rule would have it).
        let mut s = shares(Assign::Fraction);
        let c = Composition::binary(0.3).expect("composition");
        let first: usize = (0..10)
            .map(|_| s.hand_out(Some(&c), &[2.0]))
            .filter(|t| t[0] == 0)
            .count();
        assert_eq!(first, 3);
        let mut d = shares(Assign::Dominant);
        assert!((0..10).all(|_| d.hand_out(Some(&c), &[2.0])[0] == 1));
    }

    #[test]
    fn a_bead_deposits_its_tools_material_alone() {
        let s = shares(Assign::Fraction);
        assert_eq!(s.deposited(1).map(|c| c.fractions), Some(vec![0.0, 1.0]));
        assert!(s.deposited(5).is_none());
    }
}
