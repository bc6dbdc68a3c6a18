// duplex view: the page's logic. Talks only to the HTTP interface (docs/viewer.md) with the token of
// its URL. Every name that comes from the scene file is shown through textContent, never as HTML.
"use strict";

const TOKEN = new URLSearchParams(location.search).get("token") || "";
const FULL = { w: 640, h: 400 };
const LOW_FACTOR = 3;          // while the mouse moves: a third of the resolution
const SETTLE_MS = 150;         // then full resolution once it has rested this long
const PICK_RADIUS_PX = 5;
const PLOT_SECONDS = 60;

const $ = (id) => document.getElementById(id);
const state = {
  scene: null,
  camera: null,          // {eye, target, up, fov_deg}
  fitCamera: null,
  selected: null,        // node path
  hover: null,           // the last hover pick
  frameWanted: false,
  frameInFlight: false,
  lowRes: false,
  lastMove: 0,
  frames: 0,
  commit: -1,
  lastUpdate: null,      // the last commit's answer (update_ms, changes)
  history: [],           // {t, frame_ms, trace_ms}
  drag: null,
  dragGroup: 0,
  editInFlight: false,
  pendingEdit: null,
  timeline: null,
  playing: false,
  time: 0,
};

// ---- HTTP ----
async function api(method, path, body) {
  const init = { method, headers: { "X-Duplex-Token": TOKEN } };
  if (body !== undefined) {
    init.body = JSON.stringify(body);
    init.headers["Content-Type"] = "application/json";
  }
  const res = await fetch(path, init);
  if (!res.ok) {
    let message = res.status + "";
    try { message = (await res.json()).error; } catch (e) { /* not JSON */ }
    throw new Error(message);
  }
  return res;
}
const getJson = async (path) => (await api("GET", path)).json();
const postJson = async (path, body) => (await api("POST", path, body)).json();

function say(text) { $("message").textContent = text || ""; }

// ---- vectors ----
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const mul = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const len = (a) => Math.sqrt(dot(a, a));
const norm = (a) => mul(a, 1 / len(a));

// The camera's frame, as the server builds it (forward, right, up).
function frame(cam) {
  const f = norm(sub(cam.target, cam.eye));
  const r = norm(cross(f, cam.up));
  return { f, r, u: cross(r, f) };
}

function cameraJson(w, h) {
  const c = state.camera;
  return { eye: c.eye, target: c.target, up: c.up, fov_deg: c.fov_deg, width: w, height: h };
}

// World point -> pixel of the full-size frame (null behind the camera).
function project(p) {
  const c = state.camera, { f, r, u } = frame(c);
  const v = sub(p, c.eye), depth = dot(v, f);
  if (!(depth > 0)) return null;
  const halfH = Math.tan(0.5 * c.fov_deg * Math.PI / 180), halfW = halfH * FULL.w / FULL.h;
  return [(dot(v, r) / depth / halfW + 1) * 0.5 * FULL.w, (1 - dot(v, u) / depth / halfH) * 0.5 * FULL.h];
}

// ---- frames ----
function requestFrame(lowRes) {
  state.lowRes = lowRes;
  state.frameWanted = true;
  pumpFrames();
}

async function pumpFrames() {
  if (state.frameInFlight || !state.frameWanted || !state.camera) return;
  state.frameWanted = false;
  state.frameInFlight = true;
  const low = state.lowRes;
  const w = low ? Math.round(FULL.w / LOW_FACTOR) : FULL.w, h = low ? Math.round(FULL.h / LOW_FACTOR) : FULL.h;
  const t0 = performance.now();
  try {
    const res = await api("POST", "/api/render",
      { camera: cameraJson(w, h), format: "jpeg", highlight: state.selected, sensors: $("sensor-overlay").checked,
        edges: $("edges").checked });
    const blob = await res.blob();
    const url = URL.createObjectURL(blob);
    const img = $("view");
    await new Promise((resolve) => { img.onload = resolve; img.onerror = resolve; img.src = url; });
    if (img.dataset.url) URL.revokeObjectURL(img.dataset.url);
    img.dataset.url = url;
    state.frames += 1;
    img.dataset.frames = String(state.frames);
    img.dataset.commit = res.headers.get("X-Duplex-Commit") || "";
    img.dataset.width = String(w);
    const traceMs = parseFloat(res.headers.get("X-Duplex-Trace-Ms"));
    const rays = parseInt(res.headers.get("X-Duplex-Rays"), 10);
    const frameMs = performance.now() - t0;
    state.history.push({ t: performance.now() / 1000, frame_ms: frameMs, trace_ms: traceMs });
    showStats(w, h, frameMs, traceMs, rays);
    drawOverlay();
  } catch (e) {
    say("render: " + e.message);
  } finally {
    state.frameInFlight = false;
  }
  if (state.frameWanted) pumpFrames();
  else if (low && performance.now() - state.lastMove >= SETTLE_MS && !state.drag) requestFrame(false);
}

// After the mouse rests, one frame at full resolution.
setInterval(() => {
  if (state.lowRes && !state.frameInFlight && !state.drag && performance.now() - state.lastMove >= SETTLE_MS)
    requestFrame(false);
}, 50);

function showStats(w, h, frameMs, traceMs, rays) {
  const mrays = traceMs > 0 ? rays / traceMs / 1000 : 0;
  let text = `frame     ${frameMs.toFixed(1)} ms  (${w} x ${h}${state.lowRes ? ", moving" : ""})\n` +
    `trace     ${traceMs.toFixed(2)} ms  ${mrays.toFixed(1)} Mrays/s (${rays} rays)\n`;
  const u = state.lastUpdate;
  if (u) {
    const c = u.changes;
    text += `update    ${u.update_ms.toFixed(3)} ms  (commit ${c.commit}: ${c.moved} moved, ${c.appeared} appeared, ` +
      `${c.disappeared} disappeared, ${c.object_changed} object changed)\n`;
  } else {
    text += "update    (no commit yet)\n";
  }
  $("stats").textContent = text;
  drawPlot();
}

function drawPlot() {
  const cv = $("plot"), g = cv.getContext("2d"), now = performance.now() / 1000;
  state.history = state.history.filter((s) => now - s.t <= PLOT_SECONDS);
  g.clearRect(0, 0, cv.width, cv.height);
  const top = Math.max(20, ...state.history.map((s) => s.frame_ms));
  const series = [["frame_ms", "#6cf"], ["trace_ms", "#fc6"]];
  for (const [key, colour] of series) {
    g.strokeStyle = colour;
    g.beginPath();
    state.history.forEach((s, i) => {
      const x = cv.width * (1 - (now - s.t) / PLOT_SECONDS), y = cv.height * (1 - s[key] / top);
      if (i === 0) g.moveTo(x, y); else g.lineTo(x, y);
    });
    g.stroke();
  }
  g.fillStyle = "#99a";
  g.fillText(`${top.toFixed(0)} ms  (frame blue, trace yellow, last ${PLOT_SECONDS} s)`, 4, 10);
}

// The hover pick and the selection, drawn over the frame.
function drawOverlay() {
  const cv = $("overlay");
  cv.width = FULL.w; cv.height = FULL.h;
  const g = cv.getContext("2d");
  const p = state.hover;
  if (!p || !p.path || !p.point) return;
  const px = project(p.point);
  if (!px) return;
  g.strokeStyle = "#ff3"; g.lineWidth = 2;
  g.beginPath();
  if (p.element === "vertex") g.arc(px[0], px[1], 5, 0, 2 * Math.PI);
  else if (p.element === "edge") { g.moveTo(px[0] - 7, px[1] - 7); g.lineTo(px[0] + 7, px[1] + 7); g.moveTo(px[0] - 7, px[1] + 7); g.lineTo(px[0] + 7, px[1] - 7); }
  else g.rect(px[0] - 3, px[1] - 3, 6, 6);
  g.stroke();
}

function describePick(p) {
  if (!p || !p.path) return "(nothing)";
  let s = `${p.path}  ${p.element}`;
  if (p.element === "face") s += ` ${p.prim_id}`;
  else s += ` ${p.vertices.join("-")}`;
  return s + `  (${p.distance_px.toFixed(1)} px)`;
}

// ---- camera ----
function orbit(dx, dy) {
  const c = state.camera, { r } = frame(c);
  const rot = (v, axis, a) => {  // Rodrigues
    const k = norm(axis), cs = Math.cos(a), sn = Math.sin(a);
    return add(add(mul(v, cs), mul(cross(k, v), sn)), mul(k, dot(k, v) * (1 - cs)));
  };
  let off = sub(c.eye, c.target);
  off = rot(off, c.up, -dx * 0.008);
  const tilted = rot(off, r, -dy * 0.008);
  const cosToUp = dot(norm(tilted), norm(c.up));
  if (Math.abs(cosToUp) < 0.995) off = tilted;  // not over the pole
  c.eye = add(c.target, off);
}

function pan(dx, dy) {
  const c = state.camera, { r, u } = frame(c);
  const d = len(sub(c.eye, c.target));
  const perPixel = 2 * d * Math.tan(0.5 * c.fov_deg * Math.PI / 180) / FULL.h;
  const move = add(mul(r, -dx * perPixel), mul(u, dy * perPixel));
  c.eye = add(c.eye, move); c.target = add(c.target, move);
}

function zoom(steps) {
  const c = state.camera, off = sub(c.eye, c.target);
  c.eye = add(c.target, mul(off, Math.pow(1.1, steps)));
}

function fitAll() {
  state.camera = JSON.parse(JSON.stringify(state.fitCamera));
  requestFrame(false);
}

// ---- editing ----
const nodeByPath = () => new Map(state.scene.nodes.map((n) => [n.path, n]));

// 3x3 of a row-major 3x4, and its inverse.
const lin = (m) => [[m[0], m[1], m[2]], [m[4], m[5], m[6]], [m[8], m[9], m[10]]];
function inv3(a) {
  const [[a0, a1, a2], [b0, b1, b2], [c0, c1, c2]] = a;
  const d = a0 * (b1 * c2 - b2 * c1) - a1 * (b0 * c2 - b2 * c0) + a2 * (b0 * c1 - b1 * c0);
  return [[(b1 * c2 - b2 * c1) / d, (a2 * c1 - a1 * c2) / d, (a1 * b2 - a2 * b1) / d],
          [(b2 * c0 - b0 * c2) / d, (a0 * c2 - a2 * c0) / d, (a2 * b0 - a0 * b2) / d],
          [(b0 * c1 - b1 * c0) / d, (a1 * c0 - a0 * c1) / d, (a0 * b1 - a1 * b0) / d]];
}
const mv = (m, v) => [dot(m[0], v), dot(m[1], v), dot(m[2], v)];

// A drag of the selected part: the cursor's motion in the plane through the grabbed point,
// parallel to the image, becomes a translation of the node (in its parent's space).
function dragTo(x, y) {
  const d = state.drag, c = state.camera, { f, r, u } = frame(c);
  const depth = dot(sub(d.point, c.eye), f);
  const perPixel = 2 * depth * Math.tan(0.5 * c.fov_deg * Math.PI / 180) / FULL.h;
  const world = add(mul(r, (x - d.x0) * perPixel), mul(u, -(y - d.y0) * perPixel));
  // parent_from_world's linear part = local * world^-1 (world = parent * local).
  const delta = mv(lin(d.local), mv(inv3(lin(d.world)), world));
  const m = d.local.slice();
  m[3] += delta[0]; m[7] += delta[1]; m[11] += delta[2];
  sendEdit({ edits: [{ node: d.path, set_transform: m }], group: d.group });
}

// Affine maps as row-major 3x4 arrays (the interface's form): a after b, and the inverse.
function compose(a, b) {
  const out = new Array(12);
  for (let i = 0; i < 3; i++) {
    for (let j = 0; j < 4; j++) {
      out[4 * i + j] = a[4 * i] * b[j] + a[4 * i + 1] * b[4 + j] + a[4 * i + 2] * b[8 + j] + (j === 3 ? a[4 * i + 3] : 0);
    }
  }
  return out;
}
function inverseAffine(m) {
  const l = inv3(lin(m)), t = mv(l, [m[3], m[7], m[11]]);
  return [l[0][0], l[0][1], l[0][2], -t[0], l[1][0], l[1][1], l[1][2], -t[1], l[2][0], l[2][1], l[2][2], -t[2]];
}

// A Ctrl-drag of the selected part: turns it about the axis through the grabbed point along the
// image's up direction (a turntable), 0.5 degree per pixel of horizontal motion. The new world
// transform is M * world with M that rotation, so local' = local * world^-1 * M * world.
function rotateTo(x) {
  const d = state.drag, { u } = frame(state.camera);
  const a = norm(u), angle = (x - d.x0) * 0.5 * Math.PI / 180, c = Math.cos(angle), s = Math.sin(angle), k = 1 - c;
  const r = [[c + a[0] * a[0] * k, a[0] * a[1] * k - a[2] * s, a[0] * a[2] * k + a[1] * s],
             [a[1] * a[0] * k + a[2] * s, c + a[1] * a[1] * k, a[1] * a[2] * k - a[0] * s],
             [a[2] * a[0] * k - a[1] * s, a[2] * a[1] * k + a[0] * s, c + a[2] * a[2] * k]];
  const t = sub(d.point, mv(r, d.point));  // the grabbed point stays where it is
  const m = [r[0][0], r[0][1], r[0][2], t[0], r[1][0], r[1][1], r[1][2], t[1], r[2][0], r[2][1], r[2][2], t[2]];
  const local = compose(d.local, compose(inverseAffine(d.world), compose(m, d.world)));
  sendEdit({ edits: [{ node: d.path, set_transform: local }], group: d.group });
}

// One edit request in flight; a newer one replaces a waiting one (drags send absolute transforms).
function sendEdit(body) {
  state.pendingEdit = body;
  pumpEdits();
}

async function pumpEdits() {
  if (state.editInFlight || !state.pendingEdit) return;
  const body = state.pendingEdit;
  state.pendingEdit = null;
  state.editInFlight = true;
  try {
    state.lastUpdate = await postJson("/api/edits", body);
    say("");
    requestFrame(!!state.drag);
  } catch (e) {
    say("edit refused: " + e.message);
  } finally {
    state.editInFlight = false;
  }
  if (state.pendingEdit) pumpEdits();
  else if (!state.drag) await reloadScene();
}

async function undo() {
  try {
    state.lastUpdate = await postJson("/api/undo");
    say("");
    await reloadScene();
    requestFrame(false);
  } catch (e) { say("undo: " + e.message); }
}

// ---- picking ----
let hoverInFlight = false, hoverWanted = null;
async function hoverPick(x, y) {
  hoverWanted = [x, y];
  if (hoverInFlight) return;
  hoverInFlight = true;
  while (hoverWanted) {
    const [hx, hy] = hoverWanted;
    hoverWanted = null;
    try {
      state.hover = await postJson("/api/pick", { camera: cameraJson(FULL.w, FULL.h), x: hx, y: hy, radius_px: PICK_RADIUS_PX });
      $("hover").textContent = "under the cursor: " + describePick(state.hover) +
        (state.hover.pick_ms !== undefined ? `  pick ${state.hover.pick_ms.toFixed(2)} ms` : "");
      drawOverlay();
    } catch (e) { $("hover").textContent = "pick: " + e.message; }
  }
  hoverInFlight = false;
}

async function select(x, y) {
  const p = await postJson("/api/pick", { camera: cameraJson(FULL.w, FULL.h), x, y, radius_px: PICK_RADIUS_PX });
  state.selected = p.path;
  $("pick").textContent = p.path || "(none)";
  $("pick-detail").textContent = p.path ? describePick(p) : "";
  markTree();
  requestFrame(false);
  return p;
}

// ---- mouse ----
function setupMouse() {
  const box = $("frame-box");
  const pos = (e) => { const b = box.getBoundingClientRect(); return [e.clientX - b.left, e.clientY - b.top]; };
  box.addEventListener("contextmenu", (e) => e.preventDefault());
  box.addEventListener("mousedown", async (e) => {
    const [x, y] = pos(e);
    state.lastMove = performance.now();
    const panning = e.button === 2 || e.shiftKey;
    state.mouse = { x, y, x0: x, y0: y, mode: panning ? "pan" : "orbit", moved: false };
    if (!panning && state.selected && state.hover && state.hover.path === state.selected && state.hover.point) {
      const n = nodeByPath().get(state.selected);
      if (n && n.local) {
        state.dragGroup += 1;
        state.drag = { path: n.path, local: n.local, world: n.world, point: state.hover.point, x0: x, y0: y,
          group: `drag-${Date.now()}-${state.dragGroup}`, rotate: e.ctrlKey || e.metaKey };
        state.mouse.mode = "drag";
      }
    }
  });
  window.addEventListener("mousemove", (e) => {
    const [x, y] = pos(e);
    const m = state.mouse;
    if (!m) {
      if (x >= 0 && y >= 0 && x < FULL.w && y < FULL.h) hoverPick(x, y);
      return;
    }
    const dx = x - m.x, dy = y - m.y;
    if (Math.abs(x - m.x0) + Math.abs(y - m.y0) > 2) m.moved = true;
    m.x = x; m.y = y;
    if (!m.moved) return;
    state.lastMove = performance.now();
    if (m.mode === "drag") { if (state.drag.rotate) rotateTo(x); else dragTo(x, y); return; }
    if (m.mode === "pan") pan(dx, dy); else orbit(dx, dy);
    requestFrame(true);
  });
  window.addEventListener("mouseup", async (e) => {
    const m = state.mouse;
    state.mouse = null;
    const wasDrag = state.drag;
    state.drag = null;
    if (!m) return;
    if (!m.moved) { try { await select(m.x0, m.y0); } catch (err) { say("pick: " + err.message); } return; }
    if (wasDrag) {
      state.hover = null;  // it marked the part where it was
      drawOverlay();
      await reloadScene();
    }
    requestFrame(false);
  });
  box.addEventListener("wheel", (e) => {
    e.preventDefault();
    state.lastMove = performance.now();
    zoom(e.deltaY > 0 ? 1 : -1);
    requestFrame(true);
  }, { passive: false });
  window.addEventListener("keydown", (e) => {
    if (e.target.tagName === "INPUT") return;
    if (e.key === "f" || e.key === "F") fitAll();
    else if (e.key === "u" || (e.key === "z" && (e.ctrlKey || e.metaKey))) { e.preventDefault(); undo(); }
  });
}

// ---- scene tree ----
function buildTree() {
  const tree = $("tree");
  tree.textContent = "";
  const byPath = nodeByPath();
  const walk = (path, depth) => {
    const n = byPath.get(path);
    if (!n) return;
    if (path !== "/") {
      const row = document.createElement("div");
      row.dataset.path = n.path;
      row.style.paddingLeft = (depth * 12) + "px";
      const box = document.createElement("input");
      box.type = "checkbox";
      box.checked = n.visible;
      box.title = "visible";
      box.addEventListener("change", () => sendEdit({ edits: [{ node: n.path, visible: box.checked }] }));
      const name = document.createElement("span");
      name.textContent = " " + n.path.slice(n.path.lastIndexOf("/") + 1) + " ";
      name.addEventListener("click", () => {
        state.selected = n.kind === "instance" ? n.path : null;
        $("pick").textContent = state.selected || "(none)";
        markTree(); requestFrame(false);
      });
      const kind = document.createElement("span");
      kind.className = "kind";
      kind.textContent = n.kind === "instance" ? n.object : n.kind;
      row.append(box, name, kind);
      tree.append(row);
    }
    for (const c of n.children) walk(c, depth + (path === "/" ? 0 : 1));
  };
  walk("/", 0);
  const body = $("objects").querySelector("tbody");
  body.textContent = "";
  for (const o of state.scene.objects) {
    const tr = document.createElement("tr");
    for (const v of [o.name, o.type, o.triangles.toLocaleString(), (o.memory_bytes / 1048576).toFixed(2) + " MB"]) {
      const td = document.createElement("td");
      td.textContent = v;
      tr.append(td);
    }
    body.append(tr);
  }
  markTree();
}

function markTree() {
  for (const row of $("tree").children) row.classList.toggle("selected", row.dataset.path === state.selected);
}

async function reloadScene() {
  state.scene = await getJson("/api/scene");
  state.commit = state.scene.commit;
  buildTree();
}

// ---- timeline ----
function setupTimeline() {
  const times = state.scene.timeline;
  if (!times || !times.length) return;
  $("timeline").hidden = false;
  const scrub = $("scrub");
  scrub.max = String(times[times.length - 1]);
  scrub.value = String(state.scene.time || 0);
  let busy = false, wanted = null;
  const go = async (t) => {
    wanted = t;
    if (busy) return;
    busy = true;
    while (wanted !== null) {
      const tt = wanted;
      wanted = null;
      try {
        state.lastUpdate = await postJson("/api/time", { t: tt });
        state.time = tt;
        $("time-label").textContent = `t = ${tt.toFixed(2)} s (${state.lastUpdate.edits_applied} edits)`;
        requestFrame(state.playing);
      } catch (e) { say("time: " + e.message); }
    }
    busy = false;
  };
  scrub.addEventListener("input", () => go(parseFloat(scrub.value)));
  scrub.addEventListener("change", async () => { await reloadScene(); });
  let last = 0;
  const tick = (now) => {
    if (!state.playing) return;
    const dt = last ? (now - last) / 1000 : 0;
    last = now;
    let t = parseFloat(scrub.value) + dt;
    if (t >= parseFloat(scrub.max)) { t = parseFloat(scrub.max); state.playing = false; $("play").textContent = "play"; }
    scrub.value = String(t);
    go(t);
    if (state.playing) requestAnimationFrame(tick); else { reloadScene(); requestFrame(false); }
  };
  $("play").addEventListener("click", () => {
    state.playing = !state.playing;
    $("play").textContent = state.playing ? "pause" : "play";
    if (state.playing) {
      if (parseFloat(scrub.value) >= parseFloat(scrub.max)) scrub.value = "0";
      last = 0;
      requestAnimationFrame(tick);
    } else { reloadScene(); requestFrame(false); }
  });
}

// ---- sensors ----
function falseColour(t) {  // t in [0, 1]: dark blue, cyan, yellow, red
  const stops = [[0, 0, 0.3], [0, 0.8, 1], [1, 1, 0], [1, 0.1, 0]];
  const x = Math.min(0.9999, Math.max(0, t)) * (stops.length - 1), i = Math.floor(x), f = x - i;
  return stops[i].map((a, k) => Math.round(255 * (a + (stops[i + 1][k] - a) * f)));
}

function showSensorResults(sensors) {
  const out = $("sensor-results");
  out.textContent = "";
  for (const s of sensors) {
    const box = document.createElement("div");
    box.className = "sensor-map";
    const cv = document.createElement("canvas");
    const caption = document.createElement("div");
    caption.textContent = `${s.name}: ${s.total_flux_w.toPrecision(4)} W` +
      (s.relative_stderr !== null ? ` (\u00b1${(100 * s.relative_stderr).toFixed(1)}%)` : "");
    if (s.shape === "farfield") {
      // Polar plot: intensity against gamma, one curve per C-plane (up to 4 drawn).
      cv.width = 160; cv.height = 160;
      const g = cv.getContext("2d"), nc = s.bins[0], ng = s.bins[1];
      const max = Math.max(1e-30, ...s.intensity_w_sr);
      g.strokeStyle = "#445";
      for (const r of [0.25, 0.5, 0.75, 1]) { g.beginPath(); g.arc(80, 80, 75 * r, 0, 2 * Math.PI); g.stroke(); }
      const colours = ["#6cf", "#fc6", "#f6c", "#6f9"];
      for (let k = 0; k < Math.min(4, nc); ++k) {
        const ic = Math.floor(k * nc / Math.min(4, nc));
        g.strokeStyle = colours[k];
        g.beginPath();
        for (let ig = 0; ig < ng; ++ig) {
          const gamma = s.gamma_deg[ig] * Math.PI / 180, r = 75 * s.intensity_w_sr[ic * ng + ig] / max;
          const x = 80 + r * Math.sin(gamma), y = 80 + r * Math.cos(gamma);  // nadir down
          if (ig === 0) g.moveTo(x, y); else g.lineTo(x, y);
        }
        g.stroke();
      }
    } else {
      const nx = s.bins[0], ny = s.bins[1];
      cv.width = nx; cv.height = ny;
      const scale = Math.max(1, Math.floor(160 / Math.max(nx, ny)));
      cv.style.width = (nx * scale) + "px"; cv.style.height = (ny * scale) + "px";
      const g = cv.getContext("2d"), img = g.createImageData(nx, ny);
      const max = Math.max(1e-30, ...s.irradiance_w_m2);
      for (let iy = 0; iy < ny; ++iy) for (let ix = 0; ix < nx; ++ix) {
        const c = falseColour(s.irradiance_w_m2[iy * nx + ix] / max), o = ((ny - 1 - iy) * nx + ix) * 4;  // +y up
        img.data[o] = c[0]; img.data[o + 1] = c[1]; img.data[o + 2] = c[2]; img.data[o + 3] = 255;
      }
      g.putImageData(img, 0, 0);
      caption.textContent += `, peak ${max.toPrecision(3)} W/unit\u00b2`;
    }
    box.append(cv, caption);
    out.append(box);
  }
}

function setupSensors() {
  if (!state.scene.sensors || !state.scene.sensors.length || !state.scene.lights) return;
  $("sensors").hidden = false;
  let timer = null;
  const poll = async () => {
    try {
      const s = await getJson("/api/sensors/status");
      $("sensor-progress").value = s.progress;
      $("sensor-state").textContent = `${s.state} ${s.rays_done.toLocaleString()} / ${s.rays.toLocaleString()} rays` +
        (s.error ? ": " + s.error : "");
      const running = s.state === "running";
      $("sensor-run").disabled = running;
      $("sensor-cancel").disabled = !running;
      if (!running) {
        clearInterval(timer); timer = null;
        if (s.sensors.length) {
          showSensorResults(s.sensors);
          if (s.state === "completed" && !$("sensor-overlay").checked) { $("sensor-overlay").checked = true; requestFrame(false); }
        }
      }
    } catch (e) { say("sensors: " + e.message); }
  };
  $("sensor-run").addEventListener("click", async () => {
    try {
      await postJson("/api/sensors/run", { rays: parseInt($("sensor-rays").value, 10), seed: 1 });
      if (!timer) timer = setInterval(poll, 400);
      poll();
    } catch (e) { say("sensors: " + e.message); }
  });
  $("sensor-overlay").addEventListener("change", () => requestFrame(false));
  $("sensor-cancel").addEventListener("click", async () => {
    try { await postJson("/api/sensors/cancel"); } catch (e) { say("sensors: " + e.message); }
  });
  poll();
}

// Other tabs share the scene: follow their commits while this one is idle.
setInterval(async () => {
  if (!state.scene || state.mouse || state.playing || state.editInFlight) return;
  try {
    const s = await getJson("/api/scene");
    if (s.commit !== state.commit) { state.scene = s; state.commit = s.commit; buildTree(); requestFrame(false); }
  } catch (e) { /* the server may be gone; the next frame says so */ }
}, 2000);

async function start() {
  try {
    await reloadScene();
  } catch (e) { say("scene: " + e.message); return; }
  $("file").textContent = state.scene.file + " (" + state.scene.format + ")";
  if (!state.scene.camera) { say("the scene has no visible instance"); return; }
  state.fitCamera = { eye: state.scene.camera.eye, target: state.scene.camera.target, up: state.scene.camera.up,
    fov_deg: state.scene.camera.fov_deg };
  state.camera = JSON.parse(JSON.stringify(state.fitCamera));
  setupMouse();
  setupTimeline();
  setupSensors();
  $("undo").addEventListener("click", undo);
  $("fit").addEventListener("click", fitAll);
  $("edges").addEventListener("change", () => requestFrame(false));
  requestFrame(false);
}

start();
