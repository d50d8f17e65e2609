//! `diagnose` of a 10 kHz, 10 s single-axis train/valid pair (target: <= 2 s on 2 cores), and
//! of two such pairs at once (two training and two validation records, one model).
//!
//! `cargo bench -p hal-sim --bench diagnose`
use criterion::{criterion_group, criterion_main, Criterion};
use hal_sim::ident::diagnose::{diagnose, diagnose_records, Cause, Options};
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
    // Several records: two training and two validation records of the same stage.
    let plant = Hidden::draw_at(3, &[Cause::Dynamics], 10_000.0, 10.0).expect("valid draw");
    let train = [plant.record(0), plant.record(2)];
    let valid = [plant.record(1), plant.record(3)];
    let d = diagnose_records(&train, &valid, &Options::default()).expect("diagnose runs");
    eprintln!("2+2 records: cause {} gain {:.3}", d.cause(), d.gain());
    g.bench_function("10kHz_10s_dynamics_2train_2valid", |b| {
        b.iter(|| diagnose_records(&train, &valid, &Options::default()).expect("diagnose runs"))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
