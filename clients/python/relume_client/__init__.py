"""relume-client: drive a relume server from Python.

    from relume_client import Client
    with Client("http://127.0.0.1:8080") as c:
        s = c.create_session(scene="walker", technique={"id": "photon_reuse"}, width=256, height=256)
        s.edit([{"target": "object", "name": "walker", "transform": {"translation": [1, 0, 2]}}])
        stats = s.tick()
        img = s.frame()  # numpy float32 (H, W, 3), linear
"""
from .client import AsyncClient, AsyncSession, Client, RelumeError, Session, TickUpdate, raw_frame
from .models import EditsAccepted, ErrorBody, SessionView, TickDone, TickStats, UploadRecord

__all__ = [
    "AsyncClient",
    "AsyncSession",
    "Client",
    "EditsAccepted",
    "ErrorBody",
    "RelumeError",
    "Session",
    "SessionView",
    "TickDone",
    "TickStats",
    "TickUpdate",
    "UploadRecord",
    "raw_frame",
]
