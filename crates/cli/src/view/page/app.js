// The page of `semdynreg view`: one pane per run, one shared camera and time. Frames come
// from /api/splat (the run's Gaussians at t, made by the server from the checkpoint) and
// are drawn by the vendored gsplat.js. The address carries the view: t, the camera
// (`cam=<name>` or `orbit=yaw,pitch,radius,tx,ty,tz`) and `objects=1`; `blank=1` draws
// nothing (the browser test proves with it that its pixel checks can fail).
//
// window.__semdynreg tells a test where the page is: `ready` once every pane has drawn the
// time last asked for (`t`), `firstFrameMs` (from navigation start), `lastStepMs` (from a
// time change to its drawing; `lastFetchMs` of it went to fetching the frames), `error`.

import * as SPLAT from "/vendor/gsplat/index.es.js";
import { Orbit } from "/orbit.js";

const state = (window.__semdynreg = {
  ready: false,
  t: null,
  firstFrameMs: null,
  lastStepMs: null,
  lastFetchMs: null,
  stepsDrawn: 0,
  serverMillis: [],
  error: null,
});
const params = new URLSearchParams(location.search);
const blank = params.get("blank") === "1";
const $ = (id) => document.getElementById(id);

let meta, orbit, camera, panes;
let view = "orbit"; // "orbit" or a camera's name
let focal = 1; // the renderer's fx (pixels of the canvas), fixed for the session
let wanted = null; // the time asked for; `shown` is the time on screen
let shown = null;
let loading = false;
let playing = false;

main().catch(fail);

function fail(e) {
  const msg = String(e && e.message ? e.message : e);
  state.error = msg;
  $("error").textContent = msg;
  console.error(e);
}

async function main() {
  const r = await fetch("/api/meta");
  if (!r.ok) throw new Error(`/api/meta: ${await r.text()}`);
  meta = await r.json();
  camera = new SPLAT.Camera();
  orbit = new Orbit(meta.orbit.target, meta.orbit.up, meta.orbit.radius);
  camera.data.near = meta.orbit.radius * 0.01;
  camera.data.far = meta.orbit.radius * 100;
  panes = meta.runs.map(makePane);
  layout();
  setupControls();
  restoreView();
  requestAnimationFrame(loop);
  const t = Number(params.get("t"));
  const start = params.has("t") && t >= 0 && t <= 1 ? t : meta.times[0];
  $("time").value = String(nearestIndex(start));
  want(start);
}

function makePane(run, index) {
  const div = document.createElement("div");
  div.className = "pane";
  const label = document.createElement("div");
  label.className = "label";
  const objs = run.objects.length ? `, ${run.objects.length} objects` : "";
  label.textContent = `${run.name} · iteration ${run.iteration} · ${run.gaussians} Gaussians${objs}`;
  const legend = document.createElement("div");
  legend.className = "legend";
  legend.hidden = true;
  for (const o of run.objects) {
    const sw = document.createElement("span");
    sw.className = "swatch";
    sw.style.background = `rgb(${o.colour.join(",")})`;
    legend.append(sw, o.name);
  }
  label.append(legend);
  div.append(label);
  // Two canvases: a new time step is drawn on the hidden one and shown once sorted, so
  // the pane never flashes empty while the renderer sorts the new Gaussians.
  const bufs = [0, 1].map(() => {
    const canvas = document.createElement("canvas");
    canvas.dataset.pane = String(index);
    const renderer = new SPLAT.WebGLRenderer(canvas, []);
    canvas.style.background = cssColour(meta.background);
    div.append(canvas);
    return { canvas, renderer, scene: null };
  });
  $("panes").append(div);
  return { run, index, div, legend, bufs, front: 0, pending: null };
}

function cssColour(rgb) {
  return `rgb(${rgb.map((c) => Math.round(c * 255)).join(",")})`;
}

// Sizes the panes to the window at the scene's aspect ratio. The renderer reads the focal
// length when it sets up a scene, so it is chosen here once for the session.
function layout() {
  const [w0, h0] = meta.image;
  const n = panes.length;
  const top = $("panes").getBoundingClientRect().top + 12;
  let w = Math.floor((window.innerWidth - 12 - 6 * (n - 1)) / n);
  let h = Math.round((w * h0) / w0);
  const maxH = Math.max(120, window.innerHeight - top);
  if (h > maxH) {
    h = maxH;
    w = Math.round((h * w0) / h0);
  }
  for (const p of panes) {
    p.div.style.width = `${w}px`;
    p.div.style.height = `${h}px`;
    for (const b of p.bufs) {
      b.canvas.style.width = `${w}px`;
      b.canvas.style.height = `${h}px`;
      b.renderer.setSize(w, h);
    }
    showBuffer(p);
  }
  const cam0 = meta.cameras[0];
  focal = cam0 ? (cam0.fx * w) / cam0.width : w;
  camera.data.fx = focal;
  camera.data.fy = cam0 ? (cam0.fy * h) / cam0.height : focal;
  redraw();
}

function redraw() {
  for (const p of panes) for (const b of p.bufs) b.needsDraw = true;
}

function showBuffer(p) {
  p.bufs.forEach((b, k) => (b.canvas.style.visibility = k === p.front ? "visible" : "hidden"));
}

function setupControls() {
  const slider = $("time");
  slider.max = String(meta.times.length - 1);
  slider.addEventListener("input", () => want(meta.times[Number(slider.value)]));
  $("play").addEventListener("click", togglePlay);
  const select = $("view");
  for (const c of meta.cameras) {
    const o = document.createElement("option");
    o.value = c.name;
    o.textContent = `${c.name} (t=${c.time.toFixed(3)})`;
    select.append(o);
  }
  select.addEventListener("change", () => setView(select.value));
  const hasObjects = meta.runs.some((r) => r.objects.length > 0);
  $("objwrap").hidden = !hasObjects;
  $("objects").checked = hasObjects && params.get("objects") === "1";
  $("objects").addEventListener("change", () => {
    shown = null; // every pane reloads in the other colouring
    want(wanted);
  });
  for (const p of panes) attachPointer(p.div);
}

function attachPointer(el) {
  let last = null;
  el.addEventListener("contextmenu", (e) => e.preventDefault());
  el.addEventListener("pointerdown", (e) => {
    last = { x: e.clientX, y: e.clientY, pan: e.button === 2 || e.shiftKey };
    el.setPointerCapture(e.pointerId);
  });
  el.addEventListener("pointermove", (e) => {
    if (!last) return;
    const dx = e.clientX - last.x;
    const dy = e.clientY - last.y;
    if (last.pan) orbit.pan(dx, dy, focal);
    else orbit.rotate(dx, dy);
    last.x = e.clientX;
    last.y = e.clientY;
    toOrbit();
  });
  el.addEventListener("pointerup", () => (last = null));
  el.addEventListener(
    "wheel",
    (e) => {
      e.preventDefault();
      orbit.zoom(Math.exp(e.deltaY * 0.001));
      toOrbit();
    },
    { passive: false },
  );
}

function toOrbit() {
  view = "orbit";
  $("view").value = "orbit";
  applyCamera();
}

function restoreView() {
  const cam = params.get("cam");
  const o = params.get("orbit");
  if (o && orbit.fromParam(o)) return toOrbit();
  const named = meta.cameras.find((c) => c.name === cam);
  const first = meta.cameras.find((c) => c.split === "test") || meta.cameras[0];
  if (named || first) setView((named || first).name);
  else toOrbit();
}

function setView(name) {
  const c = meta.cameras.find((c) => c.name === name);
  if (!c) return toOrbit();
  view = name;
  $("view").value = name;
  orbit.lookFrom(c.position, c.rotation);
  applyCamera(c);
}

// Puts the shared camera where the view says: a scene camera's exact pose, or the orbit's.
function applyCamera(sceneCam) {
  const pose = sceneCam || orbit.pose();
  camera.position = new SPLAT.Vector3(...pose.position);
  camera.rotation = new SPLAT.Quaternion(...pose.rotation);
  redraw();
  updateAddress();
}

function updateAddress() {
  const q = new URLSearchParams();
  if (wanted !== null) q.set("t", wanted.toFixed(4));
  if (view === "orbit") q.set("orbit", orbit.toParam());
  else q.set("cam", view);
  if ($("objects").checked) q.set("objects", "1");
  if (blank) q.set("blank", "1");
  history.replaceState(null, "", `?${q.toString().replaceAll("%2F", "/").replaceAll("%2C", ",")}`);
}

function nearestIndex(t) {
  let best = 0;
  meta.times.forEach((v, k) => {
    if (Math.abs(v - t) < Math.abs(meta.times[best] - t)) best = k;
  });
  return best;
}

// Asks for time t; one load runs at a time, and only the latest wish is loaded next, so
// dragging the slider does not queue up every step it passes.
function want(t) {
  wanted = t;
  state.ready = false;
  $("tlabel").textContent = t.toFixed(3);
  updateAddress();
  if (!loading) loadLoop().catch(fail);
}

async function loadLoop() {
  loading = true;
  try {
    while (wanted !== shown) {
      const t = wanted;
      const asked = performance.now();
      const colour = $("objects").checked;
      const bufs = await Promise.all(panes.map((p) => fetchFrame(p, t, colour)));
      if (wanted !== t && !playing) continue; // superseded while loading
      const fetched = performance.now();
      await Promise.all(panes.map((p, k) => swapIn(p, bufs[k])));
      shown = t;
      state.t = t;
      state.lastStepMs = performance.now() - asked;
      state.lastFetchMs = fetched - asked;
      state.stepsDrawn += 1;
      if (state.firstFrameMs === null) state.firstFrameMs = performance.now();
      const ms = (v) => v.toFixed(0);
      $("status").textContent =
        `t=${t.toFixed(3)} drawn in ${ms(state.lastStepMs)} ms (frames fetched in ` +
        `${ms(state.lastFetchMs)} ms)`;
    }
    state.ready = true;
  } finally {
    loading = false;
  }
}

async function fetchFrame(p, t, colourByObject) {
  const colour = colourByObject && p.run.objects.length ? "objects" : "rgb";
  const url = `/api/splat?run=${p.index}&t=${t}&colour=${colour}`;
  const r = await fetch(url);
  if (!r.ok) throw new Error(`${url}: ${await r.text()}`);
  state.serverMillis.push(Number(r.headers.get("X-Frame-Millis")));
  p.legend.hidden = colour !== "objects";
  return r.arrayBuffer();
}

// Loads a frame into the pane's hidden canvas; resolves once it is drawn and shown.
function swapIn(p, buffer) {
  const back = p.bufs[1 - p.front];
  back.scene = new SPLAT.Scene();
  SPLAT.Loader.LoadFromArrayBuffer(buffer, back.scene);
  return new Promise((resolve) => {
    p.pending = { back, sorted: back.renderer.renderProgram.depthIndex, resolve };
  });
}

// Draws only what changed: the renderer sorts in a worker, re-sorting only when the camera
// moved, and a draw before its sort arrives would be wasted (SwiftShader draws on the CPU).
function loop() {
  requestAnimationFrame(loop);
  for (const p of panes) {
    if (p.pending) drawPending(p);
    else drawFront(p);
  }
}

// A new time step on the hidden canvas. The renderer packs the Gaussians asynchronously,
// then hands them to its sort worker on the next draw; draws before the depth order
// arrives (a new index array) cost little, as the new scene's index buffer is still empty.
// The first draw after it is complete and is shown.
function drawPending(p) {
  const pend = p.pending;
  if (blank) return finishSwap(p);
  const { renderer, scene } = pend.back;
  const sorted = renderer.renderProgram.depthIndex !== pend.sorted;
  renderer.render(scene, camera);
  if (sorted) {
    pend.back.lastIndex = renderer.renderProgram.depthIndex;
    finishSwap(p);
  }
}

// The visible canvas: drawn after a camera change, and once more when the worker's sort
// for the new camera arrives.
function drawFront(p) {
  const b = p.bufs[p.front];
  if (!b.scene || blank) return;
  const index = b.renderer.renderProgram.depthIndex;
  if (b.needsDraw || index !== b.lastIndex) {
    b.renderer.render(b.scene, camera);
    b.needsDraw = false;
    b.lastIndex = index;
  }
}

function finishSwap(p) {
  const { resolve } = p.pending;
  p.pending = null;
  p.front = 1 - p.front;
  showBuffer(p);
  resolve();
}

function togglePlay() {
  playing = !playing;
  $("play").textContent = playing ? "pause" : "play";
  if (playing) playLoop().catch(fail);
}

// Steps through the slider's times at the chosen speed (t per second), waiting for each
// step to be drawn, so a slow step slows the playback rather than skipping.
async function playLoop() {
  const slider = $("time");
  while (playing) {
    const started = performance.now();
    const next = (Number(slider.value) + 1) % meta.times.length;
    slider.value = String(next);
    want(meta.times[next]);
    while (loading || wanted !== shown) await sleep(10);
    const step = meta.times.length > 1 ? Math.abs(meta.times[1] - meta.times[0]) : 1;
    const period = (1000 * step) / Number($("speed").value);
    await sleep(Math.max(0, period - (performance.now() - started)));
  }
}

function sleep(ms) {
  return new Promise((r) => setTimeout(r, ms));
}

window.addEventListener("resize", () => {
  if (panes) layout();
});
