//! Per-sample cost of every feedforward compensator (f32, host). On the target the same
//! code runs; host numbers rank the compensators, they are not target cycle counts.
//!
//! `cargo bench -p hal-sim --bench feedforward`

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use piezo_core::feedforward::*;
use piezo_core::hysteresis::*;
use piezo_core::signals::Setpoint;

const DT: f32 = 1e-5;

fn all() -> Vec<Feedforward<f32>> {
    let cbw = Cbw::with_n1(0.9f32, 0.3, 0.012, 0.004).unwrap();
    let creep = CreepInverse::new(&[0.01f32, 0.015, 0.02], &[0.02, 0.3, 5.0], DT).unwrap();
    let mbw = Mbw002::from_002(
        1.0998f32, -0.0656, 0.3922, -0.15, 1.0, -0.011, 0.0108, 3.68e-5,
    )
    .unwrap();
    let wp = Wpmbw::new(
        MbwRlm::new(0.6485f32, 0.7217, 0.7440).unwrap(),
        [0.9268, 0.0048],
    )
    .unwrap();
    let w = [0.03f32, 0.02, 0.01, 0.01, 0.005, 0.005, 0.002, 0.002];
    let r = [1.0f32, 3.0, 6.0, 10.0, 15.0, 21.0, 28.0, 36.0];
    let pi = Pi::new(0.1f32, w, r).unwrap();
    let ppi = Ppi::new(1e-6f32, 0.1, w, r).unwrap();
    let dpi = Dpi::new(w, r, [1.0f32, 0.3], [0.0, 8.0]).unwrap();
    vec![
        Feedforward::Linear(LinearFf {
            um_per_volt: 0.9,
            offset_um: 0.0,
        }),
        Feedforward::ImsCbw(Ims::new(cbw, ImsLoop::Delayed, 0.0, 150.0, DT).unwrap()),
        Feedforward::ImsCbw(Ims::new(cbw, ImsLoop::Solved, 0.0, 150.0, DT).unwrap()),
        Feedforward::ImsCbw(
            Ims::new(cbw, ImsLoop::Solved, 0.0, 150.0, DT)
                .unwrap()
                .with_quadratic(-2e-4)
                .unwrap()
                .with_creep(creep),
        ),
        Feedforward::ImsMbw(Ims::new(mbw, ImsLoop::Solved, 0.0, 150.0, DT).unwrap()),
        Feedforward::Mbw(MbwFf::new(mbw, 1.0, 0.0, 150.0, DT).unwrap()),
        Feedforward::Wpmbw(
            WpmbwInverse::new(
                &wp,
                Some(LinearPart::second_order(9400.0, 0.03)),
                Some(314.0),
                0.0,
                150.0,
                DT,
            )
            .unwrap(),
        ),
        Feedforward::PiInverse(PiInverse::new(&pi, 0.0, 150.0).unwrap()),
        Feedforward::PpiInverse(ppi_inverse(&ppi, 0.0, 150.0, DT).unwrap()),
        Feedforward::DpiInverse(DpiInverse::new(&dpi, 0.0, 150.0).unwrap()),
    ]
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("feedforward_per_sample");
    for (k, mut ff) in all().into_iter().enumerate() {
        let name = format!("{k:02}-{}", ff.name());
        let mut t = 0.0f32;
        g.bench_function(name, |b| {
            b.iter(|| {
                // 10 Hz, 40 um sine at 100 kHz: realistic per-sample increments.
                t += DT;
                let ph = 2.0 * core::f32::consts::PI * 10.0 * t;
                let sp = Setpoint {
                    y_um: 50.0 + 40.0 * ph.sin(),
                    dy: 2513.0 * ph.cos(),
                    ddy: 0.0,
                };
                black_box(ff.compensate(black_box(&sp)))
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
