//! `z`: grading along the build direction (topological-hierarchy-fgm Eq. 9): a layer's
//! level is r_i = (z_i - z_s) / (z_e - z_s) between a start and an end layer, held at 0
//! below the start and 1 above the end, and a control function of r gives the
//! composition of every region of the layer.

use lamina_api::stage::{AnyStage, FamilyContext, Grader, StageConfig, StageInfo, StageKind};
use lamina_api::{Result, StageFactory, SubRegion};

use crate::control::{Control, ControlOptions, region_args};

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        f: Option<String> = use crate::control::F,
        mu: Option<f64> = use crate::control::MU,
        lambda: Option<f64> = use crate::control::LAMBDA,
        alpha: Option<f64> = use crate::control::ALPHA,
        k: Option<f64> = use crate::control::K,
        /// layer index (from 0) where r = 0
        #[range(0, 1e7)]
        from_layer: Option<usize>,
        /// layer index where r = 1
        #[range(0, 1e7)]
        to_layer: Option<usize>,
        /// height (mm) where r = 0, compared with the layer's top; default: the part's bottom (mid-layer)
        #[range(-1e6, 1e6)]
        from_z: Option<f64>,
        /// height (mm) where r = 1; default: the part's top
        #[range(-1e6, 1e6)]
        to_z: Option<f64>,
    }
}

/// Where the grading starts and ends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Span {
    /// Layer indices: r = (i - start) / (end - start). Equal to the height ratio for
    /// layers of equal thickness, as in the paper.
    Layers(usize, usize),
    /// Heights (mm) compared with the layer's top.
    Heights(f64, f64),
    /// The part's own height range, compared with the layer's mid-height so that the
    /// first and last layers sit symmetrically inside it.
    Part,
}

struct AlongZ {
    control: Control,
    span: Span,
}

/// r in [0, 1] for a layer; a start equal to its end makes a step there.
pub(crate) fn level(span: Span, index: usize, z: f64, thickness: f64, part: (f64, f64)) -> f64 {
    let ratio = |v: f64, s: f64, e: f64| {
        if e == s {
            if v >= e { 1.0 } else { 0.0 }
        } else {
            ((v - s) / (e - s)).clamp(0.0, 1.0)
        }
    };
    match span {
        Span::Layers(s, e) => ratio(index as f64, s as f64, e as f64),
        Span::Heights(s, e) => ratio(z, s, e),
        Span::Part => ratio(z - thickness / 2.0, part.0, part.1),
    }
}

impl Grader for AlongZ {
    /// Reads the layer's height and the regions' levels and references only.
    fn reads_geometry(&self) -> bool {
        false
    }

    fn grade(&self, ctx: &FamilyContext<'_>, regions: &mut [SubRegion]) -> Result<()> {
        let part = &ctx.info.parts[ctx.part];
        let n = part.materials.len();
        let r = level(
            self.span,
            ctx.layer.index,
            ctx.layer.z,
            ctx.layer.thickness,
            (part.z_min, part.z_max),
        );
        for region in regions.iter_mut() {
            let args = region_args(ctx, region, r);
            let context = || {
                format!(
                    "part `{}`, layer {} (z = {:.4}, r = {r}), region {}",
                    part.name, ctx.layer.index, ctx.layer.z, region.index
                )
            };
            region.composition = Some(self.control.composition(&args, n, context)?);
        }
        Ok(())
    }
}

/// The span the `from_layer`/`to_layer` or `from_z`/`to_z` options give.
pub(crate) fn span(
    config: &StageConfig<'_>,
    layers: (Option<usize>, Option<usize>),
    heights: (Option<f64>, Option<f64>),
) -> Result<Span> {
    Ok(match (layers.0, layers.1, heights.0, heights.1) {
        (None, None, None, None) => Span::Part,
        (Some(s), Some(e), None, None) => {
            if e < s {
                return Err(config.error("to_layer", "must not come before from_layer"));
            }
            Span::Layers(s, e)
        }
        (None, None, Some(s), Some(e)) => {
            if !(s.is_finite() && e.is_finite()) || e < s {
                return Err(config.error("to_z", "must be a finite height not below from_z"));
            }
            Span::Heights(s, e)
        }
        _ => {
            return Err(config.error(
                "from_layer",
                "give both from_layer and to_layer, or both from_z and to_z (or neither: the part's height)",
            ));
        }
    })
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: Options = config.parse()?;
    let span = span(config, (o.from_layer, o.to_layer), (o.from_z, o.to_z))?;
    let control = Control::from_options(
        config,
        &ControlOptions {
            f: o.f,
            mu: o.mu,
            lambda: o.lambda,
            alpha: o.alpha,
            k: o.k,
        },
        (1.0, 0.0),
    )?;
    Ok(AnyStage::Grade(Box::new(AlongZ { control, span })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Grade,
        name: "z",
        doc: "Grades along Z: r = (z - z_start) / (z_end - z_start) between two layers or heights (held outside), fractions from a control function of r (default f = r for the first material).",
        options: Options::SPECS,
        example: "use = \"z\"\nf = \"wave\"\nfrom_layer = 0\nto_layer = 3",
    },
    build,
});

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_follow_the_span_and_hold_outside() {
        let part = (0.0, 2.0);
        assert_eq!(level(Span::Layers(3, 9), 3, 0.0, 0.1, part), 0.0);
        assert_eq!(level(Span::Layers(3, 9), 6, 0.0, 0.1, part), 0.5);
        assert_eq!(level(Span::Layers(3, 9), 12, 0.0, 0.1, part), 1.0);
        assert_eq!(level(Span::Layers(3, 9), 1, 0.0, 0.1, part), 0.0);
        assert_eq!(level(Span::Heights(1.0, 2.0), 0, 1.5, 0.1, part), 0.5);
        assert_eq!(level(Span::Heights(1.0, 1.0), 0, 1.5, 0.1, part), 1.0);
        assert!((level(Span::Part, 0, 0.5, 0.5, part) - 0.125).abs() < 1e-12);
        assert!((level(Span::Part, 3, 2.0, 0.5, part) - 0.875).abs() < 1e-12);
    }
}
