//! Binary and ASCII STL: any bytes parse to a soup or an error, and a soup welds.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(soups) = lamina_model::stl::parse(Path::new("fuzz.stl"), data) {
        for (name, soup) in soups {
            let (mesh, _) = lamina_model::weld::weld(&name, &soup, 1e-5);
            let _ = mesh.bbox();
        }
    }
});
