//! `diagnose` of a 10 kHz, 20 s single-axis train/valid pair of hal-sim's stage with none and
//! with one, two and three hidden causes (target: <= 2 s median per case on 2 cores).
//!
//! `cargo bench -p hal-sim --bench diagnose`
use criterion::{criterion_group, criterion_main, Criterion};
use hal_sim::ident::diagnose::{diagnose, Cause, Options};
use hal_sim::ident::generate::Hidden;

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("diagnose");
    g.sample_size(10);
    for (name, effects) in [
        ("clean", vec![]),
        ("one", vec![Cause::Dynamics]),
        ("two", vec![Cause::Dynamics, Cause::Drift]),
        (
            "three",
            vec![Cause::RateDependence, Cause::Creep, Cause::Drift],
        ),
    ] {
        // hal-sim's simulated stage with the hidden causes (the hidden-effect tests' generator).
        let plant = Hidden::draw_at(3, &effects, 10_000.0, 20.0).expect("valid draw");
        let (train, valid) = (plant.record(0), plant.record(1));
        let d = diagnose(&train, &valid, &Options::default()).expect("diagnose runs");
        let found: Vec<&str> = d.findings.iter().map(|f| f.cause.name()).collect();
        eprintln!(
            "{name}: hidden {effects:?}, found {found:?}, gain {:.3}",
            d.gain()
        );
        g.bench_function(format!("10kHz_20s_{name}"), |b| {
            b.iter(|| diagnose(&train, &valid, &Options::default()).expect("diagnose runs"))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
