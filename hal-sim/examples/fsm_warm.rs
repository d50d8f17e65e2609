//! Scratch: per-level linear fits, each level warm-started from the previous level's model.
use hal_sim::ident::ss::frf::{self, PeriodicSpectra};
use hal_sim::ident::ss::pem::{self, LineStats, PemConfig};
use hal_sim::ident::ss::subspace;
use hal_sim::record::Record;

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
    let n = 8192;
    let mut prev = None;
    for &l in &levels {
        let sp: Vec<PeriodicSpectra> = (1..=4)
            .map(|r| PeriodicSpectra::of(&rec(l, r), n).unwrap())
            .collect();
        let data = frf::bla(&sp).unwrap().data;
        let stats = LineStats::from_frf(&data);
        let cfg = PemConfig { iterations: iters, ftol: 1e-9, progress: None };
        let mut inits = vec![("subspace", subspace::identify(&data, order).unwrap())];
        if let Some(p) = &prev {
            let mut m: hal_sim::ident::ss::model::Modal = Clone::clone(p);
            subspace::fit_bd(&mut m, &data).unwrap();
            inits.push(("warm", m));
        }
        let mut best: Option<(f64, _)> = None;
        for (tag, init) in inits {
            let t0 = std::time::Instant::now();
            let r = pem::refine(&init, &[], (&[], &[]), &|_, _| Ok(stats.clone()), &cfg).unwrap();
            let mut s = 0.0;
            for rr in [5, 6] {
                let t = rec(l, rr);
                s += score(&t.y, &r.model.simulate(&t.u).unwrap(), n) / 2.0;
            }
            eprintln!(
                "{l} mV {tag}: init cost {:.4e} -> {:.4e} in {} it {:.0}s; held-out r5/r6 {s:.4}",
                pem::cost(&init, &stats),
                r.cost,
                r.iterations,
                t0.elapsed().as_secs_f64()
            );
            if best.as_ref().is_none_or(|b| r.cost < b.0) {
                best = Some((r.cost, r.model));
            }
        }
        prev = best.map(|b| b.1);
    }
}
