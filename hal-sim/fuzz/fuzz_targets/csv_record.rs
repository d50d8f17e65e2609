//! The CSV record reader on arbitrary text: never panics; a parsed record is consistent.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        if let Ok(r) = piezo_ident::record::Record::parse(text) {
            let n = r.t.len();
            assert!(r.u.iter().chain(r.y.iter()).all(|c| c.len() == n));
        }
    }
});
