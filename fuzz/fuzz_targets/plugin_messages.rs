//! The plugin boundary's messages as the other side may send them: bytes decoded as a
//! request (what a plugin reads), a reply (what the host reads from a plugin), a host
//! request and a host reply. Decoding must end in a value or an error, and an error a
//! plugin reports must become a host error that prints.
#![no_main]

use lamina_core::plugin::wire::{HostReply, HostRequest, Reply, Request, decode, encode};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(request) = decode::<Request<'static>>(data) {
        // What decodes, encodes again.
        let _ = encode(&request).expect("a decoded request encodes");
    }
    match decode::<Reply>(data) {
        Ok(Err(e)) => {
            let error = lamina_core::Error::from(e);
            let _ = error.to_string();
            let _ = error.location().map(|l| l.line_col());
        }
        Ok(Ok(response)) => {
            let _ = encode(&response).expect("a decoded reply encodes");
        }
        Err(_) => {}
    }
    let _ = decode::<HostRequest<'static>>(data);
    if let Ok(Err(e)) = decode::<HostReply>(data) {
        let _ = lamina_core::Error::from(e).to_string();
    }
});
