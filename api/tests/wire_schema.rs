//! The messages' schema, traced from the serde definitions of every type a message
//! carries, against the schema `wire-schema.json` records and the version
//! `plugin::abi::WIRE_SCHEMAS` gives it: a change to a message that no version
//! records fails here, whatever else changed with it.
//!
//! `LAMINA_UPDATE_SCHEMA=1 cargo test -p lamina-api --test wire_schema` rewrites the
//! file; the version is given by hand (see `WIRE_SCHEMAS`).

use std::path::Path;

use lamina_api::diagnostic::Severity;
use lamina_api::machine::{
    BedOrigin, BedPlacement, BedShape, Cornering, Firmware, FirstLayerSpeed, Flavor, HeadClass,
};
use lamina_api::model::PathKind;
use lamina_api::plugin::abi::{ABI_MAJOR, ABI_MINOR, FINGERPRINT_SEED, WIRE_FINGERPRINT, WIRE_SCHEMAS};
use lamina_api::plugin::wire::{HostRequest, HostResponse, Request, Response, WireError, WireStep};
use lamina_api::stage::StageKind;
use serde_reflection::{Tracer, TracerConfig};

/// The schema as text: every container a message reaches, by name, with its fields or
/// variants in order.
fn traced() -> String {
    let mut tracer = Tracer::new(TracerConfig::default());
    // The messages each way.
    tracer.trace_simple_type::<Request<'static>>().expect("Request");
    tracer.trace_simple_type::<Response>().expect("Response");
    tracer
        .trace_simple_type::<HostRequest<'static>>()
        .expect("HostRequest");
    tracer.trace_simple_type::<HostResponse>().expect("HostResponse");
    tracer.trace_simple_type::<WireError>().expect("WireError");
    // Every variant of the enums inside them (the registry names any left out).
    tracer.trace_simple_type::<BedOrigin>().expect("BedOrigin");
    tracer.trace_simple_type::<BedPlacement>().expect("BedPlacement");
    tracer.trace_simple_type::<BedShape>().expect("BedShape");
    tracer.trace_simple_type::<Cornering>().expect("Cornering");
    tracer.trace_simple_type::<Firmware>().expect("Firmware");
    tracer
        .trace_simple_type::<FirstLayerSpeed>()
        .expect("FirstLayerSpeed");
    tracer.trace_simple_type::<Flavor>().expect("Flavor");
    tracer.trace_simple_type::<HeadClass>().expect("HeadClass");
    tracer.trace_simple_type::<PathKind>().expect("PathKind");
    tracer.trace_simple_type::<Severity>().expect("Severity");
    tracer.trace_simple_type::<StageKind>().expect("StageKind");
    tracer.trace_simple_type::<WireStep>().expect("WireStep");
    let registry = tracer
        .registry()
        .unwrap_or_else(|e| panic!("{e}: {}", e.explanation()));
    let mut text = serde_json::to_string_pretty(&registry).expect("the schema as JSON");
    text.push('\n');
    text
}

/// FNV-1a over the schema's bytes, as `WIRE_SCHEMAS` records it.
fn hash(text: &str) -> u64 {
    text.bytes().fold(FINGERPRINT_SEED, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

#[test]
fn every_message_change_has_a_version() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("wire-schema.json");
    let now = traced();
    if std::env::var_os("LAMINA_UPDATE_SCHEMA").is_some() {
        std::fs::write(&path, &now).expect("write wire-schema.json");
    }
    let recorded = std::fs::read_to_string(&path).unwrap_or_default();
    let h = hash(&now);
    assert!(
        recorded == now,
        "the messages changed (their schema hashes to {h:#018x}): review the difference with \
         `LAMINA_UPDATE_SCHEMA=1 cargo test -p lamina-api --test wire_schema` and `git diff \
         api/wire-schema.json`, then give it a version in plugin::abi::WIRE_SCHEMAS"
    );
    assert!(
        WIRE_FINGERPRINT == h,
        "the schema of ABI {ABI_MAJOR}.{ABI_MINOR} is {WIRE_FINGERPRINT:#018x}, the messages' is {h:#018x}: \
         append {h:#018x} to WIRE_SCHEMAS if older plugins can do without what changed (fields with \
         #[serde(default)], requests only newer plugins are sent), or else raise ABI_MAJOR and start \
         WIRE_SCHEMAS again with it"
    );
}

#[test]
fn the_versions_of_one_major_are_distinct() {
    for (i, a) in WIRE_SCHEMAS.iter().enumerate() {
        for b in &WIRE_SCHEMAS[i + 1..] {
            assert_ne!(a, b, "WIRE_SCHEMAS names {a:#018x} twice");
        }
    }
}
