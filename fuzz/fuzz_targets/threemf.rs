//! 3MF packages (ZIP, XML, components, transforms, units, base materials): any bytes
//! read to meshes or an error, within the default limits.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(meshes) = lamina_model::threemf::read(Path::new("fuzz.3mf"), data) {
        for m in meshes {
            let _ = m.bbox();
        }
    }
});
