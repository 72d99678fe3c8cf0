"""Blocking and asyncio clients for relume's HTTP API and WebSocket (`proto/openapi.yaml`,
`proto/ws.schema.json`).

Frames come back as numpy float32 arrays of shape (height, width, 3), linear Rec.709 radiance,
from the server's raw `frame.f32` (little-endian floats, rows from the top); `frame_png` gives
the encoded bytes. Every error answer raises :class:`RelumeError`.
"""
from __future__ import annotations

import asyncio
import json
import os
import pathlib
import struct
import urllib.parse
from dataclasses import dataclass
from typing import Any, AsyncIterator, Callable, Dict, Iterable, List, Optional, Sequence, Union

import httpx
import numpy as np
import websockets

from .models import EditsAccepted, SessionView, TickDone, TickStats, UploadRecord

Edit = Dict[str, Any]
#: Edits for each step of a stream: a list per step, or a function of the step's index.
EditSource = Union[Sequence[Sequence[Edit]], Callable[[int], Sequence[Edit]]]

FRAME_HEADER = struct.Struct("<4sQQB3xII")
FRAME_FORMATS = {0: "png", 1: "jpg", 2: "exr", 3: "f32"}


class RelumeError(Exception):
    """An error answer: the HTTP `status` (0 for a WebSocket message), the machine-readable
    `error` and the `detail` that names the field at fault."""

    def __init__(self, status: int, error: str, detail: str):
        super().__init__(f"{status} {error}: {detail}")
        self.status = status
        self.error = error
        self.detail = detail


def _raise_for(response: httpx.Response) -> None:
    if response.is_success:
        return
    try:
        body = response.json()
        error, detail = body.get("error", "error"), body.get("detail", response.text)
    except ValueError:
        error, detail = "error", response.text
    raise RelumeError(response.status_code, error, detail)


def raw_frame(data: bytes, width: int, height: int) -> np.ndarray:
    """A `frame.f32` body as a (height, width, 3) float32 array."""
    expected = width * height * 3 * 4
    if len(data) != expected:
        raise RelumeError(0, "bad_frame", f"{len(data)} bytes for a {width}x{height} RGB float frame ({expected})")
    return np.frombuffer(data, dtype="<f4").reshape(height, width, 3)


def _headers(token: Optional[str]) -> Dict[str, str]:
    return {"authorization": f"Bearer {token}"} if token else {}


#: Bytes an upload reads from its file at a time.
UPLOAD_CHUNK = 1 << 20


def _file_chunks(path: pathlib.Path) -> Iterable[bytes]:
    with open(path, "rb") as f:
        while chunk := f.read(UPLOAD_CHUNK):
            yield chunk


def _create_body(scene: Union[str, Dict[str, Any]], technique: Optional[Dict[str, Any]], **options: Any) -> Dict[str, Any]:
    body: Dict[str, Any] = {"scene": scene}
    if technique is not None:
        body["technique"] = technique
    body.update({k: v for k, v in options.items() if v is not None})
    return body


class Session:
    """A running session, driven over HTTP (blocking)."""

    def __init__(self, client: "Client", view: SessionView):
        self._client = client
        self.view = view
        self.id = view.id

    def _path(self, rest: str) -> str:
        return f"/v1/sessions/{self.id}/{rest}"

    def edit(self, edits: Iterable[Edit]) -> EditsAccepted:
        """Queues an edit batch for the next tick; returns its acknowledgement (`seq`)."""
        body = self._client._request("POST", self._path("edits"), json={"edits": list(edits)})
        return EditsAccepted.from_json(body)

    def tick(self) -> TickStats:
        """Runs one tick (or joins the one pending) and returns its stats."""
        return self.tick_done().stats

    def tick_done(self) -> TickDone:
        return TickDone.from_json(self._client._request("POST", self._path("tick")))

    def frame(self, tick: Optional[int] = None, denoised: bool = True) -> np.ndarray:
        """The newest frame (or tick `tick`'s) as linear float32 radiance, (height, width, 3)."""
        params = {k: v for k, v in {"tick": tick, "denoised": None if denoised else "false"}.items() if v is not None}
        response = self._client._raw("GET", self._path("frame.f32"), params=params)
        width = int(response.headers["x-relume-width"])
        height = int(response.headers["x-relume-height"])
        return raw_frame(response.content, width, height)

    def frame_png(self, exposure: float = 0.0, tick: Optional[int] = None) -> bytes:
        """The newest frame (or tick `tick`'s) as PNG bytes, `exposure` stops brighter."""
        params: Dict[str, Any] = {"exposure": exposure}
        if tick is not None:
            params["tick"] = tick
        return self._client._raw("GET", self._path("frame.png"), params=params).content

    def stats(self) -> List[TickStats]:
        """The stats of the session's recent ticks, oldest first."""
        body = self._client._request("GET", self._path("stats"))
        return [TickStats.from_json(s) for s in body["stats"]]

    def snapshot(self) -> Dict[str, Any]:
        """Everything another server needs to continue this session (`POST /v1/sessions`)."""
        return self._client._request("GET", self._path("snapshot"))

    def refresh(self) -> SessionView:
        self.view = SessionView.from_json(self._client._request("GET", f"/v1/sessions/{self.id}"))
        return self.view

    def delete(self) -> None:
        self._client._raw("DELETE", f"/v1/sessions/{self.id}")


class Client:
    """The blocking client: `with Client(url) as c: s = c.create_session(scene="walker")`."""

    def __init__(self, url: str = "http://127.0.0.1:8080", token: Optional[str] = None, timeout: float = 60.0):
        self.url = url.rstrip("/")
        self.token = token
        self._http = httpx.Client(base_url=self.url, headers=_headers(token), timeout=timeout)

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._http.close()

    def _raw(self, method: str, path: str, **kwargs: Any) -> httpx.Response:
        response = self._http.request(method, path, **kwargs)
        _raise_for(response)
        return response

    def _request(self, method: str, path: str, **kwargs: Any) -> Any:
        return self._raw(method, path, **kwargs).json()

    def techniques(self) -> Dict[str, Any]:
        """The server's techniques with their parameters and defaults."""
        return self._request("GET", "/v1/techniques")

    def scenes(self) -> List[Dict[str, Any]]:
        """The bundled and uploaded scenes (uploads with `bytes`, `sha256` and `triangles`)."""
        return self._request("GET", "/v1/scenes")["scenes"]

    def upload_scene(self, path: Union[str, os.PathLike], name: Optional[str] = None) -> UploadRecord:
        """Uploads a `.glb`, or a `.zip` of a `.gltf` with its files, streamed from disk (any
        size up to the server's `--upload-limit`), as `name` (default: the file's name). Sessions
        then open it by that name; the same name again replaces it."""
        path = pathlib.Path(path)
        target = urllib.parse.quote(name or path.name, safe="")
        headers = {"content-length": str(path.stat().st_size), "content-type": "application/octet-stream"}
        body = self._request("PUT", f"/v1/scenes/{target}", content=_file_chunks(path), headers=headers)
        return UploadRecord.from_json(body)

    def delete_scene(self, name: str) -> None:
        """Deletes an uploaded scene (sessions already open on it keep it)."""
        self._raw("DELETE", f"/v1/scenes/{urllib.parse.quote(name, safe='')}")

    def sessions(self) -> List[SessionView]:
        return [SessionView.from_json(v) for v in self._request("GET", "/v1/sessions")["sessions"]]

    def create_session(
        self,
        scene: Union[str, Dict[str, Any]],
        technique: Optional[Dict[str, Any]] = None,
        **options: Any,
    ) -> Session:
        """Starts a session on a bundled scene's name or an inline scene document; `options` are
        the other fields of `POST /v1/sessions` (width, height, seed, tick_hz, denoise,
        environment)."""
        view = SessionView.from_json(self._request("POST", "/v1/sessions", json=_create_body(scene, technique, **options)))
        return Session(self, view)


@dataclass
class TickUpdate:
    """One tick as a stream saw it: its stats, its frame (a float32 array for `f32` frames,
    bytes otherwise, None without frames) and how many frames the stream skipped so far."""

    stats: TickStats
    frame: Union[np.ndarray, bytes, None]
    frames_dropped: int


class AsyncSession:
    """A running session, driven over HTTP and the WebSocket (asyncio)."""

    def __init__(self, client: "AsyncClient", view: SessionView):
        self._client = client
        self.view = view
        self.id = view.id
        #: `seq` of every edit batch a stream sent, in order, as the server acknowledged it.
        self.acknowledged: List[int] = []

    def _path(self, rest: str) -> str:
        return f"/v1/sessions/{self.id}/{rest}"

    async def edit(self, edits: Iterable[Edit]) -> EditsAccepted:
        body = await self._client._request("POST", self._path("edits"), json={"edits": list(edits)})
        return EditsAccepted.from_json(body)

    async def tick(self) -> TickStats:
        return TickDone.from_json(await self._client._request("POST", self._path("tick"))).stats

    async def frame(self, tick: Optional[int] = None) -> np.ndarray:
        params = {"tick": tick} if tick is not None else {}
        response = await self._client._raw("GET", self._path("frame.f32"), params=params)
        return raw_frame(response.content, int(response.headers["x-relume-width"]), int(response.headers["x-relume-height"]))

    async def delete(self) -> None:
        await self._client._raw("DELETE", f"/v1/sessions/{self.id}")

    async def stream(
        self,
        hz: float = 30.0,
        edits: Optional[EditSource] = None,
        frames: str = "f32",
        ticks: Optional[int] = None,
    ) -> AsyncIterator[TickUpdate]:
        """Sends each step's edits and a tick over the WebSocket at `hz` (forever, or for `ticks`
        steps), and yields every tick the server publishes, with its frame in the format
        `frames` asks for (`f32`, `png`, `jpg`, `exr` or `none`). Edits are acknowledged by
        `seq` (kept in `acknowledged`); each tick's stats say which it applied
        (`edits_applied_through`). A slow consumer skips frames, counted in `frames_dropped`.
        With `ticks`, the stream ends once a tick has applied every batch it sent."""
        url = self._client.ws_url(self._path("ws"))
        async with websockets.connect(url, additional_headers=_headers(self._client.token), max_size=None) as ws:
            await ws.send(json.dumps({"type": "subscribe", "frames": frames, "stats": True}))
            progress = _Progress()
            sender = asyncio.create_task(self._send(ws, hz, edits, ticks, progress))
            try:
                async for event in self._receive(ws, frames != "none"):
                    if isinstance(event, TickUpdate):
                        progress.applied = event.stats.edits_applied_through
                        yield event
                    else:
                        self.acknowledged.append(event)
                        progress.acknowledged += 1
                    if progress.finished(self._last_seq()):
                        return
            finally:
                sender.cancel()

    def _last_seq(self) -> int:
        return self.acknowledged[-1] if self.acknowledged else 0

    async def _send(
        self, ws: Any, hz: float, edits: Optional[EditSource], ticks: Optional[int], progress: "_Progress"
    ) -> None:
        period = 1.0 / hz
        step = 0
        while ticks is None or step < ticks:
            if step:
                await asyncio.sleep(period)
            batch = list(edits(step) if callable(edits) else edits[step % len(edits)]) if edits else []
            if batch:
                await ws.send(json.dumps({"type": "edits", "edits": batch}))
                progress.sent += 1
            await ws.send(json.dumps({"type": "tick"}))
            step += 1
        # One more tick, asked for after the last step: a tick is published after this point,
        # whether or not the earlier ones have all come back.
        progress.all_sent = True
        await ws.send(json.dumps({"type": "tick"}))

    async def _receive(self, ws: Any, with_frames: bool) -> AsyncIterator[Union[TickUpdate, int]]:
        """The socket's ticks (with their frames) and edit acknowledgements (their `seq`)."""
        pending: Optional[Dict[str, Any]] = None
        async for message in ws:
            if isinstance(message, bytes):
                if pending is None:
                    continue
                _magic, _tick, _acc, fmt, width, height = FRAME_HEADER.unpack_from(message)
                body = message[FRAME_HEADER.size:]
                frame: Union[np.ndarray, bytes] = raw_frame(body, width, height) if FRAME_FORMATS.get(fmt) == "f32" else body
                yield TickUpdate(TickStats.from_json(pending["stats"]), frame, pending["frames_dropped"])
                pending = None
                continue
            body = json.loads(message)
            kind = body.get("type")
            if kind == "edits_accepted":
                yield int(body["seq"])
            elif kind == "error":
                raise RelumeError(0, body.get("error", "error"), body.get("detail", ""))
            elif kind == "stats":
                if with_frames:
                    pending = body
                else:
                    yield TickUpdate(TickStats.from_json(body["stats"]), None, body["frames_dropped"])


@dataclass
class _Progress:
    """How far a stream with a set number of steps has come."""

    sent: int = 0
    acknowledged: int = 0
    applied: int = 0
    all_sent: bool = False

    def finished(self, last_seq: int) -> bool:
        return self.all_sent and self.acknowledged == self.sent and self.applied >= last_seq


class AsyncClient:
    """The asyncio client: `async with AsyncClient(url) as c: s = await c.create_session(...)`."""

    def __init__(self, url: str = "http://127.0.0.1:8080", token: Optional[str] = None, timeout: float = 60.0):
        self.url = url.rstrip("/")
        self.token = token
        self._http = httpx.AsyncClient(base_url=self.url, headers=_headers(token), timeout=timeout)

    async def __aenter__(self) -> "AsyncClient":
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self._http.aclose()

    def ws_url(self, path: str) -> str:
        return ("ws" + self.url[4:] if self.url.startswith("http") else self.url) + path

    async def _raw(self, method: str, path: str, **kwargs: Any) -> httpx.Response:
        response = await self._http.request(method, path, **kwargs)
        _raise_for(response)
        return response

    async def _request(self, method: str, path: str, **kwargs: Any) -> Any:
        return (await self._raw(method, path, **kwargs)).json()

    async def techniques(self) -> Dict[str, Any]:
        return await self._request("GET", "/v1/techniques")

    async def scenes(self) -> List[Dict[str, Any]]:
        return (await self._request("GET", "/v1/scenes"))["scenes"]

    async def create_session(
        self,
        scene: Union[str, Dict[str, Any]],
        technique: Optional[Dict[str, Any]] = None,
        **options: Any,
    ) -> AsyncSession:
        body = _create_body(scene, technique, **options)
        return AsyncSession(self, SessionView.from_json(await self._request("POST", "/v1/sessions", json=body)))
