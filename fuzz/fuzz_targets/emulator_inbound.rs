#![no_main]
//! See `ringswarm::fuzzing::emulator_inbound`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = ringswarm::fuzzing::emulator_inbound(data);
});
