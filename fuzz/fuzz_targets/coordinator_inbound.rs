#![no_main]
//! See `ringswarm::fuzzing::coordinator_inbound`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = ringswarm::fuzzing::coordinator_inbound(data);
});
