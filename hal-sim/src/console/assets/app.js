// The lab console's page: one WebSocket for events (frames, link, progress), JSON requests
// for actions. Every value is checked against the firmware's settings table before sending.
"use strict";
const $ = (id) => document.getElementById(id);
const el = (tag, attrs = {}, text) => {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  return e;
};
let info = null;
let table = {};
let lastWaveCentre = null;

// The page's counters, read by the browser checks.
window.consoleState = { frames: 0, lastSeq: 0, lastFrame: null, rate: 0, linkUp: false, mode: null };

async function api(path, body, method) {
  const opts = { method: method || (body === undefined ? "GET" : "POST"), headers: {} };
  if (body !== undefined) {
    if (typeof body === "string") { opts.body = body; opts.headers["content-type"] = "text/plain"; }
    else { opts.body = JSON.stringify(body); opts.headers["content-type"] = "application/json"; }
  }
  let r;
  try { r = await fetch(path, opts); }
  catch (e) { return { ok: false, body: { error: "the console server does not answer: " + e } }; }
  let j;
  try { j = await r.json(); } catch (e) { j = { error: "HTTP " + r.status }; }
  return { ok: r.ok, status: r.status, body: j };
}

// How a refusal reads: the firmware's numbered error, or the host's check.
function why(b) {
  if (b.code !== undefined && b.code !== null)
    return `err ${b.code}${b.name ? " (" + b.name + ")" : ""}: ${b.message || ""}`;
  return b.error || JSON.stringify(b);
}

function show(id, ok, text) {
  const e = $(id);
  e.textContent = text;
  e.className = ok ? "note ok" : "error";
}

// ---- link and events ----
function setLink(up, detail) {
  window.consoleState.linkUp = up;
  const b = $("link");
  b.textContent = up ? "connected: " + detail : "not connected";
  b.className = "badge " + (up ? "good" : "bad");
  const banner = $("link-banner");
  banner.hidden = up;
  if (!up) banner.textContent = "No connection to the controller: " + detail + " (retrying every second)";
}

// `stats` since boot or `stats reset`: bad once a deadline was missed (an overrun, a lost
// sample, an NMPC plan not back by its boundary). Counts are the board's clock (QEMU: 25 MHz
// SysTick ticks; H743: core cycles).
function onTiming(s) {
  const t = $("timing");
  const missed = s.nmpc_missed ?? 0;
  const parts = [`${s.overruns} overruns`];
  if (s.lost != null) parts.push(`${s.lost} lost`);
  if (s.nmpc_jobs != null) parts.push(`nmpc ${missed} of ${s.nmpc_jobs} plans late`);
  t.textContent = "timing " + parts.join(", ");
  t.className = "badge " + (s.overruns === 0 && (s.lost ?? 0) === 0 && missed === 0 ? "good" : "bad");
  t.title = `${s.samples} samples; step max ${s.step_max}, interrupt max ${s.isr_max}` +
    (s.late_max != null ? `, latest start after the trigger ${s.late_max}` : "") +
    " (counts of the board's clock); `stats reset` starts again";
}

function connectEvents() {
  const ws = new WebSocket(`ws://${location.host}/ws`);
  ws.onmessage = (m) => {
    const ev = JSON.parse(m.data);
    switch (ev.type) {
      case "link": setLink(ev.connected, ev.detail); break;
      case "frame": onFrame(ev); break;
      case "scope": onScopeState(ev); break;
      case "scope_cfg": onScopeCfg(ev.cfg); break;
      case "fault": {
        const f = $("fault");
        f.textContent = "fault " + ev.detail.replace(/^fault /, "");
        f.className = "badge " + (/^fault none/.test(ev.detail) ? "good" : "bad");
        break;
      }
      case "timing": onTiming(ev.stats); break;
      case "progress": onProgress(ev); break;
    }
  };
  ws.onclose = () => {
    setLink(false, "the console server is gone (piezo ui stopped?)");
    setTimeout(connectEvents, 1000);
  };
}

// ---- scope ----
let plot = null, plotKey = "", zoomed = false, paused = false, shown = null;
const colours = ["#1565c0", "#2e7d32", "#c62828", "#ef6c00"];

function makePlot(ev) {
  if (plot) plot.destroy();
  const units = [...new Set(ev.units)];
  const series = [{ label: "t [ms]" }];
  ev.channels.forEach((c, k) => series.push({ label: `${c} [${ev.units[k]}]`, scale: ev.units[k], stroke: colours[k % 4], width: 1.5 }));
  const axes = [{ label: "t [ms]" }];
  units.forEach((u, k) => axes.push({ scale: u, label: u, side: k === 0 ? 3 : 1, grid: { show: k === 0 } }));
  const scales = { x: { time: false } };
  units.forEach((u) => (scales[u] = { auto: true }));
  const width = Math.max(600, $("scope").clientWidth || window.innerWidth - 40);
  plot = new uPlot({
    width, height: 320, series, axes, scales,
    cursor: { drag: { x: true, y: false } },
    hooks: { setSelect: [(u) => { if (u.select.width > 0) zoomed = true; }] },
  }, [[]].concat(ev.channels.map(() => [])), $("scope"));
  plot.over.addEventListener("dblclick", () => { zoomed = false; });
  plotKey = ev.channels.join(",") + "|" + ev.units.join(",");
}

// A capture streams in parts (`from`, `columns` of the new frames) while it fills; the
// plot keeps the whole capture's time span, so the trace sweeps across it.
let building = null;

function onFrame(ev) {
  const s = window.consoleState;
  s.frames += 1;
  s.rate = ev.updates_per_s;
  if (!building || building.seq !== ev.seq || ev.from === 0) {
    building = { ...ev, columns: ev.channels.map(() => []) };
  }
  if (ev.from !== building.columns[0].length) { building = null; return; } // a part missed
  ev.columns.forEach((c, k) => { for (const v of c) building.columns[k].push(v); });
  building.complete = ev.complete;
  building.updates_per_s = ev.updates_per_s;
  if (ev.complete) { s.lastSeq = ev.seq; s.lastFrame = building; }
  if (paused) return;
  shown = building;
  const key = ev.channels.join(",") + "|" + ev.units.join(",");
  if (!plot || key !== plotKey) makePlot(ev);
  const b = building, n = b.columns[0].length;
  const t = new Array(n);
  for (let i = 0; i < n; i++) t[i] = ((i - b.pre) / b.sample_hz) * 1e3;
  plot.setData([t].concat(b.columns), !zoomed);
  if (!zoomed) plot.setScale("x", { min: (-b.pre / b.sample_hz) * 1e3, max: ((b.total - 1 - b.pre) / b.sample_hz) * 1e3 });
  const span = (b.total / b.sample_hz * 1e3).toFixed(2);
  $("scope-status").textContent = (b.complete ? `capture ${b.seq}: ${n} frames` : `capture ${b.seq}: ${n} of ${b.total} frames`) +
    ` at ${b.sample_hz} Hz (${span} ms), trigger ${b.trigger}; ${ev.updates_per_s} updates/s`;
  $("scope-error").textContent = "";
}

function onScopeState(ev) {
  if (ev.state === "error") $("scope-error").textContent = "scope: " + ev.detail;
  else if (ev.state === "armed") $("scope-status").textContent = "armed: " + ev.detail;
}

function onScopeCfg(cfg) {
  paused = !cfg.running;
  $("scope-run").textContent = paused ? "Run" : "Pause";
  cfg.signals.forEach((s, k) => { if ($("sig" + k)) $("sig" + k).value = s; });
  $("scope-frames").value = cfg.frames;
  $("scope-every").value = cfg.every;
  $("scope-pre").value = cfg.pre;
  const m = /^(rise|fall|level):([^:]+):(.*)$/.exec(cfg.trigger);
  if (cfg.trigger === "now") $("scope-trigger").value = "now";
  else if (m) {
    $("scope-trigger").value = $("scope-trigger").value === "wave" && m[1] === "rise" && m[2] === "ref_um" ? "wave" : m[1];
    $("scope-trig-sig").value = m[2];
    $("scope-level").value = m[3];
  }
}

function scopeCfg(running) {
  const signals = [0, 1, 2, 3].map((k) => $("sig" + k).value).filter((s) => s);
  let trigger = "now";
  const kind = $("scope-trigger").value;
  if (kind === "wave") {
    const level = lastWaveCentre !== null ? lastWaveCentre : Number($("scope-level").value);
    $("scope-level").value = level;
    trigger = `rise:ref_um:${level}`;
  } else if (kind !== "now") trigger = `${kind}:${$("scope-trig-sig").value}:${$("scope-level").value}`;
  return {
    running, signals, trigger,
    frames: Number($("scope-frames").value), every: Number($("scope-every").value),
    pre: kind === "now" ? 0 : Number($("scope-pre").value),
  };
}

async function applyScope(running) {
  const r = await api("/api/scope", scopeCfg(running));
  if (!r.ok) $("scope-error").textContent = "scope: " + why(r.body) + " (nothing changed)";
  else $("scope-error").textContent = "";
}

function exportCsv() {
  if (!shown) return;
  const a = el("a", { href: `/api/scope/csv?seq=${shown.seq}`, download: `scope-${shown.seq}.csv` });
  document.body.appendChild(a); a.click(); a.remove();
}

// ---- settings ----
function fmt(v) { return v === null || v === undefined ? "-" : String(v); }

function buildSettings() {
  const body = document.querySelector("#settings tbody");
  body.innerHTML = "";
  for (const s of info.table) {
    const tr = el("tr");
    tr.appendChild(el("td", { title: s.about }, s.name));
    tr.appendChild(el("td", { id: "val-" + s.name, class: "num" }, "?"));
    tr.appendChild(el("td", {}, s.unit));
    tr.appendChild(el("td", {}, s.settable ? `${s.min} .. ${s.max}` : "read-only"));
    tr.appendChild(el("td", {}, fmt(s.default)));
    const inp = el("td"), btn = el("td");
    if (s.settable) {
      const i = el("input", { id: "set-" + s.name, type: "text", placeholder: s.unit });
      i.addEventListener("keydown", (e) => { if (e.key === "Enter") setOne(s.name); });
      inp.appendChild(i);
      const b = el("button", { id: "setbtn-" + s.name }, "set");
      b.addEventListener("click", () => setOne(s.name));
      btn.appendChild(b);
    }
    tr.appendChild(inp); tr.appendChild(btn);
    tr.appendChild(el("td", { id: "msg-" + s.name, title: s.about }, s.about));
    body.appendChild(tr);
  }
}

// The table's check, as the host's `piezo serial set` does it: a finite number in range.
function checkSetting(name, text) {
  const s = table[name];
  if (!s) return `unknown setting ${name}`;
  if (!s.settable) return `${name} is read-only (the board decides it)`;
  if (!/^\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\s*$/.test(text)) return `\`${text}\` is not a number in ${s.unit}`;
  const v = Number(text);
  if (!(Number.isFinite(v) && v >= s.min && v <= s.max))
    return `${name} = ${v} ${s.unit} outside ${s.min} .. ${s.max} (${s.about}); nothing sent`;
  return null;
}

async function setOne(name) {
  const text = $("set-" + name).value;
  const bad = checkSetting(name, text);
  if (bad) { show("msg-" + name, false, bad); return; }
  show("msg-" + name, true, "sending ...");
  const r = await api("/api/set", { name, value: Number(text) });
  if (r.ok) {
    $("val-" + name).textContent = r.body.value;
    show("msg-" + name, true, `ok ${name} ${r.body.value}`);
  } else show("msg-" + name, false, why(r.body));
}

async function readSettings() {
  const r = await api("/api/settings");
  if (!r.ok) { show("settings-result", false, why(r.body)); return; }
  for (const [k, v] of Object.entries(r.body)) if ($("val-" + k)) $("val-" + k).textContent = v;
  show("settings-result", true, "read " + Object.keys(r.body).length + " settings");
}

async function flashOp(op) {
  const r = await api("/api/flash", { op });
  if (r.ok) {
    // The values read back, then the operation's own reply stays on screen.
    await readSettings();
    show("settings-result", true, r.body.reply + "; values read back");
  } else {
    // The firmware writes its flash only in the safe state (the command table's `save`).
    const hint = op === "save" && r.body.code === 12
      ? " (the firmware saves only in the safe state, open loop holding or a fault latched: press STOP first)" : "";
    show("settings-result", false, `${op}: ` + why(r.body) + hint);
  }
}

async function downloadSettings() {
  const r = await api("/api/settings/file");
  if (!r.ok) { show("settings-result", false, why(r.body)); return; }
  const a = el("a", { href: URL.createObjectURL(new Blob([r.body.text], { type: "text/csv" })), download: "settings.csv" });
  document.body.appendChild(a); a.click(); a.remove();
  show("settings-result", true, `downloaded ${r.body.count} settings`);
}

async function restoreSettings() {
  const f = $("file-upload").files[0];
  if (!f) { show("settings-result", false, "choose a settings file first"); return; }
  const r = await api("/api/settings/file", await f.text());
  if (r.ok) { show("settings-result", true, `restored ${r.body.restored} settings from ${f.name}`); readSettings(); }
  else show("settings-result", false, why(r.body));
}

// ---- mode ----
async function selectMode() {
  const law = $("mode-law").value, ff = $("mode-ff").value;
  show("mode-result", true, "sending ...");
  const r = await api("/api/mode", { law, ff: ff || null });
  if (r.ok) {
    show("mode-result", true, r.body.replies.join("; "));
    window.consoleState.mode = law + (ff ? " + " + ff : "");
    $("hdr-mode").textContent = "mode: " + window.consoleState.mode;
  } else show("mode-result", false, "refused: " + why(r.body));
}

// ---- wave ----
const WAVES = {
  sine: [["amp_um", 5, "um"], ["freq_hz", 100, "Hz"], ["offset_um", 10, "um"]],
  triangle: [["amp_um", 5, "um"], ["freq_hz", 100, "Hz"], ["offset_um", 10, "um"]],
  square: [["amp_um", 5, "um"], ["freq_hz", 100, "Hz"], ["offset_um", 10, "um"]],
  raster: [["x_span_um", 10, "um"], ["y_span_um", 10, "um"], ["lines", 4, ""], ["line_hz", 20, "Hz"], ["xc_um", 10, "um"], ["yc_um", 10, "um"]],
  prbs: [["low_um", 10, "um"], ["high_um", 12, "um"], ["order", 12, "bits"], ["bit_hz", 10000, "Hz"], ["seed", 1, ""]],
  chirp: [["amp_um", 2, "um"], ["f0_hz", 10, "Hz"], ["f1_hz", 2000, "Hz"], ["duration_s", 0.1, "s"], ["offset_um", 10, "um"]],
  multisine: [["amp_um", 2, "um"], ["f0_hz", 100, "Hz"], ["harmonics", 16, ""], ["offset_um", 10, "um"], ["seed", 0, ""]],
  hold: [["position_um", 10, "um"]],
  off: [],
};

function buildWave() {
  const p = $("wave-params");
  p.innerHTML = "";
  for (const [name, dflt, unit] of WAVES[$("wave-shape").value]) {
    const l = el("label", {}, name.replace(/_(um|hz|s)$/, "") + " ");
    l.appendChild(el("input", { id: "wave-" + name, type: "number", value: dflt, step: "any" }));
    if (unit) l.appendChild(document.createTextNode(" " + unit));
    p.appendChild(l);
  }
}

async function startWave() {
  const shape = $("wave-shape").value;
  const body = { shape };
  for (const [name] of WAVES[shape]) {
    const v = Number($("wave-" + name).value);
    if (!Number.isFinite(v)) { show("wave-result", false, `${name}: not a number; nothing sent`); return; }
    body[name] = v;
  }
  const r = await api("/api/wave", body);
  if (r.ok) {
    show("wave-result", true, r.body.reply);
    // The wave's centre: where "wave start" triggers.
    if ("offset_um" in body) lastWaveCentre = body.offset_um;
    else if (shape === "prbs") lastWaveCentre = (body.low_um + body.high_um) / 2;
    else if (shape === "raster") lastWaveCentre = body.xc_um;
  } else show("wave-result", false, why(r.body));
}

// ---- stop ----
async function stop() {
  show("stop-result", true, "stopping ...");
  const r = await api("/api/stop", {});
  if (r.ok) {
    show("stop-result", true, "stopped: open loop, 0 V");
    window.consoleState.mode = "open-loop + linear";
    $("hdr-mode").textContent = "mode: open-loop + linear (stopped)";
  } else show("stop-result", false, "STOP FAILED: " + why(r.body));
}

// ---- tools ----
let bodeNotch = null, bodePlots = [];
async function runBode() {
  $("bode-apply").disabled = true;
  show("bode-result", true, "measuring (the scope waits) ...");
  const r = await api("/api/bode", {
    loop: $("bode-loop").value, excitation: $("bode-exc").value,
    amplitude_um: Number($("bode-amp").value), offset_um: Number($("bode-offset").value),
    averages: Number($("bode-avg").value),
  });
  if (!r.ok) { show("bode-result", false, why(r.body)); return; }
  const b = r.body;
  window.consoleState.bode = b;
  bodePlots.forEach((p) => p.destroy());
  const mk = (target, label, y) => new uPlot({
    width: Math.max(600, $("tab-tools").clientWidth - 40), height: 220,
    scales: { x: { time: false, distr: 3 } },
    series: [{ label: "f [Hz]" }, { label, stroke: "#1565c0", width: 1.5, points: { show: true } }],
    axes: [{ label: "f [Hz]" }, { label }],
  }, [b.f_hz, y], target);
  bodePlots = [mk($("bode-mag"), `|H| [dB ${b.unit}]`, b.magnitude_db), mk($("bode-phase"), "phase [deg]", b.phase_deg)];
  if (b.resonance) {
    bodeNotch = b.notch;
    show("bode-result", true, `${b.what}: resonance ${b.resonance.f_hz.toFixed(1)} Hz, ${b.resonance.prominence_db.toFixed(1)} dB above its neighbours, Q ${b.resonance.q.toFixed(2)}; suggested notch_hz ${b.notch.notch_hz.toFixed(1)} notch_q ${b.notch.notch_q.toFixed(2)}`);
    $("bode-apply").disabled = false;
  } else show("bode-result", true, `${b.what}: no resonance (no line 3 dB above its neighbours)`);
}

async function applyNotch() {
  if (!bodeNotch) return;
  for (const name of ["notch_hz", "notch_q"]) {
    const v = Number(bodeNotch[name].toFixed(name === "notch_hz" ? 1 : 2));
    const bad = checkSetting(name, String(v));
    if (bad) { show("bode-result", false, bad); return; }
    const r = await api("/api/set", { name, value: v });
    if (!r.ok) { show("bode-result", false, `${name}: ` + why(r.body)); return; }
    if ($("val-" + name)) $("val-" + name).textContent = r.body.value;
  }
  show("bode-result", true, `notch applied: notch_hz ${bodeNotch.notch_hz.toFixed(1)} notch_q ${bodeNotch.notch_q.toFixed(2)}`);
}

function onProgress(ev) {
  if (ev.tool === "identify") $("ident-progress").appendChild(el("li", {}, ev.line));
}

function filesList(files) {
  const d = el("div");
  for (const f of files) {
    if (f.endsWith("/index.html")) { d.appendChild(el("a", { href: "/files/" + f, target: "_blank", class: "report" }, "open the report")); d.appendChild(document.createTextNode(" ")); }
    else if (f.endsWith(".svg")) d.appendChild(el("img", { src: "/files/" + f, class: "plot" }));
    else { const a = el("a", { href: "/files/" + f, download: f.split("/").pop() }, f.split("/").pop()); d.appendChild(a); d.appendChild(document.createTextNode(" ")); }
  }
  return d;
}

async function runIdentify() {
  $("ident-progress").innerHTML = "";
  $("ident-result").textContent = "running (the scope waits) ...";
  const r = await api("/api/identify", {});
  const out = $("ident-result");
  out.innerHTML = "";
  if (!r.ok) { out.appendChild(el("div", { class: "error" }, why(r.body))); return; }
  const b = r.body, f = (x) => x.map((v) => v.toPrecision(4)).join(", ");
  out.appendChild(el("div", { class: "ok" }, `tracking error ${b.rmse_before_um.toFixed(4)} um RMS before, ${b.rmse_after_um.toFixed(4)} um after`));
  out.appendChild(el("div", {}, `CBW loaded (d, alpha um/V; beta, gamma 1/V): ${f(b.cbw)} (was ${f(b.cbw_before)})`));
  if (b.diagnosis) out.appendChild(el("div", {}, "diagnosis: " + b.diagnosis));
  out.appendChild(filesList(b.files || []));
  readSettings();
}

async function runDiagnose(seq) {
  const out = $("diag-result");
  let r;
  if (seq !== undefined) {
    out.textContent = `diagnosing capture ${seq} ...`;
    r = await api(`/api/diagnose?seq=${seq}`, "");
  } else {
    const f = $("diag-file").files[0];
    if (!f) { out.textContent = "choose a record (CSV) first"; return; }
    out.textContent = `diagnosing ${f.name} ...`;
    r = await api("/api/diagnose", await f.text());
  }
  out.innerHTML = "";
  if (!r.ok) { out.appendChild(el("div", { class: "error" }, why(r.body))); if (r.body.report) out.appendChild(el("pre", {}, r.body.report)); return; }
  out.appendChild(el("pre", {}, r.body.report));
  out.appendChild(filesList(r.body.files || []));
}

// ---- wire ----
async function sendRaw() {
  const line = $("raw-line").value;
  const r = await api("/api/raw", { line });
  const out = $("raw-out");
  const text = r.ok ? r.body.data.concat([r.body.reply]).join("\n") : why(r.body);
  out.textContent = `> ${line}\n${text}\n` + out.textContent;
  window.consoleState.lastRaw = { line, ok: r.ok, text };
}

async function refreshWire() {
  const r = await api("/api/wire");
  if (!r.ok) return;
  $("wire-count").textContent = `${r.body.sent} lines sent, ${r.body.sets} of them set or cbw (recorder polling not listed)`;
  $("wire-log").textContent = r.body.last.slice().reverse().join("\n");
  window.consoleState.wire = r.body;
}

// ---- start ----
async function main() {
  const r = await api("/api/info");
  info = r.body;
  for (const s of info.table) table[s.name] = s;
  buildSettings();
  for (let k = 0; k < 4; k++) {
    const sel = $("sig" + k);
    sel.appendChild(el("option", { value: "" }, "-"));
    for (const s of info.signals) sel.appendChild(el("option", { value: s }, s));
  }
  for (const s of info.signals) $("scope-trig-sig").appendChild(el("option", { value: s }, s));
  for (const l of info.laws) $("mode-law").appendChild(el("option", { value: l }, l));
  $("mode-ff").appendChild(el("option", { value: "" }, "(keep)"));
  for (const f of info.ffs) $("mode-ff").appendChild(el("option", { value: f }, f));
  buildWave();
  for (const r of info.reports || []) {
    const li = el("li");
    li.appendChild(el("a", { href: r.url, target: "_blank" }, r.dir));
    $("reports").appendChild(li);
  }
  if (!(info.reports || []).length) $("reports").appendChild(el("li", { class: "note" }, "none given (piezo ui --report DIR)"));
  document.querySelectorAll(".tab").forEach((t) => t.addEventListener("click", () => {
    document.querySelectorAll(".tab").forEach((u) => u.classList.toggle("active", u === t));
    document.querySelectorAll(".tabpanel").forEach((p) => (p.hidden = p.id !== "tab-" + t.dataset.tab));
    if (t.dataset.tab === "wire") refreshWire();
  }));
  $("stop").addEventListener("click", stop);
  $("scope-run").addEventListener("click", () => applyScope(paused));
  $("scope-apply").addEventListener("click", () => applyScope(true));
  $("scope-export").addEventListener("click", exportCsv);
  $("scope-diagnose").addEventListener("click", () => {
    if (shown) { document.querySelector('.tab[data-tab="tools"]').click(); runDiagnose(shown.seq); }
  });
  $("settings-refresh").addEventListener("click", readSettings);
  $("flash-save").addEventListener("click", () => flashOp("save"));
  $("flash-load").addEventListener("click", () => flashOp("load"));
  $("flash-defaults").addEventListener("click", () => flashOp("defaults"));
  $("file-download").addEventListener("click", downloadSettings);
  $("file-restore").addEventListener("click", restoreSettings);
  $("mode-apply").addEventListener("click", selectMode);
  $("wave-shape").addEventListener("change", buildWave);
  $("wave-start").addEventListener("click", startWave);
  $("bode-run").addEventListener("click", runBode);
  $("bode-apply").addEventListener("click", applyNotch);
  $("ident-run").addEventListener("click", runIdentify);
  $("diag-run").addEventListener("click", () => runDiagnose());
  $("raw-send").addEventListener("click", sendRaw);
  $("raw-line").addEventListener("keydown", (e) => { if (e.key === "Enter") sendRaw(); });
  $("wire-refresh").addEventListener("click", refreshWire);
  connectEvents();
  readSettings();
}
main();
