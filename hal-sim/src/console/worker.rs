//! The one thread that owns the link to the firmware. Every request of every page is a job
//! run here whole, one after the other, so two tabs never interleave half-commands; between
//! jobs it runs the scope's captures. A link that closes, times out or fails is dropped,
//! shown on every page, and opened again once a second.
use std::collections::VecDeque;
use std::io;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Result};
use piezo_core::command::{Command, RecCmd};
use piezo_core::recorder::Signal;
use serde::Serialize;
use serde_json::{json, Value};
use tokio::sync::{broadcast, oneshot};

use crate::cli::serial::record::parse_trigger;
use crate::cli::serial::recording::{signal_unit, Recording};
use crate::cli::serial::{open_link, Conn};
use crate::serial::bulk::read_bin;
use crate::serial::{Client, Link, SerialError};

/// Work for the link's thread: runs on the connected client, answers JSON.
pub type JobFn = Box<dyn FnOnce(&mut Client) -> Result<Value> + Send>;

struct Job {
    run: JobFn,
    reply: oneshot::Sender<Result<Value>>,
}

/// What the scope captures; the pages change it, the link's thread applies it.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct ScopeCfg {
    pub running: bool,
    /// Recorder signals (the firmware records 4).
    pub signals: Vec<String>,
    /// Frames per capture (`rec len`).
    pub frames: usize,
    /// Record every n-th control period (`rec div`).
    pub every: usize,
    /// `now` or `rise|fall|level:<signal>:<level>` (as `piezo serial record --trigger`).
    pub trigger: String,
    /// Frames kept before the trigger.
    pub pre: usize,
}

impl Default for ScopeCfg {
    fn default() -> Self {
        Self {
            running: true,
            signals: ["ref_um", "y_um", "error_um", "u_volts"]
                .map(String::from)
                .to_vec(),
            frames: 256,
            every: 4,
            trigger: "now".into(),
            pre: 0,
        }
    }
}

impl ScopeCfg {
    /// Refuses what the recorder would refuse, before anything is sent.
    pub fn check(&self) -> Result<Vec<Signal>> {
        if self.signals.is_empty() || self.signals.len() > 4 {
            bail!("1 to 4 signals, got {}", self.signals.len());
        }
        let signals = self
            .signals
            .iter()
            .map(|n| {
                Signal::from_name(n).ok_or_else(|| {
                    anyhow!(
                        "unknown signal `{n}`; one of {}",
                        Signal::ALL.map(|s| s.name()).join(", ")
                    )
                })
            })
            .collect::<Result<Vec<_>>>()?;
        if !(16..=8192).contains(&self.frames) {
            bail!("frames per capture: 16 to 8192, got {}", self.frames);
        }
        if !(1..=1000).contains(&self.every) {
            bail!("every: 1 to 1000 control periods, got {}", self.every);
        }
        parse_trigger(&self.trigger, &self.signals, self.pre)?;
        if self.pre >= self.frames {
            bail!("pre {} is not below the {} frames", self.pre, self.frames);
        }
        Ok(signals)
    }
}

/// The lines the console sent (every one, counted; the last ones kept for the page).
#[derive(Debug, Default, Serialize)]
pub struct Wire {
    pub sent: u64,
    /// `set` and `cbw` lines sent: what can change a setting.
    pub sets: u64,
    pub last: VecDeque<String>,
}

/// A [`Link`] that logs the lines it sends into [`Wire`].
struct Logged {
    inner: Box<dyn Link>,
    wire: Arc<Mutex<Wire>>,
}

impl Link for Logged {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        {
            let mut w = self.wire.lock().unwrap_or_else(|e| e.into_inner());
            for l in String::from_utf8_lossy(bytes).split('\n') {
                if l.is_empty() {
                    continue;
                }
                w.sent += 1;
                if l.starts_with("set ") || l.starts_with("cbw ") {
                    w.sets += 1;
                }
                // Recorder polling is most of the traffic; the page wants the commands.
                if !(l.starts_with("rec ") || l == "stats" || l == "fault") {
                    if w.last.len() >= 200 {
                        w.last.pop_front();
                    }
                    w.last.push_back(l.to_string());
                }
            }
        }
        self.inner.send(bytes)
    }
    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        self.inner.recv(buf, timeout)
    }
}

/// Shortest time between two scope updates of one capture while it fills (at most 33 per
/// second); a finished capture goes out at once.
const UPDATE_EVERY: Duration = Duration::from_millis(30);

/// One scope capture (finished, or as far as it was streamed), kept for the CSV export.
pub struct Capture {
    pub seq: u64,
    pub rec: Recording,
}

/// What the server and the link's thread share.
pub struct Shared {
    pub scope: Mutex<ScopeCfg>,
    /// Bumped on every scope change so the thread applies it.
    pub scope_version: AtomicUsize,
    pub wire: Arc<Mutex<Wire>>,
    /// `connected` and why not.
    pub link: Mutex<(bool, String)>,
    /// The last captures (newest last).
    pub captures: Mutex<VecDeque<Arc<Capture>>>,
    /// Events for every page, as JSON text.
    pub events: broadcast::Sender<Arc<str>>,
    /// Jobs sent but not yet taken: a scope capture waiting for its trigger gives way.
    pending: AtomicUsize,
    jobs: Mutex<mpsc::Sender<Job>>,
}

impl Shared {
    /// Sends an event to every page.
    pub fn event(&self, v: Value) {
        let _ = self.events.send(Arc::from(v.to_string()));
    }

    /// Runs `f` on the link's thread after the jobs before it; its result.
    pub async fn job(&self, f: JobFn) -> Result<Value> {
        let (tx, rx) = oneshot::channel();
        self.pending.fetch_add(1, Ordering::SeqCst);
        let sent = self
            .jobs
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .send(Job { run: f, reply: tx });
        if sent.is_err() {
            self.pending.fetch_sub(1, Ordering::SeqCst);
            bail!("the link's thread has ended");
        }
        rx.await
            .map_err(|_| anyhow!("the link's thread dropped the request"))?
    }

    fn set_link(&self, up: bool, detail: String) {
        let mut l = self.link.lock().unwrap_or_else(|e| e.into_inner());
        if *l != (up, detail.clone()) {
            *l = (up, detail.clone());
            drop(l);
            self.event(json!({"type": "link", "connected": up, "detail": detail}));
        }
    }
}

/// Whether `e` means the link is gone or out of step (closed, I/O error, no reply in time):
/// it is dropped and opened again.
pub fn link_lost(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        matches!(
            c.downcast_ref::<SerialError>(),
            Some(SerialError::Closed { .. } | SerialError::Io { .. } | SerialError::Timeout { .. })
        )
    })
}

/// Starts the link's thread for `conn`.
pub fn spawn(conn: Conn) -> Arc<Shared> {
    let (tx, rx) = mpsc::channel();
    let (events, _) = broadcast::channel(64);
    let shared = Arc::new(Shared {
        scope: Mutex::new(ScopeCfg::default()),
        scope_version: AtomicUsize::new(1),
        wire: Arc::default(),
        link: Mutex::new((false, "connecting".into())),
        captures: Mutex::new(VecDeque::new()),
        events,
        pending: AtomicUsize::new(0),
        jobs: Mutex::new(tx),
    });
    let s = shared.clone();
    std::thread::Builder::new()
        .name("link".into())
        .spawn(move || run(conn, &s, rx))
        .expect("spawning the link's thread");
    shared
}

fn connect(conn: &Conn, wire: &Arc<Mutex<Wire>>) -> Result<Client> {
    let timeout = Duration::from_secs_f64(conn.timeout_s);
    let link = Logged {
        inner: open_link(conn, timeout)?,
        wire: wire.clone(),
    };
    let mut c = Client::new(Box::new(link), timeout);
    c.sync().map_err(|e| anyhow!("no answer to ping: {e}"))?;
    Ok(c)
}

/// The scope as the thread applied it.
#[derive(Default)]
struct ScopeRun {
    /// The [`Shared::scope_version`] applied (0: none).
    applied: usize,
    cfg: Option<ScopeCfg>,
    channels: Vec<String>,
    frame_hz: f64,
    seq: u64,
    /// Capture times of the last second, for the update rate shown.
    times: VecDeque<Instant>,
    /// An error was shown; cleared with the next capture.
    failed: bool,
}

fn run(conn: Conn, shared: &Shared, rx: mpsc::Receiver<Job>) {
    let mut client: Option<Client> = None;
    let mut scope = ScopeRun::default();
    let mut next_try = Instant::now();
    let mut next_fault = Instant::now();
    loop {
        if client.is_none() && Instant::now() >= next_try {
            match connect(&conn, &shared.wire) {
                Ok(c) => {
                    client = Some(c);
                    scope.applied = 0;
                    shared.set_link(true, where_(&conn));
                }
                Err(e) => {
                    shared.set_link(false, format!("{}: {e:#}", where_(&conn)));
                    next_try = Instant::now() + Duration::from_secs(1);
                }
            }
        }
        let scope_on = client.is_some()
            && shared
                .scope
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .running;
        let job = if scope_on {
            match rx.try_recv() {
                Ok(j) => Some(j),
                Err(mpsc::TryRecvError::Empty) => None,
                Err(mpsc::TryRecvError::Disconnected) => return,
            }
        } else {
            match rx.recv_timeout(Duration::from_millis(100)) {
                Ok(j) => Some(j),
                Err(mpsc::RecvTimeoutError::Timeout) => None,
                Err(mpsc::RecvTimeoutError::Disconnected) => return,
            }
        };
        if let Some(job) = job {
            shared.pending.fetch_sub(1, Ordering::SeqCst);
            let r = match client.as_mut() {
                Some(c) => (job.run)(c),
                None => Err(anyhow!(
                    "not connected to the firmware ({})",
                    shared.link.lock().unwrap_or_else(|e| e.into_inner()).1
                )),
            };
            if let Err(e) = &r {
                if client.is_some() && link_lost(e) {
                    client = None;
                    shared.set_link(false, format!("connection lost: {e:#}"));
                }
            }
            // A job may have changed the recorder (bode, identify): select again.
            scope.applied = 0;
            let _ = job.reply.send(r);
            continue;
        }
        let Some(c) = client.as_mut() else { continue };
        if Instant::now() >= next_fault {
            next_fault = Instant::now() + Duration::from_secs(1);
            // The fault, and the deadlines with it (overruns, lost samples, late starts,
            // NMPC's missed plans).
            let polled = c
                .send(&Command::Fault)
                .map(|r| shared.event(json!({"type": "fault", "detail": r.details})))
                .and_then(|()| c.stats())
                .map(|s| shared.event(json!({"type": "timing", "stats": s})));
            if let Err(e) = polled {
                let e = anyhow::Error::from(e);
                if link_lost(&e) {
                    client = None;
                    shared.set_link(false, format!("connection lost: {e:#}"));
                }
                continue;
            }
        }
        if scope_on {
            if let Err(e) = scope_step(c, shared, &mut scope) {
                if link_lost(&e) {
                    client = None;
                    shared.set_link(false, format!("connection lost: {e:#}"));
                } else {
                    // Shown once; the thread waits for a change of the scope or a job.
                    shared.event(
                        json!({"type": "scope", "state": "error", "detail": format!("{e:#}")}),
                    );
                    scope.failed = true;
                    scope.applied = usize::MAX;
                    let mut cfg = shared.scope.lock().unwrap_or_else(|e| e.into_inner());
                    cfg.running = false;
                    shared.event(json!({"type": "scope_cfg", "cfg": cfg.clone()}));
                }
            }
        }
    }
}

fn where_(conn: &Conn) -> String {
    match (&conn.port, &conn.tcp) {
        (Some(p), _) => format!("{p} at {} Bd", conn.baud),
        (_, Some(a)) => format!("tcp {a}"),
        _ => "nowhere".into(),
    }
}

/// One capture: apply a changed configuration, arm, wait (giving way to a job), read it
/// over `rec bin` and send it to the pages.
fn scope_step(c: &mut Client, shared: &Shared, run: &mut ScopeRun) -> Result<()> {
    let version = shared.scope_version.load(Ordering::SeqCst);
    if run.applied != version {
        let cfg = shared
            .scope
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone();
        let signals = cfg.check()?;
        c.send(&Command::Rec(RecCmd::Stop))?;
        let channels = c.rec_select(&signals)?;
        let trig = parse_trigger(&cfg.trigger, &channels, cfg.pre)?;
        c.send(&Command::Rec(RecCmd::Trigger(trig)))?;
        c.send(&Command::Rec(RecCmd::Divider(Some(cfg.every))))?;
        c.send(&Command::Rec(RecCmd::Length(Some(cfg.frames))))?;
        run.frame_hz = c.get("sample_hz")? / cfg.every as f64;
        run.channels = channels;
        run.cfg = Some(cfg);
        run.applied = version;
    }
    let Some(cfg) = run.cfg.clone() else {
        return Ok(());
    };
    c.send(&Command::Rec(RecCmd::Arm))?;
    run.seq += 1;
    let units: Vec<&str> = run
        .channels
        .iter()
        .map(|n| Signal::from_name(n).map_or("?", signal_unit))
        .collect();
    let mut told_armed = false;
    // Streamed: from the trigger on, the frames in place are read while the capture fills
    // (`rec bin` takes them; they do not change until the next arm), at most one update per
    // UPDATE_EVERY; the last part goes out as soon as the capture is done.
    let mut frames: Vec<Vec<f64>> = Vec::with_capacity(cfg.frames);
    let mut last_update: Option<Instant> = None;
    loop {
        if shared.pending.load(Ordering::SeqCst) > 0
            || shared.scope_version.load(Ordering::SeqCst) != version
        {
            // A job or a new configuration goes first; this capture is dropped.
            c.send(&Command::Rec(RecCmd::Stop))?;
            return Ok(());
        }
        let (state, n) = c.rec_status()?;
        let readable = match state.as_str() {
            "done" | "triggered" => n,
            "idle" => bail!("the recorder went idle without a capture (stopped by someone else?)"),
            "armed" if !told_armed => {
                told_armed = true;
                shared.event(json!({"type": "scope", "state": "armed", "detail": format!("waiting for the trigger {}", cfg.trigger)}));
                0
            }
            _ => 0,
        };
        let done = state == "done";
        let due = last_update.is_none_or(|t| t.elapsed() >= UPDATE_EVERY);
        if readable > frames.len() && (done || due) {
            let from = frames.len();
            let (more, _) = read_bin(c, from, readable - from, run.channels.len())?;
            frames.extend(more);
            let complete = done && frames.len() >= readable;
            let now = Instant::now();
            last_update = Some(now);
            run.times.push_back(now);
            while run
                .times
                .front()
                .is_some_and(|t| now.duration_since(*t) > Duration::from_secs(1))
            {
                run.times.pop_front();
            }
            let columns: Vec<Vec<f64>> = (0..run.channels.len())
                .map(|k| {
                    frames[from..]
                        .iter()
                        .map(|f| f.get(k).copied().unwrap_or(f64::NAN))
                        .collect()
                })
                .collect();
            // The export takes what the page shows: the capture so far, replaced as it grows;
            // stored before the page hears of it (an export right after an event has its frames).
            let rec = Recording {
                channels: run.channels.clone(),
                sample_hz: run.frame_hz,
                pre: cfg.pre,
                trigger: cfg.trigger.clone(),
                frames: frames.clone(),
            };
            {
                let mut caps = shared.captures.lock().unwrap_or_else(|e| e.into_inner());
                if caps.back().is_some_and(|c| c.seq == run.seq) {
                    caps.pop_back();
                }
                if caps.len() >= 16 {
                    caps.pop_front();
                }
                caps.push_back(Arc::new(Capture { seq: run.seq, rec }));
            }
            shared.event(json!({
                "type": "frame",
                "seq": run.seq,
                "channels": run.channels,
                "units": units,
                "sample_hz": run.frame_hz,
                "pre": cfg.pre,
                "trigger": cfg.trigger,
                "from": from,
                "total": cfg.frames,
                "complete": complete,
                "columns": columns,
                "updates_per_s": run.times.len(),
            }));
            if run.failed {
                run.failed = false;
                shared.event(json!({"type": "scope", "state": "running", "detail": ""}));
            }
        }
        if done && frames.len() >= readable {
            return Ok(());
        }
        std::thread::sleep(Duration::from_millis(1));
    }
}
