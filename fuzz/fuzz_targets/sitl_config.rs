#![no_main]
//! See `ringswarm::fuzzing::sitl_config`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| ringswarm::fuzzing::sitl_config(data));
