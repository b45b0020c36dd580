#![no_main]
//! See `ringswarm::fuzzing::decode`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| ringswarm::fuzzing::decode(data));
