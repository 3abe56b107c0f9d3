//! Whether each part is made: its layers' contours against the area its mesh's cut
//! encloses. A slicer joins a cut's segments into loops; where an open mesh leaves a
//! chain it cannot close, the chain and the area it bounds are dropped, and a part can
//! lose much of its layers with nothing else noticing (the sub-regions still tile what
//! is left, and the beads still fill them). The slicer measures what each layer should
//! hold, its contours and the chains it dropped ([`Layer::section_area`](crate::model::Layer));
//! a run whose part keeps less than [`MIN_KEPT`] of that volume fails, naming the
//! heights where it went missing.

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

/// The sliced volumes of one mesh, summed over its layers.
#[derive(Debug, Default, Clone)]
struct Sums {
    /// Section area times layer thickness (mm³).
    section: f64,
    /// Contour area times layer thickness (mm³).
    kept: f64,
    /// The layers short of their section: index, bottom and top (mm).
    short: Vec<(usize, f64, f64)>,
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
        }
    }

    /// Fails when a mesh's layers keep less than [`MIN_KEPT`] of what its cuts enclose;
    /// `names(mesh)` says which parts it makes.
    pub(super) fn check(&self, names: impl Fn(usize) -> String) -> Result<()> {
        for (mesh, sums) in self.meshes.iter().enumerate() {
            if sums.section - sums.kept <= NOISE_VOLUME || sums.kept >= MIN_KEPT * sums.section {
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
        Ok(())
    }
}

/// `layers 0-20 (z 0.000-4.200 mm), 31 (z 6.200-6.400 mm)`: consecutive layers as one
/// range, at most six ranges named and the rest counted.
fn short_ranges(short: &[(usize, f64, f64)]) -> String {
    const SHOWN: usize = 6;
    if short.is_empty() {
        return "no single layer is short by itself, but many are a little".to_string();
    }
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
    format!("short on {word} {}", out.join(", "))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kept(section: f64, kept: f64) -> Kept {
        Kept {
            mesh: 0,
            section,
            kept,
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
