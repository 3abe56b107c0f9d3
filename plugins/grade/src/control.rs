//! Control functions f(r) (topological-hierarchy-fgm Eq. 10-12, grading-step-width's
//! power law): the fraction of a part's first material as a function of a normalised
//! level r. With two materials the second fraction is 1 - f; a Rhai function may return
//! one fraction per material instead, for any number of materials.

use lamina_api::options::SharedOption;
use lamina_api::script::{ScriptArgs, ScriptFn};
use lamina_api::stage::{FamilyContext, StageConfig};
use lamina_api::{Composition, Error, Result, SubRegion};
use serde::Deserialize;

/// The options every control-function grader takes.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControlOptions {
    /// `linear`, `constant`, `wave`, `power`, or a Rhai expression / `file.rhai#fn`.
    pub f: Option<String>,
    pub mu: Option<f64>,
    pub lambda: Option<f64>,
    pub alpha: Option<f64>,
    pub k: Option<f64>,
}

/// A control function of r.
pub enum Control {
    /// mu r + lambda (Eq. 10).
    Linear { mu: f64, lambda: f64 },
    /// mu (Eq. 11).
    Constant { mu: f64 },
    /// mu sin(lambda r) (Eq. 12).
    Wave { mu: f64, lambda: f64 },
    /// (alpha r)^k.
    Power { alpha: f64, k: f64 },
    /// A user's Rhai function, compiled once.
    Script(ScriptFn),
}

/// Options shared by the graders that take a control function.
pub const F: SharedOption = SharedOption::new(
    "\"linear\"",
    "\"linear\" (mu r + lambda), \"constant\" (mu), \"wave\" (mu sin(lambda r)), \"power\" ((alpha r)^k), or a Rhai expression / \"file.rhai#fn\" of r, x, y, z, layer, part",
);
pub const MU: SharedOption =
    SharedOption::without_default("unset: linear: 1; constant: 1; wave: 1").within(-1000.0, 1000.0);
pub const LAMBDA: SharedOption =
    SharedOption::without_default("unset: linear: 0; wave: pi").within(-1000.0, 1000.0);
pub const ALPHA: SharedOption =
    SharedOption::without_default("power: scale of r, in (0, 1]; unset: 1.0").within(0.0001, 1.0);
pub const K: SharedOption =
    SharedOption::without_default("power: exponent, positive; unset: 1.0").within(0.001, 1000.0);

impl Control {
    /// Builds the control function from a stage's options; `default_linear` gives the
    /// (mu, lambda) of `linear` when they are not set.
    pub fn from_options(
        config: &StageConfig<'_>,
        o: &ControlOptions,
        default_linear: (f64, f64),
    ) -> Result<Self> {
        let num = |key: &str, v: Option<f64>, default: f64| -> Result<f64> {
            let v = v.unwrap_or(default);
            if v.is_finite() {
                Ok(v)
            } else {
                Err(config.error(key, "must be a finite number"))
            }
        };
        let name = o.f.as_deref().unwrap_or("linear");
        let unused = |keys: &[(&str, bool)]| -> Result<()> {
            for (key, given) in keys {
                if *given {
                    return Err(config.error(key, format!("has no meaning for f = \"{name}\"")));
                }
            }
            Ok(())
        };
        Ok(match name {
            "linear" => {
                unused(&[("alpha", o.alpha.is_some()), ("k", o.k.is_some())])?;
                Control::Linear {
                    mu: num("mu", o.mu, default_linear.0)?,
                    lambda: num("lambda", o.lambda, default_linear.1)?,
                }
            }
            "constant" => {
                unused(&[
                    ("lambda", o.lambda.is_some()),
                    ("alpha", o.alpha.is_some()),
                    ("k", o.k.is_some()),
                ])?;
                Control::Constant {
                    mu: num("mu", o.mu, 1.0)?,
                }
            }
            "wave" => {
                unused(&[("alpha", o.alpha.is_some()), ("k", o.k.is_some())])?;
                Control::Wave {
                    mu: num("mu", o.mu, 1.0)?,
                    lambda: num("lambda", o.lambda, std::f64::consts::PI)?,
                }
            }
            "power" => {
                unused(&[("mu", o.mu.is_some()), ("lambda", o.lambda.is_some())])?;
                // r runs over [0, 1] (normalised, as d in distance-field Eq. 1), so
                // (alpha r)^k is a volume fraction for every r only with 0 < alpha <= 1
                // and k > 0; past 1 the paper leaves it undefined (a grading source's
                // f > 1 is its +ve complementary region instead).
                let alpha = num("alpha", o.alpha, 1.0)?;
                if !(alpha > 0.0 && alpha <= 1.0) {
                    return Err(config.error(
                        "alpha",
                        format!(
                            "must be in (0, 1], not {alpha}: r runs from 0 to 1, so (alpha r)^k would leave [0, 1]{};                              to saturate a composition use a grading source (`discretise.sources`), whose f > 1 is its +ve complementary region",
                            if alpha > 1.0 {
                                format!(" for r > {:.4}", 1.0 / alpha)
                            } else {
                                String::new()
                            }
                        ),
                    ));
                }
                let k = num("k", o.k, 1.0)?;
                if k <= 0.0 {
                    return Err(config.error(
                        "k",
                        format!("must be positive, not {k}: (alpha r)^k at r = 0 is 0 only then"),
                    ));
                }
                Control::Power { alpha, k }
            }
            script => {
                unused(&[
                    ("mu", o.mu.is_some()),
                    ("lambda", o.lambda.is_some()),
                    ("alpha", o.alpha.is_some()),
                    ("k", o.k.is_some()),
                ])?;
                let origin = config.string_location("f");
                Control::Script(config.scripts.compile(script, origin)?)
            }
        })
    }

    /// The composition at `args.r` over `n` materials; `context` names the place for
    /// errors (part, layer, region). It is a closure because a grader calls this for
    /// every region or sample point, and writing the place out costs more than a
    /// built-in control function: it is written only for an error, or for a script,
    /// whose host reports its own errors with it.
    pub fn composition(
        &self,
        args: &ScriptArgs<'_>,
        n: usize,
        context: impl Fn() -> String,
    ) -> Result<Composition> {
        let r = args.r;
        let f = match self {
            Control::Linear { mu, lambda } => mu * r + lambda,
            Control::Constant { mu } => *mu,
            Control::Wave { mu, lambda } => mu * (lambda * r).sin(),
            Control::Power { alpha, k } => (alpha * r).powf(*k),
            Control::Script(s) => return Composition::new(s.fractions(args, n, &context())?),
        };
        // sin(pi) and friends leave a rounding residue just outside [0, 1].
        let f = if (-1e-12..0.0).contains(&f) {
            0.0
        } else if (1.0..1.0 + 1e-12).contains(&f) {
            1.0
        } else {
            f
        };
        match n {
            1 if (f - 1.0).abs() <= 1e-9 => Ok(Composition::pure(0, 1)),
            2 => Composition::binary(f)
                .map_err(|e| Error::stage("grade", format!("{}: f(r = {r}) = {f}: {e}", context()))),
            _ => Err(Error::stage(
                "grade",
                format!(
                    "{}: a built-in control function grades two materials, the part has {n}; \
                     use a Rhai function that returns {n} fractions",
                    context()
                ),
            )),
        }
    }
}

/// What a control function of `r` sees for `region` of the family in `ctx`: its
/// reference point, the layer's height and index, and the part's name.
pub fn region_args<'a>(ctx: &FamilyContext<'a>, region: &SubRegion, r: f64) -> ScriptArgs<'a> {
    ScriptArgs {
        r,
        d: 0.0,
        x: region.reference.x,
        y: region.reference.y,
        z: ctx.layer.z,
        layer: ctx.layer.index as i64,
        part: &ctx.info.parts[ctx.part].name,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(c: &Control, r: f64, n: usize) -> Result<Composition> {
        let args = ScriptArgs {
            r,
            d: 0.0,
            x: 0.0,
            y: 0.0,
            z: 0.0,
            layer: 0,
            part: "p",
        };
        c.composition(&args, n, || "test".to_string())
    }

    fn first(c: &Control, r: f64) -> f64 {
        let comp = at(c, r, 2).expect("a composition");
        assert!((comp.fractions[0] + comp.fractions[1] - 1.0).abs() < 1e-12);
        comp.fractions[0]
    }

    /// Eq. 10-12 and the power law at points where a wrong operator shows: the
    /// fraction of the first material, the second taking the rest.
    #[test]
    fn built_in_control_functions_give_the_papers_fractions() {
        let linear = Control::Linear {
            mu: -0.5,
            lambda: 0.75,
        };
        assert!((first(&linear, 0.3) - 0.6).abs() < 1e-12);
        assert!((first(&Control::Constant { mu: 0.25 }, 0.9) - 0.25).abs() < 1e-12);
        // The gear's wave of Fig. 4: sin(pi r), and a half wave at r = 1/6.
        let wave = Control::Wave {
            mu: 1.0,
            lambda: std::f64::consts::PI,
        };
        assert!((first(&wave, 1.0 / 6.0) - 0.5).abs() < 1e-12);
        assert!((first(&wave, 0.5) - 1.0).abs() < 1e-12);
        assert!(first(&wave, 1.0).abs() < 1e-15);
        let damped = Control::Wave { mu: 0.8, lambda: 2.0 };
        assert!((first(&damped, 0.25) - 0.8 * 0.5f64.sin()).abs() < 1e-12);
        // (alpha r)^k: (0.5 x 0.8)^2 = 0.16.
        let power = Control::Power { alpha: 0.5, k: 2.0 };
        assert!((first(&power, 0.8) - 0.16).abs() < 1e-12);
        // A fraction past 1 is an error naming the place.
        let over = Control::Linear { mu: 1.0, lambda: 0.5 };
        let e = at(&over, 0.75, 2).expect_err("f = 1.25").to_string();
        assert!(e.contains("test") && e.contains("1.25"), "{e}");
    }

    /// A rounding residue just outside [0, 1] is a pure material, exactly: -sin(pi)
    /// is -1.2e-16, and 1 + 1e-13 is within the band of 1e-12 above 1.
    #[test]
    fn a_rounding_residue_is_a_pure_material() {
        let below = Control::Wave {
            mu: -1.0,
            lambda: std::f64::consts::PI,
        };
        assert_eq!(at(&below, 1.0, 2).expect("pure").fractions, [0.0, 1.0]);
        let above = Control::Linear {
            mu: 1e-13,
            lambda: 1.0,
        };
        assert_eq!(at(&above, 1.0, 2).expect("pure").fractions, [1.0, 0.0]);
        // Beyond the band it is an error.
        assert!(at(&Control::Constant { mu: 1.0 + 1e-6 }, 0.0, 2).is_err());
        assert!(at(&Control::Constant { mu: -1e-6 }, 0.0, 2).is_err());
    }

    /// One material: f must be 1 (the part is that material); three need a script.
    #[test]
    fn one_material_takes_f_of_one_and_three_need_a_script() {
        let one = Control::Constant { mu: 1.0 };
        assert_eq!(at(&one, 0.5, 1).expect("pure").fractions, vec![1.0]);
        assert!(at(&Control::Constant { mu: 0.5 }, 0.5, 1).is_err());
        let e = at(&one, 0.5, 3).expect_err("three").to_string();
        assert!(e.contains("Rhai"), "{e}");
    }
}
