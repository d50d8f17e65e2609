//! `index.html` of `piezo sim`, `demo`, `fit` and `diagnose` with `--out`: one page with the
//! run's table rows, every link and image pointing at a file of the folder, and every file
//! the run wrote linked.

mod cli_support;
mod diagnose_support;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use diagnose_support::Plant;
use hal_sim::ident::diagnose::Cause;
use hal_sim::record::Record;
use piezo_core::hysteresis::{Cbw, Hysteresis};

fn fresh_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("reports_{name}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `%XX` back to bytes (the page encodes names for URLs).
fn decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 2 < b.len() {
            out.push(u8::from_str_radix(&s[i + 1..i + 3], 16).unwrap());
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).unwrap()
}

/// The values of `attr="..."` in `html`.
fn attrs(html: &str, attr: &str) -> Vec<String> {
    let key = format!(" {attr}=\"");
    html.match_indices(&key)
        .map(|(at, _)| {
            let rest = &html[at + key.len()..];
            decode(&rest[..rest.find('"').unwrap()])
        })
        .collect()
}

/// Files below `dir`, relative, `/`-separated.
fn files(dir: &Path) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().to_string_lossy();
                out.insert(rel.replace('\\', "/"));
            }
        }
    }
    out
}

/// `dir/index.html` is a whole page; its links and images are files of `dir`, and every
/// file of `dir` (all written by the run) is linked. Returns the page.
fn check_index(dir: &Path, title: &str) -> String {
    let html = std::fs::read_to_string(dir.join("index.html")).expect("index.html written");
    assert!(html.starts_with("<!doctype html>\n<html"), "{:.80}", html);
    assert!(html.trim_end().ends_with("</html>"));
    assert!(html.contains(&format!("<h1>{title}")), "no title {title}");
    // Offline: nothing from another host.
    for needle in ["http://", "https://", "<script"] {
        assert!(!html.contains(needle), "the page holds {needle}");
    }
    let hrefs = attrs(&html, "href");
    let srcs = attrs(&html, "src");
    for l in hrefs.iter().chain(&srcs) {
        assert!(
            !l.starts_with('/') && !l.contains(".."),
            "not relative: {l}"
        );
        assert!(dir.join(l).is_file(), "{l} linked but not in the folder");
    }
    let linked: BTreeSet<&str> = hrefs.iter().map(|s| s.as_str()).collect();
    let all = files(dir);
    let missing: Vec<&String> = all
        .iter()
        .filter(|f| *f != "index.html" && !linked.contains(f.as_str()))
        .collect();
    assert!(missing.is_empty(), "written but not linked: {missing:?}");
    let n = all.len() - 1;
    let count = if n == 1 {
        "1 file".into()
    } else {
        format!("{n} files")
    };
    assert!(
        html.contains(&format!("{count} written")),
        "count of {n} files"
    );
    html
}

/// A table row whose cells start with `first` cells.
fn has_row(html: &str, first: &[&str]) -> bool {
    let cells: String = first.iter().map(|c| format!("<td>{c}</td>")).collect();
    html.contains(&format!("<tr>{cells}"))
}

#[test]
fn sim_report_groups_runs_per_scenario() {
    let dir = fresh_dir("sim");
    let out = cli_support::piezo(&[
        &"sim",
        &"--scenario",
        &"sine-10hz",
        &"--scenario",
        &"triangle-20hz",
        &"--controller",
        &"open-loop",
        &"--controller",
        &"ff+pid",
        &"--duration-s",
        &"0.1",
        &"--out",
        &dir,
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("index.html"), "{stdout}");
    let html = check_index(&dir, "piezo sim");
    for s in ["sine-10hz", "triangle-20hz"] {
        assert!(html.contains(&format!("<h2>Scenario {s}</h2>")), "{s}");
        for c in ["open-loop", "ff+pid"] {
            assert!(has_row(&html, &[c]), "{s} / {c} row");
            assert!(
                html.contains(&format!("src=\"{s}_{c}.svg\"")),
                "{s} / {c} plot"
            );
        }
    }
    // The overview names a best controller per scenario.
    assert!(html.contains("<tr><td>sine-10hz</td><td>2</td>"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn demo_report_lists_every_loop() {
    let dir = fresh_dir("demo");
    cli_support::piezo(&[&"demo", &"--rate-hz", &"200", &"--out", &dir]);
    let html = check_index(&dir, "piezo demo");
    for m in ["cbw", "gbw", "dahl", "wpmbw", "multi_bw_x"] {
        assert!(html.contains(&format!("<tr><td>{m}</td>")), "{m} row");
    }
    assert!(html.contains("src=\"loops.svg\""));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn fit_report_has_the_model_and_its_scores() {
    let dir = fresh_dir("fit");
    let dt = 2e-3;
    let n = 500;
    let m = Cbw::with_n1(0.16, 0.07, 0.02, 0.01).unwrap();
    let u: Vec<f64> = (0..2 * n)
        .map(|k| 50.0 * (1.0 + (2.0 * std::f64::consts::PI * k as f64 / n as f64).sin()))
        .collect();
    let mut s = m.init(u[0]);
    let y: Vec<f64> = u.iter().map(|&u| m.step(&mut s, u, dt)).collect();
    let t: Vec<f64> = (0..2 * n).map(|k| k as f64 * dt).collect();
    let train = dir.join("train.csv");
    Record::new(t, vec![u], vec![y])
        .unwrap()
        .write(&train)
        .unwrap();
    let out = dir.join("out");
    cli_support::piezo(&[
        &"fit",
        &"--model",
        &"cbw",
        &"--quiet",
        &"--generations",
        &"20",
        &"--split",
        &"0.5",
        &"--train",
        &train,
        &"--out",
        &out,
    ]);
    let html = check_index(&out, "piezo fit");
    assert!(has_row(&html, &["model", "cbw"]), "model row");
    assert!(html.contains("<h2>train_metrics</h2>"));
    assert!(html.contains("<h2>valid_metrics</h2>"));
    assert!(html.contains("src=\"train_y.svg\"") && html.contains("src=\"valid_y.svg\""));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn diagnose_report_has_the_causes_and_plots() {
    let dir = fresh_dir("diagnose");
    let plant = Plant::draw(5, &[Cause::Delay]);
    let (train, valid) = (plant.record(5, 0), plant.record(5, 1));
    for (name, s) in [("a.csv", &train), ("b.csv", &valid)] {
        Record::new(s.t.clone(), s.u.clone(), s.y.clone())
            .unwrap()
            .write(dir.join(name))
            .unwrap();
    }
    let out = dir.join("out");
    let o = cli_support::piezo(&[
        &"diagnose",
        &"--no-consistency",
        &"--train",
        &dir.join("a.csv"),
        &"--valid",
        &dir.join("b.csv"),
        &"--out",
        &out,
    ]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("report: "), "{stdout}");
    let html = check_index(&out, "piezo diagnose");
    // The report as printed, and the causes tried as a table.
    assert!(html.contains("cause: delay"), "{html:.2000}");
    assert!(html.contains("<h2>candidates</h2>"));
    assert!(html.contains("<tr><td>delay</td>"), "delay candidate row");
    assert!(html.contains("src=\"diagnose.svg\""));
    let _ = std::fs::remove_dir_all(&dir);
}
