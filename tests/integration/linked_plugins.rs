//! Two plugin crates that export themselves as dynamic plugins, linked into one program
//! instead: their entry symbols do not clash, their stages register with the program's
//! own registry, and both run in one pipeline.

use lamina_core::registry::Origin;
use lamina_core::runtime::{RunOptions, run_file};
use lamina_core::{Registry, StageKind};

// The built-in stages the pipeline uses, and the two plugin crates.
use lamina_discretise as _;
use lamina_export as _;
use lamina_fixture_script as _;
use lamina_model as _;
use lamina_slice as _;
use lamina_sort as _;
use lamina_zigzag as _;

#[test]
fn two_plugin_crates_linked_into_one_program_run_in_one_pipeline() {
    // Both entry points exist side by side, each naming its own plugin.
    let names: Vec<String> = [
        lamina_zigzag::lamina_plugin_entry(),
        lamina_fixture_script::lamina_plugin_entry(),
    ]
    .into_iter()
    .map(|d| {
        // SAFETY: each entry returns the address of its crate's static descriptor,
        // whose name points to a string literal.
        let name = unsafe { (*d).name.as_slice() };
        String::from_utf8_lossy(name).into_owned()
    })
    .collect();
    assert_eq!(names, ["zigzag", "script_fixture"]);

    let registry = Registry::linked().expect("no two stages share a name");
    for (kind, name) in [(StageKind::Plan, "zigzag"), (StageKind::Grade, "dyn-script")] {
        let entry = registry.get(kind, name).expect("registered by linking");
        assert_eq!(entry.origin, Origin::Linked);
    }

    let dir = tempfile::tempdir().expect("tempdir");
    let pipeline = dir.path().join("p.toml");
    std::fs::write(
        &pipeline,
        "[model]\nuse = \"tube\"\nheight = 1.0\n\n[materials.a]\ncolour = [255, 0, 0]\n[materials.b]\ncolour = [0, 0, 255]\n\n\
         [slice]\nuse = \"uniform\"\nthickness = 0.5\n\n[discretise]\nuse = \"offset\"\ncount = 2\n\n\
         [grade]\nuse = \"dyn-script\"\nf = \"clamp01(r)\"\n\n[plan]\nuse = \"zigzag\"\nwidth = 0.5\n\n\
         [[output]]\nuse = \"json\"\npath = \"plan.json\"\n",
    )
    .expect("pipeline");
    let out = dir.path().join("out");
    run_file(&pipeline, &out, &RunOptions::default()).expect("runs");
    let plan: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("plan.json")).expect("written")).expect("json");
    let layers = plan["layers"].as_array().expect("layers");
    assert_eq!(layers.len(), 2);
    for layer in layers {
        assert!(!layer["toolpaths"].as_array().expect("toolpaths").is_empty());
        let regions = layer["parts"][0]["families"][0]["sub_regions"]
            .as_array()
            .expect("regions");
        assert_eq!(regions.len(), 2);
        // r = 0 for the outer ring, 1 for the inner one: all of b, then all of a.
        let a: Vec<f64> = regions
            .iter()
            .map(|r| r["composition"]["a"].as_f64().expect("graded"))
            .collect();
        assert_eq!(a, [0.0, 1.0]);
    }
}
