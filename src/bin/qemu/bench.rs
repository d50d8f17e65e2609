//! Instruction counts per control step, measured in `init`.

use super::stage::SimStage;
use super::{chips, uart, Ctl};
use core::hint::black_box;
use cortex_m::peripheral::{syst::SystClkSource, SYST};
use piezo_core::command::Reply;
use piezo_core::firmware::{
    c, Budget, AXES, FFS, LAWS, NMPC_DECIMATION, SAMPLE_HZ, SOLVER_LOCK_M4F_BUILD, SOLVE_M4F_BUILD,
    WORST_M4F_BUILD,
};
use piezo_core::pipeline::Wave;

/// Steps per benchmark row.
pub const BENCH_STEPS: usize = 2_000;

pub const ROWS: usize = LAWS.len() * FFS.len();

/// Profiling build (`PIEZO_BENCH_ONLY="<law> <ff>"` at compile time): the bench runs that
/// row only, brackets its timed loop with calls to [`mark`] and exits QEMU after it, so
/// a `-singlestep -d exec,nochain` log holds one row (see the README's profile command).
const ONLY: Option<&str> = option_env!("PIEZO_BENCH_ONLY");

/// Marks the start (1) and end (2) of a timed loop in an execution log.
#[inline(never)]
pub fn mark(k: u32) {
    black_box(k);
}

fn selected(law: &str, ff: &str) -> bool {
    match ONLY {
        None => true,
        Some(o) => o.split_once(' ') == Some((law, ff)),
    }
}

#[derive(Clone, Copy, Debug, Default)]
pub struct Row {
    pub law: &'static str,
    pub ff: &'static str,
    /// Instructions per step x 100.
    pub instr_x100: u32,
    /// Worst single step (instructions, SysTick resolution): every step of the run, from
    /// rest and across a parameter change.
    pub max_instr: u32,
    /// Deferred NMPC: the worst run of the solver task (every axis' solve at one
    /// boundary, instructions), and the worst copy of a law and its job under the lock
    /// (what the solver's lock may delay the control interrupt by); 0 for other laws.
    pub solve_max: u32,
    pub copy_max: u32,
    /// The law or compensator could not be configured for this number type.
    pub unsupported: bool,
}

pub struct Table {
    pub rows: [Row; ROWS],
    /// Instructions per SysTick tick x 1000 (calibration, 40 000 expected).
    pub instr_per_tick_x1000: u32,
    /// Loop overhead subtracted (ticks over BENCH_STEPS).
    pub overhead_ticks: u32,
    /// The driver path per sample x 100: `Ad4000::convert` (with its `t_CONV` wait) +
    /// `Ad5791::set_code`, mock chips included (not part of the rows).
    pub drivers_x100: u32,
}

/// Ticks elapsed on the down-counting SysTick between two readings.
fn ticks(start: u32, end: u32) -> u32 {
    start.wrapping_sub(end) & 0x00FF_FFFF
}

/// `n` iterations of a two-instruction loop (`subs` + `bne`).
#[allow(unsafe_code)]
fn known_loop(n: u32) {
    // SAFETY: register-only countdown, no memory access.
    unsafe {
        core::arch::asm!("1:", "subs {n}, {n}, #1", "bne 1b", n = inout(reg) n => _,
            options(nomem, nostack));
    }
}

/// A loop with `ff` and `law` (`open-loop` means the feedforward alone) on a 5 um,
/// 100 Hz sine around 10 um.
fn configured(law: &str, ff: &str) -> Option<Ctl> {
    // The bench steps the loop only: no recorder storage.
    let mut ctl = Ctl::with_recorder(c(SAMPLE_HZ as f64), &mut []);
    ctl.lp.set_ff(ff).ok()?;
    let law = if law == "open-loop" {
        "feedforward"
    } else {
        law
    };
    ctl.lp.set_law(law).ok()?;
    ctl.lp
        .p
        .set_wave(
            0,
            Wave::Sine {
                offset_um: c(10.0),
                amplitude_um: c(5.0),
                freq_hz: c(100.0),
                phase_turns: c(0.0),
            },
        )
        .ok()?;
    Some(ctl)
}

/// The solver task's work between two steps (deferred NMPC, [`piezo_core::firmware::solve_nmpc`]
/// without the locks): its ticks, and the longest copy of a law and its job.
fn solve_between_steps(ctl: &mut Ctl) -> (u32, u32) {
    let (mut solve, mut copy) = (0, 0);
    for axis in 0..AXES {
        let t0 = SYST::get_current();
        let Some((law, job)) = black_box(ctl.nmpc_job(axis)) else {
            continue;
        };
        let t1 = SYST::get_current();
        let plan = black_box(law.solve_job(black_box(&job)));
        ctl.nmpc_deliver(axis, &job, plan);
        let t2 = SYST::get_current();
        copy = copy.max(ticks(t0, t1));
        solve += ticks(t0, t2);
    }
    (solve, copy)
}

/// Runs every row; SysTick is left free-running (no interrupt).
pub fn run(syst: &mut SYST) -> Table {
    syst.disable_interrupt();
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(0x00FF_FFFF);
    syst.clear_current();
    syst.enable_counter();

    const CAL: u32 = 100_000;
    let t0 = SYST::get_current();
    known_loop(CAL);
    let cal_ticks = ticks(t0, SYST::get_current()).max(1);
    let instr_per_tick_x1000 = ((2 * CAL as u64 * 1000) / cal_ticks as u64) as u32;

    // ADC codes of a closed-loop run, replayed identically to every timed run.
    let mut codes = [0i32; BENCH_STEPS];
    let mut overhead_ticks = 0;
    {
        let t0 = SYST::get_current();
        for c in codes.iter() {
            black_box(black_box(*c));
        }
        overhead_ticks = overhead_ticks.max(ticks(t0, SYST::get_current()));
    }

    let mut rows = [Row::default(); ROWS];
    let mut slot = rows.iter_mut();
    for law in LAWS {
        for ff in FFS {
            let Some(row) = slot.next() else { break };
            row.law = law;
            row.ff = ff;
            if !selected(law, ff) {
                row.unsupported = true;
                continue;
            }
            let Some(mut ctl) = configured(law, ff) else {
                row.unsupported = true;
                continue;
            };
            let mut stage = SimStage::new(SAMPLE_HZ as f32);
            let mut dac = 0;
            for c in codes.iter_mut() {
                *c = stage.step(dac);
                [dac, ..] = ctl.lp.step([*c; AXES]);
                solve_between_steps(&mut ctl);
            }
            // Same codes, same initial state: the timed run repeats that trajectory.
            let Some(mut ctl) = configured(law, ff) else {
                continue;
            };
            // The worst single step: every step timed, from rest (the first step after
            // the law's start) and across a parameter change halfway (the law rebuilt and
            // restarted bumplessly, as `mode` or `set` do), each step's two SysTick reads
            // included.
            let (mut worst, mut solve_worst, mut copy_worst) = (0, 0, 0);
            for (i, c) in codes.iter().enumerate() {
                if i == BENCH_STEPS / 2 {
                    let name = if law == "open-loop" {
                        "feedforward"
                    } else {
                        law
                    };
                    ctl.lp.set_law(name).ok();
                }
                let t = SYST::get_current();
                black_box(ctl.lp.step(black_box([*c; AXES])));
                worst = worst.max(ticks(t, SYST::get_current()));
                let (solve, copy) = solve_between_steps(&mut ctl);
                solve_worst = solve_worst.max(solve);
                copy_worst = copy_worst.max(copy);
            }
            let Some(mut ctl) = configured(law, ff) else {
                continue;
            };
            mark(1);
            let t0 = SYST::get_current();
            for c in codes.iter() {
                black_box(ctl.lp.step(black_box([*c; AXES])));
            }
            let dt = ticks(t0, SYST::get_current()).saturating_sub(overhead_ticks);
            mark(2);
            row.instr_x100 =
                ((dt as u64 * instr_per_tick_x1000 as u64) / (10 * BENCH_STEPS as u64)) as u32;
            let instr = |t: u32| ((t as u64 * instr_per_tick_x1000 as u64) / 1000) as u32;
            row.max_instr = instr(worst);
            row.solve_max = instr(solve_worst);
            row.copy_max = instr(copy_worst);
        }
    }
    // The driver path alone, on the codes of the last row: conversion (CNV high for
    // t_CONV, waited on the chips' timer), read, DAC write and LDAC pulse.
    let Ok((mut adc, mut dac)) = chips::drivers_of::<0>(0) else {
        return Table {
            rows,
            instr_per_tick_x1000,
            overhead_ticks,
            drivers_x100: 0,
        };
    };
    let (adc, dac) = (black_box(&mut adc), black_box(&mut dac));
    let t0 = SYST::get_current();
    for c in codes.iter() {
        chips::set_input(0, *c);
        let code = adc.convert().unwrap_or(i32::MIN);
        dac.set_code(black_box(code.max(0))).ok();
    }
    let dt = ticks(t0, SYST::get_current()).saturating_sub(overhead_ticks);
    let drivers_x100 =
        ((dt as u64 * instr_per_tick_x1000 as u64) / (10 * BENCH_STEPS as u64)) as u32;
    Table {
        rows,
        instr_per_tick_x1000,
        overhead_ticks,
        drivers_x100,
    }
}

/// Instructions per call x 100 of the per-sample math the step uses against micromath's
/// (issue 15 item 7; accuracy: `tests/micromath.rs`), over 1000 varied arguments.
#[cfg(target_abi = "eabihf")]
pub fn math(syst: &mut SYST, instr_per_tick_x1000: u32) {
    use micromath::F32Ext;
    use piezo_core::pipeline::excitation::sin_cos_turns;
    use piezo_core::real::Real;
    syst.disable_interrupt();
    syst.set_reload(0x00FF_FFFF);
    syst.clear_current();
    syst.enable_counter();
    const N: u32 = 1000;
    let cost = |f: &dyn Fn(f32) -> f32| {
        let t0 = SYST::get_current();
        let mut acc = 0.0f32;
        for i in 0..N {
            acc += f(black_box(i as f32 * 1e-3));
        }
        black_box(acc);
        let dt = ticks(t0, SYST::get_current());
        (dt as u64 * instr_per_tick_x1000 as u64 / (10 * N as u64)) as u32
    };
    let tau = core::f32::consts::TAU;
    let rows: [(&str, u32); 10] = [
        ("loop alone", cost(&|x| x)),
        (
            "sin_cos_turns (ours, sin and cos)",
            cost(&|x| {
                let (s, c) = sin_cos_turns(x);
                s + c
            }),
        ),
        (
            "micromath sin + cos",
            cost(&|x| F32Ext::sin(x * tau) + F32Ext::cos(x * tau)),
        ),
        (
            "exp_m1 (ours, libm expm1f)",
            cost(&|x| <f32 as Real>::exp_m1(-20.0 * x)),
        ),
        ("micromath exp - 1", cost(&|x| F32Ext::exp(-20.0 * x) - 1.0)),
        ("libm expf", cost(&|x| <f32 as Real>::exp(-20.0 * x))),
        (
            "libm powf(x, 1.5)",
            cost(&|x| <f32 as Real>::powf(x + 1e-3, 1.5)),
        ),
        (
            "micromath powf(x, 1.5)",
            cost(&|x| F32Ext::powf(x + 1e-3, 1.5)),
        ),
        ("libm logf", cost(&|x| <f32 as Real>::ln(x + 1e-3))),
        ("micromath ln", cost(&|x| F32Ext::ln(x + 1e-3))),
    ];
    let mut r = Reply::<160>::new();
    for (name, x100) in rows {
        r.clear();
        r.push_str("bench: math ");
        r.push_str(name);
        r.push_str(": ");
        r.push_fixed(x100, 2);
        r.push_str(" instr/call");
        uart::line(r.as_str());
    }
}

/// Instructions per control period under `-icount shift=0` (1 instruction per ns).
pub const PERIOD_INSTR: u32 = 1_000_000_000 / SAMPLE_HZ;
/// Per period besides the step and the drivers: interrupt entry and exit, timing, recorder
/// (the defmt timing line's interrupt maximum less the step's and the drivers': about 300).
const OVERHEAD_INSTR: u32 = 400;

/// This board's mode budget from its own measurement: each row's worst step against the
/// period, less the driver path and [`OVERHEAD_INSTR`].
pub fn budget(t: &Table) -> Budget {
    let mut worst = [[0u32; FFS.len()]; LAWS.len()];
    let mut solve = [[0u32; FFS.len()]; LAWS.len()];
    let mut lock = 0;
    for (i, row) in t.rows.iter().enumerate() {
        let (r, c) = (i / FFS.len(), i % FFS.len());
        if let Some(w) = worst.get_mut(r).and_then(|r| r.get_mut(c)) {
            *w = if row.unsupported {
                0
            } else {
                row.max_instr.max(1)
            };
        }
        if let Some(s) = solve.get_mut(r).and_then(|r| r.get_mut(c)) {
            *s = if row.unsupported { 0 } else { row.solve_max };
        }
        lock = lock.max(row.copy_max);
    }
    Budget::measured(PERIOD_INSTR, t.drivers_x100 / 100 + OVERHEAD_INSTR, worst)
        .with_solver(solve, lock)
}

/// Rows whose measured worst step exceeds the library's table for this build's axis count
/// ([`WORST_M4F_BUILD`], the H743's budget):
/// their count and the first. Only meaningful for the f32 build on the M4F.
fn above_table(t: &Table) -> (usize, Option<&Row>) {
    let over = |(i, row): &(usize, &Row)| {
        let stated = |table: &[[u32; FFS.len()]; LAWS.len()]| {
            table
                .get(i / FFS.len())
                .and_then(|r| r.get(i % FFS.len()))
                .copied()
                .unwrap_or(0)
        };
        !row.unsupported
            && (row.max_instr > stated(&WORST_M4F_BUILD)
                || row.solve_max > stated(&SOLVE_M4F_BUILD)
                || row.copy_max > SOLVER_LOCK_M4F_BUILD)
    };
    let mut rows = t.rows.iter().enumerate().filter(over);
    let first = rows.next().map(|(_, r)| r);
    (first.map_or(0, |_| 1) + rows.count(), first)
}

/// The table as text lines (UART) and, with `log`, defmt (semihosting stops the core,
/// so not while the loop runs).
pub fn print(t: &Table, log: bool) {
    let b = budget(t);
    let mut r = Reply::<160>::new();
    r.push_str("bench: instructions per control step (ADC code -> DAC code), ");
    r.push_usize(BENCH_STEPS);
    r.push_str(" steps, QEMU -icount shift=0, ");
    r.push_fixed(t.instr_per_tick_x1000, 3);
    r.push_str(" instr/SysTick tick, loop overhead ");
    r.push_u32(t.overhead_ticks);
    r.push_str(" ticks");
    uart::line(r.as_str());
    r.clear();
    r.push_str("bench: rows = pipeline step only; SPI driver path per sample (Ad4000 convert incl. t_CONV wait, Ad5791 set_code incl. LDAC pulse, mock chips): ");
    r.push_fixed(t.drivers_x100, 2);
    r.push_str(" instr");
    uart::line(r.as_str());
    uart::line("mode               feedforward        instr/step     worst  budget");
    for row in &t.rows {
        r.clear();
        r.push_padded(row.law, 19);
        r.push_padded(row.ff, 19);
        if row.unsupported {
            r.push_right("n/a", 10);
            uart::line(r.as_str());
            continue;
        }
        let mut n = Reply::<16>::new();
        n.push_fixed(row.instr_x100, 2);
        r.push_right(n.as_str(), 10);
        n.clear();
        n.push_u32(row.max_instr);
        r.push_str("  ");
        r.push_right(n.as_str(), 8);
        r.push_str(if b.check(row.law, row.ff).is_ok() {
            "  fits"
        } else {
            "  refused"
        });
        uart::line(r.as_str());
        if !log {
            continue;
        }
        defmt::info!(
            "bench {=str} + {=str}: {=u32}.{=u32:02} instructions/step",
            row.law,
            row.ff,
            row.instr_x100 / 100,
            row.instr_x100 % 100
        );
    }
    for row in t.rows.iter().filter(|row| row.solve_max > 0) {
        r.clear();
        r.push_str("bench: solver task (deferred NMPC, priority 2) ");
        r.push_str(row.law);
        r.push_str(" ");
        r.push_str(row.ff);
        r.push_str(": worst ");
        r.push_u32(row.solve_max);
        r.push_str(" instr per MPC boundary (every ");
        r.push_u32(NMPC_DECIMATION);
        r.push_str(" periods), lock copy ");
        r.push_u32(row.copy_max);
        r.push_str(" instr");
        uart::line(r.as_str());
    }
    r.clear();
    r.push_str("budget: ");
    r.push_u32(PERIOD_INSTR);
    r.push_str(" instr per period, a step may take ");
    r.push_u32(b.allowance());
    let refused = t
        .rows
        .iter()
        .filter(|row| b.check(row.law, row.ff).is_err())
        .count();
    r.push_str("; refused ");
    r.push_usize(refused);
    r.push_str(" of ");
    r.push_usize(ROWS);
    uart::line(r.as_str());
    if !piezo_core::firmware::FIXED {
        let (n, first) = above_table(t);
        r.clear();
        r.push_str("budget table: ");
        r.push_usize(n);
        r.push_str(" of ");
        r.push_usize(ROWS);
        r.push_str(if AXES == 2 {
            " combinations above WORST_M4F_XY"
        } else {
            " combinations above WORST_M4F"
        });
        if let Some(row) = first {
            r.push_str(", first ");
            r.push_str(row.law);
            r.push_str(" ");
            r.push_str(row.ff);
            r.push_str(" ");
            r.push_u32(row.max_instr);
        }
        uart::line(r.as_str());
    }
}
