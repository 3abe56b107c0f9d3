//! Slicing the generated models: they are watertight, their layers have the areas of
//! their profiles, and they fall into the expected families.

use std::path::Path;
use std::sync::Arc;

use lamina_core::stage::{MeshSlicer, Sorter};
use lamina_core::{AnyStage, LayerSlot, Mesh, StageKind};

fn stage(kind: StageKind, text: &str) -> AnyStage {
    lamina_test_support::stage(kind, text, Path::new("."))
}

fn model(text: &str) -> Vec<Mesh> {
    let AnyStage::Model(m) = stage(StageKind::Model, text) else {
        unreachable!()
    };
    m.load(Path::new(".")).expect("loads")
}

fn cut(mesh: &Mesh, z: f64) -> (lamina_core::Layer, lamina_core::ContourTree) {
    let AnyStage::Slice(s) = stage(StageKind::Slice, "use = \"uniform\"") else {
        unreachable!()
    };
    let AnyStage::Sort(sorter) = stage(StageKind::Sort, "use = \"hierarchy\"") else {
        unreachable!()
    };
    let prepared: Box<dyn MeshSlicer> = s.prepare(Arc::new(mesh.clone())).expect("prepare");
    let layer = prepared.slice(&LayerSlot::new(0, z, 0.2, z)).expect("slice");
    let sorter: &dyn Sorter = sorter.as_ref();
    let tree = sorter.sort(&layer).expect("sort");
    (layer, tree)
}

fn watertight(mesh: &Mesh) -> bool {
    let mut edges = std::collections::HashMap::new();
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_insert(0i32) += if a < b { 1 } else { -1 };
        }
    }
    edges.values().all(|&v| v == 0)
}

#[test]
fn tube_layers_have_the_ring_area_and_one_family_with_a_hole() {
    let meshes =
        model("use = \"tube\"\nouter_radius = 10.0\ninner_radius = 7.0\nheight = 5.0\nsegments = 96");
    assert!(watertight(&meshes[0]));
    let ngon = |r: f64| 0.5 * 96.0 * r * r * (std::f64::consts::TAU / 96.0).sin();
    let expected = ngon(10.0) - ngon(7.0);
    for z in [0.1, 1.0, 2.5, 4.9, 5.0] {
        let (layer, tree) = cut(&meshes[0], z);
        assert_eq!(layer.contours.len(), 2, "z = {z}");
        assert_eq!(tree.families.len(), 1);
        assert_eq!(tree.families[0].holes.len(), 1);
        let area = tree.family_polygon(&layer.contours, 0).area();
        assert!(
            (area - expected).abs() < 1e-6 * expected,
            "z = {z}: {area} vs {expected}"
        );
    }
}

#[test]
fn gear_shaft_assembly_is_two_watertight_parts_in_three_contours() {
    let meshes = model("use = \"gear-shaft\"\nteeth = 16\nheight = 5.0\nshaft_length = 9.0");
    assert_eq!(meshes.len(), 2);
    assert!(meshes.iter().all(watertight));
    assert!(meshes.iter().all(|m| m.signed_volume() > 0.0));
    // Both meshes in one layer: gear (outer + bore) and the shaft inside the bore.
    let mut both = meshes[0].clone();
    let base = both.vertices.len() as u32;
    both.vertices.extend_from_slice(&meshes[1].vertices);
    both.triangles.extend(
        meshes[1]
            .triangles
            .iter()
            .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
    );
    let (layer, tree) = cut(&both, 2.5);
    assert_eq!(layer.contours.len(), 3);
    assert_eq!(tree.families.len(), 2, "gear with its bore, and the shaft");
    let max_level = tree.nodes.iter().map(|n| n.level).max();
    assert_eq!(max_level, Some(2));
    // Above the gear only the shaft remains.
    let (layer, tree) = cut(&both, 7.0);
    assert_eq!(layer.contours.len(), 1);
    assert_eq!(tree.families.len(), 1);
}

#[test]
fn box_layers_are_exact() {
    let meshes = model("use = \"box\"\nsize = [3.0, 2.0, 1.0]");
    assert!(watertight(&meshes[0]));
    let (layer, _) = cut(&meshes[0], 0.5);
    assert_eq!(layer.contours.len(), 1);
    assert!((layer.contours[0].area() - 6.0).abs() < 1e-9);
    assert!(layer.contours[0].is_ccw());
}

#[test]
fn blade_layers_are_one_family_with_a_hole_per_cavity() {
    // Root 10 mm, airfoil 10 to 70 mm in 20 bands of 3 mm.
    for cavities in 0..=2 {
        let meshes = model(&format!("use = \"blade\"\ncavities = {cavities}"));
        assert!(watertight(&meshes[0]));
        let mut areas = Vec::new();
        for z in [0.1, 5.0, 9.9, 10.1, 13.0, 25.0, 40.0, 41.5, 55.55, 69.9, 70.0] {
            let (layer, tree) = cut(&meshes[0], z);
            assert_eq!(layer.contours.len(), 1 + cavities, "{cavities} cavities, z = {z}");
            assert_eq!(tree.families.len(), 1, "z = {z}");
            assert_eq!(tree.families[0].holes.len(), cavities, "z = {z}");
            areas.push((z, tree.family_polygon(&layer.contours, 0).area()));
        }
        // Every section is the base section turned: the same area at each section
        // height, a little less between sections (the ruled bands of a 1 degree twist
        // per section bow inwards by a few micrometres), and the
        // root's rectangle less the cavities below.
        let at = |z: f64| areas.iter().find(|a| a.0 == z).map(|a| a.1).expect("sampled");
        let section = at(13.0);
        for z in [25.0, 40.0, 55.0 + 0.55, 70.0] {
            let rel = if z == 55.55 { 5e-3 } else { 1e-7 };
            assert!(
                (at(z) - section).abs() < rel * section,
                "z = {z}: {} vs {section}",
                at(z)
            );
        }
        assert!((at(41.5) - section).abs() < 5e-3 * section);
        assert!(at(41.5) < section);
        assert!(at(5.0) > at(13.0) && (at(0.1) - at(9.9)).abs() < 1e-7 * at(5.0));
        println!(
            "blade, {cavities} cavities: root layer {:.3} mm2, airfoil section {section:.3} mm2, mid-band {:.3} mm2",
            at(5.0),
            at(41.5)
        );
    }
}
