// relume viewer: start a session with any technique (the server's registry, GET
// /v1/techniques), or on a dropped .glb; watch frames over the WebSocket with per-tick plots;
// click to pick an object or light (GET .../pick), drag to move it; play the scene's
// animation. Plain JS, no build step. ?token=... is passed to the API.
import { Client } from "/relume.js";
const $ = (id) => document.getElementById(id);
const token = new URLSearchParams(location.search).get("token");
const state = { id: null, ws: null, scene: null, frames: 0, lastUrl: null, extent: 1, pending: null, history: [] };
window.relume = state; // for tests and curious people

// Every HTTP call goes through relume's own JavaScript client (clients/js/relume.js, served at
// /relume.js): the viewer is its first user.
const client = new Client(location.origin, { token });
function api(path, { method = "GET", body, keepalive } = {}) {
  return client.request(method, path, body, keepalive ? { keepalive } : {});
}

function status(text) { $("status").textContent = text; }

// Builds an element with text content (never HTML from data: scene, object and animation names
// come from uploaded files) and optional attributes and inline style properties.
function el(tag, text, attrs = {}, style = {}) {
  const node = document.createElement(tag);
  if (text !== undefined) node.textContent = text;
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
  Object.assign(node.style, style);
  return node;
}

// Replaces a <select>'s options: items are { value, text, title }.
function setOptions(select, items) {
  select.replaceChildren(...items.map((i) => el("option", i.text, Object.assign({ value: i.value }, i.title ? { title: i.title } : {}))));
}

async function loadScenes() {
  const { scenes } = await api("/v1/scenes");
  state.scenes = scenes;
  setOptions($("scene"), scenes.map((s) => ({ value: s.name, text: s.name })));
  const preferred = scenes.find((s) => s.name === "merry-go-round") || scenes[0];
  if (preferred) $("scene").value = preferred.name;
}

// The technique picker and each technique's main parameters, from the server's registry.
async function loadTechniques() {
  const list = await api("/v1/techniques");
  state.techniques = list.techniques;
  state.limits = list;
  setOptions($("technique"), list.techniques.map((t) => ({ value: t.id, text: t.id, title: t.summary })));
  $("technique").value = "path";
  showParams();
}

function control(p, value) {
  const attrs = { id: `param-${p.name}`, "data-param": p.name, "data-type": p.type };
  const label = el("label", undefined, { title: p.help });
  if (p.type === "choice") {
    const select = el("select", undefined, attrs);
    select.append(...p.choices.map((c) => el("option", c)));
    if (p.choices.includes(String(value))) select.value = String(value);
    label.append(`${p.name} `, select);
    return label;
  }
  if (p.type === "boolean") {
    const box = el("input", undefined, Object.assign({ type: "checkbox" }, attrs));
    box.checked = Boolean(value);
    label.append(box, ` ${p.name}`);
    return label;
  }
  const max = p.name === "spp" ? Math.min(p.max, state.limits.max_spp_per_tick) : p.max;
  const step = p.type === "integer" ? 1 : "any";
  const input = el("input", undefined, Object.assign({ type: "number", min: p.min, max, step }, attrs));
  input.value = value;
  label.append(`${p.name} `, input);
  return label;
}

function showParams() {
  const t = state.techniques.find((x) => x.id === $("technique").value);
  $("params").replaceChildren(...(t ? t.parameters.map((p) => control(p, t.defaults[p.name])) : []));
}

function techniqueConfig() {
  const config = { id: $("technique").value };
  for (const el of document.querySelectorAll("[data-param]")) {
    const type = el.dataset.type;
    config[el.dataset.param] = type === "boolean" ? el.checked : type === "choice" ? el.value : Number(el.value);
  }
  return config;
}

// Every movable target: dynamic objects and lights, with their current transforms.
function targets() {
  const out = [];
  for (const o of state.scene.objects) if (o.dynamic) out.push({ kind: "object", name: o.name, t: o.transform });
  for (const l of state.scene.lights || []) if (l.dynamic) out.push({ kind: "light", name: l.name, t: l.transform });
  return out;
}

function selected() {
  const [kind, name] = $("target").value.split("/");
  return targets().find((t) => t.kind === kind && t.name === name);
}

function setSliders() {
  const t = selected();
  if (!t) return;
  ["tx", "ty", "tz"].forEach((id, i) => {
    const v = t.t.translation[i];
    Object.assign($(id), { min: v - state.extent, max: v + state.extent, value: v });
  });
  const q = t.t.rotation;
  $("turn").value = Math.round((2 * Math.atan2(q[1], q[3]) * 180) / Math.PI);
}

// Sends the selected target's transform (translation from the sliders, turn about +Y).
function sendMove() {
  const t = selected();
  if (!t || !state.ws || state.ws.readyState !== 1) return;
  const a = (Number($("turn").value) * Math.PI) / 360;
  t.t = Object.assign({}, t.t, {
    translation: [Number($("tx").value), Number($("ty").value), Number($("tz").value)],
    rotation: [0, Math.sin(a), 0, Math.cos(a)],
  });
  const edit = t.kind === "object"
    ? { target: "object", name: t.name, transform: t.t }
    : { target: "light", name: t.name, transform: t.t };
  state.ws.send(JSON.stringify({ type: "edits", edits: [edit] }));
  state.edits = (state.edits || 0) + 1;
}

// The scene's first directional light, turned by the sun sliders: elevation above the
// horizon and azimuth about +Y (0 towards −Z), of the direction the light comes from.
function sunLight() {
  return (state.scene.lights || []).find((l) => l.emitter.type === "directional");
}

function setSunSliders() {
  const sun = sunLight();
  $("sun").hidden = !sun;
  if (!sun) return;
  const d = sun.emitter.direction.map((v) => -v);
  const len = Math.hypot(...d) || 1;
  $("sun-elevation").value = (Math.asin(d[1] / len) * 180) / Math.PI;
  $("sun-azimuth").value = (Math.atan2(d[0], -d[2]) * 180) / Math.PI;
}

function sendSun() {
  const sun = sunLight();
  if (!sun || !state.ws || state.ws.readyState !== 1) return;
  const up = (Number($("sun-elevation").value) * Math.PI) / 180;
  const az = (Number($("sun-azimuth").value) * Math.PI) / 180;
  const from = [Math.cos(up) * Math.sin(az), Math.sin(up), -Math.cos(up) * Math.cos(az)];
  sun.emitter = Object.assign({}, sun.emitter, { direction: from.map((v) => -v) });
  state.ws.send(JSON.stringify({ type: "edits", edits: [{ target: "light", name: sun.name, emitter: sun.emitter }] }));
  state.edits = (state.edits || 0) + 1;
}

function scheduleMove() {
  if (state.pending) return;
  state.pending = requestAnimationFrame(() => { state.pending = null; sendMove(); });
}

function showStats(s, dropped) {
  state.history.push(s);
  if (state.history.length > 120) state.history.shift();
  drawPlots();
  const rows = [
    ["tick", s.tick], ["spp", s.spp], ["accumulation", s.accumulation_id],
    ["tick time (ms)", s.times.total_ms.toFixed(1)],
    ["rays primary", s.rays.primary], ["rays secondary", s.rays.secondary], ["rays shadow", s.rays.shadow],
    ["edits received / coalesced / unchanged", `${s.edits_received} / ${s.edits_coalesced} / ${s.edits_unchanged}`],
    ["frames dropped", dropped],
    ["edits applied through (seq)", s.edits_applied_through],
    ["resident memory (MiB)", (s.detail.memory.total_bytes / 1048576).toFixed(1)],
  ];
  $("stats").tBodies[0].replaceChildren(...rows.map(([k, v]) => {
    const tr = el("tr");
    tr.append(el("td", k), el("td", String(v)));
    return tr;
  }));
  const stages = ["apply_ms", "commit_ms", "update_ms", "render_ms", "resolve_ms", "denoise_ms"];
  const total = Math.max(s.times.total_ms, 1e-6);
  $("stages").replaceChildren(...stages.map((k) =>
    el("div", `${k.replace("_ms", "")} ${s.times[k].toFixed(2)} ms`, { class: "bar" }, { width: `${Math.max(1, (100 * s.times[k]) / total)}%` })));
}

const STAGES = [["apply_ms", "#a78bfa"], ["commit_ms", "#f59e0b"], ["update_ms", "#ef4444"], ["render_ms", "#3b82f6"], ["resolve_ms", "#10b981"], ["denoise_ms", "#ec4899"]];
const RAYS = [["primary", "#3b82f6"], ["secondary", "#f59e0b"], ["shadow", "#9ca3af"]];

// Stacked columns, one per tick (newest right), scaled to the tallest.
function stacked(canvas, series) {
  const g = canvas.getContext("2d");
  const { width: w, height: h } = canvas;
  g.clearRect(0, 0, w, h);
  const n = state.history.length;
  const totals = state.history.map((_, i) => series.reduce((a, s) => a + s.values[i], 0));
  const top = Math.max(...totals, 1e-9);
  const bar = w / 120;
  state.history.forEach((_, i) => {
    let y = h;
    for (const s of series) {
      const dh = (s.values[i] / top) * (h - 12);
      g.fillStyle = s.color;
      g.fillRect(w - (n - i) * bar, y - dh, Math.max(1, bar - 1), dh);
      y -= dh;
    }
  });
  g.fillStyle = "#9aa0a6";
  g.font = "10px system-ui";
  g.fillText(`max ${top.toPrecision(3)}`, 2, 10);
}

function drawPlots() {
  const h = state.history;
  stacked($("plot-stages"), STAGES.map(([k, color]) => ({ color, values: h.map((s) => s.times[k] || 0) })));
  stacked($("plot-rays"), RAYS.map(([k, color]) => ({ color, values: h.map((s) => s.rays[k]) })));
  stacked($("plot-spp"), [{ color: "#10b981", values: h.map((s) => s.spp) }]);
  if (!$("legend").childElementCount) {
    $("legend").replaceChildren(...[...STAGES, ...RAYS].map(([k, c]) => {
      const span = el("span");
      span.append(el("i", undefined, {}, { background: c }), k.replace("_ms", ""));
      return span;
    }));
  }
}

function showFrame(buffer) {
  const view = new DataView(buffer);
  const magic = String.fromCharCode(...new Uint8Array(buffer, 0, 4));
  if (magic !== "RLM1") return;
  const tick = Number(view.getBigUint64(4, true));
  const accumulation = Number(view.getBigUint64(12, true));
  const format = ["image/png", "image/jpeg", "image/x-exr"][view.getUint8(20)] || "image/png";
  const blob = new Blob([new Uint8Array(buffer, 32)], { type: format });
  const url = URL.createObjectURL(blob);
  $("frame").src = url;
  if (state.lastUrl) URL.revokeObjectURL(state.lastUrl);
  state.lastUrl = url;
  state.frames += 1;
  state.tick = tick;
  state.accumulation = accumulation;
  // A cheap fingerprint of the encoded frame, so tests can tell frames apart.
  const bytes = new Uint8Array(buffer, 32);
  let h = 2166136261;
  for (let i = 0; i < bytes.length; i += 7) h = Math.imul(h ^ bytes[i], 16777619) >>> 0;
  state.fingerprint = h;
  document.body.dataset.frames = String(state.frames);
}

// Starts a session on the picked scene, or on a glTF file (base64) when given one.
async function start(glb) {
  if (state.ws) state.ws.close();
  if (state.id) api(`/v1/sessions/${state.id}`, { method: "DELETE" }).catch(() => {});
  state.history = [];
  const size = Number($("size").value);
  const body = { technique: techniqueConfig(), width: size, height: size, tick_hz: Number($("hz").value) };
  if (glb) body.scene_glb = glb;
  else body.scene = $("scene").value;
  if ($("denoise").value) body.denoise = { quality: $("denoise").value };
  status("starting…");
  try {
    const s = await api("/v1/sessions", { method: "POST", body });
    state.id = s.id;
    state.scene = await api(`/v1/sessions/${s.id}/scene`);
    const c = state.scene.camera;
    state.extent = Math.hypot(c.position[0] - c.look_at[0], c.position[1] - c.look_at[1], c.position[2] - c.look_at[2]) * 0.6;
    setOptions($("target"), targets().map((t) => ({ value: `${t.kind}/${t.name}`, text: `${t.kind} ${t.name}` })));
    setSliders();
    setSunSliders();
    const entry = glb ? null : state.scenes.find((x) => x.name === $("scene").value);
    const animations = (s.animations || []).length ? s.animations : entry ? entry.animations : [];
    setOptions($("animation"), animations.map((a) => ({ value: a, text: a })));
    connect(s.id);
    $("switch").disabled = false;
    status(`session ${s.id}` + (s.warnings ? ` — ${s.warnings.length} load warning(s): ${s.warnings.join("; ")}` : ""));
  } catch (e) {
    status("error: " + e.message);
  }
}

// Runs the picked technique, parameters and denoiser on this session from its next tick on,
// keeping its scene as moved (PATCH /v1/sessions/{id}); the plots start over with it.
async function switchTechnique() {
  if (!state.id) return;
  const denoise = $("denoise").value ? { quality: $("denoise").value } : null;
  try {
    const s = await api(`/v1/sessions/${state.id}`, { method: "PATCH", body: { technique: techniqueConfig(), denoise } });
    state.history = [];
    status(`session ${s.id} — now running ${s.technique.id}`);
  } catch (e) {
    status("error: " + e.message);
  }
}

// Denoising sessions send their denoised frames unless "raw" is ticked.
function subscribe() {
  if (state.ws && state.ws.readyState === WebSocket.OPEN) {
    state.ws.send(JSON.stringify({ type: "subscribe", frames: "png", stats: true, every: 1, denoised: !$("raw").checked }));
  }
}

function connect(id) {
  const proto = location.protocol === "https:" ? "wss" : "ws";
  const ws = new WebSocket(`${proto}://${location.host}/v1/sessions/${id}/ws${token ? "?token=" + encodeURIComponent(token) : ""}`);
  ws.binaryType = "arraybuffer";
  ws.onopen = subscribe;
  ws.onmessage = (m) => {
    if (typeof m.data !== "string") return showFrame(m.data);
    const msg = JSON.parse(m.data);
    if (msg.type === "stats") showStats(msg.stats, msg.frames_dropped);
    else if (msg.type === "error") status(`error: ${msg.detail}`);
  };
  ws.onclose = () => status("disconnected");
  state.ws = ws;
}

// Selects what the camera sees under the pointer (GET .../pick); a static surface is named
// but cannot be moved, so the selection stays.
async function pickAt(e) {
  if (!state.id || !state.scene) return;
  const img = $("frame");
  const c = state.scene.camera;
  const x = (e.offsetX / img.clientWidth) * c.resolution[0];
  const y = (e.offsetY / img.clientHeight) * c.resolution[1];
  try {
    const p = await api(`/v1/sessions/${state.id}/pick?x=${x.toFixed(2)}&y=${y.toFixed(2)}`);
    state.picked = p;
    if (!p.hit) return;
    if (p.dynamic) {
      $("target").value = `${p.target}/${p.name}`;
      setSliders();
      status(`selected ${p.target} ${p.name}`);
    } else {
      status(`${p.target} ${p.name} is static`);
    }
  } catch (err) {
    status("pick: " + err.message);
  }
}

function toBase64(buffer) {
  const bytes = new Uint8Array(buffer);
  let text = "";
  for (let i = 0; i < bytes.length; i += 0x8000) text += String.fromCharCode(...bytes.subarray(i, i + 0x8000));
  return btoa(text);
}

// Files up to this size go inline with the session request (as base64, within the server's
// 8 MiB request limit); larger ones, and every .zip, are uploaded first.
const INLINE_BYTES = 4 << 20;

// A .glb, a self-contained .gltf, or a .zip of a .gltf with its files, dropped on the page or
// chosen, starts a session on it: small ones inline, others uploaded (PUT /v1/scenes/NAME,
// streamed from disk by the browser, so any size the server allows) and then opened by name.
async function startFile(file) {
  if (!file) return;
  const zip = file.name.toLowerCase().endsWith(".zip");
  if (!zip && file.size <= INLINE_BYTES) {
    status(`reading ${file.name}…`);
    await start(toBase64(await file.arrayBuffer()));
    return;
  }
  const stem = file.name.replace(/\.[^.]*$/, "").replace(/[^A-Za-z0-9_-]+/g, "-").replace(/^-+|-+$/g, "") || "scene";
  const name = `${stem}.${zip ? "zip" : "glb"}`;
  status(`uploading ${file.name} (${(file.size / 1048576).toFixed(1)} MiB) as ${name}…`);
  try {
    const record = await client.uploadScene(name, file);
    await loadScenes();
    $("scene").value = record.name;
    await start();
  } catch (e) {
    status("error: " + e.message);
  }
}
state.startFile = startFile; // for tests

function installDrop() {
  document.addEventListener("dragover", (e) => { e.preventDefault(); document.body.classList.add("dropping"); });
  document.addEventListener("dragleave", () => document.body.classList.remove("dropping"));
  document.addEventListener("drop", (e) => {
    e.preventDefault();
    document.body.classList.remove("dropping");
    startFile(e.dataTransfer.files[0]);
  });
  $("glb").addEventListener("change", () => startFile($("glb").files[0]));
}

// Dragging on the image moves the selected target over the ground plane, in camera-relative
// directions: right along the camera's right, up along its forward (both projected to XZ).
function installDrag() {
  const img = $("frame");
  let last = null;
  let down = false;
  img.addEventListener("pointerdown", async (e) => {
    down = true;
    img.setPointerCapture(e.pointerId);
    img.classList.add("dragging");
    await pickAt(e);
    if (down) last = [e.clientX, e.clientY];
  });
  img.addEventListener("pointerup", () => { down = false; last = null; img.classList.remove("dragging"); });
  img.addEventListener("pointermove", (e) => {
    if (!last || !state.scene) return;
    const [dx, dy] = [e.clientX - last[0], e.clientY - last[1]];
    last = [e.clientX, e.clientY];
    const c = state.scene.camera;
    const f = [c.look_at[0] - c.position[0], 0, c.look_at[2] - c.position[2]];
    const fl = Math.hypot(f[0], f[2]) || 1;
    const fwd = [f[0] / fl, f[2] / fl];
    const right = [-fwd[1], fwd[0]];
    const scale = (2 * state.extent) / img.clientWidth;
    $("tx").value = Number($("tx").value) + (dx * right[0] - dy * fwd[0]) * scale;
    $("tz").value = Number($("tz").value) + (dx * right[1] - dy * fwd[1]) * scale;
    scheduleMove();
  });
}

$("start").addEventListener("click", () => start());
$("switch").addEventListener("click", switchTechnique);
$("technique").addEventListener("change", showParams);
$("raw").addEventListener("change", subscribe);
// Leaving the page deletes its session rather than leaving it to the server's idle expiry.
window.addEventListener("pagehide", () => {
  if (state.id) api(`/v1/sessions/${state.id}`, { method: "DELETE", keepalive: true }).catch(() => {});
});
$("target").addEventListener("change", setSliders);
["tx", "ty", "tz", "turn"].forEach((id) => $(id).addEventListener("input", scheduleMove));
["sun-elevation", "sun-azimuth"].forEach((id) => $(id).addEventListener("input", () => {
  if (state.pendingSun) return;
  state.pendingSun = requestAnimationFrame(() => { state.pendingSun = null; sendSun(); });
}));
$("play").addEventListener("click", () => state.ws && state.ws.send(JSON.stringify({ type: "play", anim: $("animation").value, speed: 1 })));
$("pause").addEventListener("click", () => state.ws && state.ws.send(JSON.stringify({ type: "pause" })));
installDrag();
installDrop();
Promise.all([loadScenes(), loadTechniques()]).catch((e) => status("error: " + e.message));
