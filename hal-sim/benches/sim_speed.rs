//! Simulation speed: simulated seconds per wall-clock second at a 100 kHz loop (goal: at
//! least 200x real time on one core). The whole loop is measured: ADC mock + AD4000
//! driver, the firmware pipeline, AD5791 driver + mock, and the stage at its default
//! internal rate.
//!
//! `cargo bench -p hal-sim --bench sim_speed`; criterion's throughput is in loop samples
//! per second, so real-time factor = samples/s / 100_000 (also printed at the end).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use hal_sim::scenario::Scenario;
use hal_sim::sim::controllers::find;
use hal_sim::sim::{calibrate, default_scenarios, Bench, StageInfo};
use std::hint::black_box;
use std::time::Instant;

const SAMPLES: u64 = 10_000; // 0.1 s simulated per iteration

fn bench_for(sc: &Scenario) -> Bench<1> {
    let lin = calibrate(sc).unwrap();
    let c = (find("open-loop").unwrap().one_axis)(&StageInfo {
        scenario: sc,
        linear: lin,
    })
    .unwrap();
    Bench::<1>::new(sc, c, &lin).unwrap()
}

fn scenarios() -> Vec<Scenario> {
    let mut sc = default_scenarios(None, None);
    sc.retain(|s| s.name == "sine-10hz");
    let mut plain = sc[0].clone();
    plain.name = "sine-10hz-linear-stage".into();
    plain.stage.hysteresis.model = hal_sim::scenario::HysteresisModel::None;
    plain.stage.creep.enabled = false;
    sc.push(plain);
    sc
}

fn sim_speed(c: &mut Criterion) {
    let mut g = c.benchmark_group("sim_100khz");
    g.throughput(Throughput::Elements(SAMPLES));
    for sc in scenarios() {
        let mut b = bench_for(&sc);
        g.bench_function(&sc.name, |bn| {
            bn.iter(|| {
                for _ in 0..SAMPLES {
                    black_box(b.step());
                }
            })
        });
    }
    g.finish();
    // The headline number, measured over 10 simulated seconds.
    for sc in scenarios() {
        let mut b = bench_for(&sc);
        let n = 1_000_000u64;
        let t0 = Instant::now();
        for _ in 0..n {
            black_box(b.step());
        }
        let wall = t0.elapsed().as_secs_f64();
        let sim = n as f64 / sc.run.loop_hz;
        println!(
            "{}: {sim:.1} s simulated in {wall:.3} s wall = {:.0}x real time ({:.1} ns/sample)",
            sc.name,
            sim / wall,
            wall / n as f64 * 1e9
        );
    }
}

criterion_group!(benches, sim_speed);
criterion_main!(benches);
