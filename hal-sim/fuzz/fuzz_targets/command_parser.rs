//! The serial command parser on arbitrary bytes: never panics, and a parsed line is
//! shorter than the documented maximum. The firmware's own float parser agrees with core's
//! bit for bit on every input both accept, and rejects exactly what it documents.
#![no_main]
use libfuzzer_sys::fuzz_target;
use piezo_core::command::{parse_f32, Error, MAX_DIGITS};

fuzz_target!(|data: &[u8]| {
    if piezo_core::command::parse(data).is_ok() {
        assert!(data.len() <= piezo_core::command::MAX_LINE);
    }
    let Ok(s) = core::str::from_utf8(data) else {
        return;
    };
    let ours = parse_f32(s);
    // Core also accepts inf/nan words; ours takes digits only.
    let digits_only = s
        .bytes()
        .all(|b| b.is_ascii_digit() || matches!(b, b'+' | b'-' | b'.' | b'e' | b'E'));
    match (s.parse::<f32>(), ours) {
        (Ok(v), Ok(o)) => assert_eq!(v.to_bits(), o.to_bits(), "{s:?}"),
        (Ok(v), Err(Error::TooManyDigits)) => {
            let mant = s.split(['e', 'E']).next().unwrap_or("");
            let d: String = mant.chars().filter(|c| c.is_ascii_digit()).collect();
            let sig = d.trim_start_matches('0').trim_end_matches('0').len();
            assert!(sig > MAX_DIGITS as usize, "{s:?} -> {v}");
        }
        (Ok(v), Err(Error::BadNumber)) => assert!(!v.is_finite() || !digits_only, "{s:?} -> {v}"),
        (Ok(v), Err(e)) => panic!("{s:?}: {e:?}, core {v}"),
        (Err(_), Ok(o)) => panic!("{s:?}: core rejects, ours {o}"),
        (Err(_), Err(_)) => {}
    }
});
