/* triaxcal live page. Data: server-sent events from api/events (the same document as
   api/state, plus the thinned point sets that changed). 3D views: plotly.js, served by
   triaxcal from the installed plotly package. Nothing is loaded from anywhere else. */
"use strict";

const T = (window.triaxcal = {
  messages: 0, applied: 0, painted: 0, draws: { accel: 0, mag: 0 }, drawMs: { accel: 0, mag: 0 },
  drawAvg: { accel: 0, mag: 0 },
  state: null, points: {}, errors: [],
  seen: [],  // [version, status, accelerometer poses, coverage %] of each state shown
  banners: [],  // [kind, text] of the banners shown, in order
});
const NAMES = { accel: "Accelerometer", mag: "Magnetometer" };
const AX = ["x", "y", "z"];
const cards = {};
let lastMessageAt = 0;

// ------------------------------------------------------------------ small helpers
function $(id) { return document.getElementById(id); }
function esc(s) {
  return String(s).replace(/[&<>"']/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;",
    '"': "&quot;", "'": "&#39;" }[c]));
}
function fmt(v, d) {
  if (v === null || v === undefined || !isFinite(v)) return "-";
  return Number(v).toFixed(d);
}
function sig(v, n) {
  if (v === null || v === undefined || !isFinite(v)) return "-";
  if (v === 0) return "0";
  const d = Math.max(0, n - 1 - Math.floor(Math.log10(Math.abs(v))));
  return Number(v).toFixed(Math.min(d, 12));
}
/* A number shown on the page, tagged with its place in api/state so that scripts and the
   tests can check that the page shows exactly what the API says. */
function num(key, value, text) {
  const v = value === null || value === undefined ? "" : String(value);
  return `<span class="num" data-key="${esc(key)}" data-value="${esc(v)}">${esc(text)}</span>`;
}
function matApply(fit, p) {
  const o = fit.offset, m = fit.matrix, d = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
  return [0, 1, 2].map((i) => m[i][0] * d[0] + m[i][1] * d[1] + m[i][2] * d[2]);
}
function inv3(m) {
  const [a, b, c] = m[0], [d, e, f] = m[1], [g, h, i] = m[2];
  const A = e * i - f * h, B = -(d * i - f * g), C = d * h - e * g;
  const det = a * A + b * B + c * C;
  return [[A / det, -(b * i - c * h) / det, (b * f - c * e) / det],
          [B / det, (a * i - c * g) / det, -(a * f - c * d) / det],
          [C / det, -(a * h - b * g) / det, (a * e - b * d) / det]];
}
function norm(v) { return Math.hypot(v[0], v[1], v[2]); }
/* Replace an element's content only when it changed: layout is the page's main cost. */
function setHTML(el, html) {
  if (el.__html !== html) { el.innerHTML = html; el.__html = html; }
}
function setText(el, text) {
  if (el.textContent !== text) el.textContent = text;
}
function shortPath(p) {
  return p.length > 28 ? "\u2026/" + p.split(/[\\/]/).pop() : p;
}
function displayScale(sensor, st) {
  const unit = st.unit;
  if (sensor === "accel" && unit === "g") return [T.state.options.units_per_g, "counts/g"];
  if (sensor === "mag" && unit === "uT") return [10, "counts/uT"];
  return [1, ""];
}

// ------------------------------------------------------------------ connection
/* Every message updates the page's numbers at once (cheap); the 3D views are redrawn from
   animation frames, as often as this machine manages (see schedule). */
function connect() {
  const es = new EventSource("api/events");
  es.onmessage = (ev) => {
    T.messages += 1;
    lastMessageAt = performance.now();
    const t0 = performance.now();
    try {
      const msg = JSON.parse(ev.data);
      for (const [k, v] of Object.entries(msg.points || {})) T.points[k] = v;
      apply(msg.state);
    } catch (e) {
      T.errors.push(String(e));
      throw e;
    }
    T.applyMs = performance.now() - t0;
    fresh = true;
    schedule();
  };
}
let fresh = false;
setInterval(() => {
  const lost = lastMessageAt && performance.now() - lastMessageAt > 4000;
  $("pageLost").classList.toggle("hidden", !lost);
  if (lost) {
    const dot = document.querySelector("#source .dot");
    if (dot) dot.className = "dot off";
  }
}, 1000);

function apply(st) {
  T.state = st;
  header(st);
  banner(st.stream);
  guide(st);
  for (const sensor of ["accel", "mag"]) {
    if (st.sensors[sensor]) {
      ensureCard(sensor);
      card(sensor, st);
      cards[sensor].dirty = true;
    }
  }
  gyro(st);
  stream(st);
  setText($("commands"), st.fit_commands.join("\n"));
  setText($("bufsize"), String(st.options.mag_buffer));
  T.applied += 1;
  T.version = st.version;
  const a = st.sensors.accel;
  T.seen.push([st.version, st.status, a ? a.poses : null, a ? a.coverage.pct : null]);
  if (T.seen.length > 3000) T.seen.splice(0, 1000);
}

// ------------------------------------------------------------------ header, banner, guide
function header(st) {
  const ended = st.status === "finished" || st.status === "fitting";
  const dotClass = ended ? "done" : st.stream.connected ? "on" : "off";
  const what = ended ? `capture ended (${esc(st.stopped_by || "")})`
    : st.status === "waiting" ? "waiting for data" : "capturing";
  setHTML($("source"), `<span class="dot ${dotClass}"></span>${what} &middot; ${esc(shortPath(st.port))}
    (${esc(st.protocol)}) &rarr; ${esc(st.session.split(/[\\/]/).pop())} &middot;
    ${num("samples", st.samples, st.samples.toLocaleString("en"))} rows`);
  const s = st.stream;
  const age = s.since_last_s;
  const items = [
    ["records/s", num("stream.records_per_s", s.records_per_s, fmt(s.records_per_s, 0)), false],
    ["dropped", num("stream.dropped", s.dropped, s.dropped), s.dropped > 0],
    ["resyncs", num("stream.resyncs", s.resyncs, s.resyncs), s.resyncs > 0],
    ["last frame", age === null ? "-" : fmt(age, 1) + " s ago",
     age !== null && age > 2 && !ended],
    ["reconnects", num("stream.reconnects", s.reconnects, s.reconnects), false],
  ];
  setHTML($("health"), items.map(([k, v, bad]) =>
    `<span class="item${bad ? " bad" : ""}">${k} <b>${v}</b></span>`).join(""));
}

function banner(s) {
  const b = $("banner");
  const bn = s.banner;
  if (!bn) { b.classList.add("hidden"); b.dataset.kind = ""; return; }
  let cls = "warn", text = bn.message;
  if (bn.kind === "disconnected") {
    cls = "bad";
    text = "Cable pulled: the board is gone. Plug it back in - the capture resumes by itself and nothing is lost. (" + bn.message + ")";
  } else if (bn.kind === "reconnected" || bn.kind === "resumed") {
    cls = "good";
    text = "The board is back: capturing again. (" + bn.message + ")";
  } else if (bn.kind === "silent") {
    cls = "bad";
    text = "No data from the board: " + bn.message;
  }
  b.className = "banner " + cls;
  if (b.dataset.kind !== bn.kind) T.banners.push([bn.kind, text]);
  b.dataset.kind = bn.kind;
  setText(b, text);
}

function guide(st) {
  const next = $("next");
  setText(next, st.next);
  const sensors = Object.keys(st.sensors).filter((k) => k === "accel" || k === "mag");
  const allReady = sensors.length > 0 && sensors.every((k) => st.sensors[k].ready);
  next.classList.toggle("all-good", allReady);
  const steps = [];
  let current = false;
  if (st.sensors.accel) {
    const a = st.sensors.accel, done = a.ready;
    steps.push([`Accelerometer: hold the board still in many orientations (${a.poses} poses so far; 18+ spread over every side)`, done]);
  }
  if (st.sensors.mag) {
    steps.push(["Magnetometer: turn it slowly in every direction until its four numbers are green", st.sensors.mag.ready]);
  }
  steps.push(["Save calibration (then Export C header or Send to board)", false]);
  setHTML($("steps"), steps.map(([text, done], i) => {
    let cls = done ? "done" : "";
    if (!done && !current && (i < steps.length - 1 || allReady)) { cls = "current"; current = true; }
    return `<li class="${cls}">${esc(text)}</li>`;
  }).join(""));
  $("btnSave").classList.toggle("ready", allReady);
  $("btnSend").disabled = busy || !st.actions.send_possible;
  $("btnSend").title = st.actions.send_possible
    ? "Save, then the MotionCal packet over the open port, checked against the board's echo"
    : "the port is not open for sending (capture ended, or polled binary): use `triaxcal send`";
  const last = st.actions.last;
  if (last && !busy) showAction(last);
}

// ------------------------------------------------------------------ sensor cards
function ensureCard(sensor) {
  if (cards[sensor]) return;
  const node = $("sensorCard").content.firstElementChild.cloneNode(true);
  node.id = "card-" + sensor;
  node.querySelector(".title").textContent = NAMES[sensor];
  $("sensors").appendChild(node);
  const c = (cards[sensor] = { node, view: "cal", dirty: true, lastDraw: 0, plot: node.querySelector(".plot3d") });
  for (const b of node.querySelectorAll(".view-toggle button")) {
    b.addEventListener("click", () => {
      c.view = b.dataset.view;
      for (const o of node.querySelectorAll(".view-toggle button")) o.classList.toggle("on", o === b);
      c.dirty = true;
      c.lastDraw = 0;
      schedule();
    });
  }
}

function card(sensor, st) {
  const s = st.sensors[sensor], c = cards[sensor], n = c.node;
  const badge = n.querySelector(".ready-badge");
  setText(badge, s.ready ? "good: ready to save" : "not ready yet");
  badge.classList.toggle("ok", s.ready);
  const hint = n.querySelector(".hint");
  setText(hint, s.hint.charAt(0).toUpperCase() + s.hint.slice(1));
  hint.classList.toggle("ok", s.ready);
  // checks: green / red against their limits
  setHTML(n.querySelector(".checks"), s.quality.map((q, i) => {
    const digits = q.unit === "" ? 0 : q.value < 1 ? 2 : 1;
    const lim = (q.op === ">=" ? "need \u2265 " : "good < ") + q.limit + (q.unit === "%" ? " %" : q.unit ? " " + q.unit : "");
    return `<div class="chk ${q.ok ? "ok" : "bad"}" title="${esc(q.help)}">
      <div class="n">${esc(q.name)} ${q.ok ? "\u2713" : "\u2717"}</div>
      <div class="v">${num(`sensors.${sensor}.quality.${i}.value`, q.value, fmt(q.value, digits))}${q.unit === "%" ? " %" : q.unit === "deg" ? "\u00b0" : ""}</div>
      <div class="l">${lim}</div></div>`;
  }).join(""));
  // coverage
  const cov = s.coverage;
  drawCoverage(n.querySelector(".covmap"), cov, latestDirection(sensor, s));
  const cap = cov.empty_cap;
  setHTML(n.querySelector(".cov-text"),
    `<b>${num(`sensors.${sensor}.coverage.pct`, cov.pct, fmt(cov.pct, 0))} %</b> of the sphere of directions covered<br>
     (${cov.cells_hit} of ${cov.cells_total} equal-area cells, the measure capture, fit and report use; green = hit)` +
    (cap ? `<br>biggest empty region: <b>${esc(cap.words)}</b>, ${num(`sensors.${sensor}.coverage.empty_cap.deg`, cap.deg, fmt(cap.deg, 0))}\u00b0 across (orange)` : ""));
  // fit
  setHTML(n.querySelector(".fit"), fitTable(sensor, s));
  drawPrecision(n.querySelector(".precision"), s.precision);
}

function latestDirection(sensor, s) {
  if (!s.latest) return null;
  if (s.fit) return matApply(s.fit, s.latest);
  return null;
}

function fitTable(sensor, s) {
  const f = s.fit;
  if (!f) return `<div class="err">${esc(s.fit_error || "no fit yet")}</div>`;
  const se = f.stderr || {};
  const [k, kunit] = displayScale(sensor, s);
  const key = `sensors.${sensor}.fit`;
  const cell = (name, i, j) => {
    if (name === "offset") {
      const v = f.offset[i], e = se["offset_" + AX[i]];
      return `<td>${num(`${key}.offset.${i}`, v, fmt(v, 1))} <span class="se">\u00b1 ${num(`${key}.stderr.offset_${AX[i]}`, e, sig(e, 2))}</span></td>`;
    }
    const v = f.matrix[i][j];
    const sname = i === j ? "diag_" + AX[i] : "offdiag_" + AX[Math.min(i, j)] + AX[Math.max(i, j)];
    const e = se[sname];
    return `<td>${num(`${key}.matrix.${i}.${j}`, v, fmt(v * k, 5))} <span class="se">${e === undefined ? "" : "\u00b1 " + sig(e * k, 2)}</span></td>`;
  };
  const rows = [`<tr><th></th><th>x</th><th>y</th><th>z</th></tr>`,
    `<tr><td class="lbl">offset (${esc(f.raw_unit)})</td>${[0, 1, 2].map((i) => cell("offset", i)).join("")}</tr>`];
  for (let i = 0; i < 3; i++) {
    rows.push(`<tr><td class="lbl">${i === 0 ? "gain matrix" + (k !== 1 ? ` \u00d7 ${k} ${kunit}` : "") : ""}</td>${[0, 1, 2].map((j) => cell("m", i, j)).join("")}</tr>`);
  }
  const src = f.source === "session" ? "the whole session file, as <code>triaxcal fit</code> gives it"
    : sensor === "accel" ? `the ${f.n + f.rejected} still poses so far` : `the ${f.n + f.rejected} well-spread samples in the buffer`;
  return `<table>${rows.join("")}</table>
    <div class="meta">radius ${num(`${key}.radius`, f.radius, sig(f.radius, 5))} ${esc(f.unit)} &middot;
      fit error (RMS) ${num(`${key}.rms`, f.rms, sig(f.rms, 3))} ${esc(f.unit)}
      (${num(`${key}.rms_pct`, f.rms_pct, sig(f.rms_pct, 3))} %) &middot; model <b>${esc(f.model)}</b>
      &middot; ${num(`${key}.n`, f.n, f.n)} used, ${num(`${key}.rejected`, f.rejected, f.rejected)} rejected as outliers</div>
    <div class="muted">calibrated = gain matrix \u00d7 (raw \u2212 offset); \u00b1 are standard errors; fitted on ${src}.</div>`;
}

// ------------------------------------------------------------------ small canvases
/* Redraw a canvas only when what it shows changed (each redraw is raster work for the page). */
function unchanged(cv, key) {
  if (cv.__key === key) return true;
  cv.__key = key;
  return false;
}

function drawCoverage(cv, cov, dir) {
  // the shared equal-area cells (triaxcal.quality.coverage) in the cylindrical equal-area projection:
  // longitude across (-180..180 deg, -X at both ends), height z up
  const dkey = dir ? dir.map((v) => (v / (norm(dir) || 1)).toFixed(2)).join() : "";
  if (unchanged(cv, cov.counts.join() + "|" + (cov.empty_cap ? cov.empty_cap.deg.toFixed(1) +
      cov.empty_cap.center.map((v) => v.toFixed(2)).join() : "") + "|" + dkey)) return;
  const g = cv.getContext("2d"), W = cv.width, H = cv.height;
  g.clearRect(0, 0, W, H);
  const L = 22, B = 16;
  const X = (deg) => L + (deg + 180) / 360 * (W - L);
  const Y = (z) => (H - B) * (1 - (z + 1) / 2);
  let max = 1;
  for (const v of cov.counts) max = Math.max(max, v);
  cov.rects.forEach(([lo, hi, zlo, zhi], i) => {
    const v = cov.counts[i];
    g.fillStyle = v > 0 ? `rgba(31,138,76,${0.35 + 0.65 * Math.log1p(v) / Math.log1p(max)})` : "#d9dde2";
    for (const shift of [0, -360]) {  // a cell may run past 180 deg: draw its wrapped part too
      const a = Math.max(lo + shift, -180), b = Math.min(hi + shift, 180);
      if (b > a) g.fillRect(X(a) + 0.5, Y(zhi) + 0.5, X(b) - X(a) - 1, Y(zlo) - Y(zhi) - 1);
    }
  });
  const px = (lon) => L + (lon + Math.PI) / (2 * Math.PI) * (W - L);
  const py = (z) => (H - B) * (1 - (z + 1) / 2);
  const cap = cov.empty_cap;
  if (cap) {
    // the cap's edge: directions at cap.deg from its centre, in the same projection
    const c = cap.center, a = cap.deg * Math.PI / 180;
    const t1 = Math.abs(c[2]) < 0.9 ? [0, 0, 1] : [1, 0, 0];
    let e1 = [c[1] * t1[2] - c[2] * t1[1], c[2] * t1[0] - c[0] * t1[2], c[0] * t1[1] - c[1] * t1[0]];
    const n1 = norm(e1); e1 = e1.map((x) => x / n1);
    const e2 = [c[1] * e1[2] - c[2] * e1[1], c[2] * e1[0] - c[0] * e1[2], c[0] * e1[1] - c[1] * e1[0]];
    g.strokeStyle = "#e67e00"; g.lineWidth = 2; g.beginPath();
    let prev = null;
    for (let k = 0; k <= 72; k++) {
      const p = k / 72 * 2 * Math.PI;
      const v = [0, 1, 2].map((i) => Math.cos(a) * c[i] + Math.sin(a) * (Math.cos(p) * e1[i] + Math.sin(p) * e2[i]));
      const lon = Math.atan2(v[1], v[0]);
      if (prev !== null && Math.abs(lon - prev) > Math.PI) g.moveTo(px(lon), py(v[2]));
      else if (prev === null) g.moveTo(px(lon), py(v[2]));
      else g.lineTo(px(lon), py(v[2]));
      prev = lon;
    }
    g.stroke();
    g.fillStyle = "#e67e00";
    g.beginPath(); g.arc(px(Math.atan2(c[1], c[0])), py(c[2]), 4, 0, 2 * Math.PI); g.fill();
  }
  if (dir) {
    const u = norm(dir);
    if (u > 0) {
      g.fillStyle = "#d62728"; g.strokeStyle = "#fff"; g.lineWidth = 1.5;
      g.beginPath(); g.arc(px(Math.atan2(dir[1], dir[0])), py(dir[2] / u), 5, 0, 2 * Math.PI);
      g.fill(); g.stroke();
    }
  }
  g.fillStyle = "#66707c"; g.font = "10px sans-serif"; g.textAlign = "center";
  ["-X", "-Y", "+X", "+Y", "-X"].forEach((t, i) => g.fillText(t, L + i * (W - L) / 4, H - 4));
  g.textAlign = "left";
  g.fillText("+Z", 2, 10); g.fillText("-Z", 2, H - B - 2);
}

function drawPrecision(cv, hist) {
  if (unchanged(cv, hist.length + ":" + (hist.length ? hist[hist.length - 1].join() : ""))) return;
  const g = cv.getContext("2d"), W = cv.width, H = cv.height;
  g.clearRect(0, 0, W, H);
  const vals = hist.filter((p) => p[1] !== null && p[1] > 0);
  if (vals.length < 2) {
    g.fillStyle = "#66707c"; g.font = "11px sans-serif";
    g.fillText("the precision appears after the first fits", 8, H / 2 + 4);
    return;
  }
  const t0 = vals[0][0], t1 = vals[vals.length - 1][0];
  const ly = vals.map((p) => Math.log10(p[1]));
  const lo = Math.min(...ly), hi = Math.max(...ly) + 1e-9;
  g.strokeStyle = "#2d6fd6"; g.lineWidth = 2; g.beginPath();
  vals.forEach((p, i) => {
    const x = 4 + (W - 8) * (t1 > t0 ? (p[0] - t0) / (t1 - t0) : 1);
    const y = 6 + (H - 12) * (1 - (ly[i] - lo) / (hi - lo || 1));
    if (i === 0) g.moveTo(x, y); else g.lineTo(x, y);
  });
  g.stroke();
  g.fillStyle = "#1d232b"; g.font = "11px sans-serif";
  g.fillText(sig(vals[vals.length - 1][1], 2) + " counts now", W - 110, 12);
}

// ------------------------------------------------------------------ 3D views (plotly)
function wire(center, minv, r, color, name) {
  // latitude circles and meridians of a sphere of radius r, mapped by center + minv @ v
  const x = [], y = [], z = [];
  const push = (v) => {
    const p = [0, 1, 2].map((i) => center[i] + minv[i][0] * v[0] + minv[i][1] * v[1] + minv[i][2] * v[2]);
    x.push(p[0]); y.push(p[1]); z.push(p[2]);
  };
  for (let la = -60; la <= 60; la += 30) {
    const c = Math.cos(la * Math.PI / 180), s = Math.sin(la * Math.PI / 180);
    for (let k = 0; k <= 48; k++) { const p = k / 48 * 2 * Math.PI; push([r * c * Math.cos(p), r * c * Math.sin(p), r * s]); }
    x.push(null); y.push(null); z.push(null);
  }
  for (let lo = 0; lo < 180; lo += 30) {
    const cl = Math.cos(lo * Math.PI / 180), sl = Math.sin(lo * Math.PI / 180);
    for (let k = 0; k <= 48; k++) { const p = k / 48 * 2 * Math.PI; push([r * Math.cos(p) * cl, r * Math.cos(p) * sl, r * Math.sin(p)]); }
    x.push(null); y.push(null); z.push(null);
  }
  return { type: "scatter3d", mode: "lines", x, y, z, name, hoverinfo: "skip",
    line: { color, width: 2 }, connectgaps: false };
}

function capRing(cap, r, center, minv) {
  const c = cap.center, a = cap.deg * Math.PI / 180;
  const t1 = Math.abs(c[2]) < 0.9 ? [0, 0, 1] : [1, 0, 0];
  let e1 = [c[1] * t1[2] - c[2] * t1[1], c[2] * t1[0] - c[0] * t1[2], c[0] * t1[1] - c[1] * t1[0]];
  const n1 = norm(e1); e1 = e1.map((v) => v / n1);
  const e2 = [c[1] * e1[2] - c[2] * e1[1], c[2] * e1[0] - c[0] * e1[2], c[0] * e1[1] - c[1] * e1[0]];
  const x = [], y = [], z = [];
  for (let k = 0; k <= 60; k++) {
    const p = k / 60 * 2 * Math.PI;
    const v = [0, 1, 2].map((i) => r * (Math.cos(a) * c[i] + Math.sin(a) * (Math.cos(p) * e1[i] + Math.sin(p) * e2[i])));
    const q = [0, 1, 2].map((i) => center[i] + minv[i][0] * v[0] + minv[i][1] * v[1] + minv[i][2] * v[2]);
    x.push(q[0]); y.push(q[1]); z.push(q[2]);
  }
  return { type: "scatter3d", mode: "lines", x, y, z, name: "biggest empty region", hoverinfo: "name",
    line: { color: "#e67e00", width: 6 } };
}

function draw3d(sensor) {
  const c = cards[sensor], st = T.state, s = st.sensors[sensor];
  const P = T.points[sensor], trailSet = T.points.trail;
  if (!P || !s) return;
  const fit = s.fit;
  const view = fit ? c.view : "raw";
  const raw = P.raw;
  const rejected = new Set(fit && fit.source === "live" ? P.rejected : []);
  const trail = trailSet && trailSet[sensor] ? trailSet[sensor] : [];
  const traces = [];
  const unit = view === "cal" ? fit.unit : "counts";
  const I = [[1, 0, 0], [0, 1, 0], [0, 0, 1]];
  const map = view === "cal" ? (p) => matApply(fit, p) : (p) => p;
  const pts = raw.map(map);
  let cmax = 1;
  let res = null;
  if (fit) {
    res = raw.map((p) => norm(matApply(fit, p)) - fit.radius);
    cmax = Math.max(3 * (fit.rms || 0), 1e-12);
  }
  if (fit) {
    traces.push(view === "cal" ? wire([0, 0, 0], I, fit.radius, "#c9ced6", "sphere of radius " + sig(fit.radius, 4))
      : wire(fit.offset, inv3(fit.matrix), fit.radius, "#f0a030", "fitted ellipsoid"));
  }
  if (trail.length > 1) {
    const tp = trail.map(map);
    traces.push({ type: "scatter3d", mode: "lines", name: "last 10 s", hoverinfo: "skip",
      x: tp.map((p) => p[0]), y: tp.map((p) => p[1]), z: tp.map((p) => p[2]),
      line: { color: "rgba(80,90,110,0.45)", width: 2 } });
  }
  const keep = pts.map((_, i) => !rejected.has(i));
  const sel = (arr) => arr.filter((_, i) => keep[i]);
  const label = sensor === "accel" ? "still poses" : "buffered samples";
  traces.push({
    type: "scatter3d", mode: "markers", name: label,
    x: sel(pts.map((p) => p[0])), y: sel(pts.map((p) => p[1])), z: sel(pts.map((p) => p[2])),
    marker: res ? { size: sensor === "accel" ? 5 : 3, color: sel(res), cmin: -cmax, cmax: cmax,
      colorscale: "RdBu", reversescale: true, showscale: true,
      colorbar: { title: { text: "residual<br>(" + esc(fit.unit) + ")", side: "top" }, thickness: 10, len: 0.55, x: 0.98 } }
      : { size: sensor === "accel" ? 5 : 3, color: "#4a6fa5" },
    hovertemplate: "%{x:.4g}, %{y:.4g}, %{z:.4g}<extra>" + label + "</extra>",
  });
  if (rejected.size) {
    const rp = pts.filter((_, i) => !keep[i]);
    traces.push({ type: "scatter3d", mode: "markers", name: "rejected (outliers)",
      x: rp.map((p) => p[0]), y: rp.map((p) => p[1]), z: rp.map((p) => p[2]),
      marker: { size: 3, color: "#555", symbol: "cross" } });
  }
  if (fit && s.coverage.empty_cap) {
    traces.push(view === "cal" ? capRing(s.coverage.empty_cap, fit.radius, [0, 0, 0], I)
      : capRing(s.coverage.empty_cap, fit.radius, fit.offset, inv3(fit.matrix)));
  }
  if (s.latest) {
    // the newest reading: a needle from the centre of the fit (just a marker before a fit)
    const p = map(s.latest);
    const o = view === "cal" ? [0, 0, 0] : fit ? fit.offset : null;
    traces.push({ type: "scatter3d", mode: o ? "lines+markers" : "markers", name: "newest reading",
      x: o ? [o[0], p[0]] : [p[0]], y: o ? [o[1], p[1]] : [p[1]], z: o ? [o[2], p[2]] : [p[2]],
      line: { color: "#d62728", width: 5 },
      marker: { size: o ? [0, 8] : 8, color: "#d62728", symbol: "diamond" },
      hovertemplate: "newest: %{x:.4g}, %{y:.4g}, %{z:.4g}<extra></extra>" });
  }
  const ax = (t) => ({ title: { text: t + " (" + unit + ")" }, showspikes: false, zeroline: false,
    backgroundcolor: "#fbfbfc", showbackground: true, gridcolor: "#e3e6ea" });
  const layout = {
    uirevision: sensor + view, margin: { l: 0, r: 0, t: 0, b: 0 }, showlegend: true,
    legend: { x: 0, y: 1, bgcolor: "rgba(255,255,255,0.7)", font: { size: 11 } },
    scene: { aspectmode: "data", xaxis: ax("X"), yaxis: ax("Y"), zaxis: ax("Z"),
      camera: { eye: { x: 1.45, y: 1.25, z: 0.85 } } },
    paper_bgcolor: "#ffffff",
  };
  const t0 = performance.now();
  Plotly.react(c.plot, traces, layout, { displayModeBar: false, responsive: true });
  T.drawMs[sensor] = performance.now() - t0;
  T.draws[sensor] += 1;
  // typical draw time, leaving out the first draw (it sets WebGL up and is much slower)
  if (T.draws[sensor] > 1) {
    const prev = T.drawAvg[sensor];
    T.drawAvg[sensor] = prev ? 0.7 * prev + 0.3 * T.drawMs[sensor] : T.drawMs[sensor];
  }
}

let rafPending = false;
function schedule() {
  if (rafPending) return;
  rafPending = true;
  requestAnimationFrame(() => {
    rafPending = false;
    if (fresh) { T.painted += 1; fresh = false; }  // frames that showed new data
    const now = performance.now();
    for (const [sensor, c] of Object.entries(cards)) {
      // redraw a view at most every 250 ms, and keep the 3D views to about a quarter of the
      // page's time where drawing is slow (software WebGL), so the numbers stay live
      const gap = Math.max(250, 8 * (T.drawAvg[sensor] || 0));
      if (c.dirty && now - c.lastDraw >= gap) {
        c.dirty = false;
        c.lastDraw = now;
        try { draw3d(sensor); } catch (e) { T.errors.push(String(e)); throw e; }
        break;  // one 3D view per frame, so that the page stays responsive
      }
    }
    if (Object.values(cards).some((c) => c.dirty)) setTimeout(schedule, 60);
  });
}

// ------------------------------------------------------------------ gyro and stream
function gyro(st) {
  const g = st.sensors.gyro, el = $("gyro");
  if (!g) { el.classList.add("hidden"); return; }
  el.classList.remove("hidden");
  const l = g.latest, b = g.bias_from_poses;
  const still = st.sensors.accel ? st.sensors.accel.still : false;
  if (!el.querySelector("canvas")) {
    el.innerHTML = `<h3>Gyroscope (rates, deg/s)</h3><div class="rates"></div>
      <canvas width="420" height="90"></canvas><div class="gbias muted"></div>`;
  }
  setHTML(el.querySelector(".rates"), l ? AX.map((a, i) =>
    `${a} ${num(`sensors.gyro.latest.${i}`, l[i], fmt(l[i], 2))}`).join(" &nbsp; ") +
    (still ? " &nbsp; <b>still</b>" : " &nbsp; moving") : "no data yet");
  setHTML(el.querySelector(".gbias"), b ? `bias estimate from ${g.poses} still poses: ` + AX.map((a, i) =>
    `${a} ${num(`sensors.gyro.bias_from_poses.${i}`, b[i], fmt(b[i], 3))}`).join(", ") + " deg/s (subtract it from the rates)" : "the bias appears after the first still pose");
  const tr = T.points.trail;
  const cv = el.querySelector("canvas");
  if (unchanged(cv, tr ? tr.version : -1)) return;
  const c = cv.getContext("2d"), W = cv.width, H = cv.height;
  c.clearRect(0, 0, W, H);
  if (!tr || !tr.gyro || tr.gyro.length < 2) return;
  let m = 1;
  for (const r of tr.gyro) for (const v of r) m = Math.max(m, Math.abs(v));
  const t0 = tr.t[0], span = Math.max(-t0, 1e-3);
  c.strokeStyle = "#ccc"; c.beginPath(); c.moveTo(0, H / 2); c.lineTo(W, H / 2); c.stroke();
  ["#d62728", "#2ca02c", "#1f77b4"].forEach((col, k) => {
    c.strokeStyle = col; c.lineWidth = 1.5; c.beginPath();
    tr.gyro.forEach((r, i) => {
      const x = W * (1 + tr.t[i] / span) - 1, y = H / 2 - (H / 2 - 4) * r[k] / m;
      if (i === 0) c.moveTo(x, y); else c.lineTo(x, y);
    });
    c.stroke();
  });
  c.fillStyle = "#66707c"; c.font = "10px sans-serif";
  c.fillText("\u00b1" + fmt(m, 0) + " deg/s, last " + fmt(span, 0) + " s (x red, y green, z blue)", 4, 11);
}

function stream(st) {
  const s = st.stream;
  const rows = [
    ["records", num("stream.records", s.records, s.records)],
    ["records per second", fmt(s.records_per_s, 0)],
    ["frames dropped (damaged or lost)", s.dropped],
    ["resyncs (bytes skipped to find a frame)", s.resyncs],
    ["bytes dropped", s.dropped_bytes],
    ["cable pulls / reconnects", `${s.disconnects} / ${s.reconnects}`],
    ["seconds since the last frame", s.since_last_s === null ? "-" : fmt(s.since_last_s, 1)],
  ];
  setHTML($("stream"), rows.map(([k, v]) => `<div class="row"><span>${k}</span><b>${v}</b></div>`).join(""));
  setHTML($("events"), s.events.slice().reverse().map((e) => {
    const cls = e.kind === "disconnected" || e.kind === "error" ? "bad" : e.kind === "reconnected" || e.kind === "resumed" ? "good" : "";
    return `<li class="${cls}">${new Date(e.time * 1000).toLocaleTimeString()}: ${esc(e.message)}</li>`;
  }).join(""));
}

// ------------------------------------------------------------------ buttons
let busy = false;
function showAction(r) {
  const m = $("actionMsg");
  const cls = "action-msg " + (r.ok ? "ok" : "err");
  if (m.className !== cls) m.className = cls;
  setText(m, (r.ok ? "\u2713 " : "\u2717 ") + r.message);
}
async function press(path, label) {
  if (busy) return;
  busy = true;
  for (const b of document.querySelectorAll(".buttons button")) b.disabled = true;
  $("actionMsg").className = "action-msg";
  $("actionMsg").textContent = label + "...";
  try {
    const r = await fetch(path, { method: "POST", headers: { "X-Triaxcal": "1" } });
    const body = await r.json();
    T.lastAction = body;
    showAction(body);
    if (body.needs_offsets_only && confirm(body.message + "\n\nSend the offsets only?")) {
      busy = false;
      return await press(path + "?offsets_only=1", label);
    }
  } catch (e) {
    showAction({ ok: false, message: "no answer from triaxcal: " + e });
  } finally {
    busy = false;
    for (const b of document.querySelectorAll(".buttons button")) b.disabled = false;
  }
}
$("btnSave").addEventListener("click", () => press("api/save", "fitting the session and saving"));
$("btnExportC").addEventListener("click", () => press("api/export/c", "saving and exporting"));
$("btnExportFixed").addEventListener("click", () => press("api/export/c-fixed", "saving and exporting"));
$("btnSend").addEventListener("click", () => press("api/send", "saving and sending"));
$("btnReset").addEventListener("click", () => {
  if (confirm("Forget the poses, the magnetometer buffer and the fits, and start again? The session file keeps every row.")) press("api/reset", "resetting");
});

connect();
