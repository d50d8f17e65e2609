//! Diagnostics of the FSM linear fit (scratch).
use hal_sim::ident::ss::frf::{self, PeriodicSpectra};
use hal_sim::ident::ss::model::C64;
use hal_sim::ident::ss::pem::{self, LineStats, PemConfig};
use hal_sim::ident::ss::subspace;
use hal_sim::record::Record;
use nalgebra::DMatrix;

fn rec(l: u32, r: u32) -> Record {
    Record::read(format!("../shared/data/fsm-benchmark/fsm_{l}mV_r{r}.csv")).unwrap()
}

fn score(y: &[Vec<f64>], s: &[Vec<f64>], n: usize) -> f64 {
    let start = y[0].len() - n;
    y.iter()
        .zip(s)
        .map(|(a, b)| {
            ((start..a.len()).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>() / n as f64).sqrt()
        })
        .sum::<f64>()
        / y.len() as f64
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let levels: Vec<u32> = args[1].split(',').map(|s| s.parse().unwrap()).collect();
    let order: usize = args[2].parse().unwrap();
    let iters: usize = args[3].parse().unwrap();
    let mut train = Vec::new();
    for &l in &levels {
        for r in 1..=3 {
            train.push(rec(l, r));
        }
    }
    let n = 8192;
    let sp: Vec<PeriodicSpectra> = train
        .iter()
        .map(|r| PeriodicSpectra::of(r, n).unwrap())
        .collect();
    let bla = frf::bla(&sp).unwrap();
    eprintln!(
        "lines {} ({:.1}..{:.1} Hz)",
        bla.data.bins.len(),
        bla.data.freq_hz(0),
        bla.data.freq_hz(bla.data.bins.len() - 1)
    );
    // Nonparametric floor: BLA applied to the test inputs in steady state.
    for l in [100, 200, 300] {
        for r in [4] {
            let t = rec(l, r);
            let s = PeriodicSpectra::of(&t, n).unwrap();
            let mut ms = [0.0; 3];
            for (li, &k) in bla.data.bins.iter().enumerate() {
                let u = DMatrix::from_fn(3, 1, |j, _| s.u[j][k]);
                let yh = &bla.data.g[li] * u;
                for o in 0..3 {
                    ms[o] += (s.y[o][k] - yh[o]).norm_sqr() * frf::bin_weight(k, n);
                }
            }
            // Unexcited bins count fully.
            let exc: std::collections::HashSet<usize> = bla.data.bins.iter().copied().collect();
            let mut rest = [0.0; 3];
            for k in 0..=n / 2 {
                if !exc.contains(&k) {
                    for o in 0..3 {
                        rest[o] += s.y[o][k].norm_sqr() * frf::bin_weight(k, n);
                    }
                }
            }
            let sc: f64 = (0..3).map(|o| (ms[o] + rest[o]).sqrt()).sum::<f64>() / 3.0;
            let sr: f64 = (0..3).map(|o| rest[o].sqrt()).sum::<f64>() / 3.0;
            eprintln!("BLA floor {l} mV r{r}: {sc:.4} (unexcited lines alone {sr:.4})");
        }
    }
    let t0 = std::time::Instant::now();
    let init = subspace::identify(&bla.data, order).unwrap();
    eprintln!(
        "subspace {:.1}s radius {:.6}",
        t0.elapsed().as_secs_f64(),
        init.spectral_radius()
    );
    let stats = LineStats::from_frf(&bla.data);
    let eval = |m: &hal_sim::ident::ss::model::Modal, tag: &str| {
        for l in [100, 200, 300] {
            let mut td = 0.0;
            let mut ss = 0.0;
            for r in [5, 6] {
                let t = rec(l, r);
                let y = m.simulate(&t.u).unwrap();
                td += score(&t.y, &y, n) / 2.0;
                // periodic steady state: simulate 3 periods, score the last
                let u3: Vec<Vec<f64>> = t
                    .u
                    .iter()
                    .map(|u| u[..n].iter().chain(&u[..n]).chain(&u[..n]).chain(&u[..n]).copied().collect())
                    .collect();
                let y3 = m.simulate(&u3).unwrap();
                let y3l: Vec<Vec<f64>> = y3.iter().map(|v| v[2 * n..].to_vec()).collect();
                ss += score(&t.y, &y3l, n) / 2.0;
            }
            eprintln!("{tag} {l} mV: from rest {td:.4}, steady state {ss:.4}");
        }
    };
    eval(&init, "subspace");
    let cfg = PemConfig {
        iterations: iters,
        ftol: 1e-9,
        progress: Some("lm".into()),
    };
    let t0 = std::time::Instant::now();
    let r = pem::refine(&init, &[], (&[], &[]), &|_, _| Ok(stats.clone()), &cfg).unwrap();
    eprintln!(
        "lm {} it {:.1}s radius {:.6}",
        r.iterations,
        t0.elapsed().as_secs_f64(),
        r.model.spectral_radius()
    );
    eval(&r.model, "lm");
    let modes = r.model.modes_hz(6400.0);
    eprintln!("{:?}", modes);
    let _ = C64::new(0.0, 0.0);
}
