//! The stored-settings reader (issue 17 item 8): `decode` on arbitrary bytes never panics
//! and accepts only exactly the stored settings; and a well-formed record (valid header and
//! CRC) carrying the fuzzer's values (any f32 bit patterns: NaN, inf, out of range) installs
//! on a control state all or nothing: a refused record leaves every setting as it was.
#![no_main]
use libfuzzer_sys::fuzz_target;
use piezo_core::firmware::{
    c, decode, encode, stored, Ctl, OnChip, Record, MAX_RECORD, SAMPLE_HZ,
};

std::thread_local! {
    // One controller for every run, reset to the defaults by each: building one (a
    // 4096-frame recorder) costs more than the check itself.
    static CTL: std::cell::RefCell<Ctl<OnChip>> =
        std::cell::RefCell::new(Ctl::<OnChip>::new(c(SAMPLE_HZ as f64)));
}

fn all_or_nothing(rec: &Record) {
    CTL.with(|ctl| check(&mut ctl.borrow_mut(), rec));
}

fn check(ctl: &mut Ctl<OnChip>, rec: &Record) {
    ctl.lp.default_settings().unwrap();
    let mut before = [0u8; MAX_RECORD];
    let n = ctl.lp.settings_record(&mut before).unwrap();
    if ctl.lp.apply_settings(rec).is_err() {
        let mut after = [0u8; MAX_RECORD];
        let m = ctl.lp.settings_record(&mut after).unwrap();
        assert_eq!(&before[..n], &after[..m], "a refused record changed a setting");
    }
}

fuzz_target!(|data: &[u8]| {
    if let Ok(rec) = decode(data) {
        assert_eq!(rec.len(), stored().count());
        all_or_nothing(&rec);
    }
    // The same bytes as the values of a well-formed record.
    let values = data.chunks(4).map(|b| {
        let mut w = [0u8; 4];
        w[..b.len()].copy_from_slice(b);
        f32::from_le_bytes(w)
    });
    let mut out = [0u8; MAX_RECORD];
    if let Ok(n) = encode(stored().zip(values.chain(core::iter::repeat(0.0))), &mut out) {
        let rec = decode(&out[..n]).expect("a record encode wrote decodes");
        all_or_nothing(&rec);
    }
});
