//! Scratch: nonlinear feedback (LFR-like) with shared poles, train r1-r3, validate r4.
use hal_sim::ident::ss::frf::{self, period_spectra, PeriodicSpectra};
use hal_sim::ident::ss::model::{Modal, C64};
use hal_sim::ident::ss::pem::{self, PemConfig};
use hal_sim::ident::ss::subspace;
use hal_sim::record::Record;
use nalgebra::{DMatrix, DVector};

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

#[derive(Clone, Copy, PartialEq)]
enum Src {
    U,
    Y,
}

struct Basis {
    src: Src,
    scale: Vec<f64>,
    kinds: Vec<u8>, // 2: s|s|, 3: s^3, 1: |s|
}

impl Basis {
    fn nw(&self) -> usize {
        self.scale.len() * self.kinds.len()
    }
    fn eval(&self, s: &[f64], out: &mut [f64]) {
        let mut i = 0;
        for (c, &sc) in self.scale.iter().enumerate() {
            let x = s[c] / sc;
            for &k in &self.kinds {
                out[i] = match k {
                    1 => x.abs(),
                    2 => x * x.abs(),
                    3 => x * x * x,
                    _ => x * x,
                };
                i += 1;
            }
        }
    }
}

/// Simulates x+ = A x + B [u; w], y = C x + D u, w = phi(u or y).
fn sim(m: &Modal, bs: &Basis, u: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let (p, n) = (m.outputs(), m.order());
    let mu = u.len();
    let nw = bs.nw();
    let len = u[0].len();
    let a = m.a();
    let mut x = DVector::<f64>::zeros(n);
    let mut y = vec![vec![0.0; len]; p];
    let mut v = vec![0.0; mu + nw];
    let mut yk = vec![0.0; p];
    for k in 0..len {
        for j in 0..mu {
            v[j] = u[j][k];
        }
        for o in 0..p {
            let mut s = 0.0;
            for i in 0..n {
                s += m.c[(o, i)] * x[i];
            }
            for j in 0..mu {
                s += m.d[(o, j)] * v[j];
            }
            yk[o] = s;
            y[o][k] = s;
        }
        let (head, tail) = v.split_at_mut(mu);
        match bs.src {
            Src::U => bs.eval(head, tail),
            Src::Y => bs.eval(&yk, tail),
        }
        let vv = DVector::from_row_slice(&v);
        x = &a * &x + &m.b * vv;
        if !x[0].is_finite() {
            break;
        }
    }
    y
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let order: usize = args[1].parse().unwrap();
    let iters: usize = args[2].parse().unwrap();
    let valid_r: u32 = 4;
    let train_r: Vec<u32> = (1..valid_r).collect();
    let levels = [100u32, 200, 300];
    let n = 8192;
    let mut train = Vec::new();
    for &l in &levels {
        for &r in &train_r {
            train.push(rec(l, r));
        }
    }
    let valid: Vec<Record> = levels.iter().map(|&l| rec(l, valid_r)).collect();
    let sp: Vec<PeriodicSpectra> = train
        .iter()
        .map(|r| PeriodicSpectra::of(r, n).unwrap())
        .collect();
    let bla = frf::bla(&sp).unwrap();
    let t0 = std::time::Instant::now();
    let init = subspace::identify(&bla.data, order).unwrap();
    let stats = pem::LineStats::from_frf(&bla.data);
    let cfg = PemConfig {
        iterations: iters,
        ftol: 1e-9,
        progress: None,
    };
    let lin = pem::refine(&init, &[], (&[], &[]), &|_, _| Ok(stats.clone()), &cfg)
        .unwrap()
        .model;
    eprintln!("linear {:.1}s", t0.elapsed().as_secs_f64());
    let evalv = |tag: &str, f: &dyn Fn(&[Vec<f64>]) -> Vec<Vec<f64>>| {
        let s: Vec<String> = valid
            .iter()
            .map(|v| format!("{:.4}", score(&v.y, &f(&v.u), n)))
            .collect();
        eprintln!("{tag}: r4 {}", s.join(" / "));
    };
    evalv("linear", &|u| lin.simulate(u).unwrap());
    let (p, m) = (3usize, 3usize);
    let rms = |x: &[f64]| (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt();
    let uscale: Vec<f64> = (0..m)
        .map(|j| rms(&train.iter().flat_map(|r| r.u[j].clone()).collect::<Vec<_>>()))
        .collect();
    let yscale: Vec<f64> = (0..p)
        .map(|o| rms(&train.iter().flat_map(|r| r.y[o].clone()).collect::<Vec<_>>()))
        .collect();
    let variants: Vec<(&str, Basis)> = vec![
        ("u: s|s|,s^3", Basis { src: Src::U, scale: uscale.clone(), kinds: vec![2, 3] }),
        ("y: s|s|,s^3", Basis { src: Src::Y, scale: yscale.clone(), kinds: vec![2, 3] }),
        ("y: s^2,s|s|,s^3", Basis { src: Src::Y, scale: yscale.clone(), kinds: vec![0, 2, 3] }),
        ("y: s^3", Basis { src: Src::Y, scale: yscale.clone(), kinds: vec![3] }),
    ];
    for (tag, bs) in variants {
        let t0 = std::time::Instant::now();
        let nw = bs.nw();
        let q = m + nw;
        let nx = lin.order();
        // Spectra of V = [u; w] with w from the measured signals.
        let vsp: Vec<Vec<Vec<C64>>> = train
            .iter()
            .map(|r| {
                let len = r.len();
                let mut w = vec![vec![0.0; len]; nw];
                let mut buf = vec![0.0; nw];
                for k in 0..len {
                    let s: Vec<f64> = match bs.src {
                        Src::U => (0..m).map(|j| r.u[j][k]).collect(),
                        Src::Y => (0..p).map(|o| r.y[o][k]).collect(),
                    };
                    bs.eval(&s, &mut buf);
                    for i in 0..nw {
                        w[i][k] = buf[i];
                    }
                }
                let mut out: Vec<Vec<C64>> = Vec::new();
                for x in r.u.iter().chain(w.iter()) {
                    // second period only
                    out.push(period_spectra(&x[n..], n).remove(0));
                }
                for x in r.y.iter() {
                    out.push(period_spectra(&x[n..], n).remove(0));
                }
                out
            })
            .collect();
        let nu = nx * q + p * m;
        let mut h = DMatrix::<f64>::zeros(nu, nu);
        let mut g = DVector::<f64>::zeros(nu);
        let cc = lin.c.map(|v| C64::new(v, 0.0));
        for k in 1..n / 2 {
            let z = C64::from_polar(1.0, 2.0 * std::f64::consts::PI * k as f64 / n as f64);
            let wk = frf::bin_weight(k, n);
            let mut svv = DMatrix::<C64>::zeros(q, q);
            let mut syv = DMatrix::<C64>::zeros(p, q);
            for s in &vsp {
                let v = DMatrix::from_fn(q, 1, |j, _| s[j][k]);
                let y = DMatrix::from_fn(p, 1, |o, _| s[q + o][k]);
                svv += &v * v.adjoint();
                syv += &y * v.adjoint();
            }
            // M = C (zI - A)^-1
            let a = lin.a().map(|v| C64::new(v, 0.0));
            let r = (DMatrix::<C64>::identity(nx, nx) * z - a).try_inverse().unwrap();
            let mm = &cc * r;
            let mhm = mm.adjoint() * &mm;
            for s1 in 0..nx {
                for j1 in 0..q {
                    let i1 = s1 * q + j1;
                    for s2 in 0..nx {
                        for j2 in 0..q {
                            h[(i1, s2 * q + j2)] +=
                                wk * (mhm[(s1, s2)] * svv[(j1, j2)].conj()).re;
                        }
                    }
                    for o in 0..p {
                        for j2 in 0..m {
                            let val = wk * (mm[(o, s1)].conj() * svv[(j1, j2)].conj()).re;
                            h[(i1, nx * q + o * m + j2)] += val;
                            h[(nx * q + o * m + j2, i1)] += val;
                        }
                    }
                    g[i1] += wk
                        * (0..p)
                            .map(|o| (mm[(o, s1)].conj() * syv[(o, j1)]).re)
                            .sum::<f64>();
                }
            }
            for o in 0..p {
                for j1 in 0..m {
                    for j2 in 0..m {
                        h[(nx * q + o * m + j1, nx * q + o * m + j2)] +=
                            wk * svv[(j1, j2)].conj().re;
                    }
                    g[nx * q + o * m + j1] += wk * syv[(o, j1)].re;
                }
            }
        }
        let reg = 1e-9 * h.diagonal().max();
        for i in 0..nu {
            h[(i, i)] += reg;
        }
        let x = h.cholesky().unwrap().solve(&g);
        let mut ext = lin.clone();
        ext.b = DMatrix::from_fn(nx, q, |s, j| x[s * q + j]);
        ext.d = DMatrix::from_fn(p, m, |o, j| x[nx * q + o * m + j]);
        eprintln!("{tag}: solve {:.1}s", t0.elapsed().as_secs_f64());
        evalv(tag, &|u| sim(&ext, &bs, u));
    }
}
