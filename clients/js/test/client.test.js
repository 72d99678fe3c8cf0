// relume.js against a real server (RELUME_URL, started by tests/js_client.rs), with node:test.
import { test } from "node:test";
import assert from "node:assert/strict";
import { createRequire } from "node:module";
import { createHash } from "node:crypto";
import { readFileSync } from "node:fs";
import { Client, RelumeError } from "../relume.js";

// Node's own WebSocket (22+), else the `ws` package scripts/nodetools.sh installs.
const WebSocket = globalThis.WebSocket ?? createRequire(import.meta.url)(process.env.RELUME_WS_MODULE).WebSocket;

const URL = process.env.RELUME_URL;
const L = [0.2, 0.5, 0.9];
// A grey sphere (reflectance 0.5) up and left under a uniform environment: the background is L
// and the sphere rho*L exactly for `path`, so the frame's pixels are known.
const SPHERE = {
  camera: { position: [0, 0, 5], look_at: [0, 0, 0], vfov_deg: 40, resolution: [32, 24] },
  materials: { grey: { type: "diffuse", reflectance: [0.5, 0.5, 0.5] } },
  objects: [{ name: "ball", shape: { type: "sphere", segments: 64 }, material: "grey",
    transform: { translation: [-0.9, 0.6, 0], scale: [0.7, 0.7, 0.7] } }],
  environment: { radiance: L },
};

const pixel = (f, x, y) => Array.from(f.data.slice(3 * (y * f.width + x), 3 * (y * f.width + x) + 3));
const close = (a, b, rel) => a.every((v, i) => Math.abs(v - b[i]) <= rel * Math.abs(b[i]));

test("a frame is the linear radiance, row by row", async () => {
  assert.ok(URL, "RELUME_URL is not set: run this through tests/js_client.rs");
  const s = await new Client(URL).createSession(SPHERE, { technique: { id: "path", spp: 4 }, width: 32, height: 24 });
  const stats = await s.tick();
  assert.equal(stats.tick, 0);
  const f = await s.frame();
  assert.equal(f.data.length, 32 * 24 * 3);
  assert.ok(close(pixel(f, 31, 23), L, 1e-6), `background ${pixel(f, 31, 23)}`);
  assert.ok(close(pixel(f, 8, 5), L.map((c) => 0.5 * c), 1e-5), `ball ${pixel(f, 8, 5)}`);
  // Negative control: the rows read bottom-up miss the ball.
  assert.ok(!close(pixel(f, 8, 23 - 5), L.map((c) => 0.5 * c), 1e-5));
  const png = await s.framePng();
  assert.deepEqual(Array.from(png.slice(0, 4)), [0x89, 0x50, 0x4e, 0x47]);
  await s.delete();
});

test("an uploaded scene is the bytes sent and opens as a session", async () => {
  const c = new Client(URL);
  const glb = readFileSync(new globalThis.URL("../../../scenes/cornell-box.glb", import.meta.url));
  const record = await c.uploadScene("js-box.glb", new Uint8Array(glb));
  assert.equal(record.bytes, glb.length);
  assert.equal(record.sha256, createHash("sha256").update(glb).digest("hex"));
  const listed = (await c.scenes()).find((s) => s.name === "js-box.glb");
  assert.equal(listed.triangles, record.triangles);
  const frames = [];
  for (const scene of ["cornell-box.glb", "js-box.glb"]) {
    const s = await c.createSession(scene, { technique: { id: "path", spp: 2 }, width: 16, height: 12, seed: 3 });
    await s.tick();
    frames.push((await s.frame()).data);
    await s.delete();
  }
  assert.deepEqual(frames[0], frames[1]);
  await c.deleteScene("js-box.glb");
  await assert.rejects(c.deleteScene("js-box.glb"), (e) => e instanceof RelumeError && e.status === 404);
});

test("errors reject with one error type naming the field", async () => {
  const c = new Client(URL);
  const s = await c.createSession("cornell-box", { technique: { id: "path" }, width: 16, height: 16 });
  await assert.rejects(s.edit([{ target: "object", name: "no-such-object", transform: {} }]), (e) =>
    e instanceof RelumeError && e.status === 422 && e.detail.includes("edits[0].name"));
  await s.delete();
});

test("the socket acknowledges every batch and a tick applies them", async () => {
  const s = await new Client(URL).createSession("cornell-box", { technique: { id: "path" }, width: 16, height: 16 });
  const socket = await s.connect({ frames: "f32", WebSocket });
  const acks = [];
  let last = null;
  // Every check runs inside the promise, so a failed one (or the socket closing early) ends
  // the test with its reason instead of leaving it waiting on an open socket.
  const done = new Promise((resolve, reject) => {
    const guard = (f) => (...args) => {
      try {
        f(...args);
        if (acks.length === 5 && last && last.stats.edits_applied_through >= 5) resolve(last);
      } catch (e) {
        reject(e);
      }
    };
    socket.onError = reject;
    socket.onClose = (code, reason) => reject(new Error(`socket closed (${code} ${reason}) with acks ${acks}`));
    socket.onAck = guard((seq) => acks.push(seq));
    socket.onTick = guard((t) => {
      assert.equal(t.frame.format, "f32");
      assert.equal(t.frame.data.length, 16 * 16 * 3);
      last = t;
    });
  });
  try {
    for (let k = 0; k < 5; k++) {
      socket.sendEdits([{ target: "camera", position: [278, 273, -800 + k] }]);
      socket.sendTick();
    }
    socket.sendTick();
    const final = await done;
    assert.deepEqual(acks, [1, 2, 3, 4, 5]);
    assert.ok(final.stats.edits_applied_through >= 5);
  } finally {
    socket.onClose = () => {};
    socket.close();
    await s.delete();
  }
});
