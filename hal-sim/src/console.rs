//! The lab console behind `piezo ui`: a local web server (axum on tokio) whose page shows the
//! recorder as a live scope and drives the settings, the mode, the waveform, Stop and the
//! tools (bode, identify, diagnose).
//!
//! * [`worker`]: the one thread that owns the link ([`crate::serial::Client`], as `piezo
//!   serial` opens it): every request is a job run whole there, so pages cannot interleave
//!   half-commands; between jobs it runs the scope's captures (`rec bin`); a lost link is
//!   shown and opened again.
//! * [`jobs`]: what the buttons do, through `piezo serial`'s own code (settings check,
//!   `bode`, `identify`).
//! * The page (`console/assets/`) is compiled into the binary, with uPlot (MIT, vendored
//!   with its licence) for the plots: it works without network.
pub mod jobs;
pub mod worker;

use std::net::SocketAddr;
use std::path::{Component, Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use anyhow::{Context, Result};
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Path as UrlPath, Query, State};
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde::Deserialize;
use serde_json::{json, Value};

use worker::{link_lost, ScopeCfg, Shared};

/// The page and its scripts, inside the binary.
const ASSETS: [(&str, &str, &str); 6] = [
    (
        "/",
        "text/html; charset=utf-8",
        include_str!("console/assets/index.html"),
    ),
    (
        "/app.js",
        "text/javascript; charset=utf-8",
        include_str!("console/assets/app.js"),
    ),
    (
        "/style.css",
        "text/css; charset=utf-8",
        include_str!("console/assets/style.css"),
    ),
    (
        "/uPlot.iife.min.js",
        "text/javascript; charset=utf-8",
        include_str!("console/assets/uPlot.iife.min.js"),
    ),
    (
        "/uPlot.min.css",
        "text/css; charset=utf-8",
        include_str!("console/assets/uPlot.min.css"),
    ),
    (
        "/uPlot-LICENSE.txt",
        "text/plain; charset=utf-8",
        include_str!("console/assets/uPlot-LICENSE.txt"),
    ),
];

/// The server's state: the link's thread and a folder for the tools' files.
#[derive(Clone)]
pub struct App {
    shared: Arc<Shared>,
    work: Arc<PathBuf>,
    runs: Arc<AtomicU64>,
    exe: Arc<PathBuf>,
    conn: Arc<String>,
    /// Report folders (`--out` of sim, demo, fit, diagnose) served below `/reports/<n>/`.
    reports: Arc<Vec<PathBuf>>,
}

/// Serves the console on `listener` until the process ends; `reports` are folders with an
/// `index.html` ([`crate::report`]) the page links.
pub async fn serve(
    listener: tokio::net::TcpListener,
    conn: crate::cli::serial::Conn,
    work: PathBuf,
    reports: Vec<PathBuf>,
) -> Result<()> {
    std::fs::create_dir_all(&work).with_context(|| format!("creating {}", work.display()))?;
    let describe = match (&conn.port, &conn.tcp) {
        (Some(p), _) => format!("{p} at {} Bd", conn.baud),
        (_, Some(a)) => format!("tcp {a}"),
        _ => String::new(),
    };
    let app = App {
        shared: worker::spawn(conn),
        work: Arc::new(work),
        runs: Arc::default(),
        exe: Arc::new(std::env::current_exe().context("the console's own executable")?),
        conn: Arc::new(describe),
        reports: Arc::new(reports),
    };
    let mut router = Router::new();
    for (path, mime, body) in ASSETS {
        router = router.route(
            path,
            get(move || async move { ([(header::CONTENT_TYPE, mime)], body) }),
        );
    }
    let router = router
        .route("/ws", get(ws))
        .route("/api/info", get(info))
        .route("/api/settings", get(settings))
        .route("/api/set", post(set))
        .route("/api/flash", post(flash))
        .route("/api/settings/file", get(settings_file).post(restore))
        .route("/api/mode", post(mode))
        .route("/api/wave", post(wave))
        .route("/api/stop", post(stop))
        .route("/api/raw", post(raw))
        .route("/api/scope", get(scope_get).post(scope_set))
        .route("/api/scope/csv", get(scope_csv))
        .route("/api/bode", post(bode))
        .route("/api/identify", post(identify))
        .route("/api/diagnose", post(diagnose))
        .route("/api/wire", get(wire))
        .route("/files/{*path}", get(file))
        .route("/reports/{n}/", get(report_index))
        .route("/reports/{n}/{*path}", get(report_file))
        .with_state(app);
    axum::serve(listener, router)
        .await
        .context("the console's server")
}

type Reply = (StatusCode, Json<Value>);

fn ok(v: Value) -> Reply {
    (StatusCode::OK, Json(v))
}

/// Refused on the host: nothing was sent.
fn refused(why: impl std::fmt::Display) -> Reply {
    (
        StatusCode::BAD_REQUEST,
        Json(json!({"error": why.to_string(), "sent": false})),
    )
}

/// A job's result: the firmware's refusal (422, with `err N`), a lost link (503), or
/// another failure (500).
fn answer(r: Result<Value>) -> Reply {
    match r {
        Ok(v) => ok(v),
        Err(e) => {
            let body = jobs::refusal(&e);
            let status = if body.get("code").is_some() {
                StatusCode::UNPROCESSABLE_ENTITY
            } else if link_lost(&e) || format!("{e}").starts_with("not connected") {
                StatusCode::SERVICE_UNAVAILABLE
            } else {
                StatusCode::INTERNAL_SERVER_ERROR
            };
            (status, Json(body))
        }
    }
}

async fn ws(State(app): State<App>, up: WebSocketUpgrade) -> Response {
    up.on_upgrade(move |socket| events(app, socket))
}

/// Sends every event to one page: first the link's state and the scope's settings.
async fn events(app: App, mut socket: WebSocket) {
    let mut rx = app.shared.events.subscribe();
    let (up, detail) = app
        .shared
        .link
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .clone();
    let cfg = app
        .shared
        .scope
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .clone();
    for v in [
        json!({"type": "link", "connected": up, "detail": detail}),
        json!({"type": "scope_cfg", "cfg": cfg}),
    ] {
        if socket
            .send(Message::Text(v.to_string().into()))
            .await
            .is_err()
        {
            return;
        }
    }
    loop {
        tokio::select! {
            ev = rx.recv() => match ev {
                Ok(text) => {
                    if socket.send(Message::Text(text.as_ref().into())).await.is_err() {
                        return;
                    }
                }
                // A slow page misses frames, not the connection.
                Err(tokio::sync::broadcast::error::RecvError::Lagged(_)) => {}
                Err(_) => return,
            },
            msg = socket.recv() => match msg {
                Some(Ok(_)) => {}
                _ => return,
            },
        }
    }
}

async fn info(State(app): State<App>) -> Reply {
    use piezo_core::firmware::{FFS, LAWS};
    use piezo_core::recorder::Signal;
    ok(json!({
        "table": jobs::table(),
        "laws": LAWS.iter().copied().chain(["feedforward"]).collect::<Vec<_>>(),
        "ffs": FFS,
        "signals": Signal::ALL.map(|s| s.name()),
        "conn": *app.conn,
        "reports": app.reports.iter().enumerate().map(|(n, d)| json!({
            "dir": d.display().to_string(),
            "url": format!("/reports/{n}/"),
        })).collect::<Vec<_>>(),
        "version": env!("CARGO_PKG_VERSION"),
    }))
}

async fn settings(State(app): State<App>) -> Reply {
    answer(app.shared.job(Box::new(jobs::settings)).await)
}

#[derive(Deserialize)]
struct SetReq {
    name: String,
    value: f64,
}

async fn set(State(app): State<App>, Json(r): Json<SetReq>) -> Reply {
    // The settings table decides before anything is sent.
    let name = match jobs::check_setting(&r.name, r.value) {
        Ok(n) => n,
        Err(why) => return refused(why),
    };
    let v = r.value;
    answer(
        app.shared
            .job(Box::new(move |c| jobs::set(c, name, v)))
            .await,
    )
}

#[derive(Deserialize)]
struct OpReq {
    op: String,
}

async fn flash(State(app): State<App>, Json(r): Json<OpReq>) -> Reply {
    answer(
        app.shared
            .job(Box::new(move |c| jobs::flash(c, &r.op)))
            .await,
    )
}

async fn settings_file(State(app): State<App>) -> Reply {
    answer(app.shared.job(Box::new(jobs::settings_file)).await)
}

async fn restore(State(app): State<App>, body: String) -> Reply {
    let all = match crate::cli::serial::params::parse_settings(&body, "the settings file") {
        Ok(a) => a,
        Err(e) => return refused(format!("{e:#}")),
    };
    answer(
        app.shared
            .job(Box::new(move |c| jobs::restore(c, all)))
            .await,
    )
}

#[derive(Deserialize)]
struct ModeReq {
    law: String,
    ff: Option<String>,
}

async fn mode(State(app): State<App>, Json(r): Json<ModeReq>) -> Reply {
    answer(
        app.shared
            .job(Box::new(move |c| jobs::mode(c, &r.law, r.ff.as_deref())))
            .await,
    )
}

async fn wave(State(app): State<App>, Json(w): Json<jobs::Wave>) -> Reply {
    // The firmware's own parser checks the line before it is sent.
    if let Err(e) = crate::serial::lines::checked_line(&w.command()) {
        return refused(e);
    }
    answer(app.shared.job(Box::new(move |c| jobs::wave(c, &w))).await)
}

async fn stop(State(app): State<App>) -> Reply {
    answer(app.shared.job(Box::new(jobs::stop)).await)
}

#[derive(Deserialize)]
struct RawReq {
    line: String,
}

async fn raw(State(app): State<App>, Json(r): Json<RawReq>) -> Reply {
    answer(
        app.shared
            .job(Box::new(move |c| jobs::raw(c, &r.line)))
            .await,
    )
}

async fn scope_get(State(app): State<App>) -> Reply {
    let cfg = app
        .shared
        .scope
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .clone();
    ok(json!(cfg))
}

async fn scope_set(State(app): State<App>, Json(cfg): Json<ScopeCfg>) -> Reply {
    if let Err(e) = cfg.check() {
        return refused(format!("{e:#}"));
    }
    *app.shared.scope.lock().unwrap_or_else(|e| e.into_inner()) = cfg.clone();
    app.shared.scope_version.fetch_add(1, Ordering::SeqCst);
    app.shared
        .event(json!({"type": "scope_cfg", "cfg": cfg.clone()}));
    ok(json!(cfg))
}

#[derive(Deserialize)]
struct SeqReq {
    seq: Option<u64>,
}

/// A capture the page showed, as `piezo serial record` writes it.
async fn scope_csv(State(app): State<App>, Query(q): Query<SeqReq>) -> Response {
    let caps = app
        .shared
        .captures
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    let cap = match q.seq {
        Some(s) => caps.iter().find(|c| c.seq == s),
        None => caps.back(),
    };
    match cap {
        Some(c) => (
            [
                (header::CONTENT_TYPE, "text/csv; charset=utf-8".to_string()),
                (
                    header::CONTENT_DISPOSITION,
                    format!("attachment; filename=\"scope-{}.csv\"", c.seq),
                ),
            ],
            c.rec.csv(),
        )
            .into_response(),
        None => refused("no such capture (only the last 16 are kept)").into_response(),
    }
}

async fn bode(State(app): State<App>, Json(r): Json<jobs::BodeReq>) -> Reply {
    let a = match r.args() {
        Ok(a) => a,
        Err(e) => return refused(format!("{e:#}")),
    };
    app.shared
        .event(json!({"type": "progress", "tool": "bode", "line": "bode: measuring"}));
    let frames = r.frames.unwrap_or(1024);
    answer(
        app.shared
            .job(Box::new(move |c| jobs::bode(c, &a, frames)))
            .await,
    )
}

async fn identify(State(app): State<App>) -> Reply {
    let n = app.runs.fetch_add(1, Ordering::SeqCst);
    let dir = app.work.join(format!("identify-{n}"));
    let shared = app.shared.clone();
    let rel = format!("identify-{n}");
    let r = app
        .shared
        .job(Box::new(move |c| {
            let s = shared.clone();
            let progress = Box::new(move |line: &str| {
                s.event(json!({"type": "progress", "tool": "identify", "line": line}));
            });
            jobs::identify(c, dir, progress)
        }))
        .await;
    let mut reply = answer(r);
    if reply.0 == StatusCode::OK {
        (reply.1).0["files"] = json!(files_in(&app.work, &rel));
    }
    reply
}

#[derive(Deserialize)]
struct DiagnoseReq {
    /// Diagnose a scope capture (its sequence number) instead of the uploaded body.
    seq: Option<u64>,
}

/// `piezo diagnose` on an uploaded record (the body) or a scope capture, run as this
/// binary's own subcommand beside the link (it needs no firmware).
async fn diagnose(State(app): State<App>, Query(q): Query<DiagnoseReq>, body: String) -> Reply {
    let text = match q.seq {
        Some(s) => {
            let caps = app
                .shared
                .captures
                .lock()
                .unwrap_or_else(|e| e.into_inner());
            match caps.iter().find(|c| c.seq == s) {
                Some(c) => c.rec.csv(),
                None => return refused("no such capture (only the last 16 are kept)"),
            }
        }
        None => body,
    };
    if text.trim().is_empty() {
        return refused("no record: upload a CSV file or pick a capture");
    }
    let n = app.runs.fetch_add(1, Ordering::SeqCst);
    let rel = format!("diagnose-{n}");
    let dir = app.work.join(&rel);
    if let Err(e) = std::fs::create_dir_all(&dir) {
        return answer(Err(e.into()));
    }
    let record = dir.join("record.csv");
    if let Err(e) = std::fs::write(&record, text) {
        return answer(Err(e.into()));
    }
    let out = tokio::process::Command::new(&*app.exe)
        .arg("diagnose")
        .arg("--train")
        .arg(&record)
        .arg("--out")
        .arg(&dir)
        .output()
        .await;
    match out {
        Ok(o) => {
            let report = String::from_utf8_lossy(&o.stdout).into_owned();
            let err = String::from_utf8_lossy(&o.stderr).into_owned();
            if o.status.success() {
                ok(json!({"report": report, "stderr": err, "files": files_in(&app.work, &rel)}))
            } else {
                (
                    StatusCode::UNPROCESSABLE_ENTITY,
                    Json(
                        json!({"error": format!("piezo diagnose failed: {}", err.trim()), "report": report}),
                    ),
                )
            }
        }
        Err(e) => answer(Err(e.into())),
    }
}

async fn wire(State(app): State<App>) -> Reply {
    let w = app.shared.wire.lock().unwrap_or_else(|e| e.into_inner());
    ok(serde_json::to_value(&*w).unwrap_or(Value::Null))
}

/// The files a tool wrote under `work/rel`, as paths below `/files/`.
fn files_in(work: &Path, rel: &str) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(work.join(rel))
        .map(|d| {
            d.filter_map(|e| e.ok())
                .filter(|e| e.path().is_file())
                .map(|e| format!("{rel}/{}", e.file_name().to_string_lossy()))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// A file the tools wrote (only below the console's folder).
async fn file(State(app): State<App>, UrlPath(path): UrlPath<String>) -> Response {
    file_below(&app.work, &path)
}

/// A report's page.
async fn report_index(State(app): State<App>, UrlPath(n): UrlPath<usize>) -> Response {
    match app.reports.get(n) {
        Some(dir) => file_below(dir, crate::report::INDEX),
        None => (StatusCode::NOT_FOUND, "no such report").into_response(),
    }
}

/// A file of a report folder (its page links them relatively).
async fn report_file(
    State(app): State<App>,
    UrlPath((n, path)): UrlPath<(usize, String)>,
) -> Response {
    match app.reports.get(n) {
        Some(dir) => file_below(dir, &path),
        None => (StatusCode::NOT_FOUND, "no such report").into_response(),
    }
}

/// `root/rel`, for a relative path of plain names only (no `..`, no root).
fn file_below(root: &Path, rel: &str) -> Response {
    let rel = Path::new(rel);
    if !rel.components().all(|c| matches!(c, Component::Normal(_))) {
        return refused("not a file of the console").into_response();
    }
    let p = root.join(rel);
    let mime = match p.extension().and_then(|e| e.to_str()) {
        Some("svg") => "image/svg+xml",
        Some("csv") | Some("txt") => "text/plain; charset=utf-8",
        Some("json") => "application/json",
        Some("html") => "text/html; charset=utf-8",
        Some("png") => "image/png",
        _ => "application/octet-stream",
    };
    match std::fs::read(&p) {
        Ok(bytes) => ([(header::CONTENT_TYPE, mime)], bytes).into_response(),
        Err(_) => (StatusCode::NOT_FOUND, "no such file").into_response(),
    }
}

/// Binds `addr`; a non-loopback address gets a warning (the console has no login).
pub async fn bind(addr: SocketAddr) -> Result<tokio::net::TcpListener> {
    if !addr.ip().is_loopback() {
        eprintln!(
            "warning: the console listens on {addr}: anyone who reaches this address can \
             drive the stage (there is no login)"
        );
    }
    tokio::net::TcpListener::bind(addr)
        .await
        .with_context(|| format!("cannot listen on {addr}"))
}
