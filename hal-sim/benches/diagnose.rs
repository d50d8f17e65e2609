//! `diagnose` of a 10 kHz, 10 s single-axis train/valid pair (target: <= 2 s on 2 cores).
//!
//! `cargo bench -p hal-sim --bench diagnose`
use criterion::{criterion_group, criterion_main, Criterion};
use hal_sim::ident::diagnose::{diagnose, Cause, Options};
use hal_sim::ident::generate::Hidden;

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("diagnose");
    g.sample_size(10);
    for (name, effects) in [("clean", vec![]), ("dynamics", vec![Cause::Dynamics])] {
        // hal-sim's simulated stage with the hidden cause (the hidden-effect tests' generator).
        let plant = Hidden::draw_at(3, &effects, 10_000.0, 10.0).expect("valid draw");
        let (train, valid) = (plant.record(0), plant.record(1));
        let d = diagnose(&train, &valid, &Options::default()).expect("diagnose runs");
        eprintln!("{name}: cause {} gain {:.3}", d.cause(), d.gain());
        g.bench_function(format!("10kHz_10s_{name}"), |b| {
            b.iter(|| diagnose(&train, &valid, &Options::default()).expect("diagnose runs"))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
