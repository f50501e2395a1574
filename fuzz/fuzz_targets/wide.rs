#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| guidebake_suite::fuzzing::wide(data));
