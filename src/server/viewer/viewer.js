// relume viewer: start a session, watch frames over the WebSocket, move objects and lights,
// play the scene's animation. Plain JS, no build step. ?token=... is passed to the API.
"use strict";
const $ = (id) => document.getElementById(id);
const token = new URLSearchParams(location.search).get("token");
const state = { id: null, ws: null, scene: null, frames: 0, lastUrl: null, extent: 1, pending: null };
window.relume = state; // for tests and curious people

function api(path, options = {}) {
  const headers = Object.assign({ "content-type": "application/json" }, options.headers || {});
  if (token) headers.authorization = "Bearer " + token;
  return fetch(path, Object.assign({}, options, { headers })).then(async (r) => {
    const body = r.headers.get("content-type")?.includes("json") ? await r.json() : await r.text();
    if (!r.ok) throw new Error(body.detail || body.error || r.statusText);
    return body;
  });
}

function status(text) { $("status").textContent = text; }

async function loadScenes() {
  const { scenes } = await api("/v1/scenes");
  state.scenes = scenes;
  $("scene").innerHTML = scenes.map((s) => `<option>${s.name}</option>`).join("");
  const preferred = scenes.find((s) => s.name === "merry-go-round") || scenes[0];
  if (preferred) $("scene").value = preferred.name;
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

function scheduleMove() {
  if (state.pending) return;
  state.pending = requestAnimationFrame(() => { state.pending = null; sendMove(); });
}

function showStats(s, dropped) {
  const rows = [
    ["tick", s.tick], ["spp", s.spp], ["accumulation", s.accumulation_id],
    ["tick time (ms)", s.times.total_ms.toFixed(1)],
    ["rays primary", s.rays.primary], ["rays secondary", s.rays.secondary], ["rays shadow", s.rays.shadow],
    ["edits received / coalesced / unchanged", `${s.edits_received} / ${s.edits_coalesced} / ${s.edits_unchanged}`],
    ["frames dropped", dropped],
    ["resident memory (MiB)", (s.detail.memory.total_bytes / 1048576).toFixed(1)],
  ];
  $("stats").tBodies[0].innerHTML = rows.map(([k, v]) => `<tr><td>${k}</td><td>${v}</td></tr>`).join("");
  const stages = ["apply_ms", "commit_ms", "update_ms", "render_ms", "resolve_ms", "denoise_ms"];
  const total = Math.max(s.times.total_ms, 1e-6);
  $("stages").innerHTML = stages
    .map((k) => `<div class="bar" style="width:${Math.max(1, (100 * s.times[k]) / total)}%">${k.replace("_ms", "")} ${s.times[k].toFixed(2)} ms</div>`)
    .join("");
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

async function start() {
  if (state.ws) state.ws.close();
  if (state.id) api(`/v1/sessions/${state.id}`, { method: "DELETE" }).catch(() => {});
  const size = Number($("size").value);
  const body = {
    scene: $("scene").value,
    technique: { id: $("technique").value, spp: Number($("spp").value) },
    width: size, height: size, tick_hz: Number($("hz").value),
  };
  if ($("denoise").value) body.denoise = { quality: $("denoise").value };
  status("starting…");
  try {
    const s = await api("/v1/sessions", { method: "POST", body: JSON.stringify(body) });
    state.id = s.id;
    state.scene = await api(`/v1/sessions/${s.id}/scene`);
    const c = state.scene.camera;
    state.extent = Math.hypot(c.position[0] - c.look_at[0], c.position[1] - c.look_at[1], c.position[2] - c.look_at[2]) * 0.6;
    $("target").innerHTML = targets().map((t) => `<option value="${t.kind}/${t.name}">${t.kind} ${t.name}</option>`).join("");
    setSliders();
    const entry = state.scenes.find((x) => x.name === $("scene").value);
    $("animation").innerHTML = (entry ? entry.animations : []).map((a) => `<option>${a}</option>`).join("");
    connect(s.id);
    status(`session ${s.id}`);
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

// Dragging on the image moves the selected target over the ground plane, in camera-relative
// directions: right along the camera's right, up along its forward (both projected to XZ).
function installDrag() {
  const img = $("frame");
  let last = null;
  img.addEventListener("pointerdown", (e) => { last = [e.clientX, e.clientY]; img.classList.add("dragging"); img.setPointerCapture(e.pointerId); });
  img.addEventListener("pointerup", () => { last = null; img.classList.remove("dragging"); });
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

$("start").addEventListener("click", start);
$("raw").addEventListener("change", subscribe);
// Leaving the page deletes its session rather than leaving it to the server's idle expiry.
window.addEventListener("pagehide", () => {
  if (state.id) api(`/v1/sessions/${state.id}`, { method: "DELETE", keepalive: true }).catch(() => {});
});
$("target").addEventListener("change", setSliders);
["tx", "ty", "tz", "turn"].forEach((id) => $(id).addEventListener("input", scheduleMove));
$("play").addEventListener("click", () => state.ws && state.ws.send(JSON.stringify({ type: "play", anim: $("animation").value, speed: 1 })));
$("pause").addEventListener("click", () => state.ws && state.ws.send(JSON.stringify({ type: "pause" })));
installDrag();
loadScenes().catch((e) => status("error: " + e.message));
