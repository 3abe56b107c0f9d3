//! Computes the wire fingerprint: a hash of the source of every type that travels
//! between the host and a dynamic plugin as a message, comments and whitespace aside.
//! Two builds with the same fingerprint read and write the same messages; the plugin
//! loader refuses a plugin whose fingerprint differs, naming both.

use std::path::Path;

/// Files whose types are serialised across the plugin boundary.
const WIRE_SOURCES: &[&str] = &[
    "src/diagnostic.rs",
    "../geom/src/shape.rs",
    "src/limits.rs",
    "src/machine.rs",
    "src/machine/template.rs",
    "src/mesh.rs",
    "src/model.rs",
    "src/plugin/wire/error.rs",
    "src/plugin/wire/mod.rs",
    "src/process.rs",
    "src/reach.rs",
    "src/stage.rs",
];

fn main() {
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    for file in WIRE_SOURCES {
        println!("cargo:rerun-if-changed={file}");
        let text = std::fs::read_to_string(Path::new(file)).unwrap_or_else(|e| panic!("{file}: {e}"));
        for line in text.lines() {
            let code = line.trim();
            if code.is_empty() || code.starts_with("//") {
                continue;
            }
            for byte in code.bytes().filter(|b| !b.is_ascii_whitespace()) {
                hash ^= u64::from(byte);
                hash = hash.wrapping_mul(0x0100_0000_01b3);
            }
        }
    }
    println!("cargo:rustc-env=LAMINA_WIRE_FINGERPRINT={hash:016x}");
}
