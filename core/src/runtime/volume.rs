//! Whether each part is made: its layers' contours against the area its mesh's cut
//! encloses. A slicer joins a cut's segments into loops; where an open mesh leaves a
//! chain it cannot close, the chain and the area it bounds are dropped, and a part can
//! lose much of its layers with nothing else noticing (the sub-regions still tile what
//! is left, and the beads still fill them). The slicer measures what each layer should
//! hold, its contours and the chains it dropped ([`Layer::section_area`](crate::model::Layer));
//! a run whose part keeps less than [`MIN_KEPT`] of that volume fails, naming the
//! heights where it went missing. A part that keeps enough in all is still told which
//! of its layers are short, and where a repaired layer's area jumps against both its
//! neighbours (a cut closed the wrong way, or not closed): never silently.

use super::layer::Kept;
use crate::error::{Error, Result};

/// The least share of its mesh's sliced volume a part's layers must hold.
pub(super) const MIN_KEPT: f64 = 0.98;

/// A layer is short when its contours miss more than this share of its section.
const SHORT_LAYER: f64 = 0.02;

/// Below this area (mm²) a section's shortfall is noise: the width of a sliver.
const NOISE_AREA: f64 = 1e-3;

/// Below this volume (mm³) what a mesh's layers miss is noise.
const NOISE_VOLUME: f64 = 1e-3;

/// A repaired layer whose area is below this share of both neighbours', or above its
/// inverse, has jumped.
const JUMP: f64 = 0.5;

/// One layer of one mesh, as the jump test remembers it.
#[derive(Debug, Clone, Copy)]
struct Recent {
    index: usize,
    bottom: f64,
    top: f64,
    kept: f64,
    repaired: bool,
}

/// The sliced volumes of one mesh, summed over its layers.
#[derive(Debug, Default, Clone)]
struct Sums {
    /// Section area times layer thickness (mm³).
    section: f64,
    /// Contour area times layer thickness (mm³).
    kept: f64,
    /// The layers short of their section: index, bottom and top (mm).
    short: Vec<(usize, f64, f64)>,
    /// The last two layers, and the repaired layers whose area jumped against both
    /// neighbours.
    recent: Vec<Recent>,
    jumps: Vec<(usize, f64, f64)>,
}

impl Sums {
    /// Remembers a layer; tests the one before it against its neighbours.
    fn follow(&mut self, layer: Recent) {
        self.recent.push(layer);
        if self.recent.len() < 3 {
            return;
        }
        let [a, m, b] = [self.recent[0], self.recent[1], self.recent[2]];
        self.recent.remove(0);
        let (low, high) = (a.kept.min(b.kept), a.kept.max(b.kept));
        let dipped = m.kept < JUMP * low && low - m.kept > NOISE_AREA;
        let rose = JUMP * m.kept > high && m.kept - high > NOISE_AREA;
        if m.repaired && (dipped || rose) {
            self.jumps.push((m.index, m.bottom, m.top));
        }
    }
}

/// What every mesh's layers enclosed and kept, tallied layer by layer in build order.
#[derive(Debug, Default)]
pub(super) struct Volumes {
    meshes: Vec<Sums>,
}

impl Volumes {
    /// Adds layer `index` (top `z`, `thickness` thick).
    pub(super) fn add(&mut self, index: usize, z: f64, thickness: f64, kept: &[Kept]) {
        for k in kept {
            if self.meshes.len() <= k.mesh {
                self.meshes.resize_with(k.mesh + 1, Sums::default);
            }
            let sums = &mut self.meshes[k.mesh];
            sums.section += k.section * thickness;
            sums.kept += k.kept * thickness;
            if k.section - k.kept > (SHORT_LAYER * k.section).max(NOISE_AREA) {
                sums.short.push((index, z - thickness, z));
            }
            sums.follow(Recent {
                index,
                bottom: z - thickness,
                top: z,
                kept: k.kept,
                repaired: k.repaired,
            });
        }
    }

    /// Fails when a mesh's layers keep less than [`MIN_KEPT`] of what its cuts enclose;
    /// `names(mesh)` says which parts it makes. Otherwise returns the warnings (code,
    /// message) about the layers that are short or jumped in meshes that passed.
    pub(super) fn check(&self, names: impl Fn(usize) -> String) -> Result<Vec<(&'static str, String)>> {
        let mut warnings = Vec::new();
        for (mesh, sums) in self.meshes.iter().enumerate() {
            if !sums.jumps.is_empty() {
                warnings.push((
                    AREA_JUMP,
                    format!(
                        "{}: where the slicer repaired an open cut, the area is less than half or more than twice that of the layers on either side, on {}: a hole closed the wrong way, or left open; check the mesh there",
                        names(mesh),
                        ranges(&sums.jumps)
                    ),
                ));
            }
            if sums.section - sums.kept <= NOISE_VOLUME || sums.kept >= MIN_KEPT * sums.section {
                if !sums.short.is_empty() {
                    warnings.push((
                        LAYERS_SHORT,
                        format!(
                            "{}: the layers hold {:.2} % of the volume its mesh's cut encloses, enough in all, but some miss part of their section (open chains dropped): {}",
                            names(mesh),
                            100.0 * sums.kept / sums.section,
                            short_ranges(&sums.short)
                        ),
                    ));
                }
                continue;
            }
            return Err(Error::stage(
                "slice",
                format!(
                    "{}: the layers hold {:.1} mm³ of the {:.1} mm³ its mesh encloses ({:.1} %, below {:.0} %): \
                     {}, where the mesh is open and its cut left chains that could not be closed. \
                     Repair the mesh, or join wider gaps with [slice] close_gaps",
                    names(mesh),
                    sums.kept,
                    sums.section,
                    100.0 * sums.kept / sums.section,
                    100.0 * MIN_KEPT,
                    short_ranges(&sums.short),
                ),
            ));
        }
        Ok(warnings)
    }
}

/// The code of the warning about repaired layers whose area jumped.
pub(super) const AREA_JUMP: &str = "area-jump";
/// The code of the warning about short layers in a part that holds enough in all.
pub(super) const LAYERS_SHORT: &str = "layers-short";

/// `layers 0-20 (z 0.000-4.200 mm), 31 (z 6.200-6.400 mm)`: consecutive layers as one
/// range, at most six ranges named and the rest counted.
fn short_ranges(short: &[(usize, f64, f64)]) -> String {
    if short.is_empty() {
        return "no single layer is short by itself, but many are a little".to_string();
    }
    format!("short on {}", ranges(short))
}

/// `layers 0-20 (z 0.000-4.200 mm), 31 (z 6.200-6.400 mm)`: consecutive layers as one
/// range, at most six ranges named and the rest counted.
fn ranges(short: &[(usize, f64, f64)]) -> String {
    const SHOWN: usize = 6;
    let mut ranges: Vec<(usize, usize, f64, f64)> = Vec::new();
    for &(i, bottom, top) in short {
        match ranges.last_mut() {
            Some(r) if r.1 + 1 == i => {
                r.1 = i;
                r.3 = top;
            }
            _ => ranges.push((i, i, bottom, top)),
        }
    }
    let mut out: Vec<String> = ranges
        .iter()
        .take(SHOWN)
        .map(|&(a, b, bottom, top)| {
            let layers = if a == b {
                format!("{a}")
            } else {
                format!("{a}-{b}")
            };
            format!("{layers} (z {bottom:.3}-{top:.3} mm)")
        })
        .collect();
    if ranges.len() > SHOWN {
        out.push(format!("and {} more ranges", ranges.len() - SHOWN));
    }
    let word = if short.len() == 1 { "layer" } else { "layers" };
    format!("{word} {}", out.join(", "))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kept(section: f64, kept: f64) -> Kept {
        Kept {
            mesh: 0,
            section,
            kept,
            repaired: false,
        }
    }

    #[test]
    fn a_part_missing_its_lower_layers_fails_naming_them() {
        let mut v = Volumes::default();
        for i in 0..10 {
            let k = if (2..5).contains(&i) {
                kept(100.0, 0.0)
            } else {
                kept(100.0, 100.0)
            };
            v.add(i, 0.2 * (i + 1) as f64, 0.2, &[k]);
        }
        let e = v
            .check(|_| "part `gear`".into())
            .expect_err("30 % missing")
            .to_string();
        assert!(
            e.contains("part `gear`: the layers hold 140.0 mm³ of the 200.0 mm³")
                && e.contains("(70.0 %, below 98 %)")
                && e.contains("short on layers 2-4 (z 0.400-1.000 mm)"),
            "{e}"
        );
    }

    #[test]
    fn small_losses_and_slivers_pass_and_only_short_layers_are_named() {
        let mut v = Volumes::default();
        // 1.5 % less on every layer: within the share, and no layer short by itself.
        for i in 0..10 {
            v.add(i, 0.2 * (i + 1) as f64, 0.2, &[kept(100.0, 98.5)]);
        }
        v.check(|_| String::new()).expect("98.5 % kept");
        assert!(v.meshes[0].short.is_empty());
        // A tiny section wholly lost is noise; a second mesh is tallied apart.
        let mut v = Volumes::default();
        v.add(
            0,
            0.2,
            0.2,
            &[
                Kept {
                    mesh: 1,
                    section: 5e-4,
                    kept: 0.0,
                    repaired: false,
                },
                kept(100.0, 100.0),
            ],
        );
        v.check(|_| String::new()).expect("a sliver");
        assert!(v.meshes[1].short.is_empty());
        // Just below the share fails; the layers' list is then the summary's.
        let mut v = Volumes::default();
        v.add(0, 0.2, 0.2, &[kept(100.0, 97.9)]);
        let e = v.check(|_| "m".into()).expect_err("97.9 %").to_string();
        assert!(e.contains("short on layer 0 (z 0.000-0.200 mm)"), "{e}");
    }

    #[test]
    fn a_part_that_holds_enough_is_still_told_its_short_and_jumped_layers() {
        let mut v = Volumes::default();
        for i in 0..100 {
            let mut k = kept(100.0, 100.0);
            if i == 40 {
                // A chain dropped: half the section gone.
                k.kept = 50.0;
            }
            if i == 60 {
                // A cut closed across a hole into a section of a third the area, its
                // own section agreeing.
                (k.section, k.kept, k.repaired) = (30.0, 30.0, true);
            }
            if i == 70 {
                // A thin slot the mesh has: as small, but no repair made it.
                (k.section, k.kept) = (30.0, 30.0);
            }
            v.add(i, 0.2 * (i + 1) as f64, 0.2, &[k]);
        }
        let w = v.check(|_| "part `p`".into()).expect("99 % kept");
        assert_eq!(w.len(), 2, "{w:?}");
        assert_eq!(w[0].0, AREA_JUMP);
        assert!(w[0].1.contains("on layer 60 (z 12.000-12.200 mm)"), "{}", w[0].1);
        assert_eq!(w[1].0, LAYERS_SHORT);
        assert!(
            w[1].1.starts_with("part `p`: the layers hold 99.")
                && w[1].1.ends_with("short on layer 40 (z 8.000-8.200 mm)"),
            "{}",
            w[1].1
        );
        // A repaired layer twice its neighbours' area has jumped too.
        let mut v = Volumes::default();
        for (i, area) in [10.0, 25.0, 10.0].into_iter().enumerate() {
            let mut k = kept(area, area);
            k.repaired = i == 1;
            v.add(i, 0.2 * (i + 1) as f64, 0.2, &[k]);
        }
        let w = v.check(|_| String::new()).expect("whole");
        assert_eq!(w.len(), 1);
        assert_eq!(w[0].0, AREA_JUMP);
    }

    #[test]
    fn many_short_ranges_are_counted_past_six() {
        let short: Vec<(usize, f64, f64)> = (0..9).map(|k| (3 * k, k as f64, k as f64 + 0.1)).collect();
        let s = short_ranges(&short);
        assert!(
            s.starts_with("short on layers 0 (z 0.000-0.100 mm), 3 (z 1.000-1.100 mm)"),
            "{s}"
        );
        assert!(s.ends_with("and 3 more ranges"), "{s}");
        assert!(short_ranges(&[]).contains("many are a little"));
    }
}
