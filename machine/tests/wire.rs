//! Machines cross the plugin boundary in a run's facts.

use std::path::PathBuf;

use lamina_api::plugin::wire;
use lamina_api::stage::RunInfo;

/// Every built-in machine travels in a run's facts and reads back the same.
#[test]
fn run_facts_with_every_built_in_machine_read_back_the_same() {
    for profile in lamina_machine::builtin::PROFILES {
        let machine = lamina_machine::load::builtin(profile.name).expect("built-in profile");
        let info = RunInfo {
            base_dir: PathBuf::from("/p"),
            materials: Vec::new(),
            parts: Vec::new(),
            z_min: 0.0,
            z_max: f64::MAX,
            xy_bounds: lamina_api::geom::BBox2::EMPTY,
            machine: Some(machine.clone()),
            model_frame: None,
        };
        let bytes = wire::encode(&info).expect("encodes");
        let back: RunInfo = wire::decode(&bytes).expect("decodes");
        assert_eq!(wire::encode(&back).expect("encodes"), bytes, "{}", profile.name);
        let mut back_machine = back.machine.expect("machine");
        back_machine.origin = machine.origin.clone();
        assert_eq!(back_machine, machine, "{}", profile.name);
    }
}
