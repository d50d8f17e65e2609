//! The serial command parser on arbitrary bytes: never panics, and a parsed line is
//! shorter than the documented maximum.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if piezo_core::command::parse(data).is_ok() {
        assert!(data.len() <= piezo_core::command::MAX_LINE);
    }
});
