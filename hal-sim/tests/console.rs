//! The lab console's link thread (`hal_sim::console::worker`) against the firmware's own
//! executor behind TCP (as `tests/serial.rs` runs it): jobs from many tasks never
//! interleave, the scope's captures arrive, a lost link is reported and opened again.
//! The server itself (`hal_sim::console::serve`) for the report folders it serves.

mod control {
    pub use piezo_core::firmware::*;
    use piezo_core::firmware::{Converters, OnChip};
    pub type Ctl = piezo_core::firmware::Ctl<OnChip>;
    pub const DAC_MAX: i32 = OnChip::DAC_MAX;
}

use std::collections::VecDeque;
use std::io::{Read, Write};
use std::net::TcpListener;
use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant};

use hal_sim::cli::serial::Conn;
use hal_sim::console::worker::{self, Shared};
use piezo_core::command::LineBuffer;
use serde_json::{json, Value};

/// The firmware's control state and a first-order stage (0.16 um/V).
struct Fake {
    ctl: control::Ctl,
    y_um: f64,
    dac: i32,
}

impl Fake {
    fn new() -> Self {
        Self {
            ctl: control::Ctl::new(control::c(control::SAMPLE_HZ as f64)),
            y_um: 0.0,
            dac: 0,
        }
    }

    fn run(&mut self, periods: usize) {
        for _ in 0..periods {
            let volts = self.dac as f64 * 150.0 / control::DAC_MAX as f64;
            self.y_um += 0.3 * (0.16 * volts - self.y_um);
            let code = (1000.0 + self.y_um * 655.35).clamp(0.0, 65535.0) as i32;
            [self.dac] = self.ctl.lp.step([code]);
            self.ctl.record([code], [self.dac]);
        }
    }
}

/// Serves connections one after another on one firmware state; the first `drop_after`
/// lines of the first connection only, then it hangs up (a lost link).
fn spawn_firmware(drop_after: Option<usize>) -> String {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    thread::spawn(move || {
        let mut fake = Fake::new();
        let mut limit = drop_after;
        for mut s in listener.incoming().flatten() {
            s.write_all(b"boot noise\nready\n").ok();
            let mut lb = LineBuffer::new();
            let mut buf = [0u8; 512];
            let mut lines = 0;
            'conn: loop {
                let n = match s.read(&mut buf) {
                    Ok(0) | Err(_) => break,
                    Ok(n) => n,
                };
                let mut out = VecDeque::new();
                for &b in &buf[..n] {
                    if let Some(line) = lb.push(b) {
                        lines += 1;
                        if limit.is_some_and(|l| lines > l) {
                            limit = None;
                            break 'conn;
                        }
                        fake.run(50);
                        fake.ctl.serve(line, &mut out);
                    }
                }
                if s.write_all(out.make_contiguous()).is_err() {
                    break;
                }
            }
        }
    });
    addr
}

fn conn(addr: &str) -> Conn {
    Conn::tcp(addr, 5.0)
}

/// The next event of `type` (within `limit` events).
async fn next_event(
    rx: &mut tokio::sync::broadcast::Receiver<Arc<str>>,
    kind: &str,
    limit: usize,
) -> Value {
    for _ in 0..limit {
        let text = tokio::time::timeout(Duration::from_secs(30), rx.recv())
            .await
            .expect("an event within 30 s")
            .expect("the event channel open");
        let v: Value = serde_json::from_str(&text).unwrap();
        if v["type"] == kind {
            return v;
        }
    }
    panic!("no `{kind}` event among {limit}");
}

/// The next whole capture as the scope streams it: its parts from frame 0 on, each
/// starting where the last ended, to the one marked complete; the first part and the
/// columns put together.
async fn next_capture(
    rx: &mut tokio::sync::broadcast::Receiver<Arc<str>>,
    limit: usize,
) -> (Value, Vec<Vec<f64>>, usize) {
    let mut first: Option<Value> = None;
    let mut columns: Vec<Vec<f64>> = Vec::new();
    let mut parts = 0;
    for _ in 0..limit {
        let f = next_event(rx, "frame", limit).await;
        if f["from"] == json!(0) {
            columns = vec![Vec::new(); f["channels"].as_array().unwrap().len()];
            first = Some(f.clone());
            parts = 0;
        }
        let Some(head) = &first else { continue };
        if f["seq"] != head["seq"] {
            first = None;
            continue;
        }
        assert_eq!(
            f["from"].as_u64().unwrap() as usize,
            columns[0].len(),
            "a gap"
        );
        for (c, part) in columns.iter_mut().zip(f["columns"].as_array().unwrap()) {
            c.extend(part.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()));
        }
        parts += 1;
        if f["complete"] == json!(true) {
            return (head.clone(), columns, parts);
        }
    }
    panic!("no whole capture among {limit} events");
}

async fn connected(shared: &Shared) {
    let t = Instant::now();
    while !shared.link.lock().unwrap().0 {
        assert!(t.elapsed() < Duration::from_secs(30), "never connected");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn jobs_of_many_pages_never_interleave_and_the_scope_streams() {
    let shared = worker::spawn(conn(&spawn_firmware(None)));
    let mut rx = shared.events.subscribe();
    connected(&shared).await;
    // The capture streams in parts while it fills (the fake firmware runs 50 periods per
    // line it answers: several status polls per capture).
    let (f, columns, parts) = next_capture(&mut rx, 400).await;
    assert_eq!(
        f["channels"],
        json!(["ref_um", "y_um", "error_um", "u_volts"])
    );
    assert_eq!(f["total"], json!(256));
    assert!(columns.iter().all(|c| c.len() == 256), "{parts} parts");
    assert_eq!(f["sample_hz"], json!(100_000.0 / 4.0));
    // The export holds the same frames as the parts.
    {
        let caps = shared.captures.lock().unwrap();
        let cap = caps.iter().find(|c| json!(c.seq) == f["seq"]).unwrap();
        assert_eq!(cap.rec.frames.len(), 256);
        for (k, c) in columns.iter().enumerate() {
            for (i, v) in c.iter().enumerate() {
                assert_eq!(cap.rec.frames[i][k], *v, "frame {i} channel {k}");
            }
        }
    }

    // Eight pages, each setting pid_kp to its own value and reading it back in one job:
    // a command of another page between the two would show as a wrong value.
    let mut tasks = Vec::new();
    for page in 0..8u32 {
        let s = shared.clone();
        tasks.push(tokio::spawn(async move {
            for k in 0..10u32 {
                let v = 0.25 + f64::from(page) * 0.125 + f64::from(k) * 0.001;
                let got = s
                    .job(Box::new(move |c| {
                        hal_sim::console::jobs::set(c, "pid_kp", v)?;
                        Ok(json!(c.get("pid_kp")?))
                    }))
                    .await
                    .unwrap();
                assert!((got.as_f64().unwrap() - v).abs() < 1e-6, "{got} != {v}");
            }
        }));
    }
    for t in tasks {
        t.await.unwrap();
    }
    // The scope goes on after the jobs.
    let before = f["seq"].as_u64().unwrap();
    let g = next_event(&mut rx, "frame", 500).await;
    assert!(g["seq"].as_u64().unwrap() > before);

    // Stop: open loop holding offset_um, the output at 0 V.
    let r = shared
        .job(Box::new(hal_sim::console::jobs::stop))
        .await
        .unwrap();
    assert_eq!(
        r["replies"],
        json!([
            "ok wave off",
            "ok mode open-loop",
            "ok ff linear",
            "ok wave hold 0"
        ])
    );
    // A firmware refusal keeps its number.
    let e = shared
        .job(Box::new(|c| hal_sim::console::jobs::mode(c, "warp", None)))
        .await
        .unwrap_err();
    let body = hal_sim::console::jobs::refusal(&e);
    assert_eq!(body["code"], json!(9), "{body}");

    // A wave the firmware would refuse (60 kHz at 100 kHz) is refused before it is sent,
    // by the firmware's own executor run here; a good one goes out.
    use hal_sim::console::jobs::{wave, Wave};
    let sent = |s: &Shared| s.wire.lock().unwrap().sent;
    let before = sent(&shared);
    let e = shared
        .job(Box::new(|c| {
            let w = Wave::Sine {
                amp_um: 5.0,
                freq_hz: 60_000.0,
                offset_um: 10.0,
            };
            wave(c, &w)
        }))
        .await
        .unwrap_err();
    let msg = format!("{e:#}");
    assert!(
        msg.contains("err 8") && msg.contains("nothing sent"),
        "{msg}"
    );
    assert!(
        !shared
            .wire
            .lock()
            .unwrap()
            .last
            .iter()
            .any(|l| l.contains("60000")),
        "the refused wave went out"
    );
    let r = shared
        .job(Box::new(|c| {
            let w = Wave::Sine {
                amp_um: 5.0,
                freq_hz: 100.0,
                offset_um: 10.0,
            };
            wave(c, &w)
        }))
        .await
        .unwrap();
    assert_eq!(r["reply"], json!("ok wave sine 5 100 10"));
    assert!(sent(&shared) > before);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_lost_link_is_shown_and_opened_again() {
    let shared = worker::spawn(conn(&spawn_firmware(Some(40))));
    let mut rx = shared.events.subscribe();
    let up = next_event(&mut rx, "link", 10).await;
    assert_eq!(up["connected"], json!(true), "{up}");
    let lost = next_event(&mut rx, "link", 10_000).await;
    assert_eq!(lost["connected"], json!(false), "{lost}");
    assert!(
        lost["detail"]
            .as_str()
            .unwrap()
            .starts_with("connection lost"),
        "{lost}"
    );
    let again = next_event(&mut rx, "link", 10_000).await;
    assert_eq!(again["connected"], json!(true), "{again}");
    let r = shared
        .job(Box::new(|c| Ok(json!(c.get("sample_hz")?))))
        .await
        .unwrap();
    assert_eq!(r, json!(100_000.0));
}

#[test]
fn the_pages_waves_pass_the_firmwares_parser_and_bad_scopes_are_refused() {
    use hal_sim::console::jobs::Wave;
    use hal_sim::console::worker::ScopeCfg;
    use hal_sim::serial::lines::checked_line;
    // The Wave panel's defaults (assets/app.js), as the page sends them.
    for body in [
        json!({"shape": "sine", "amp_um": 5, "freq_hz": 100, "offset_um": 10}),
        json!({"shape": "triangle", "amp_um": 5, "freq_hz": 100, "offset_um": 10}),
        json!({"shape": "square", "amp_um": 5, "freq_hz": 100, "offset_um": 10}),
        json!({"shape": "raster", "x_span_um": 10, "y_span_um": 10, "lines": 4, "line_hz": 20, "xc_um": 10, "yc_um": 10}),
        json!({"shape": "prbs", "low_um": 10, "high_um": 12, "order": 12, "bit_hz": 10000, "seed": 1}),
        json!({"shape": "chirp", "amp_um": 2, "f0_hz": 10, "f1_hz": 2000, "duration_s": 0.1, "offset_um": 10}),
        json!({"shape": "multisine", "amp_um": 2, "f0_hz": 100, "harmonics": 16, "offset_um": 10, "seed": 0}),
        json!({"shape": "hold", "position_um": 10}),
        json!({"shape": "off"}),
    ] {
        let w: Wave = serde_json::from_value(body.clone()).unwrap();
        let line = checked_line(&w.command()).unwrap_or_else(|e| panic!("{body}: {e}"));
        assert!(line.starts_with("wave "), "{line}");
    }
    // A PRBS order the firmware does not have is refused before it is sent.
    let w: Wave = serde_json::from_value(
        json!({"shape": "prbs", "low_um": 10, "high_um": 12, "order": 40, "bit_hz": 10000, "seed": 1}),
    )
    .unwrap();
    assert!(checked_line(&w.command()).is_err());

    assert!(ScopeCfg::default().check().is_ok());
    for (cfg, why) in [
        (
            ScopeCfg {
                signals: vec!["warp_um".into()],
                ..Default::default()
            },
            "unknown signal",
        ),
        (
            ScopeCfg {
                frames: 4,
                ..Default::default()
            },
            "frames",
        ),
        (
            ScopeCfg {
                every: 0,
                ..Default::default()
            },
            "every",
        ),
        (
            ScopeCfg {
                trigger: "rise:dac_code:1".into(),
                ..Default::default()
            },
            "dac_code",
        ),
        (
            ScopeCfg {
                trigger: "rise:ref_um:10".into(),
                pre: 300,
                ..Default::default()
            },
            "pre",
        ),
    ] {
        let e = format!("{:#}", cfg.check().unwrap_err());
        assert!(e.contains(why), "{e}");
    }
    // The table's check of the Settings panel, as `piezo serial set` does it.
    use hal_sim::console::jobs::check_setting;
    assert_eq!(check_setting("u_max", 120.0), Ok("u_max"));
    assert!(check_setting("u_max", 200.0)
        .unwrap_err()
        .contains("outside 0 .. 150"));
    assert!(check_setting("sample_hz", 1.0)
        .unwrap_err()
        .contains("read-only"));
    assert!(check_setting("notch_q", f64::NAN).is_err());
}

/// One HTTP/1.1 GET on the console: status line, `content-type`, body.
async fn get(addr: std::net::SocketAddr, path: &str) -> (String, String, String) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    let req = format!("GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n");
    s.write_all(req.as_bytes()).await.unwrap();
    let mut text = String::new();
    tokio::time::timeout(Duration::from_secs(30), s.read_to_string(&mut text))
        .await
        .expect("an answer within 30 s")
        .unwrap();
    let (head, body) = text.split_once("\r\n\r\n").unwrap();
    let status = head.lines().next().unwrap().to_string();
    let mime = head
        .lines()
        .find_map(|l| {
            l.to_ascii_lowercase()
                .strip_prefix("content-type: ")
                .map(String::from)
        })
        .unwrap_or_default();
    (status, mime, body.to_string())
}

/// `piezo ui --report DIR`: the folder's page and files are served below `/reports/<n>/`
/// and listed by `/api/info`; nothing outside the folder is.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn report_folders_are_served_and_nothing_outside_them() {
    let root = std::env::temp_dir().join(format!("console_reports_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let dir = root.join("sim");
    std::fs::create_dir_all(dir.join("sub")).unwrap();
    std::fs::write(root.join("secret.txt"), "outside").unwrap();
    let mut r = hal_sim::report::Report::start("test report");
    std::fs::write(
        dir.join("sub/a b.svg"),
        "<svg xmlns=\"http://www.w3.org/2000/svg\"/>",
    )
    .unwrap();
    r.section("plots").plot("sub/a b.svg");
    r.write(&dir).unwrap();

    let listener = hal_sim::console::bind("127.0.0.1:0".parse().unwrap())
        .await
        .unwrap();
    let addr = listener.local_addr().unwrap();
    let work = root.join("work");
    tokio::spawn(hal_sim::console::serve(
        listener,
        conn(&spawn_firmware(None)),
        work,
        vec![dir.clone()],
    ));

    let (status, mime, body) = get(addr, "/api/info").await;
    assert!(status.contains("200"), "{status}");
    let info: Value = serde_json::from_str(&body).unwrap();
    assert_eq!(info["reports"][0]["url"], "/reports/0/");
    assert_eq!(info["reports"][0]["dir"], dir.display().to_string());
    assert!(mime.starts_with("application/json"), "{mime}");

    let (status, mime, body) = get(addr, "/reports/0/").await;
    assert!(status.contains("200"), "{status}");
    assert!(mime.starts_with("text/html"), "{mime}");
    assert!(body.contains("<h1>test report</h1>") && body.contains("src=\"sub/a%20b.svg\""));
    // The page's relative link, resolved against /reports/0/.
    let (status, mime, body) = get(addr, "/reports/0/sub/a%20b.svg").await;
    assert!(status.contains("200"), "{status}");
    assert_eq!(mime, "image/svg+xml");
    assert!(body.starts_with("<svg"));

    for bad in [
        "/reports/0/..%2Fsecret.txt",
        "/reports/0/sub/..%2F..%2Fsecret.txt",
    ] {
        let (status, _, body) = get(addr, bad).await;
        assert!(status.contains("400"), "{bad}: {status}");
        assert!(!body.contains("outside"), "{bad}");
    }
    let (status, _, _) = get(addr, "/reports/1/").await;
    assert!(status.contains("404"), "{status}");
    let _ = std::fs::remove_dir_all(&root);
}
