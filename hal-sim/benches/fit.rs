//! Identification speed: model simulation per sample and a full CBW fit of a 10 kHz, 10 s
//! single-axis record (the size `piezo diagnose` must handle in <= 2 s).
//!
//! `cargo bench -p hal-sim --bench fit`
use criterion::{black_box, criterion_group, criterion_main, Criterion};
use hal_sim::ident::fit::resample::Edge;
use hal_sim::ident::fit::{fit_siso, models, FitOptions, Fitted};

fn record(n: usize, fs: f64) -> Vec<f64> {
    (0..n)
        .map(|i| {
            let t = i as f64 / fs;
            75.0 + 70.0 * (2.0 * std::f64::consts::PI * t).sin() * (1.0 - 0.05 * t)
        })
        .collect()
}

fn benches(c: &mut Criterion) {
    let fs = 10_000.0;
    let u = record(100_000, fs);
    let cbw = models::find("cbw").unwrap();
    let truth = Fitted::from_params(cbw, &[0.16, 0.07, 0.02, 0.5], 1.0, 0.0, 1).unwrap();
    let y = truth.simulate(&u, 1.0 / fs, Edge::Hold).unwrap();
    c.bench_function("simulate cbw 100k samples", |b| {
        b.iter(|| truth.simulate(black_box(&u), 1.0 / fs, Edge::Hold).unwrap())
    });
    let sbw = models::find("structural-bw").unwrap();
    let bw = Fitted::from_params(
        sbw,
        &[2.0, 10.0, 5e4, 5e4, 800.0, -1100.0, 1.0],
        1.0,
        0.0,
        5,
    )
    .unwrap();
    let force: Vec<f64> = (0..8192).map(|i| 50.0 * (i as f64 * 0.3).sin()).collect();
    c.bench_function("simulate structural-bw 8192 samples x5 upsampled", |b| {
        b.iter(|| {
            bw.simulate(black_box(&force), 1.0 / 750.0, Edge::Hold)
                .unwrap()
        })
    });
    let mut g = c.benchmark_group("fit");
    g.sample_size(10);
    g.bench_function("fit cbw 10 kHz 10 s (DE 100 gen + LM)", |b| {
        let opts = FitOptions {
            generations: 100,
            ..Default::default()
        };
        b.iter(|| fit_siso(cbw, black_box(&u), &y, 1.0 / fs, &opts).unwrap())
    });
    g.finish();
}

criterion_group!(fit, benches);
criterion_main!(fit);
