// Types of relume.js; the shapes follow proto/openapi.yaml.

export class RelumeError extends Error {
  constructor(status: number, error: string, detail: string);
  status: number;
  error: string;
  detail: string;
}

export type Edit = { target: "object" | "light" | "camera" | "material" | "environment"; [field: string]: unknown };

export interface EditsAccepted { queued: number; pending: number; seq: number }

export interface TickStats {
  tick: number;
  technique: string;
  times: Record<string, number>;
  rays: { primary: number; secondary: number; shadow: number };
  edits_received: number;
  edits_coalesced: number;
  edits_unchanged: number;
  edits_applied_through: number;
  moved_surfaces: number;
  spp: number;
  paths_per_pixel: number;
  accumulation_id: number;
  detail: { id: string; memory: { total_bytes: number; parts: Record<string, number> }; [k: string]: unknown };
  [k: string]: unknown;
}

export interface UploadRecord {
  name: string;
  bytes: number;
  sha256: string;
  triangles: number;
  animations: string[];
  scene_file: string;
}

export interface SessionView { id: string; scene: string; width: number; height: number; [k: string]: unknown }

/** Linear RGB radiance, rows from the top: data[3 * (y * width + x) + c]. */
export interface FloatFrame { width: number; height: number; data: Float32Array }

export interface SocketFrame {
  tick: number;
  accumulationId: number;
  format: "png" | "jpg" | "exr" | "f32";
  width: number;
  height: number;
  data: Float32Array | Uint8Array;
}

export interface SocketTick { stats: TickStats; framesDropped: number; frame: SocketFrame | null }

export function parseFrame(buffer: ArrayBuffer): SocketFrame;

export class Client {
  constructor(url?: string, options?: { token?: string | null });
  url: string;
  token: string | null;
  /** `body`: bytes (Blob, ArrayBuffer, typed array) are sent as they are, anything else as JSON. */
  raw(method: string, path: string, body?: unknown, init?: RequestInit): Promise<Response>;
  request(method: string, path: string, body?: unknown, init?: RequestInit): Promise<any>;
  techniques(): Promise<Record<string, unknown>>;
  scenes(): Promise<Array<Record<string, unknown>>>;
  uploadScene(name: string, data: Blob | ArrayBuffer | Uint8Array): Promise<UploadRecord>;
  deleteScene(name: string): Promise<void>;
  createSession(scene: string | Record<string, unknown>, options?: Record<string, unknown>): Promise<Session>;
  wsUrl(path: string): string;
}

export class Session {
  client: Client;
  view: SessionView;
  id: string;
  edit(edits: Edit[]): Promise<EditsAccepted>;
  tick(): Promise<TickStats>;
  frame(options?: { tick?: number }): Promise<FloatFrame>;
  framePng(options?: { exposure?: number }): Promise<Uint8Array>;
  snapshot(): Promise<Record<string, unknown>>;
  delete(): Promise<void>;
  connect(options?: { frames?: "png" | "jpg" | "exr" | "f32" | "none"; WebSocket?: unknown }): Promise<Socket>;
}

export class Socket {
  onTick: (tick: SocketTick) => void;
  onAck: (seq: number) => void;
  onError: (error: RelumeError) => void;
  /** The close code (4410 session deleted, 4409 session failed, 1001 server shutting down) and reason. */
  onClose: (code: number, reason: string) => void;
  sendEdits(edits: Edit[]): void;
  sendTick(): void;
  close(): void;
}
