// chiaro serve: the page. Plain JavaScript, no build step.
// Protocol: see crates/chiaro-serve/src/protocol.rs.
"use strict";

const $ = (id) => document.getElementById(id);
// URL parameters: still=1 renders one full-quality picture (no draft pass)
// and then sets <body data-ready="1"> for screenshots; technique=NAME picks
// the left view's technique (default: the scene's); split=1 opens the
// split view.
const params = new URLSearchParams(location.search);
// While the camera moves, frames are drafts: this fraction of the
// resolution, one sample per pixel and one sample per area light.
const DRAFT_SCALE = 0.5;
const state = {
  still: params.get("still") === "1", queued: null, connecting: false, pass: 0,
  queue: Promise.resolve(),
  info: null, ws: null, nextId: 1, sentId: 0, inFlight: false, pending: null,
  orbit: { yaw: 0, pitch: 0, zoom: 1 }, dragging: false, lastPos: null,
  stillTimer: null, done: 0, framesMoving: 0, moveStart: 0, firstMs: null,
  sentAt: 0, split: false, doneViews: 0, expectedViews: 1,
};
window.chiaro = state; // for the end-to-end test

function setStatus(text, kind) {
  const s = $("status");
  s.textContent = text;
  s.dataset.state = kind;
}

function fillSelect(sel, values, value) {
  sel.innerHTML = "";
  for (const v of values) {
    const o = document.createElement("option");
    o.value = v; o.textContent = v;
    sel.appendChild(o);
  }
  if (value !== undefined) sel.value = value;
}

function viewOf(fieldset) {
  const f = (n) => fieldset.querySelector(`[name=${n}]`);
  return {
    technique: f("technique").value, shadows: f("shadows").value,
    transparency: f("transparency").value, model: f("model").value,
    samples: Math.max(1, parseInt(f("samples").value, 10) || 1), light_samples: 0,
  };
}

function size(scale) {
  const r = $("resolution").value.split("x").map((n) => parseInt(n, 10));
  return [Math.max(8, Math.round(r[0] * scale)), Math.max(8, Math.round(r[1] * scale))];
}

// Sends a render request; while one is in flight only the newest waiting
// request is kept (so dragging renders as fast as the server can). A still
// camera gets a quick full-resolution pass first, then full quality.
function request(moving) {
  const [w, h] = size(moving ? DRAFT_SCALE : 1);
  const views = [viewOf($("view-a"))];
  if (state.split) views.push(viewOf($("view-b")));
  if (moving) for (const v of views) { v.samples = 1; v.light_samples = 1; }
  const refine = !moving && !state.still;
  const msg = { type: "render", width: w, height: h, orbit: { ...state.orbit },
    progressive: refine, refine, views };
  if (state.inFlight && moving) { state.pending = msg; return; }
  send(msg);
}

function send(msg) {
  if (!state.ws || state.ws.readyState !== WebSocket.OPEN) {
    // Closed (the server closes idle connections): reconnect, then send.
    state.queued = msg;
    connect();
    return;
  }
  msg.id = state.nextId++;
  state.sentId = msg.id;
  state.inFlight = true;
  state.sentAt = performance.now();
  state.doneViews = 0;
  // Two views also bring a metrics message (after both are done).
  state.expectedViews = msg.views.length === 2 ? 3 : 1;
  state.firstMs = null;
  state.pass = 0;
  setStatus(`rendering ${msg.width}x${msg.height}…`, "rendering");
  state.ws.send(JSON.stringify(msg));
}

function canvasFor(kind, view) {
  if (kind === "diff") return $("canvas-diff");
  return $(`canvas-${view}`);
}

async function onFrame(buf) {
  const dv = new DataView(buf);
  const hlen = dv.getUint32(0, true);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, hlen)));
  const payload = new Uint8Array(buf, 4 + hlen);
  if (header.kind === "file") {
    const a = document.createElement("a");
    a.href = URL.createObjectURL(new Blob([payload]));
    a.download = header.name;
    document.body.appendChild(a); a.click(); a.remove();
    return;
  }
  if (header.id !== state.sentId) return; // stale
  const bmp = await createImageBitmap(new Blob([payload], { type: "image/png" }));
  if (header.id !== state.sentId) return;
  const c = canvasFor(header.kind, header.view);
  const resized = c.width !== header.width || c.height !== header.height;
  if (resized) {
    c.width = header.width; c.height = header.height;
  }
  c.getContext("2d").drawImage(bmp, header.x, header.y);
  if ($("slider-mode").checked) updateSlider();
  if (resized) fit();
}

function onText(m) {
  if (m.type === "error") {
    if (m.id === undefined || m.id === state.sentId) {
      state.inFlight = false;
      setStatus(m.message, "error");
    }
    return;
  }
  if (m.id !== state.sentId) return;
  if (m.type === "first" && state.firstMs === null) {
    state.firstMs = performance.now() - state.sentAt;
  } else if (m.type === "pass") {
    state.pass = m.pass;
    setStatus(`refining: pass ${m.pass} of ${m.of}…`, "rendering");
  } else if (m.type === "done") {
    $(`cap-${m.view}`).textContent =
      `${m.technique} ${m.width}x${m.height}, ${m.samples} spp: ${m.render_ms.toFixed(0)} ms` +
      (m.rays ? `, ${(m.rays / 1e6).toFixed(2)} M rays` : "");
    state.doneViews += 1;
    if (state.doneViews >= state.expectedViews) finish();
  } else if (m.type === "metrics") {
    showMetrics(m);
    state.doneViews += 1;
    if (state.doneViews >= state.expectedViews) finish();
  }
}

// The numbers `chiaro compare` reports (chiaro_tools::metrics), with its
// digits; a PSNR of identical pictures is infinite, sent as null.
function showMetrics(m) {
  $("metrics").hidden = false;
  $("m-relmse").textContent = m.relative_mse.toFixed(5);
  $("m-flip").textContent = m.flip.toFixed(4);
  $("m-psnr").textContent = m.display_psnr === null ? "inf" : `${m.display_psnr.toFixed(2)} dB`;
  $("m-rmse").textContent = m.rmse.toFixed(5);
}

function finish() {
  const ms = performance.now() - state.sentAt;
  state.inFlight = false;
  state.done += 1;
  if (state.dragging) state.framesMoving += 1;
  const fps = state.framesMoving && state.dragging
    ? ` (${(1000 * state.framesMoving / (performance.now() - state.moveStart)).toFixed(1)} fps)` : "";
  setStatus(`done in ${ms.toFixed(0)} ms, first picture ${(state.firstMs ?? ms).toFixed(0)} ms${fps}`, "done");
  document.body.dataset.doneId = String(state.sentId);
  if (state.still) document.body.dataset.ready = "1";
  if (state.pending) { const p = state.pending; state.pending = null; send(p); }
}

function connect() {
  if (state.connecting) return;
  state.connecting = true;
  const ws = new WebSocket(`ws://${location.host}/ws`);
  ws.binaryType = "arraybuffer";
  ws.onopen = () => {
    state.ws = ws; state.connecting = false; setStatus("connected", "idle");
    const q = state.queued; state.queued = null;
    if (q) send(q); else request(false);
  };
  // Messages are handled strictly in order: a frame is decoded
  // asynchronously, and the "done" after it must wait until it is drawn.
  ws.onmessage = (e) => {
    const handle = typeof e.data === "string" ? () => onText(JSON.parse(e.data)) : () => onFrame(e.data);
    state.queue = state.queue.then(handle).catch((err) => setStatus(String(err), "error"));
  };
  ws.onclose = (e) => {
    const wasOpen = state.ws === ws;
    state.ws = null; state.connecting = false; state.inFlight = false;
    if (!wasOpen) setStatus("cannot connect to the server", "error");
    else if (e.code === 1001) setStatus("idle: disconnected; any change reconnects", "idle");
    else setStatus("disconnected; any change reconnects", "error");
  };
}

function updateSlider() {
  const a = $("canvas-0"), b = $("canvas-1"), sa = $("slider-a"), sb = $("slider-b");
  for (const [src, dst] of [[a, sa], [b, sb]]) {
    dst.width = src.width; dst.height = src.height;
    dst.getContext("2d").drawImage(src, 0, 0);
  }
  sa.style.clipPath = `inset(0 ${100 - $("slider").value}% 0 0)`;
}

// Heights below a picture (its caption; the slider's range input too) and
// between pictures, in CSS pixels, as style.css draws them.
// The metrics table's size (style.css fixes its width).
const CAPTION = 20, SLIDER = 20, GAP = 12, METRICS = 200, METRICS_HEIGHT = 110;

// Gives the pictures the window: the compared views (one, two side by
// side, or the slider's one) as large as they fit beside the controls, the
// difference image (at least half as wide as a view) and the metrics after
// them, either in a column beside the views or on the row below,
// whichever shows the views larger.
function fit() {
  const v = $("views"), cs = getComputedStyle(v);
  // A pixel of slack against rounding, so that nothing scrolls.
  const W = v.clientWidth - parseFloat(cs.paddingLeft) - parseFloat(cs.paddingRight) - 2;
  const H = v.clientHeight - parseFloat(cs.paddingTop) - parseFloat(cs.paddingBottom) - 2;
  const c = $("canvas-0"), aspect = c.width / c.height;
  const slider = $("slider-mode").checked && state.split;
  const n = state.split && !slider ? 2 : 1;
  const below = CAPTION + (slider ? SLIDER : 0);
  // The widest picture within w x h (h: the picture alone, no caption).
  const widest = (w, h) => Math.max(32, Math.floor(Math.min(w, h * aspect)));
  let main, diff, twoRows = false;
  if (!state.split) {
    main = diff = widest(W, H - below);
  } else {
    // A column beside the views, as wide as half a view (or the table).
    let w = (W - n * GAP) / (n + 0.5);
    if (w / 2 < METRICS) w = (W - n * GAP - METRICS) / n;
    const beside = widest(w, H - below);
    const column = widest(W - n * (beside + GAP), H - CAPTION - GAP - METRICS_HEIGHT);
    // Two rows: the row break adds a second gap.
    const rows = H - below - CAPTION - 2 * GAP;
    const top = widest((W - (n - 1) * GAP) / n, rows / 1.5);
    const bottom = widest(W - METRICS - GAP, rows - top / aspect);
    if (beside >= top) { main = beside; diff = column; } else { main = top; diff = bottom; twoRows = true; }
  }
  v.style.setProperty("--main", `${main}px`);
  v.style.setProperty("--diff", `${diff}px`);
  $("row-break").hidden = !twoRows;
  $("side").classList.toggle("column", !twoRows);
}

function layout() {
  const slider = $("slider-mode").checked && state.split;
  $("fig-0").hidden = slider;
  $("fig-1").hidden = !state.split || slider;
  $("fig-diff").hidden = !state.split;
  $("side").hidden = !state.split;
  $("fig-slider").hidden = !slider;
  $("metrics").hidden = !state.split;
  $("view-b").disabled = !state.split;
  for (const f of ["png", "exr"]) $(`save-${f}-1`).disabled = !state.split;
  if (slider) updateSlider();
  fit();
}

function orbitStart(e) {
  state.dragging = true; state.lastPos = [e.clientX, e.clientY];
  state.framesMoving = 0; state.moveStart = performance.now();
  e.target.setPointerCapture(e.pointerId);
}
function orbitMove(e) {
  if (!state.dragging) return;
  const [x, y] = state.lastPos;
  state.lastPos = [e.clientX, e.clientY];
  state.orbit.yaw -= (e.clientX - x) * 0.006;
  state.orbit.pitch += (e.clientY - y) * 0.006;
  state.orbit.pitch = Math.max(-1.45, Math.min(1.45, state.orbit.pitch));
  request(true);
}
function orbitEnd() {
  if (!state.dragging) return;
  state.dragging = false;
  state.pending = null;
  request(false);
}
function wheel(e) {
  e.preventDefault();
  state.orbit.zoom = Math.max(0.1, Math.min(10, state.orbit.zoom * Math.exp(-e.deltaY * 0.001)));
  request(true);
  clearTimeout(state.stillTimer);
  state.stillTimer = setTimeout(() => { state.pending = null; request(false); }, 300);
}

async function main() {
  state.info = await (await fetch("/api/info")).json();
  const i = state.info;
  $("scene-name").textContent = i.scene;
  // The right view has the same controls as the left.
  for (const label of $("view-a").querySelectorAll("label")) {
    $("view-b").append(label.cloneNode(true));
  }
  for (const fs of [$("view-a"), $("view-b")]) {
    const f = (n) => fs.querySelector(`[name=${n}]`);
    const asked = params.get("technique");
    const left = asked && i.techniques.includes(asked) ? asked : i.technique;
    fillSelect(f("technique"), i.techniques, fs.id === "view-a" ? left : "path");
    fillSelect(f("shadows"), i.shadows, "scene");
    fillSelect(f("transparency"), i.transparency, "scene");
    fillSelect(f("model"), i.models, "scene");
    f("samples").max = i.limits.max_samples;
    f("samples").value = fs.id === "view-a" ? i.samples : Math.min(i.limits.max_samples, 16);
    fs.addEventListener("change", () => request(false));
  }
  const res = [];
  for (const s of [0.5, 1, 2]) {
    const w = Math.round(i.width * s), h = Math.round(i.height * s);
    if (w <= i.limits.max_side && h <= i.limits.max_side && w >= 8 && h >= 8) res.push(`${w}x${h}`);
  }
  fillSelect($("resolution"), res, `${i.width}x${i.height}`);
  if (!$("resolution").value) $("resolution").value = res[0];
  $("resolution").onchange = () => request(false);
  $("split").onchange = () => { state.split = $("split").checked; layout(); request(false); };
  $("slider-mode").onchange = layout;
  window.addEventListener("resize", fit);
  $("slider").oninput = updateSlider;
  $("reset-camera").onclick = () => { state.orbit = { yaw: 0, pitch: 0, zoom: 1 }; request(false); };
  for (const v of [0, 1]) for (const f of ["png", "exr"]) {
    $(`save-${f}-${v}`).onclick = () => state.ws && state.ws.send(JSON.stringify({ type: "save", view: v, format: f }));
  }
  for (const c of [$("canvas-0"), $("canvas-1"), $("slider-box")]) {
    c.addEventListener("pointerdown", orbitStart);
    c.addEventListener("pointermove", orbitMove);
    c.addEventListener("pointerup", orbitEnd);
    c.addEventListener("pointercancel", orbitEnd);
    c.addEventListener("wheel", wheel, { passive: false });
  }
  if (params.get("split") === "1") { $("split").checked = true; state.split = true; }
  layout();
  connect();
}

main().catch((e) => setStatus(String(e), "error"));
