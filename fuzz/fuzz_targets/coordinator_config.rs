#![no_main]
//! See `ringswarm::fuzzing::coordinator_config`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| ringswarm::fuzzing::coordinator_config(data));
