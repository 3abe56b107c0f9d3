//! Material regions by name: the `regions` a stage is restricted to, and options keyed
//! by region, checked against the sequence when the first layer comes.

use std::collections::BTreeMap;

use lamina_api::table::TableRef;
use lamina_api::{LayerPlan, ProcessContext, Result};

/// The name of the layer's material region, if the layers follow a sequence.
pub fn name_of<'a>(ctx: &'a ProcessContext<'_>, plan: &LayerPlan) -> Option<&'a str> {
    let r = plan.material_region?;
    ctx.sequence?.regions.get(r).map(|r| r.name.as_str())
}

/// Checks that every name is a region of the sequence; an error names `key`.
pub fn check_names<'n>(
    ctx: &ProcessContext<'_>,
    table: &TableRef,
    key: &str,
    names: impl IntoIterator<Item = &'n String>,
) -> Result<()> {
    let known: Vec<&str> = ctx
        .sequence
        .map(|s| s.regions.iter().map(|r| r.name.as_str()).collect())
        .unwrap_or_default();
    for n in names {
        if !known.contains(&n.as_str()) {
            return Err(table.error_at(
                key,
                if known.is_empty() {
                    format!("names region `{n}`, but the pipeline has no [sequence] of material regions")
                } else {
                    format!("no material region named `{n}` (regions: {})", known.join(", "))
                },
            ));
        }
    }
    Ok(())
}

/// True when a stage restricted to `only` (empty: every layer) works on this layer.
pub fn selected(
    ctx: &ProcessContext<'_>,
    table: &TableRef,
    plan: &LayerPlan,
    only: &[String],
) -> Result<bool> {
    if only.is_empty() {
        return Ok(true);
    }
    check_names(ctx, table, "regions", only)?;
    Ok(name_of(ctx, plan).is_some_and(|n| only.iter().any(|o| o == n)))
}

/// The value a by-region table gives this layer's region.
pub fn value_for<'m, V>(
    ctx: &ProcessContext<'_>,
    plan: &LayerPlan,
    map: &'m BTreeMap<String, V>,
) -> Option<&'m V> {
    name_of(ctx, plan).and_then(|n| map.get(n))
}
