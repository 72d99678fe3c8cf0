// relume-client: a dependency-free ES module for relume's HTTP API and WebSocket
// (proto/openapi.yaml, proto/ws.schema.json), for browsers and Node 18+ (whose WebSocket,
// before Node 22, is the `ws` package's, passed to `connect`). Frames come as Float32Array of linear RGB radiance
// (rows from the top) from the server's raw `frame.f32`, or as encoded bytes.

/** An error answer: HTTP `status` (0 for a WebSocket message), `error` and `detail`. */
export class RelumeError extends Error {
  constructor(status, error, detail) {
    super(`${status} ${error}: ${detail}`);
    this.status = status;
    this.error = error;
    this.detail = detail;
  }
}

const FRAME_FORMATS = ["png", "jpg", "exr", "f32"];

/** Reads a binary WebSocket frame: its 32-byte header and the image after it. */
export function parseFrame(buffer) {
  const view = new DataView(buffer);
  const magic = String.fromCharCode(...new Uint8Array(buffer, 0, 4));
  if (magic !== "RLM1") throw new RelumeError(0, "bad_frame", `header magic '${magic}'`);
  const format = FRAME_FORMATS[view.getUint8(20)];
  const width = view.getUint32(24, true);
  const height = view.getUint32(28, true);
  const body = buffer.slice(32);
  return {
    tick: Number(view.getBigUint64(4, true)),
    accumulationId: Number(view.getBigUint64(12, true)),
    format,
    width,
    height,
    data: format === "f32" ? floats(body, width, height) : new Uint8Array(body),
  };
}

function floats(buffer, width, height) {
  if (buffer.byteLength !== width * height * 12) {
    throw new RelumeError(0, "bad_frame", `${buffer.byteLength} bytes for a ${width}x${height} RGB float frame`);
  }
  const out = new Float32Array(width * height * 3);
  const view = new DataView(buffer);
  for (let i = 0; i < out.length; i++) out[i] = view.getFloat32(4 * i, true);
  return out;
}

/** Whether a request body is sent as it is (bytes) rather than as JSON. */
function isBinary(body) {
  return body instanceof ArrayBuffer || ArrayBuffer.isView(body) || (typeof Blob !== "undefined" && body instanceof Blob);
}

export class Client {
  /** `url`: the server, e.g. "http://127.0.0.1:8080"; `token`: its bearer token, if any. */
  constructor(url = "http://127.0.0.1:8080", { token = null } = {}) {
    this.url = url.replace(/\/+$/, "");
    this.token = token;
  }

  /** Sends a request (`body` as JSON, or bytes as they are; `init` more fetch options, such as `keepalive`) and
   * resolves to the response, or rejects with a {@link RelumeError} for an error answer. */
  async raw(method, path, body, init = {}) {
    const headers = {};
    const binary = isBinary(body);
    if (body !== undefined) headers["content-type"] = binary ? "application/octet-stream" : "application/json";
    if (this.token) headers.authorization = `Bearer ${this.token}`;
    const response = await fetch(this.url + path, {
      ...init,
      method,
      headers,
      body: body === undefined || binary ? body : JSON.stringify(body),
    });
    if (!response.ok) {
      const text = await response.text();
      let error = "error", detail = text;
      try {
        ({ error, detail } = JSON.parse(text));
      } catch { /* not JSON: keep the text */ }
      throw new RelumeError(response.status, error, detail);
    }
    return response;
  }

  /** As {@link Client#raw}, resolving to the answer's JSON (its text when it is not JSON). */
  async request(method, path, body, init = {}) {
    const response = await this.raw(method, path, body, init);
    return response.headers.get("content-type")?.includes("json") ? response.json() : response.text();
  }

  techniques() { return this.request("GET", "/v1/techniques"); }

  /** The bundled and uploaded scenes (uploads with `bytes`, `sha256` and `triangles`). */
  async scenes() { return (await this.request("GET", "/v1/scenes")).scenes; }

  /** Uploads a scene as `name` (`NAME.glb`, or `NAME.zip` of a .gltf with its files): `data` is
   * a Blob or File (a browser streams it from disk), an ArrayBuffer or a Uint8Array. Resolves
   * to its record {name, bytes, sha256, triangles, animations, scene_file}; sessions then open
   * it by `name`, and the same name again replaces it. */
  uploadScene(name, data) { return this.request("PUT", `/v1/scenes/${encodeURIComponent(name)}`, data); }

  /** Deletes an uploaded scene (sessions already open on it keep it). */
  async deleteScene(name) { await this.raw("DELETE", `/v1/scenes/${encodeURIComponent(name)}`); }

  /** Starts a session on a bundled scene's name or an inline scene; `options` are the other
   * fields of POST /v1/sessions (technique, width, height, seed, tick_hz, denoise, environment). */
  async createSession(scene, options = {}) {
    return new Session(this, await this.request("POST", "/v1/sessions", { scene, ...options }));
  }

  wsUrl(path) {
    const base = this.url.replace(/^http/, "ws") + path;
    return this.token ? `${base}?token=${encodeURIComponent(this.token)}` : base;
  }
}

export class Session {
  constructor(client, view) {
    this.client = client;
    this.view = view;
    this.id = view.id;
  }

  path(rest) { return `/v1/sessions/${this.id}/${rest}`; }

  /** Queues an edit batch for the next tick; resolves to its acknowledgement ({queued, pending, seq}). */
  edit(edits) { return this.client.request("POST", this.path("edits"), { edits }); }

  /** Runs one tick (or joins the one pending); resolves to its stats. */
  async tick() { return (await this.client.request("POST", this.path("tick"))).stats; }

  /** The newest frame as {width, height, data: Float32Array} of linear RGB, rows from the top. */
  async frame({ tick } = {}) {
    const query = tick === undefined ? "" : `?tick=${tick}`;
    const response = await this.client.raw("GET", this.path(`frame.f32${query}`));
    const width = Number(response.headers.get("x-relume-width"));
    const height = Number(response.headers.get("x-relume-height"));
    return { width, height, data: floats(await response.arrayBuffer(), width, height) };
  }

  /** The newest frame as PNG bytes, `exposure` stops brighter. */
  async framePng({ exposure = 0 } = {}) {
    const response = await this.client.raw("GET", this.path(`frame.png?exposure=${exposure}`));
    return new Uint8Array(await response.arrayBuffer());
  }

  snapshot() { return this.client.request("GET", this.path("snapshot")); }

  async delete() { await this.client.raw("DELETE", `/v1/sessions/${this.id}`); }

  /** Opens the session's WebSocket: see {@link Socket}. `WebSocket` is the implementation to
   * use where there is no global one (Node before 22: the `ws` package's). */
  connect({ frames = "f32", WebSocket = globalThis.WebSocket } = {}) {
    return Socket.open(this.client.wsUrl(this.path("ws")), frames, WebSocket);
  }
}

/** A session's WebSocket: `send*` queue edits and ticks at once; `onTick` gets each published
 * tick with its frame, `onAck` each edit batch's `seq`, `onError` each error message, and
 * `onClose` the close code and reason once the socket has closed (4410: session deleted, 4409:
 * session failed, 1001: server shutting down). */
export class Socket {
  static open(url, frames, WebSocketImpl) {
    return new Promise((resolve, reject) => {
      if (!WebSocketImpl) throw new RelumeError(0, "socket", "no WebSocket here: pass one to connect()");
      const ws = new WebSocketImpl(url);
      ws.binaryType = "arraybuffer";
      ws.onerror = () => reject(new RelumeError(0, "socket", `cannot open ${url}`));
      ws.onopen = () => {
        ws.send(JSON.stringify({ type: "subscribe", frames, stats: true }));
        resolve(new Socket(ws, frames !== "none"));
      };
    });
  }

  constructor(ws, withFrames) {
    this.ws = ws;
    this.onTick = () => {};
    this.onAck = () => {};
    this.onError = (e) => { throw e; };
    this.onClose = () => {};
    ws.onclose = (event) => this.onClose(event.code, event.reason);
    let pending = null;
    ws.onmessage = (event) => {
      if (typeof event.data !== "string") {
        if (pending) this.onTick({ ...pending, frame: parseFrame(event.data) });
        pending = null;
        return;
      }
      const m = JSON.parse(event.data);
      if (m.type === "edits_accepted") this.onAck(m.seq);
      else if (m.type === "error") this.onError(new RelumeError(0, m.error, m.detail));
      else if (m.type === "stats") {
        const tick = { stats: m.stats, framesDropped: m.frames_dropped, frame: null };
        if (withFrames) pending = tick;
        else this.onTick(tick);
      }
    };
  }

  sendEdits(edits) { this.ws.send(JSON.stringify({ type: "edits", edits })); }

  sendTick() { this.ws.send(JSON.stringify({ type: "tick" })); }

  close() { this.ws.close(); }
}
