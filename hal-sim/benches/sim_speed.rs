//! Simulation speed: simulated seconds per wall-clock second at a 100 kHz loop (goal: at
//! least 200x real time on one core). The whole loop is measured: ADC mock + AD4000
//! driver, the firmware pipeline, AD5791 driver + mock, and the default stage (`sine-10hz`:
//! amplifier, hysteresis, creep, resonance, drift, noise, delay) at its default internal
//! rate. Controllers: open loop, `hgo-robust` (the best feedback law on `sine-10hz`) and
//! `ims-cbw` (the solved IMS feedforward).
//!
//! `cargo bench -p hal-sim --bench sim_speed`; criterion's throughput is in loop samples
//! per second, so real-time factor = samples/s / 100_000. The headline lines at the end
//! give both the wall-clock factor and the on-CPU one (the thread's own run time from
//! `/proc/thread-self/schedstat`, which a loaded machine does not inflate).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use hal_sim::scenario::Scenario;
use hal_sim::sim::controllers::find;
use hal_sim::sim::{calibrate, default_scenarios, Bench, StageInfo};
use std::hint::black_box;
use std::time::Instant;

const SAMPLES: u64 = 10_000; // 0.1 s simulated per iteration
const CONTROLLERS: [&str; 3] = ["open-loop", "hgo-robust", "ims-cbw"];

fn bench_for(sc: &Scenario, controller: &str) -> Bench<1> {
    let lin = calibrate(sc).unwrap();
    let c = (find(controller).unwrap().one_axis)(&StageInfo {
        scenario: sc,
        linear: lin,
    })
    .unwrap();
    Bench::<1>::new(sc, c, &lin).unwrap()
}

fn scenario() -> Scenario {
    let mut sc = default_scenarios(None, None);
    sc.retain(|s| s.name == "sine-10hz");
    sc.remove(0)
}

/// This thread's on-CPU time (ns), if the kernel tells.
fn cpu_ns() -> Option<u64> {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// On-CPU ns per call of `f` over `n` calls (wall if the kernel does not tell).
fn ns_per(n: u64, mut f: impl FnMut(u64)) -> f64 {
    let (t0, c0) = (Instant::now(), cpu_ns());
    for k in 0..n {
        f(k);
    }
    match (c0, cpu_ns()) {
        (Some(a), Some(b)) if b > a => (b - a) as f64 / n as f64,
        _ => t0.elapsed().as_secs_f64() * 1e9 / n as f64,
    }
}

/// Where the time of one open-loop sample goes: each part alone, same inputs as in the loop.
fn breakdown(sc: &Scenario) {
    let n = 1_000_000u64;
    let mut b = bench_for(sc, "open-loop");
    // One reference period of DAC volts, precomputed so no libm call is timed.
    let per = (sc.run.loop_hz / sc.reference.freq_hz) as usize;
    let volts: Vec<f64> = (0..per)
        .map(|k| 5.0 - 4.0 * (2.0 * std::f64::consts::PI * k as f64 / per as f64).cos())
        .collect();
    let stage = ns_per(n, |k| {
        black_box(b.stage.sensor_um(0));
        black_box(b.stage.position_um(0));
        b.stage.advance(&[volts[k as usize % per]]);
    });
    let adc = ns_per(n, |k| {
        let a = &mut b.adcs[0];
        a.chip.set_input_volts(black_box((k % 1000) as f64 * 1e-3));
        black_box(a.driver.convert().ok());
    });
    let codes: Vec<i32> = (0..1000).map(|k| 1000 * k - 500_000).collect();
    let pipe = ns_per(n, |k| {
        black_box(b.pipeline.step([codes[(k % 1000) as usize]]));
    });
    let dac = ns_per(n, |k| {
        let d = &mut b.dacs[0];
        black_box(d.driver.set_code(black_box((k % 1000) as i32 * 1000)).ok());
        black_box(d.chip.output_volts());
    });
    println!(
        "breakdown (on-CPU ns per call): stage {stage:.1}, ADC mock + driver {adc:.1}, \
         pipeline (open loop) {pipe:.1}, DAC driver + mock {dac:.1}"
    );
}

fn sim_speed(c: &mut Criterion) {
    let sc = scenario();
    let mut g = c.benchmark_group("sim_100khz");
    g.throughput(Throughput::Elements(SAMPLES));
    for name in CONTROLLERS {
        let mut b = bench_for(&sc, name);
        g.bench_function(format!("{}/{name}", sc.name), |bn| {
            bn.iter(|| {
                for _ in 0..SAMPLES {
                    black_box(b.step());
                }
            })
        });
    }
    g.finish();
    breakdown(&sc);
    // The headline numbers, measured over 10 simulated seconds each.
    for name in CONTROLLERS {
        let mut b = bench_for(&sc, name);
        let n = 1_000_000u64;
        let (t0, c0) = (Instant::now(), cpu_ns());
        for _ in 0..n {
            black_box(b.step());
        }
        let (wall, c1) = (t0.elapsed().as_secs_f64(), cpu_ns());
        let sim = n as f64 / sc.run.loop_hz;
        let cpu = match (c0, c1) {
            (Some(a), Some(b)) if b > a => format!(
                ", on-CPU {:.3} s = {:.0}x ({:.1} ns/sample)",
                (b - a) as f64 * 1e-9,
                sim / ((b - a) as f64 * 1e-9),
                (b - a) as f64 / n as f64
            ),
            _ => String::new(),
        };
        println!(
            "{} / {name}: {sim:.1} s simulated in {wall:.3} s wall = {:.0}x real time ({:.1} ns/sample){cpu}",
            sc.name,
            sim / wall,
            wall / n as f64 * 1e9
        );
    }
}

criterion_group!(benches, sim_speed);
criterion_main!(benches);
