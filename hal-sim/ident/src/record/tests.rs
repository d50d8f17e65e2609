use super::*;
use proptest::prelude::*;

#[test]
fn parses_comments_channels_and_extras() {
    let r = Record::parse("# hello\n# fs = 2 Hz\nt,y2,u,r,y1\n0,1,2,3,4\n0.5,5,6,7,8\n").unwrap();
    assert_eq!(r.comments, vec![" hello", " fs = 2 Hz"]);
    assert_eq!(r.t, vec![0.0, 0.5]);
    assert_eq!(r.u, vec![vec![2.0, 6.0]]);
    assert_eq!(r.y, vec![vec![4.0, 8.0], vec![1.0, 5.0]]);
    assert_eq!(r.extra, vec![("r".to_string(), vec![3.0, 7.0])]);
    assert_eq!(r.sample_rate_hz(), 2.0);
    assert_eq!(r.column("y2"), Some(&[1.0, 5.0][..]));
    assert_eq!(r.column("r"), Some(&[3.0, 7.0][..]));
    assert_eq!(r.column("y"), None);
    // Round trip through text.
    assert_eq!(Record::parse(&r.to_csv()).unwrap(), r);
}

fn msg(text: &str) -> String {
    Record::parse(text).unwrap_err().to_string()
}

#[test]
fn errors_name_line_and_cause() {
    assert_eq!(
        msg("t,u,y\n0,1,2\n1,x,3\n"),
        "line 3: column 2: `x` is not a number"
    );
    assert_eq!(
        msg("t,u,y\n0,1,2\n1,2\n"),
        "line 3: 2 columns, but the header (line 1) has 3"
    );
    assert_eq!(
        msg("#c\nt,u,y\n0,1,2\n1,NaN,3\n"),
        "line 4: column 2: `NaN` is not finite"
    );
    assert!(msg("t,u\n0,1\n1,2\n").contains("no `y` column"));
    assert!(msg("u,y\n0,1\n1,2\n").contains("no `t` column"));
    assert!(msg("t,u1,u3,y\n0,1,2,3\n1,1,2,3\n").contains("no `u2`"));
    assert!(msg("t,u,u1,y\n0,1,2,3\n").contains("mixes"));
    assert!(msg("t,u,y,u\n").contains("twice"));
    assert!(msg("0,1,2\n1,2,3\n").contains("found numbers"));
    assert_eq!(
        msg("t,u,y\n0,1,2\n1,1,2\n1,1,2\n"),
        "line 4: t = 1 does not increase (previous row t = 1)"
    );
    assert!(msg("t,u,y\n0,1,2\n1,1,2\n2,1,2\n4,1,2\n").starts_with("line 5: non-uniform sampling"));
    assert!(msg("t,u,y\n0,1,2\n").contains("at least 2"));
    assert!(msg("# only\n").contains("no header"));
    assert!(msg("").contains("no header"));
}

fn layout(t: Option<&str>, u: &[&str], y: &[&str]) -> Layout {
    let own = |v: &[&str]| v.iter().map(|s| s.to_string()).collect();
    Layout {
        t: t.map(Into::into),
        u: own(u),
        y: own(y),
        ..Layout::default()
    }
}

fn msg_with(text: &str, l: &Layout) -> String {
    Record::parse_with(text, l).unwrap_err().to_string()
}

#[test]
fn units_in_the_header_are_converted_to_s_volts_um() {
    let r = Record::parse("t_ms,u_mV,y_nm,r_nm\n0,1500,2500,7\n2,-500,-1000,8\n").unwrap();
    assert_eq!(r.t, vec![0.0, 2e-3]);
    assert_eq!(r.u, vec![vec![1.5, -0.5]]);
    assert_eq!(r.y, vec![vec![2.5, -1.0]]);
    // Other columns are kept by name, as they are.
    assert_eq!(r.extra, vec![("r_nm".to_string(), vec![7.0, 8.0])]);
    assert_eq!(r.unit_note, None);
    // Spreadsheet forms, metres, micro signs, and the firmware's `volts`.
    let r =
        Record::parse("t [s],u1 (V),u2_volts,y1 [m],y2_µm\n0,1,2,1e-6,4\n1,1,2,2e-6,5\n").unwrap();
    assert_eq!(r.u, vec![vec![1.0, 1.0], vec![2.0, 2.0]]);
    assert_eq!(r.y[0], vec![1.0, 2.0]);
    assert_eq!(r.y[1], vec![4.0, 5.0]);
    assert_eq!(r.unit_note, None);
    // Written back in the internal units, named in the header.
    let back = Record::parse(&r.to_csv()).unwrap();
    assert!(
        r.to_csv().starts_with("t_s,u1_V,u2_V,y1_um,y2_um\n"),
        "{}",
        r.to_csv()
    );
    assert_eq!(back, r);
}

#[test]
fn unitless_files_read_in_the_default_units_with_a_note() {
    let text = "t,u,y\n0,1.5,-123.25\n0.5,2,-124\n";
    let r = Record::parse(text).unwrap();
    // Values as they are (no conversion), and the tools are told.
    assert_eq!((r.u[0][0], r.y[0][0]), (1.5, -123.25));
    let note = r.unit_note.clone().unwrap();
    assert!(note.contains("`t` (s), `u` (V), `y` (um)"), "{note}");
    // Written back without units: the file never claimed any.
    assert!(r.to_csv().starts_with("t,u,y\n"), "{}", r.to_csv());
    // Another default for unitless outputs: converted from it, still noted.
    let l = Layout {
        y_unit: "nm".into(),
        ..Layout::default()
    };
    let r = Record::parse_with(text, &l).unwrap();
    assert_eq!(r.y[0][0], -0.12325);
    assert!(r.unit_note.unwrap().contains("`y` (nm)"));
    // A stated unit wins over the default.
    let r = Record::parse_with("t_s,u_V,y_um\n0,1,2\n1,1,2\n", &l).unwrap();
    assert_eq!((r.y[0][0], r.unit_note), (2.0, None));
}

#[test]
fn records_built_in_code_are_written_with_units() {
    let r = Record::new(vec![0.0, 1e-3], vec![vec![1.0, 2.0]], vec![vec![3.0, 4.0]]).unwrap();
    assert_eq!(r.to_csv(), "t_s,u_V,y_um\n0,1,3\n0.001,2,4\n");
}

#[test]
fn unknown_and_misplaced_units_are_refused() {
    assert_eq!(
        msg("t_s,u_V,y [ft]\n0,1,2\n1,1,2\n"),
        "line 1: column `y [ft]`: unknown length unit `ft` (accepted: um, µm, μm, nm, mm, m)"
    );
    assert!(msg("t [fortnight],u,y\n0,1,2\n1,1,2\n").contains("unknown time unit `fortnight`"));
    assert_eq!(
        msg("t_s,u_um,y_um\n0,1,2\n1,1,2\n"),
        "line 1: column `u_um`: `um` is a length unit, not a voltage unit (V, volts, mV)"
    );
    // `_ft` is no unit this reader knows, so `y_ft` is not taken for an output.
    let e = msg("t_s,u_V,y_ft\n0,1,2\n1,1,2\n");
    assert!(
        e.contains("no `y` column") && e.contains("`y_ft`: unknown unit `ft`"),
        "{e}"
    );
    // A default unit for unitless columns is checked the same way.
    let l = Layout {
        u_unit: "N".into(),
        ..Layout::default()
    };
    let e = msg_with("t,u,y\n0,1,2\n1,1,2\n", &l);
    assert!(
        e.contains("column `u` states no unit") && e.contains("unknown voltage unit `N`"),
        "{e}"
    );
    // Two time columns, or the same column twice: which one is meant is not guessed.
    assert!(msg("t,t_s,u,y\n0,0,1,2\n1,1,1,2\n").contains("2 time columns"));
    assert!(msg("t,u_V,u_mV,y\n0,0,1,2\n1,1,1,2\n").contains("2 `u` columns"));
    let e = msg_with("t,a,b\n0,1,2\n1,1,2\n", &layout(None, &["a"], &["a"]));
    assert!(e.contains("`a` is chosen twice"), "{e}");
}

#[test]
fn foreign_columns_are_chosen_by_name() {
    let text = "# logger export\ntime [ms],drive_mV,pos (nm),temp\n0,100,2000,21\n10,200,4000,21\n";
    let l = layout(Some("time [ms]"), &["drive_mV"], &["pos (nm)"]);
    let r = Record::parse_with(text, &l).unwrap();
    assert_eq!(r.t, vec![0.0, 0.01]);
    assert_eq!(r.u, vec![vec![0.1, 0.2]]);
    assert_eq!(r.y, vec![vec![2.0, 4.0]]);
    assert_eq!(r.extra, vec![("temp".to_string(), vec![21.0, 21.0])]);
    assert_eq!(r.unit_note, None);
    // Without the choice: the missing role is named with the columns present.
    assert_eq!(
        msg(text),
        "line 2: header has no `t` column (time: `t` in seconds, or with a unit as in `t_s`, \
         `t_ms`; or choose it with --t-col); the columns are `time [ms]`, `drive_mV`, \
         `pos (nm)`, `temp`"
    );
    let e = msg_with(
        text,
        &layout(Some("time [ms]"), &["drive_mV"], &["Position"]),
    );
    assert_eq!(
        e,
        "line 2: no output column `Position` in the header; the columns are `time [ms]`, \
         `drive_mV`, `pos (nm)`, `temp`"
    );
    // Unitless chosen columns take the default units and say so.
    let r = Record::parse_with(text, &layout(Some("time [ms]"), &["drive_mV"], &["temp"])).unwrap();
    assert!(r.unit_note.unwrap().contains("`temp` (um)"));
}

#[test]
fn serial_record_csv_reads_as_written() {
    // `piezo serial record`'s header: the firmware's names end in their unit.
    let text = "# piezo serial record\ni,t_s,ref_um,y_um,u_volts,error_um\n0,-1e-5,1,2,3,4\n1,0e0,1,2,3,4\n2,1e-5,1,2,3,4\n";
    let r = Record::parse(text).unwrap();
    assert_eq!(r.t, vec![-1e-5, 0.0, 1e-5]);
    assert_eq!((r.u, r.y), (vec![vec![3.0; 3]], vec![vec![2.0; 3]]));
    let names: Vec<&str> = r.extra.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["i", "ref_um", "error_um"]);
    assert_eq!(r.unit_note, None);
    // Both axes of an XY build (`u_volts`, `u1_volts`): chosen, not guessed.
    let xy = "t_s,u_volts,u1_volts,y_um,y1_um\n0,1,2,3,4\n1,1,2,3,4\n";
    assert!(msg(xy).contains("mixes `u` with numbered"));
    let l = layout(None, &["u_volts", "u1_volts"], &["y_um", "y1_um"]);
    let r = Record::parse_with(xy, &l).unwrap();
    assert_eq!((r.u.len(), r.y.len(), r.y[1][0]), (2, 2, 4.0));
}

#[test]
fn input_records_may_lack_outputs_when_allowed() {
    let text = "t_s,u1_V,u2_V\n0,1,2\n1,1,2\n";
    assert!(msg(text).contains("no `y` column"));
    let l = Layout {
        outputs_optional: true,
        ..Layout::default()
    };
    let r = Record::parse_with(text, &l).unwrap();
    assert_eq!((r.u.len(), r.y.len()), (2, 0));
}

#[test]
fn accepts_rounded_time_stamps() {
    let r = Record::parse("t,u,y\n0.0000000,1,2\n0.0013333,1,2\n0.0026667,1,2\n0.0040000,1,2\n")
        .unwrap();
    assert!((r.sample_rate_hz() - 750.0).abs() < 1e-3);
}

#[test]
fn reads_every_shared_data_file() {
    let dir = data_dir();
    if !dir.exists() {
        eprintln!("skipped: {} not found (set PIEZO_DATA)", dir.display());
        return;
    }
    let mut n = 0;
    for sub in std::fs::read_dir(&dir).unwrap() {
        let sub = sub.unwrap().path();
        if !sub.is_dir() {
            continue;
        }
        for f in std::fs::read_dir(&sub).unwrap() {
            let f = f.unwrap().path();
            if f.extension().is_some_and(|e| e == "csv") {
                let r = Record::read(&f).unwrap_or_else(|e| panic!("{e}"));
                assert!(r.len() > 1000, "{}", f.display());
                // The fine steering mirror has three actuators and three sensors.
                let axes = if sub.ends_with("fsm-benchmark") { 3 } else { 1 };
                assert_eq!((r.u.len(), r.y.len()), (axes, axes), "{}", f.display());
                assert!(!r.comments.is_empty());
                // Written before units were named: read as they are, with a note.
                assert!(r.unit_note.is_some(), "{}", f.display());
                n += 1;
            }
        }
    }
    // 6 single-axis records and the mirror's 18 (3 levels x 6 realizations).
    assert_eq!(n, 24);
}

proptest! {
    #[test]
    fn never_panics_on_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let _ = Record::parse(&String::from_utf8_lossy(&bytes));
    }

    #[test]
    fn never_panics_on_csv_like_text(s in "[tuy0-9,.\\-e#\n NaN]{0,200}") {
        let _ = Record::parse(&s);
    }

    #[test]
    fn round_trips(u in proptest::collection::vec(-1e6f64..1e6, 2..50), fs in 1.0f64..1e5) {
        let n = u.len();
        let t: Vec<f64> = (0..n).map(|i| i as f64 / fs).collect();
        let y: Vec<f64> = u.iter().map(|v| v * 0.5).collect();
        let r = Record::new(t, vec![u.clone(), y.clone()], vec![y]).unwrap();
        prop_assert_eq!(Record::parse(&r.to_csv()).unwrap(), r);
    }
}
