//! Command protocol of the serial port: line-based text, `no_std`, bounded parser.
//!
//! # Protocol
//! One command per line: ASCII, at most [`MAX_LINE`] bytes before the `\n` (a `\r` before
//! it is ignored), words separated by spaces. Every command gets exactly one reply line
//! (`rec read` first sends its data lines):
//! * `ok[ <details>]` on success,
//! * `err <code> <message>` on failure; the codes are [`Error::code`] (stable numbers).
//!
//! | command | effect | reply |
//! |---|---|---|
//! | `ping` | liveness | `ok pong` |
//! | `help` | list of commands and parameters | `ok ping help get set cbw mode ff wave axis table stats rec fault bench selftest; params: ...` |
//! | `get <param>` | read a parameter | `ok <param> <value>` |
//! | `set <param> <value>` | write a parameter (range-checked) | `ok <param> <value>` |
//! | `cbw <d> <alpha> <beta> <gamma>` | the CBW model (um/V, um/V, 1/V, 1/V) at once, as `piezo fit --model cbw` reports it | `ok cbw <d> <alpha> <beta> <gamma>` |
//! | `mode <law>` | select the feedback law (bumpless); `err 18` when its worst-case step with the current compensator does not fit the control period at the board's rate ([`crate::firmware::Budget`]), nothing changed | `ok mode <law>` |
//! | `ff <compensator>` | select the feedforward compensator; `err 18` as for `mode` | `ok ff <name>` |
//! | `wave off` / `wave hold <um>` | stop the waveform (every axis) / hold a position | `ok wave ...` |
//! | `wave sine\|triangle\|square <amp_um> <freq_hz> [<offset_um>]` | start a waveform | `ok wave ...` |
//! | `wave steps <low_um> <high_um> <levels> <freq_hz>` | staircase low..high..low, `levels` in 2..=[`MAX_LEVELS`] (2: square) | `ok wave steps ...` |
//! | `table clear` | empty the point table | `ok table 0` |
//! | `table add <um> [<um>...]` | append up to [`TABLE_ADD_MAX`] points (all or none; at most [`TABLE_LEN`] in all, else `err 8`) | `ok table <n>` |
//! | `table len` | points in the table | `ok table <n>` |
//! | `wave raster <x_span_um> <y_span_um> <lines> <line_hz> [<xc_um> <yc_um>]` | 2-axis raster: x triangle at `line_hz` over `x_span_um`, y triangle over `y_span_um` at `line_hz / (2 lines)` (one sweep of y per `lines` x periods), centred on (`xc_um`, `yc_um`) (default: half the spans, so the scan starts at 0); `lines` in 1..=[`MAX_LINES`]; 1-axis board: `err 13` | `ok wave raster <x_span> <y_span> <lines> <line_hz> <xc> <yc>` |
//! | `wave lissajous <x_amp_um> <y_amp_um> <fx_hz> <fy_hz> [<phase_deg>] [<xc_um> <yc_um>]` | 2-axis Lissajous: sines, y `phase_deg` ahead of x (default 90, in -360..=360), centred on (`xc_um`, `yc_um`) (default: the amplitudes, so the scan starts at 0); 1-axis board: `err 13` | `ok wave lissajous <x_amp> <y_amp> <fx> <fy> <phase> <xc> <yc>` |
//! | `axis [<n>]` | axis the 1-axis waves (`hold`, `sine`, `triangle`, `square`, `steps`, `table`, `prbs`, `chirp`, `multisine`) apply to (default 0; `err 8` beyond the board's axes); without `n`: report it | `ok axis <n> of <axes>` |
//! | `wave prbs <low_um> <high_um> <order> <bit_hz> [<seed>]` | PRBS between `low_um` and `high_um` for identification: a maximal LFSR of `order` bits (2..=20, `2^order - 1` bits per period), `bit_hz` bits per second (below the sample rate), start state from `seed` (default 1) | `ok wave prbs <low> <high> <order> <bit_hz> <seed> <bits_per_period>` |
//! | `wave chirp <amp_um> <f0_hz> <f1_hz> <duration_s> [<offset_um>]` | linear sine sweep `f0_hz` -> `f1_hz` over `duration_s` (> 0), repeated; both frequencies below Nyquist | `ok wave chirp <amp> <f0> <f1> <duration> <offset>` |
//! | `wave multisine <amp_um> <f0_hz> <harmonics> [<offset_um> [<seed>]]` | `harmonics` (1..=32) equal harmonics of `f0_hz` (period `1/f0_hz`), peak deviation `amp_um` around `offset_um`; seed 0 (default): Schroeder phases, else random phases | `ok wave multisine <amp> <f0> <harmonics> <offset> <seed>` |
//! | `wave table <freq_hz>` | periodic spline through the table's points, one period per `1/freq_hz` (fewer than 2 points: `err 12`) | `ok wave table <freq_hz> <n>` |
//! | `stats` / `stats reset` | timing (cycles min/max/last, overruns, lost samples, latest start after the trigger or `-`; while NMPC runs its solver's jobs and missed plans since the mode) / reset the timing | `ok step ... overruns <n> lost <n> late <n> [nmpc_jobs <n> nmpc_missed <n>]` |
//! | `rec sel <signal>...` | recorder channels (up to its channel count): `ref_um y_um error_um ff_volts u_volts adc_code dac_code` of axis 0, `ref1_um y1_um error1_um ff1_volts u1_volts adc1_code dac1_code` of axis 1 (1-axis board: `err 13`) | `ok rec sel ...` |
//! | `rec trig now` | trigger at once when armed | `ok` |
//! | `rec trig rise\|fall\|level <channel> <level> [<pre>]` | trigger on a channel | `ok` |
//! | `rec arm` / `rec stop` | start / abort a capture | `ok` |
//! | `rec div [<n>]` | record every `n`-th period, 1..=1000 (the buffer spans `n` times longer, e.g. a whole XY scan); without `n`: report it | `ok rec div <n>` |
//! | `rec status` | `idle`, `armed`, `triggered` or `done` and the frames of the capture in place (all N when done) | `ok rec <state> <n>` |
//! | `rec read <start> <count>` | frames as `<i> <v0> <v1> ...` lines | `ok rec read <n>` |
//! | `rec len [<n>]` | frames per capture, 1 up to the recorder's storage (`err 8` beyond; `err 12` while capturing); drops a finished capture; without `n`: report it | `ok rec len <n> of <capacity>` |
//! | `rec bin <start> <count>` | frames as binary packets ([`crate::bulk`]: COBS, a zero byte after each, 32 frames of f32 LE per packet, CRC-32 each) after the reply line; `err 12` when the capture holds none of them yet (readable from the trigger on, while it fills) | `ok rec bin <n> <packets>`, then the packets |
//! | `fault` | latched fault (`none`, `sensor-range`, `sensor-stuck`, `non-finite`, `dac-write`) and counters | `ok fault <state> sensor <n> nonfinite <n> dac <n>` |
//! | `fault clear` | leave the safe state (bumpless, in the current mode) | `ok fault none` |
//! | `bench` | instructions/cycles per step for every mode (QEMU board) | `ok bench ...` |
//! | `selftest` | converters and safe-state hardware: DAC read-back, ADC code and sensor window, amplifier enable, reset cause, the DAC scale at its pin (H743 on-chip, one axis), mock-chip rule violations (QEMU) | `ok selftest reset <cause> dac <read>/<wrote> ok adc <code> in ...` |
//! | `save` | store every settable parameter in the settings flash as one versioned, checksummed record (power-fail safe: the old record or the new one); only in the safe state (open loop holding, or a fault latched), else `err 12`; no settings flash on the board: `err 13` | `ok save <n> settings <bytes> B` |
//! | `load` | the stored record, checked (magic, version, CRC-32, exactly the stored settings, values as `set` checks them) and installed bumplessly, all or none; nothing stored `err 15`, refused `err 16`, flash failed `err 17` | `ok load <n> settings` |
//! | `defaults` | the built-in settings (the stored record stays) | `ok defaults` |
//!
//! Parameters (the firmware's `help` lists them; one table in the firmware,
//! [`crate::firmware::SETTINGS`], which `tests/settings_table.rs` checks this one against):
//!
//! | name | unit | sets | access | default | range (`set`) |
//! |---|---|---|---|---|---|
//! | `u_min` | V | lowest output voltage | limit | 0 | 0 .. 150 |
//! | `u_max` | V | highest output voltage (at most 150) | limit | 150 | 0 .. 150 |
//! | `slew` | V/s | output slew-rate limit | limit | 20000 | 0.001 .. 1000000000 |
//! | `guard` | um | sensor guard band: codes this close to either end of the ADC span are sensor faults | sensor | 5 | 0 .. 9 |
//! | `stuck` | samples | identical consecutive ADC codes that are a sensor fault (0 = off) | sensor | 100 | 0 .. 10000 |
//! | `um_per_code` | um | position per ADC code | read-only | board | - |
//! | `volts_per_code` | V | output voltage per DAC code | read-only | board | - |
//! | `sample_hz` | Hz | control rate | read-only | board | - |
//! | `cbw_d` | um/V | CBW piezo gain d (000 eq. 1) | model | 0.16 | 0.000001 .. 1000 |
//! | `cbw_alpha` | um/V | CBW alpha (000 eq. 2) | model | 0.07 | -1000 .. 1000 |
//! | `cbw_beta` | 1/V | CBW beta | model | 0.02 | -1000 .. 1000 |
//! | `cbw_gamma` | 1/V | CBW gamma | model | 0.01 | -1000 .. 1000 |
//! | `gbw_b` | 1/V | GBW asymmetry B of fts-gbw and nmpc-gbw (000 eq. 3) | model | 0 | -1000 .. 1000 |
//! | `um_per_volt` | um/V | open-loop scaling | model | 0.16 | -1000 .. 1000 |
//! | `offset_um` | um | open-loop offset | model | 0 | -10000 .. 10000 |
//! | `hgo_eps` | s | HGO epsilon (000 eq. 6) | model | 0.0002 | 0.0000001 .. 1 |
//! | `lambda1` | 1/s | robust law gain (000 eq. 7) | model | 2000 | 0 .. 10000000 |
//! | `lambda2` | 1/s | robust law gain (000 eq. 7) | model | 2000 | 0 .. 10000000 |
//! | `pid_kp` | V/um | PID proportional gain | model | 0.5 | 0 .. 10000 |
//! | `pid_ki` | V/(um s) | PID integral gain | model | 2000 | 0 .. 100000000 |
//! | `notch_hz` | Hz | notch on the measured position (0 = off, else 10 Hz to 0.45 of the sample rate) | model | 0 | 0 .. 1000000 |
//! | `notch_q` | 1 | notch quality factor (0.5 to 50) | model | 2 | 0.5 .. 50 |
//!
//! The CBW (n = 1) is the one `piezo fit --model cbw` identifies; `gbw_b` tilts its loop
//! (`set gbw_b` refuses `|B| >= cbw_beta + cbw_gamma`). A model or gain `set` is
//! checked by the core's constructors and installs the rebuilt law and compensator
//! bumplessly; a refused value (`err 8`) changes nothing. `save` stores all of them except
//! the read-only ones; at power-up a stored record is loaded (a refused one leaves the
//! defaults running, with a `warn settings: ...` line before `ready` and a defmt warning).
//!
//! On a 2-axis (XY) board `mode`, `ff`, `set` (limits and model) and `wave off` act on every axis;
//! `get` reads axis 0 (the axes are configured alike).
//!
//! Law and compensator names are the core's controller registry's ([`crate::registry`]),
//! one spelling for the firmware, `piezo sim` and `piezo serial`
//! (`hal-sim/tests/controller_names.rs` checks these lines against them):
//!
//! * `mode`: `open-loop` `pid` `ff+pid` `hgo-robust` `ff+hgo-robust` `fts` `ff+fts` `fts-gbw` `adrc` `ff+adrc` `nmpc` `ff+nmpc` `nmpc-gbw`
//! * `ff`: `linear` `ims-cbw` `ims-cbw-delayed`
//!
//! Parameter, law and signal names are checked by whoever executes the command (the
//! firmware), which answers [`Error::UnknownParam`], [`Error::UnknownMode`] or
//! [`Error::UnknownSignal`].
//!
//! The parser never allocates, never panics (a proptest feeds it arbitrary bytes) and its
//! work is bounded by [`MAX_LINE`].

/// Longest accepted line (bytes, without the terminator).
pub const MAX_LINE: usize = 96;
/// Most words in one line (the command word included).
pub const MAX_WORDS: usize = 10;
/// Most levels of `wave steps`.
pub const MAX_LEVELS: u16 = 64;
/// Most x lines per y sweep of `wave raster`.
pub const MAX_LINES: u16 = 4096;
/// Most points of one `table add` line.
pub const TABLE_ADD_MAX: usize = MAX_WORDS - 2;
/// Capacity of the point table of `wave table` (the reference generator's).
pub use crate::pipeline::TABLE_LEN;

mod error;
mod grammar;
mod line;
mod number;
mod reply;

pub use error::Error;
pub use grammar::{parse, Command, Points, RecCmd, Shape, TriggerCmd, Words};
pub use line::LineBuffer;
pub use number::{parse_f32, parse_usize, MAX_DIGITS};
pub use reply::Reply;
