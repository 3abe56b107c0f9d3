//! Wavefront OBJ: any text parses to meshes or an error.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Ok(meshes) = lamina_model::obj::parse(Path::new("fuzz.obj"), &text) {
        for m in meshes {
            for t in 0..m.triangles.len() {
                let _ = m.triangle(t);
            }
        }
    }
});
