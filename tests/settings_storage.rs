//! Settings across power cycles (`save`, `load`, `defaults`) on the host, over the strict
//! RAM NOR flash model: a power loss at every byte of every write and erase of a sequence
//! of saves leaves the old record or the new one, never a mix, and the boot after it never
//! erases (a repair that needs an erase is left to idle); damaged or stale records
//! are refused and change nothing; a refused value changes no setting.

use piezo_core::command::Error;
use piezo_core::firmware::{
    c, decode, encode, stored, Boot, Ctl, OnChip, RamNor, SettingsFlash, MAX_RECORD, SAMPLE_HZ,
};
use proptest::prelude::*;

/// 4 sectors of 512 B, 32-byte words: small sectors, so a few saves fill a sector and the
/// map erases one (the cuts then also fall into erases).
type Nor = RamNor<2048, 512, 32>;
const RANGE: core::ops::Range<u32> = 0..2048;

fn ask(ctl: &mut Ctl<OnChip>, line: &str) -> String {
    ctl.answer(line).as_str().to_string()
}

/// A valid record whose every value depends on `i` (distinct records, all valid settings):
/// the defaults scaled by `1 + i/200`, with `u_min = i/4`, `u_max = 100 + i`, `offset_um = i`.
fn record(i: u32) -> Vec<u8> {
    let x = i as f32;
    let ctl = Ctl::<OnChip>::new(c(SAMPLE_HZ as f64));
    let mut out = [0u8; MAX_RECORD];
    let n = ctl.lp.settings_record(&mut out).unwrap();
    let defaults = decode(&out[..n]).unwrap();
    let n = encode(
        stored().map(|name| {
            let v = match name {
                "u_min" => x * 0.25,
                "u_max" => 100.0 + x,
                "offset_um" => x,
                // Whole samples.
                "stuck" => 100.0 + x,
                _ => defaults.value(name).unwrap() * (1.0 + x / 200.0),
            };
            (name, v)
        }),
        &mut out,
    )
    .unwrap();
    out[..n].to_vec()
}

fn stored_now(flash: Nor) -> (Option<Vec<u8>>, Nor) {
    let mut s = SettingsFlash::new(flash, RANGE).unwrap();
    let mut buf = [0u8; MAX_RECORD];
    let got = s
        .load(&mut buf)
        .expect("after a power loss the flash is readable")
        .map(|n| buf[..n].to_vec());
    (got, s.into_flash())
}

#[test]
fn a_power_loss_at_every_byte_of_a_save_leaves_old_or_new() {
    const SAVES: u32 = 12;
    let mut clean = Nor::new();
    let (mut cut_points, mut erases_cut, mut repairs) = (0usize, 0usize, 0usize);
    for s in 0..SAVES {
        let new = record(s);
        let old = (s > 0).then(|| record(s - 1));
        // The save without a cut: its number of changed bytes is the number of cut points.
        let mut f = SettingsFlash::new(clean.clone(), RANGE).unwrap();
        f.save(&new).unwrap();
        let after = f.into_flash();
        let total = after.changed - clean.changed;
        for k in 0..total {
            let mut cut = clean.clone();
            cut.cut_after(Some(k));
            let mut f = SettingsFlash::new(cut, RANGE).unwrap();
            let r = f.save(&new);
            assert!(
                r.is_err(),
                "save {s} cut after {k} of {total} bytes reported success"
            );
            let mut flash = f.into_flash();
            flash.power_on();
            // Reboot: the boot's read never erases (an H743 sector erase outlasts the boot
            // watchdog); where the repair needs one, idle does it.
            let erases = flash.erases;
            let mut f = SettingsFlash::new(flash, RANGE).unwrap();
            let mut buf = [0u8; MAX_RECORD];
            let boot = f.boot_load(&mut buf).map(|n| n.map(|n| buf[..n].to_vec()));
            let needs_repair = boot.is_err() && f.needs_repair();
            let flash = f.into_flash();
            assert_eq!(
                flash.erases, erases,
                "save {s} cut after {k}: the boot erased"
            );
            let flash = if needs_repair {
                repairs += 1;
                let mut f = SettingsFlash::new(flash, RANGE).unwrap();
                f.repair().expect("idle's repair");
                f.into_flash()
            } else {
                assert!(boot.is_ok(), "save {s} cut after {k}: boot read {boot:?}");
                flash
            };
            // Then: a new store over what the boot (and idle's repair) left.
            let (got, flash) = stored_now(flash);
            if let Ok(b) = &boot {
                assert_eq!(b, &got, "what the boot read is what is stored");
            }
            match &got {
                Some(g) if *g == new => {}
                Some(g) if Some(g) == old.as_ref() => {}
                None if old.is_none() => {}
                other => {
                    panic!("save {s} cut after {k} bytes: {other:?} is neither old nor new")
                }
            }
            decode(got.as_deref().unwrap_or(&record(0))).expect("whatever is loaded is valid");
            // The flash stays usable: the next save and load work.
            let mut f = SettingsFlash::new(flash, RANGE).unwrap();
            f.save(&record(100 + s)).unwrap();
            let (again, _) = stored_now(f.into_flash());
            assert_eq!(again, Some(record(100 + s)));
            cut_points += 1;
        }
        if total > 512 {
            erases_cut += 1;
        }
        clean = after;
    }
    // Saves that erased a sector were among them (the cuts fell into erases too).
    assert!(erases_cut >= 2, "only {erases_cut} saves erased a sector");
    // Cuts after which the boot's read met a repair that erases (the former boot erased
    // there, under the watchdog).
    assert!(
        repairs > 0,
        "no cut needed a repair: the boot path is not exercised"
    );
    eprintln!("{cut_points} cut points over {SAVES} saves ({erases_cut} with a sector erase): old or new each time; {repairs} boots left the repair to idle");
}

#[test]
fn save_load_defaults_round_trip_through_the_flash() {
    let mut ctl = Ctl::<OnChip>::new(c(SAMPLE_HZ as f64));
    let mut flash = SettingsFlash::new(Nor::new(), RANGE).unwrap();
    assert_eq!(ctl.lp.boot_settings(&mut flash), Boot::Empty);
    assert_eq!(ask(&mut ctl, "set pid_kp 0.75"), "ok pid_kp 0.75");
    assert_eq!(ask(&mut ctl, "set u_max 120"), "ok u_max 120");
    // Not while the loop drives the stage.
    assert!(ask(&mut ctl, "wave sine 1 10 5").starts_with("ok wave sine"));
    assert_eq!(ctl.lp.save_settings(&mut flash), Err(Error::Busy));
    assert_eq!(ask(&mut ctl, "wave off"), "ok wave off");
    let n = ctl.lp.save_settings(&mut flash).unwrap();
    assert_eq!(n, 8 + 8 * stored().count() + 4);
    assert_eq!(ask(&mut ctl, "defaults"), "ok defaults");
    assert_eq!(ask(&mut ctl, "get pid_kp"), "ok pid_kp 0.5");
    assert_eq!(ask(&mut ctl, "get u_max"), "ok u_max 150");
    // Power cycle: a fresh controller over the same flash boots with the stored settings.
    let mut ctl = Ctl::<OnChip>::new(c(SAMPLE_HZ as f64));
    let mut flash = SettingsFlash::new(flash.into_flash(), RANGE).unwrap();
    assert_eq!(ctl.lp.boot_settings(&mut flash), Boot::Loaded);
    assert_eq!(ask(&mut ctl, "get pid_kp"), "ok pid_kp 0.75");
    assert_eq!(ask(&mut ctl, "get u_max"), "ok u_max 120");
}

#[test]
fn a_damaged_or_stale_record_is_refused_at_boot_and_defaults_run() {
    let mut ctl = Ctl::<OnChip>::new(c(SAMPLE_HZ as f64));
    assert_eq!(ask(&mut ctl, "set lambda1 1234"), "ok lambda1 1234");
    let mut buf = [0u8; MAX_RECORD];
    let n = ctl.lp.settings_record(&mut buf).unwrap();
    // Stale: another layout version, with a valid checksum over it.
    let mut stale = buf[..n].to_vec();
    stale[4] = 2;
    let crc = crc32(&stale[..n - 4]);
    stale[n - 4..].copy_from_slice(&crc.to_le_bytes());
    // A record of a table with one setting fewer (valid checksum).
    let mut short = [0u8; MAX_RECORD];
    let m = encode(stored().skip(1).map(|s| (s, 1.0)), &mut short).unwrap();
    for bad in [stale, short[..m].to_vec()] {
        let mut flash = SettingsFlash::new(Nor::new(), RANGE).unwrap();
        flash.save(&bad).unwrap();
        let mut fresh = Ctl::<OnChip>::new(c(SAMPLE_HZ as f64));
        assert_eq!(
            fresh.lp.boot_settings(&mut flash),
            Boot::Refused(Error::BadSettings)
        );
        assert_eq!(ask(&mut fresh, "get lambda1"), "ok lambda1 2000");
    }
}

#[test]
fn a_record_with_one_refused_value_changes_nothing() {
    let mut ctl = Ctl::<OnChip>::new(c(SAMPLE_HZ as f64));
    let before: Vec<String> = stored()
        .map(|s| ask(&mut ctl, &format!("get {s}")))
        .collect();
    for (bad_name, bad) in [
        ("hgo_eps", -1.0f32),
        ("u_min", 140.0),
        ("slew", 0.0),
        ("cbw_alpha", 0.0),
    ] {
        let mut out = [0u8; MAX_RECORD];
        // Every other value changed (and valid), so a half-applied record would show.
        let n = encode(
            stored().map(|s| {
                let v = if s == bad_name {
                    bad
                } else {
                    let rec = decode(&record(3)).unwrap();
                    rec.value(s).unwrap()
                };
                (s, v)
            }),
            &mut out,
        )
        .unwrap();
        let rec = decode(&out[..n]).unwrap();
        assert_eq!(
            ctl.lp.apply_settings(&rec),
            Err(Error::BadSettings),
            "{bad_name}"
        );
        let after: Vec<String> = stored()
            .map(|s| ask(&mut ctl, &format!("get {s}")))
            .collect();
        assert_eq!(before, after, "{bad_name} = {bad}: settings changed");
    }
    // The same record with a valid value goes in whole.
    assert_eq!(ctl.lp.apply_settings(&decode(&record(3)).unwrap()), Ok(()));
    assert_eq!(ask(&mut ctl, "get u_max"), "ok u_max 103");
}

fn crc32(b: &[u8]) -> u32 {
    crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(b)
}

proptest! {
    /// Any flip of 1 to 3 bits anywhere in a record is refused (CRC-32: Hamming
    /// distance 4 at these lengths), and a record loaded through `apply_settings`
    /// after a refused one is unaffected.
    #[test]
    fn a_corrupted_record_is_refused(i in 0u32..50, bits in proptest::collection::btree_set(0usize..1024, 1..=3)) {
        let rec = record(i);
        let mut bad = rec.clone();
        let len_bits = bad.len() * 8;
        let flips: std::collections::BTreeSet<usize> = bits.iter().map(|b| b % len_bits).collect();
        for b in &flips {
            bad[b / 8] ^= 1 << (b % 8);
        }
        prop_assume!(bad != rec);
        prop_assert_eq!(decode(&bad), Err(Error::BadSettings));
    }

    /// Arbitrary bytes (any length) never panic the reader; what it accepts has a valid
    /// checksum and exactly the stored settings.
    #[test]
    fn the_reader_takes_any_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
        if let Ok(r) = decode(&bytes) {
            prop_assert_eq!(r.len(), stored().count());
        }
    }

    /// Random damage to the flash sectors never panics the boot; it loads the record
    /// saved, or refuses, or finds none.
    #[test]
    fn a_damaged_flash_boots(at in 0usize..2048, val in any::<u8>(), n in 1usize..64) {
        let mut f = SettingsFlash::new(Nor::new(), RANGE).unwrap();
        f.save(&record(7)).unwrap();
        let mut nor = f.into_flash();
        for b in nor.bytes_mut().iter_mut().skip(at).take(n) {
            *b = val;
        }
        let mut f = SettingsFlash::new(nor, RANGE).unwrap();
        let mut ctl = Ctl::<OnChip>::new(c(SAMPLE_HZ as f64));
        let boot = ctl.lp.boot_settings(&mut f);
        prop_assert!(matches!(boot, Boot::Loaded | Boot::Empty | Boot::Refused(_)));
        if boot == Boot::Loaded {
            prop_assert_eq!(ask(&mut ctl, "get u_max"), "ok u_max 107");
        }
    }
}

/// A non-finite value is refused when writing, as `decode` would refuse the record (the
/// fuzz target `settings_record` found `encode` writing what `decode` then refused).
#[test]
fn encode_refuses_what_decode_would() {
    let mut out = [0u8; MAX_RECORD];
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let values = stored()
            .enumerate()
            .map(|(i, n)| (n, if i == 3 { bad } else { 1.0 }));
        assert_eq!(encode(values, &mut out), Err(Error::OutOfRange));
    }
    let n = encode(stored().map(|n| (n, 1.0)), &mut out).unwrap();
    assert!(decode(&out[..n]).is_ok());
}

/// The boards' path: the command task hands `save`/`load` to the flash job, idle runs it,
/// the command task replies. Meanwhile queries are answered and every command that would
/// change state is refused (err 12); `load` installs the record in the live loop.
#[test]
fn save_and_load_through_the_command_line_and_idle() {
    use piezo_core::firmware::{
        run_flash_job, CommandLine, FlashWork, Port, SettingsJob, WithFlash,
    };
    use rtic_core::Exclusive;

    #[derive(Default)]
    struct Lines(Vec<String>);
    impl Port for Lines {
        fn send(&mut self, line: &str) {
            self.0.push(line.to_string());
        }
        fn send_bytes(&mut self, _: &[u8]) {}
    }
    struct Board {
        ctl: Ctl<OnChip>,
        cli: CommandLine<OnChip>,
        lines: Lines,
        job: SettingsJob,
        work: FlashWork,
        flash: SettingsFlash<Nor>,
    }
    impl Board {
        /// Types a line (the command task); the replies sent so far.
        fn type_line(&mut self, line: &str) -> Vec<String> {
            let mut port = WithFlash {
                port: &mut self.lines,
                job: &mut Exclusive(&mut self.job),
            };
            for b in line.bytes().chain(Some(b'\n')) {
                self.cli.byte(b, &mut Exclusive(&mut self.ctl), &mut port);
            }
            std::mem::take(&mut self.lines.0)
        }
        /// Idle runs the job; the command task, pended, replies.
        fn idle(&mut self) -> Vec<String> {
            let ready = run_flash_job(
                &mut Exclusive(&mut self.job),
                &mut self.work,
                Some(&mut self.flash),
            );
            let mut port = WithFlash {
                port: &mut self.lines,
                job: &mut Exclusive(&mut self.job),
            };
            let sent = self
                .cli
                .flash_poll(&mut Exclusive(&mut self.ctl), &mut port);
            assert_eq!(ready, sent, "a reply exactly when idle finished a job");
            std::mem::take(&mut self.lines.0)
        }
    }
    let ctl = Ctl::<OnChip>::new(c(SAMPLE_HZ as f64));
    let mut b = Board {
        cli: CommandLine::new(&ctl.lp),
        ctl,
        lines: Lines::default(),
        job: SettingsJob::new(),
        work: FlashWork::new(),
        flash: SettingsFlash::new(Nor::new(), RANGE).unwrap(),
    };
    let n = 8 + 8 * stored().count() + 4;
    let count = stored().count();
    assert_eq!(b.type_line("load"), Vec::<String>::new());
    assert_eq!(b.idle(), ["err 15 no settings stored"]);
    assert_eq!(b.type_line("set u_max 120"), ["ok u_max 120"]);
    assert_eq!(
        b.type_line("save"),
        Vec::<String>::new(),
        "the reply waits for idle"
    );
    // An erase takes seconds on the H743: queries are answered meanwhile (the save's
    // reply, which names its command, comes after theirs) ...
    assert_eq!(b.type_line("ping"), ["ok pong"]);
    assert_eq!(b.type_line("get u_max"), ["ok u_max 120"]);
    assert!(b.type_line("stats")[0].starts_with("ok "));
    assert!(b.type_line("fault")[0].starts_with("ok "));
    assert!(b.type_line("rec status")[0].starts_with("ok "));
    // ... and whatever would change state is refused, the live settings staying those on
    // their way to the flash.
    for busy in [
        "load",
        "save",
        "set u_max 110",
        "defaults",
        "mode pid",
        "wave sine 1 10 5",
        "rec arm",
    ] {
        assert_eq!(
            b.type_line(busy),
            ["err 12 not possible in the current state"],
            "{busy}"
        );
    }
    assert_eq!(b.idle(), [format!("ok save {count} settings {n} B")]);
    assert_eq!(b.idle(), Vec::<String>::new(), "one reply per job");
    assert_eq!(b.type_line("set u_max 100"), ["ok u_max 100"]);
    assert_eq!(b.type_line("load"), Vec::<String>::new());
    assert_eq!(b.idle(), [format!("ok load {count} settings")]);
    assert_eq!(b.type_line("get u_max"), ["ok u_max 120"]);
    assert_eq!(
        b.ctl.answer("get u_max").as_str(),
        "ok u_max 120",
        "the live loop has it"
    );
    // Not while the loop drives the stage: refused at once, nothing handed to idle.
    assert!(b.type_line("wave sine 1 10 5")[0].starts_with("ok wave sine"));
    assert_eq!(
        b.type_line("save"),
        ["err 12 not possible in the current state"]
    );
    assert_eq!(b.idle(), Vec::<String>::new());
}
