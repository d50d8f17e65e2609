//! The lab console in a real browser: drives headless Chromium through chromedriver
//! (WebDriver) against a running `piezo ui` and checks what a person would see. Run by
//! `.ci/test.d/56-ui.sh` against the QEMU firmware:
//!
//! ```text
//! cargo run -p hal-sim --example ui_browser -- --ui http://127.0.0.1:8080/ \
//!     --webdriver http://127.0.0.1:9515 --out out/ui [--resonance-hz 2500] \
//!     [--kill-pid <qemu>] [--report "piezo demo: hysteresis loops"]
//! ```
//!
//! Every wait is on a condition of the page (its `window.consoleState`, an element's text),
//! polled; `--timeout-s` only caps a run whose emulator or server stopped.
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use fantoccini::{Client, ClientBuilder, Locator};
use serde_json::{json, Value};

struct Opts {
    ui: String,
    webdriver: String,
    out: PathBuf,
    chromium: String,
    resonance_hz: Option<f64>,
    safe_code: f64,
    timeout: Duration,
    /// The emulator's process: ended at the end to see the page show the lost link.
    kill_pid: Option<u32>,
    /// The title of the report `piezo ui --report` was given (opened from the Tools tab).
    report: Option<String>,
    /// The stage differs from the firmware's model (`stage` harness line): identify from the
    /// Tools tab must cut the tracking error three times.
    identify: bool,
}

fn opts() -> Result<Opts> {
    let mut o = Opts {
        ui: String::new(),
        webdriver: "http://127.0.0.1:9515".into(),
        out: "out/ui".into(),
        chromium: "/usr/bin/chromium".into(),
        resonance_hz: None,
        safe_code: 0.0,
        timeout: Duration::from_secs(600),
        kill_pid: None,
        report: None,
        identify: false,
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut v = || args.next().ok_or_else(|| anyhow!("{a} needs a value"));
        match a.as_str() {
            "--ui" => o.ui = v()?,
            "--webdriver" => o.webdriver = v()?,
            "--out" => o.out = v()?.into(),
            "--chromium" => o.chromium = v()?,
            "--resonance-hz" => o.resonance_hz = Some(v()?.parse()?),
            "--safe-code" => o.safe_code = v()?.parse()?,
            "--timeout-s" => o.timeout = Duration::from_secs_f64(v()?.parse()?),
            "--kill-pid" => o.kill_pid = Some(v()?.parse()?),
            "--report" => o.report = Some(v()?),
            "--identify" => o.identify = true,
            other => bail!("unknown argument {other}"),
        }
    }
    if o.ui.is_empty() {
        bail!("--ui <url of piezo ui> is required");
    }
    Ok(o)
}

struct Run {
    c: Client,
    out: PathBuf,
    deadline: Instant,
    passed: usize,
}

impl Run {
    /// Polls `js` (a function body returning a value) until it returns something truthy.
    async fn until(&self, what: &str, js: &str) -> Result<Value> {
        loop {
            let v = self
                .c
                .execute(js, vec![])
                .await
                .with_context(|| format!("evaluating the condition of {what}"))?;
            let truthy = match &v {
                Value::Null => false,
                Value::Bool(b) => *b,
                Value::String(s) => !s.is_empty(),
                Value::Number(n) => n.as_f64() != Some(0.0),
                _ => true,
            };
            if truthy {
                return Ok(v);
            }
            if Instant::now() > self.deadline {
                bail!("{what}: not reached before the overall timeout");
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }

    async fn click(&self, css: &str) -> Result<()> {
        self.c
            .find(Locator::Css(css))
            .await
            .with_context(|| format!("finding {css}"))?
            .click()
            .await
            .with_context(|| format!("clicking {css}"))?;
        Ok(())
    }

    async fn type_into(&self, css: &str, text: &str) -> Result<()> {
        let e = self.c.find(Locator::Css(css)).await?;
        e.clear().await?;
        e.send_keys(text).await?;
        Ok(())
    }

    async fn select(&self, css: &str, value: &str) -> Result<()> {
        self.c
            .find(Locator::Css(css))
            .await?
            .select_by_value(value)
            .await
            .with_context(|| format!("selecting {value} in {css}"))?;
        Ok(())
    }

    async fn tab(&self, name: &str) -> Result<()> {
        self.click(&format!(".tab[data-tab=\"{name}\"]")).await
    }

    async fn shot(&self, name: &str) -> Result<()> {
        let png = self.c.screenshot().await?;
        let p = self.out.join(name);
        std::fs::write(&p, png).with_context(|| format!("writing {}", p.display()))?;
        println!("ui: screenshot {}", p.display());
        Ok(())
    }

    fn pass(&mut self, what: &str) {
        self.passed += 1;
        println!("ui: ok {}: {what}", self.passed);
    }

    /// Empties a result line, so a wait on it sees the next result, not the last one.
    async fn clear(&self, id: &str) -> Result<()> {
        self.c
            .execute(
                &format!("document.getElementById('{id}').textContent = '';"),
                vec![],
            )
            .await?;
        Ok(())
    }

    /// One raw line through the console's Wire panel (the firmware's own reply).
    async fn raw(&self, line: &str) -> Result<String> {
        self.tab("wire").await?;
        self.c
            .execute("window.consoleState.lastRaw = null;", vec![])
            .await?;
        self.type_into("#raw-line", line).await?;
        self.click("#raw-send").await?;
        let v = self
            .until(
                &format!("the reply to `{line}`"),
                "const r = window.consoleState.lastRaw; return r ? r.text : null;",
            )
            .await?;
        Ok(v.as_str().unwrap_or_default().to_string())
    }

    /// The console's count of `set`/`cbw` lines it sent.
    async fn sets_sent(&self) -> Result<u64> {
        let v = self
            .c
            .execute_async(
                "const done = arguments[0]; fetch('/api/wire').then(r => r.json()).then(j => done(j.sets));",
                vec![],
            )
            .await?;
        v.as_u64().ok_or_else(|| anyhow!("/api/wire: {v}"))
    }

    /// Waits for a frame newer than `after` for which `cond` (JS over `f`, the frame event,
    /// and `col(name)`, its column) holds; returns the frame's sequence number.
    async fn frame_where(&self, what: &str, after: u64, cond: &str) -> Result<u64> {
        let js = format!(
            "const f = window.consoleState.lastFrame; if (!f || f.seq <= {after}) return null;
             const col = (n) => f.columns[f.channels.indexOf(n)];
             return ({cond}) ? f.seq : null;"
        );
        let v = self.until(what, &js).await?;
        v.as_u64().ok_or_else(|| anyhow!("{what}: {v}"))
    }

    async fn last_seq(&self) -> Result<u64> {
        Ok(self
            .c
            .execute("return window.consoleState.lastSeq;", vec![])
            .await?
            .as_u64()
            .unwrap_or(0))
    }
}

#[tokio::main(flavor = "current_thread")]
async fn main() -> Result<()> {
    let o = opts()?;
    std::fs::create_dir_all(&o.out)?;
    let profile = std::env::temp_dir().join(format!("piezo-ui-chromium-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&profile);
    let mut caps = serde_json::Map::new();
    caps.insert(
        "goog:chromeOptions".into(),
        json!({
            "binary": o.chromium,
            "args": [
                "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                "--no-first-run", "--disable-background-networking",
                "--disable-component-update", "--disable-sync",
                "--disable-dev-shm-usage", "--window-size=1400,1000",
                format!("--user-data-dir={}", profile.display()),
            ],
        }),
    );
    let c = ClientBuilder::new(hyper_util::client::legacy::connect::HttpConnector::new())
        .capabilities(caps)
        .connect(&o.webdriver)
        .await
        .with_context(|| format!("no WebDriver session at {}", o.webdriver))?;
    let mut r = Run {
        c,
        out: o.out.clone(),
        deadline: Instant::now() + o.timeout,
        passed: 0,
    };
    let result = checks(&mut r, &o).await;
    if result.is_err() {
        let _ = r.shot("failed.png").await;
    }
    let _ = r.c.clone().close().await;
    let _ = std::fs::remove_dir_all(&profile);
    result?;
    println!("ui: {} browser checks passed", r.passed);
    Ok(())
}

async fn checks(r: &mut Run, o: &Opts) -> Result<()> {
    r.c.goto(&o.ui).await?;
    r.until(
        "the console connected to the firmware",
        "return window.consoleState && window.consoleState.linkUp;",
    )
    .await?;

    // 1. The scope receives frames (and counts its updates per second).
    r.until(
        "10 scope frames",
        "return window.consoleState.frames >= 10;",
    )
    .await?;
    // The rate the page shows: updates in the last second of the server's clock. A
    // condition, not a timed wait: it holds once a second of streaming has gone by.
    let rate = r
        .until(
            "20 scope updates a second",
            "const r = window.consoleState.rate; return r >= 20 ? r : null;",
        )
        .await?;
    // And the rate 40 updates later, for the record.
    let later = r
        .until(
            "40 more scope updates",
            &format!(
                "const s = window.consoleState; return s.frames >= {} ? s.rate : null;",
                r.c.execute("return window.consoleState.frames;", vec![])
                    .await?
                    .as_u64()
                    .unwrap_or(0)
                    + 40
            ),
        )
        .await?;
    r.pass(&format!(
        "the scope receives frames: {rate} updates/s (at least 20), {later} updates/s 40 \
         updates later, at its default 256 frames, every 4th period"
    ));
    r.shot("scope.png").await?;

    // The header's timing badge: the firmware's `stats`, polled with the fault (no deadline
    // missed while the scope streamed).
    let timing = r
        .until(
            "the timing badge",
            "const t = document.getElementById('timing');
             return /^timing \\d+ overruns/.test(t.textContent) ? t.textContent + ' | ' + t.className : null;",
        )
        .await?;
    let timing = timing.as_str().unwrap_or_default().to_string();
    if !timing.starts_with("timing 0 overruns, 0 lost") || !timing.ends_with("good") {
        bail!("timing badge: `{timing}`, expected 0 overruns and 0 lost, shown good");
    }
    r.pass(&format!("the header's timing badge: `{timing}`"));

    // 2. A valid setting reaches the firmware: set in the Settings panel, read back with `get`.
    r.tab("settings").await?;
    r.type_into("#set-pid_kp", "0.75").await?;
    r.click("#setbtn-pid_kp").await?;
    r.until(
        "the reply to set pid_kp",
        "return document.getElementById('msg-pid_kp').textContent.startsWith('ok pid_kp');",
    )
    .await?;
    let back = r.raw("get pid_kp").await?;
    if back.trim() != "ok pid_kp 0.75" {
        bail!("get pid_kp after setting 0.75 answered `{back}`");
    }
    r.pass("pid_kp = 0.75 set in the Settings panel; `get pid_kp` answers `ok pid_kp 0.75`");

    // 3. An out-of-range value shows the table's range and sends nothing.
    let before = r.sets_sent().await?;
    let u_max = r.raw("get u_max").await?;
    r.tab("settings").await?;
    r.type_into("#set-u_max", "200").await?;
    r.click("#setbtn-u_max").await?;
    r.until(
        "the range error by u_max",
        "const m = document.getElementById('msg-u_max');
         return m.className === 'error' && m.textContent.includes('outside 0 .. 150');",
    )
    .await?;
    r.shot("settings-refused.png").await?;
    let after = r.sets_sent().await?;
    let u_max_after = r.raw("get u_max").await?;
    if after != before || u_max_after != u_max {
        bail!(
            "u_max = 200: {} set lines sent, u_max `{u_max}` -> `{u_max_after}`",
            after - before
        );
    }
    r.pass("u_max = 200 V is refused by the page with the table's range; no set line sent, u_max unchanged");

    // 3b. A value inside the table that the firmware refuses shows its `err N` by the field.
    r.tab("settings").await?;
    r.type_into("#set-notch_hz", "100000").await?;
    r.click("#setbtn-notch_hz").await?;
    let msg = r
        .until(
            "the firmware's refusal by notch_hz",
            "const m = document.getElementById('msg-notch_hz');
             return m.className === 'error' && m.textContent.startsWith('err ') ? m.textContent : null;",
        )
        .await?;
    r.pass(&format!(
        "notch_hz = 100 kHz (above 0.45 of the sample rate): the firmware's refusal is shown by the field: {msg}"
    ));

    // 4. A mode change is reflected.
    r.tab("mode").await?;
    r.select("#mode-law", "ff+pid").await?;
    r.select("#mode-ff", "ims-cbw").await?;
    r.click("#mode-apply").await?;
    r.until(
        "the reply to mode ff+pid",
        "return document.getElementById('mode-result').textContent.includes('ok mode ff+pid')
             && document.getElementById('hdr-mode').textContent.includes('ff+pid');",
    )
    .await?;
    r.pass("mode ff+pid with ff ims-cbw selected: `ok ff ims-cbw; ok mode ff+pid` shown and in the header");

    // A wave the firmware would refuse (60 kHz, above half the sample rate) is refused by
    // the firmware's own check run in the console: shown, and no wave line sent.
    r.tab("wave").await?;
    r.select("#wave-shape", "sine").await?;
    r.type_into("#wave-amp_um", "5").await?;
    r.type_into("#wave-freq_hz", "60000").await?;
    r.type_into("#wave-offset_um", "10").await?;
    r.clear("wave-result").await?;
    r.click("#wave-start").await?;
    let why = r
        .until(
            "the refusal of wave sine at 60 kHz",
            "const t = document.getElementById('wave-result').textContent; return t ? t : null;",
        )
        .await?;
    let why = why.as_str().unwrap_or_default().to_string();
    let went = r
        .c
        .execute_async(
            "const done = arguments[0]; fetch('/api/wire').then(r => r.json()).then(j => done(j.last.some(l => l.includes('60000'))));",
            vec![],
        )
        .await?;
    if !(why.contains("err 8") && why.contains("nothing sent")) || went != json!(false) {
        bail!("wave sine at 60 kHz: `{why}`, sent: {went}");
    }
    r.pass(&format!(
        "a 60 kHz sine is refused in the console by the firmware's own check, nothing sent: {why}"
    ));

    // 5. A sine, and the scope triggered on its start: ref_um rises through its centre at t = 0.
    r.tab("wave").await?;
    r.select("#wave-shape", "sine").await?;
    r.type_into("#wave-amp_um", "5").await?;
    r.type_into("#wave-freq_hz", "100").await?;
    r.type_into("#wave-offset_um", "10").await?;
    r.click("#wave-start").await?;
    r.until(
        "the reply to wave sine",
        "return document.getElementById('wave-result').textContent.startsWith('ok wave sine');",
    )
    .await?;
    r.select("#scope-trigger", "wave").await?;
    r.type_into("#scope-pre", "64").await?;
    r.click("#scope-apply").await?;
    let seq = r.last_seq().await?;
    r.frame_where(
        "a capture triggered on the sine's start",
        seq,
        "f.trigger === 'rise:ref_um:10' && f.pre === 64 && col('ref_um')[63] < 10 && col('ref_um')[64] >= 10",
    )
    .await?;
    r.pass("scope triggered on the wave's start: ref_um crosses 10 um rising at frame 64 (t = 0)");
    r.tab("settings").await?;
    r.click("#settings-refresh").await?;
    r.until(
        "the settings read",
        "return document.getElementById('val-sample_hz').textContent !== '?';",
    )
    .await?;
    r.shot("console.png").await?;

    // 6. Bode on the QEMU stage: the resonance's peak within +-50 Hz.
    if let Some(f_res) = o.resonance_hz {
        r.tab("tools").await?;
        r.click("#bode-run").await?;
        let f = r
            .until(
                "the Bode measurement",
                "const b = window.consoleState.bode; return b && b.resonance ? b.resonance.f_hz : null;",
            )
            .await?
            .as_f64()
            .ok_or_else(|| anyhow!("no resonance frequency"))?;
        r.until(
            "the resonance shown",
            "return document.getElementById('bode-result').textContent.includes('resonance');",
        )
        .await?;
        r.shot("bode.png").await?;
        if (f - f_res).abs() > 50.0 {
            bail!("bode: resonance at {f:.1} Hz, not within 50 Hz of {f_res} Hz");
        }
        r.click("#bode-apply").await?;
        r.until(
            "the notch applied",
            "return document.getElementById('bode-result').textContent.startsWith('notch applied');",
        )
        .await?;
        let notch = r.raw("get notch_hz").await?;
        r.pass(&format!(
            "bode: resonance at {f:.1} Hz (stage {f_res} Hz, +-50 Hz), notch applied: `{notch}`"
        ));
    }

    // Identify from the Tools tab, on a stage that differs from the firmware's model.
    if o.identify {
        r.tab("tools").await?;
        let d_before = r.raw("get cbw_d").await?;
        r.tab("tools").await?;
        r.click("#ident-run").await?;
        let text = r
            .until(
                "identify's result",
                "const t = document.getElementById('ident-result').textContent;
                 return /tracking error|error/.test(t) && !t.startsWith('running') ? t : null;",
            )
            .await?;
        let text = text.as_str().unwrap_or_default().to_string();
        let steps =
            r.c.execute(
                "return document.getElementById('ident-progress').children.length;",
                vec![],
            )
            .await?;
        r.shot("identify.png").await?;
        let nums: Vec<f64> = text
            .strip_prefix("tracking error ")
            .and_then(|t| t.split(" um after").next())
            .map(|t| {
                t.split(|c: char| !(c.is_ascii_digit() || c == '.'))
                    .filter_map(|w| w.parse().ok())
                    .collect()
            })
            .unwrap_or_default();
        let [before, after] = nums[..] else {
            bail!("identify: no `tracking error <a> um RMS before, <b> um after` in: {text}");
        };
        if !(after > 0.0 && before >= 3.0 * after) {
            bail!("identify: tracking error {before} -> {after} um, not 3x smaller");
        }
        let d_after = r.raw("get cbw_d").await?;
        if d_after == d_before {
            bail!("identify: the firmware's model did not change (`{d_after}`)");
        }
        r.pass(&format!(
            "identify from the Tools tab ({steps} progress lines): tracking error {before} -> \
             {after} um RMS, model loaded (`{d_before}` -> `{d_after}`)"
        ));
    }

    // Save to flash from the Settings panel: refused while the stage is driven (with the
    // reason), taken after Stop; a later change is undone by `load`.
    let kp = r.raw("get pid_kp").await?;
    r.tab("mode").await?;
    r.select("#mode-law", "ff+pid").await?;
    r.click("#mode-apply").await?;
    r.until(
        "mode ff+pid before save",
        "return document.getElementById('mode-result').textContent.includes('ok mode ff+pid');",
    )
    .await?;
    r.tab("settings").await?;
    r.clear("settings-result").await?;
    r.click("#flash-save").await?;
    let refused = r
        .until(
            "save refused in closed loop",
            "const t = document.getElementById('settings-result').textContent;
             return t.startsWith('save:') ? t : null;",
        )
        .await?;
    let refused = refused.as_str().unwrap_or_default().to_string();
    if !(refused.contains("err 12") && refused.contains("press STOP first")) {
        bail!("save in closed loop: `{refused}`, not err 12 with the reason");
    }
    r.clear("stop-result").await?;
    r.click("#stop").await?;
    r.until(
        "Stop before save",
        "return document.getElementById('stop-result').textContent.startsWith('stopped');",
    )
    .await?;
    r.tab("settings").await?;
    r.clear("settings-result").await?;
    r.click("#flash-save").await?;
    r.until(
        "the reply to save",
        "const t = document.getElementById('settings-result').textContent;
         return t.startsWith('ok save') || t.startsWith('save:') ? t : null;",
    )
    .await?;
    let saved =
        r.c.execute(
            "return document.getElementById('settings-result').textContent;",
            vec![],
        )
        .await?;
    let saved = saved.as_str().unwrap_or_default().to_string();
    if !saved.starts_with("ok save") {
        bail!("flash save from the Settings panel: {saved}");
    }
    let changed = r.raw("set pid_kp 0.5").await?;
    r.tab("settings").await?;
    r.clear("settings-result").await?;
    r.click("#flash-load").await?;
    r.until(
        "the reply to load",
        "const t = document.getElementById('settings-result').textContent;
         return t.startsWith('ok load') || t.startsWith('load:') ? t : null;",
    )
    .await?;
    let back = r.raw("get pid_kp").await?;
    if back != kp {
        bail!("saved with `{kp}`, then `{changed}`, load gave `{back}`");
    }
    r.pass(&format!(
        "Settings: flash save in closed loop refused with its reason (`{refused}`); after \
         Stop, save (`{saved}`), `set pid_kp 0.5`, load: `{back}` again"
    ));

    // 7. Stop: from a sine in closed loop, the DAC ends at the safe code and stays there.
    r.tab("mode").await?;
    r.select("#mode-law", "ff+pid").await?;
    r.click("#mode-apply").await?;
    r.until(
        "mode ff+pid again",
        "return document.getElementById('mode-result').textContent.includes('ok mode ff+pid');",
    )
    .await?;
    r.tab("wave").await?;
    r.select("#wave-shape", "sine").await?;
    r.type_into("#wave-amp_um", "5").await?;
    r.type_into("#wave-offset_um", "12").await?;
    r.click("#wave-start").await?;
    r.select("#scope-trigger", "now").await?;
    r.select("#sig3", "dac_code").await?;
    r.select("#sig2", "u_volts").await?;
    r.click("#scope-apply").await?;
    let seq = r.last_seq().await?;
    let safe = o.safe_code;
    r.frame_where(
        "the DAC away from the safe code",
        seq,
        &format!("f.channels.includes('dac_code') && col('dac_code').every(v => v !== {safe})"),
    )
    .await?;
    r.clear("stop-result").await?;
    r.click("#stop").await?;
    r.until(
        "Stop done",
        "return document.getElementById('stop-result').textContent.startsWith('stopped');",
    )
    .await?;
    let seq = r.last_seq().await?;
    // The output slews to 0 V at the slew limit: a whole capture at the safe code, twice.
    let first = r
        .frame_where(
            "a capture at the safe code",
            seq,
            &format!(
                "col('dac_code').every(v => v === {safe}) && col('u_volts').every(v => v === 0)"
            ),
        )
        .await?;
    r.frame_where(
        "a later capture still at the safe code",
        first,
        &format!("col('dac_code').every(v => v === {safe})"),
    )
    .await?;
    r.shot("stop.png").await?;
    r.pass(&format!(
        "Stop: from a 5 um sine in ff+pid the DAC went to the safe code {safe} (0 V) and stays there"
    ));

    // 8. The controller goes away: the page says so.
    if let Some(pid) = o.kill_pid {
        let st = std::process::Command::new("kill")
            .arg(pid.to_string())
            .status()?;
        if !st.success() {
            bail!("kill {pid} failed");
        }
        let text = r
            .until(
                "the lost link shown",
                "const b = document.getElementById('link-banner');
                 return !b.hidden && b.textContent.includes('No connection') ? b.textContent : null;",
            )
            .await?;
        r.shot("link-lost.png").await?;
        r.pass(&format!("the firmware ended: the page shows {text}"));
    }

    // 9. A report (`piezo ui --report DIR`) opens from the Tools tab, its plots load.
    if let Some(title) = &o.report {
        r.tab("tools").await?;
        let url = r
            .until(
                "the report listed",
                "const a = document.querySelector('#reports a'); return a ? a.href : null;",
            )
            .await?;
        let url = url.as_str().unwrap_or_default().to_string();
        r.c.goto(&url).await?;
        let rows = r
            .until(
                "the report's page with its table and plots loaded",
                &format!(
                    "const h = document.querySelector('h1'); if (!h || h.textContent !== {title:?}) return null;
                     const imgs = [...document.querySelectorAll('details[open] img')];
                     if (!imgs.length || !imgs.every(i => i.complete && i.naturalWidth > 0)) return null;
                     return document.querySelectorAll('tbody tr').length;"
                ),
            )
            .await?;
        r.shot("report.png").await?;
        r.pass(&format!(
            "the report `{title}` opens from the console ({url}): {rows} table rows, its plots loaded"
        ));
    }
    Ok(())
}
