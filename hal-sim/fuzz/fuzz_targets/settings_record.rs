//! The stored-settings reader (issue 17 item 8) on arbitrary bytes: `decode` never panics;
//! what it accepts has exactly the stored settings, and installing it on a control state is
//! all or nothing: a refused record leaves every setting as it was.
#![no_main]
use libfuzzer_sys::fuzz_target;
use piezo_core::firmware::{c, decode, stored, Ctl, OnChip, MAX_RECORD, SAMPLE_HZ};

fuzz_target!(|data: &[u8]| {
    let Ok(rec) = decode(data) else {
        return;
    };
    assert_eq!(rec.len(), stored().count());
    let mut ctl = Ctl::<OnChip>::new(c(SAMPLE_HZ as f64));
    let mut before = [0u8; MAX_RECORD];
    let n = ctl.lp.settings_record(&mut before).unwrap();
    if ctl.lp.apply_settings(&rec).is_err() {
        let mut after = [0u8; MAX_RECORD];
        let m = ctl.lp.settings_record(&mut after).unwrap();
        assert_eq!(&before[..n], &after[..m], "a refused record changed a setting");
    }
});
