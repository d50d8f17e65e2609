//! The firmware's command line (`CommandLine`, as both boards run it: each command on the
//! command task's replica, its changes handed to the live pipeline by `Pipeline::adopt`)
//! against the executor run directly on the live control state: the same replies, and the
//! live loop runs the same DAC codes and state after every command.

use piezo_core::firmware::{c, CommandLine, Converters, Ctl, OnChip, Port, SAMPLE_HZ};
use rtic_core::Exclusive;

#[derive(Default)]
struct Lines(Vec<String>);

impl Port for Lines {
    fn send(&mut self, line: &str) {
        self.0.push(line.to_string());
    }
    fn send_bytes(&mut self, bytes: &[u8]) {
        self.0.push(format!("{bytes:02x?}"));
    }
}

fn direct(ctl: &mut Ctl<OnChip>, line: &str) -> String {
    ctl.answer(line).as_str().to_string()
}

/// Types `line` and its newline into the command line, `ctl` the live loop behind it.
fn type_line(cli: &mut CommandLine<OnChip>, ctl: &mut Ctl<OnChip>, port: &mut Lines, line: &str) {
    for byte in line.bytes().chain(Some(b'\n')) {
        cli.byte(byte, &mut Exclusive(&mut *ctl), port);
    }
}

/// The live loop and its twin at the board's rate, and a command line on the live one.
fn live_and_twin() -> (Ctl<OnChip>, Ctl<OnChip>, CommandLine<OnChip>, Lines) {
    let hz = c(SAMPLE_HZ as f64);
    let (a, b) = (Ctl::<OnChip>::new(hz), Ctl::<OnChip>::new(hz));
    let cli = CommandLine::new(&b.lp);
    (a, b, cli, Lines::default())
}

#[test]
fn the_replica_path_answers_and_steps_as_the_direct_executor() {
    let (mut a, mut b, mut cli, mut port) = live_and_twin();
    let script = [
        "ping",
        "get u_max",
        "wave sine 5 100 10",
        "mode ff+hgo-robust",
        "ff ims-cbw",
        "set lambda1 2500",
        "set slew 0",
        "set u_max 120",
        "cbw 0.17 0.07 0.02 0.01",
        "set cbw_d -1",
        "mode fts",
        "mode nonsense",
        "ff ims-cbw-delayed",
        "table add 8 10 12 10",
        "wave table 50",
        "wave triangle 4 20 10",
        "wave off",
        "wave steps 5 15 4 50",
        "mode adrc",
        "set u_min 5",
        "mode ff+pid",
        "fault",
        "fault clear",
        "get lambda1",
        "axis",
        "help",
    ];
    // A closed trajectory of ADC codes around mid-range, the same for both.
    let mid = 1i32 << (OnChip::ADC_BITS - 1);
    let mut k = 0i32;
    for line in script {
        let want = direct(&mut a, line);
        port.0.clear();
        type_line(&mut cli, &mut b, &mut port, line);
        assert_eq!(port.0, [want], "reply to `{line}`");
        for _ in 0..50 {
            k += 1;
            let code = [mid + (k * 37) % 900 - 450];
            assert_eq!(a.lp.step(code), b.lp.step(code), "after `{line}`");
        }
        assert_eq!(a.lp.p.state(), b.lp.p.state(), "state after `{line}`");
        assert_eq!((a.lp.law, a.lp.ff), (b.lp.law, b.lp.ff));
    }
}

/// A mode whose worst step does not fit the board's period (issue 15 item 4) is refused
/// with `err 18` and changes nothing: the live loop keeps its law and compensator and runs
/// the same codes as a loop that never got the command.
#[test]
fn a_mode_over_budget_is_refused_and_changes_nothing() {
    use piezo_core::firmware::Budget;
    let (mut twin, mut live, mut cli, mut port) = live_and_twin();
    // The H743's period with the SPI pair (4 000 cycles at 100 kHz, 1 200 of them the
    // drivers): `fts` does not fit the step's room, NMPC's solve not the ten periods of
    // its move.
    cli.set_budget(Budget::m4f(4_000, 1_200));
    for line in [
        "mode ff+hgo-robust",
        "ff ims-cbw",
        "mode nmpc",
        "mode fts",
        "mode pid",
    ] {
        type_line(&mut cli, &mut live, &mut port, line);
    }
    for line in ["mode ff+hgo-robust", "ff ims-cbw", "mode pid"] {
        direct(&mut twin, line);
    }
    let refused = "err 18 mode does not fit the control period at this rate";
    assert_eq!(
        port.0,
        [
            "ok mode ff+hgo-robust",
            "ok ff ims-cbw",
            refused,
            refused,
            "ok mode pid"
        ]
    );
    assert_eq!((live.lp.law, live.lp.ff), ("pid", "ims-cbw"));
    let mid = 1 << (OnChip::ADC_BITS - 1);
    for _ in 0..200 {
        assert_eq!(live.lp.step([mid]), twin.lp.step([mid]));
    }
}

/// Two commands inside one control period: a mode change (its restart waits for the next
/// step) and then a limit change (no restart of its own). The step after them still runs
/// the restart, as the direct executor did: the same codes and state.
#[test]
fn a_limit_change_after_a_mode_change_keeps_its_restart() {
    let (mut a, mut b, mut cli, mut port) = live_and_twin();
    let mid = 1i32 << (OnChip::ADC_BITS - 1);
    let mut k = 0i32;
    let mut steps = |a: &mut Ctl<OnChip>, b: &mut Ctl<OnChip>, n: usize| {
        for _ in 0..n {
            k += 1;
            let code = [mid + (k * 37) % 900 - 450];
            assert_eq!(a.lp.step(code), b.lp.step(code));
        }
    };
    for burst in [
        &["wave sine 5 100 10", "ff ims-cbw"][..],
        &["mode ff+hgo-robust", "set u_max 140"],
        &["mode pid", "set u_min 2"],
        &["mode ff+hgo-robust", "set slew 30000", "set u_max 150"],
        // In the fused main mode: a new compensator, then a limit.
        &["ff ims-cbw", "set u_max 130"],
        &["cbw 0.17 0.07 0.02 0.01", "set u_min 1"],
    ] {
        for line in burst {
            direct(&mut a, line);
            type_line(&mut cli, &mut b, &mut port, line);
        }
        steps(&mut a, &mut b, 300);
        assert_eq!(a.lp.p.state(), b.lp.p.state(), "after {burst:?}");
    }
}
