"""The service's answers as dataclasses, named and shaped as `proto/openapi.yaml` describes them.

Every class here has one field per property of the schema of the same name (a test keeps them
in step); properties the schema does not require are optional. `from_json` ignores properties a
newer server may add, so an old client keeps working.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Type, TypeVar

T = TypeVar("T")


def _from_json(cls: Type[T], body: Dict[str, Any]) -> T:
    names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    return cls(**{k: v for k, v in body.items() if k in names})


@dataclass(frozen=True)
class ErrorBody:
    """Every error answer's body: a machine-readable `error` and a `detail` naming the field."""

    error: str
    detail: str


@dataclass(frozen=True)
class EditsAccepted:
    """An edit batch was queued: `seq` is applied by the first tick whose
    `edits_applied_through` reaches it."""

    queued: int
    pending: int
    seq: int

    @classmethod
    def from_json(cls, body: Dict[str, Any]) -> "EditsAccepted":
        return _from_json(cls, body)


@dataclass(frozen=True)
class TickStats:
    """What one tick did: phase times (ms), rays by kind, edits, samples, and the technique's own
    figures in `detail` (with its resident `memory`)."""

    tick: int
    technique: str
    times: Dict[str, float]
    rays: Dict[str, int]
    edits_received: int
    edits_coalesced: int
    edits_unchanged: int
    edits_applied_through: int
    moved_surfaces: int
    spp: int
    paths_per_pixel: float
    accumulation_id: int
    detail: Dict[str, Any]
    aux_rays: Optional[int] = None
    denoise_reused: Optional[bool] = None
    resolve_reused: Optional[bool] = None
    restored: Optional[bool] = None

    @classmethod
    def from_json(cls, body: Dict[str, Any]) -> "TickStats":
        return _from_json(cls, body)


@dataclass(frozen=True)
class TickDone:
    """`POST .../tick`: the tick's stats and where its frame is."""

    stats: TickStats
    frame_url: str

    @classmethod
    def from_json(cls, body: Dict[str, Any]) -> "TickDone":
        return cls(stats=TickStats.from_json(body["stats"]), frame_url=body["frame_url"])


@dataclass(frozen=True)
class SessionView:
    """A session as the server lists it."""

    id: str
    scene: str
    technique: Dict[str, Any]
    width: int
    height: int
    seed: int
    ticks: int
    state: str
    links: Dict[str, str]
    tick_hz: Optional[float] = None
    denoise: Optional[Dict[str, Any]] = None
    failure: Optional[str] = None
    last_stats: Optional[TickStats] = None
    warnings: Optional[List[str]] = None
    animations: Optional[List[str]] = None

    @classmethod
    def from_json(cls, body: Dict[str, Any]) -> "SessionView":
        view = _from_json(cls, body)
        if body.get("last_stats") is not None:
            view = dataclasses.replace(view, last_stats=TickStats.from_json(body["last_stats"]))
        return view


@dataclass(frozen=True)
class UploadRecord:
    """`PUT /v1/scenes/{name}`: the scene stored, with the size and SHA-256 of the bytes sent."""

    name: str
    bytes: int
    sha256: str
    triangles: int
    animations: List[str]
    scene_file: str

    @classmethod
    def from_json(cls, body: Dict[str, Any]) -> "UploadRecord":
        return _from_json(cls, body)


#: The classes a test checks against the OpenAPI description's schemas of the same name.
SCHEMAS = (ErrorBody, EditsAccepted, TickStats, TickDone, SessionView, UploadRecord)
