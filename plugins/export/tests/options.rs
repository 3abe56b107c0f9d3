//! The CLI exporter's options, built as a pipeline builds them.

use lamina_core::StageKind;

#[test]
fn units_outside_a_nanometre_to_a_metre_are_refused() {
    let dir = std::path::Path::new(".");
    for units in ["5e-324", "1e300", "0.0", "-1.0"] {
        let table = format!("use = \"cli\"\npath = \"l.cli\"\nunits = {units}");
        let err = lamina_test_support::try_stage(StageKind::Export, &table, dir)
            .err()
            .unwrap_or_else(|| panic!("units = {units} accepted"));
        assert!(
            err.to_string().contains("is outside its range 1e-6 to 1000"),
            "{err}"
        );
    }
    let table = "use = \"cli\"\npath = \"l.cli\"\nunits = 0.001";
    assert!(lamina_test_support::try_stage(StageKind::Export, table, dir).is_ok());
}
