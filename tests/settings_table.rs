//! One table of settings (issue 14 item 1): the firmware's `SETTINGS`, the protocol
//! documentation's parameter table (`src/command.rs`), `help`'s list and `get` agree. A
//! setting added, renamed or re-united in one place and not the others fails here.
use piezo_core::firmware::{c, Access, Ctl, OnChip, SAMPLE_HZ, SETTINGS};

fn ask(ctl: &mut Ctl<OnChip>, line: &str) -> String {
    ctl.answer(line).as_str().to_string()
}

#[test]
fn the_protocol_doc_help_and_get_follow_the_settings_table() {
    let doc = include_str!("../src/command.rs");
    let rows: Vec<Vec<String>> = doc
        .lines()
        .filter_map(|l| l.strip_prefix("//! | `"))
        .map(|l| {
            l.split('|')
                .map(|c| c.trim().trim_matches('`').to_string())
                .collect()
        })
        .filter(|r: &Vec<String>| r.len() == 7 && SETTINGS.iter().any(|s| s.name == r[0]))
        .collect();
    let access = |a: Access| match a {
        Access::Limit => "limit",
        Access::ReadOnly => "read-only",
        Access::Model => "model",
        Access::Sensor => "sensor",
    };
    let want: Vec<Vec<String>> = SETTINGS
        .iter()
        .map(|s| {
            let (default, range) = match s.access {
                Access::ReadOnly => ("board".to_string(), "-".to_string()),
                _ => (format!("{}", s.default), format!("{} .. {}", s.min, s.max)),
            };
            vec![
                s.name.into(),
                s.unit.into(),
                s.about.into(),
                access(s.access).into(),
                default,
                range,
                String::new(),
            ]
        })
        .collect();
    let table: String = want
        .iter()
        .map(|r| {
            format!(
                "//! | `{}` | {} | {} | {} | {} | {} |\n",
                r[0], r[1], r[2], r[3], r[4], r[5]
            )
        })
        .collect();
    assert_eq!(
        rows, want,
        "src/command.rs's parameter table differs from SETTINGS; it should read:\n{table}"
    );
    let mut ctl = Ctl::<OnChip>::new(c(SAMPLE_HZ as f64));
    let help = ask(&mut ctl, "help");
    let listed: Vec<&str> = help
        .split_once("params:")
        .unwrap()
        .1
        .split_whitespace()
        .collect();
    let names: Vec<&str> = SETTINGS.iter().map(|s| s.name).collect();
    assert_eq!(listed, names, "help lists other parameters");
    for s in SETTINGS {
        let r = ask(&mut ctl, &format!("get {}", s.name));
        assert!(r.starts_with(&format!("ok {} ", s.name)), "{r}");
        if s.access != Access::ReadOnly {
            // Beyond the table's range: refused before anything else looks at it.
            let beyond = if s.max > 0.0 {
                s.max * 2.0
            } else {
                s.max + 1.0
            };
            assert_eq!(
                ask(&mut ctl, &format!("set {} {beyond}", s.name)),
                "err 8 value out of range",
                "{}",
                s.name
            );
        }
        if s.access == Access::ReadOnly {
            assert_eq!(
                ask(&mut ctl, &format!("set {} 1", s.name)),
                "err 12 not possible in the current state"
            );
        }
    }
}
