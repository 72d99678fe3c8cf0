"""The Python client against a real server (RELUME_URL, started by tests/clients.rs)."""
import asyncio
import dataclasses
import hashlib
import os
import pathlib

import numpy as np
import pytest
import yaml

from relume_client import AsyncClient, Client, RelumeError
from relume_client.models import SCHEMAS, EditsAccepted

ROOT = pathlib.Path(__file__).resolve().parents[3]
URL = os.environ.get("RELUME_URL", "")

# A grey sphere (reflectance 0.5) up and left of the view's centre under a uniform environment:
# the background is L and the sphere rho*L exactly (path's samples of a convex body under a
# uniform environment are exact), so a frame's pixels are known to float precision.
L = [0.2, 0.5, 0.9]
SPHERE = {
    "camera": {"position": [0, 0, 5], "look_at": [0, 0, 0], "vfov_deg": 40, "resolution": [32, 24]},
    "materials": {"grey": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
    "objects": [{"name": "ball", "shape": {"type": "sphere", "segments": 64}, "material": "grey",
                 "transform": {"translation": [-0.9, 0.6, 0], "scale": [0.7, 0.7, 0.7]}}],
    "environment": {"radiance": L},
}


def schema_fields(name):
    doc = yaml.safe_load((ROOT / "proto" / "openapi.yaml").read_text())
    schema = doc["components"]["schemas"][name]
    return set(schema.get("properties", {})), set(schema.get("required", []))


def mismatches(cls):
    """How a model differs from the OpenAPI schema of its name (empty when in step)."""
    properties, required = schema_fields(cls.__name__)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    out = [f"{p}: in the schema, not the model" for p in properties - fields.keys()]
    out += [f"{f}: in the model, not the schema" for f in fields.keys() - properties]
    no_default = {n for n, f in fields.items() if f.default is dataclasses.MISSING}
    out += [f"{r}: required but optional in the model" for r in required - no_default]
    out += [f"{n}: optional in the schema but required in the model" for n in no_default - required]
    return out


def test_models_are_in_step_with_the_openapi_description():
    for cls in SCHEMAS:
        assert mismatches(cls) == [], cls.__name__
    # Negative control: a model missing one property is caught.
    broken = dataclasses.make_dataclass("EditsAccepted", [("queued", int), ("seq", int)])
    assert mismatches(broken) == ["pending: in the schema, not the model", "pending: required but optional in the model"]
    assert EditsAccepted.from_json({"queued": 1, "pending": 1, "seq": 3, "new_field": 0}).seq == 3


@pytest.fixture
def client():
    assert URL, "RELUME_URL is not set: run this through tests/clients.rs"
    with Client(URL) as c:
        yield c


def test_a_frame_is_the_linear_radiance_row_by_row(client):
    s = client.create_session(SPHERE, technique={"id": "path", "spp": 4}, width=32, height=24)
    stats = s.tick()
    assert stats.tick == 0 and stats.technique == "path"
    img = s.frame()
    assert img.shape == (24, 32, 3) and img.dtype == np.float32
    # Row 0 is the top: the sphere sits up and left, the background fills the bottom right.
    ball, background = img[5, 8], img[23, 31]
    assert np.allclose(background, L, rtol=1e-6), background
    assert np.allclose(ball, [0.5 * c for c in L], rtol=1e-5), ball
    # Negative control: the rows read bottom-up (or the channels reversed) miss both.
    assert not np.allclose(np.flipud(img)[5, 8], [0.5 * c for c in L], rtol=1e-5)
    assert not np.allclose(img[23, 31][::-1], L, rtol=1e-6)
    assert client.create_session  # the client stays usable
    assert s.frame_png()[:8] == b"\x89PNG\r\n\x1a\n"
    s.delete()


def test_edits_are_acknowledged_and_applied(client):
    s = client.create_session("cornell-box", technique={"id": "path"}, width=16, height=16)
    first = s.edit([{"target": "camera", "position": [278, 273, -790]}])
    second = s.edit([{"target": "camera", "position": [278, 273, -780]}])
    assert (first.seq, second.seq) == (1, 2)
    stats = s.tick()
    assert stats.edits_applied_through == 2
    assert stats.edits_received == 2 and stats.edits_coalesced == 1
    assert s.snapshot()["scene"]["camera"]["position"] == [278, 273, -780]
    assert [t.tick for t in s.stats()] == [0]
    s.delete()
    with pytest.raises(RelumeError) as gone:
        s.refresh()
    assert gone.value.status == 404


def test_every_error_answer_raises_one_exception_naming_the_field(client):
    s = client.create_session("cornell-box", technique={"id": "path"}, width=16, height=16)
    with pytest.raises(RelumeError) as bad:
        s.edit([{"target": "object", "name": "no-such-object", "transform": {}}])
    assert bad.value.status == 422 and bad.value.error and "edits[0].name" in bad.value.detail
    with pytest.raises(RelumeError) as unknown:
        client.create_session("no-such-scene")
    assert unknown.value.status == 404 and "scene" in unknown.value.detail
    s.delete()


def test_an_uploaded_scene_opens_as_the_scene_it_is(client, tmp_path):
    # A scene the server has as cornell-box.glb, uploaded under another name from a file: the
    # record is the bytes' own, and a session on the upload renders the same frame, bit for bit.
    glb = (ROOT / "scenes" / "cornell-box.glb").read_bytes()
    (tmp_path / "py-box.glb").write_bytes(glb)
    record = client.upload_scene(tmp_path / "py-box.glb")
    assert (record.name, record.bytes, record.sha256) == ("py-box.glb", len(glb), hashlib.sha256(glb).hexdigest())
    listed = next(s for s in client.scenes() if s["name"] == "py-box.glb")
    assert listed["triangles"] == record.triangles > 0
    frames = []
    for scene in ["cornell-box.glb", "py-box.glb"]:
        s = client.create_session(scene, technique={"id": "path", "spp": 2}, width=16, height=12, seed=3)
        s.tick()
        frames.append(s.frame())
        s.delete()
    assert np.array_equal(frames[0], frames[1])
    # Control: the camera moved, the frame differs, so equal frames are not a given.
    s = client.create_session("py-box.glb", technique={"id": "path", "spp": 2}, width=16, height=12, seed=3)
    s.edit([{"target": "camera", "position": [278, 273, -700]}])
    s.tick()
    assert not np.array_equal(frames[0], s.frame())
    s.delete()
    client.delete_scene("py-box.glb")
    assert all(s["name"] != "py-box.glb" for s in client.scenes())
    with pytest.raises(RelumeError) as again:
        client.delete_scene("py-box.glb")
    assert again.value.status == 404 and "py-box.glb" in again.value.detail


def test_the_async_stream_yields_ticks_with_their_acknowledged_edits():
    assert URL, "RELUME_URL is not set"

    def camera(step):
        return [{"target": "camera", "position": [278, 273, -800 + step]}]

    async def run():
        async with AsyncClient(URL) as c:
            s = await c.create_session("cornell-box", technique={"id": "path"}, width=16, height=16)
            updates = [u async for u in s.stream(hz=60, edits=camera, ticks=6)]
            await s.delete()
            return s, updates

    s, updates = asyncio.run(run())
    assert s.acknowledged == list(range(1, 7)), s.acknowledged
    assert updates[-1].stats.edits_applied_through == 6
    ticks = [u.stats.tick for u in updates]
    assert ticks == sorted(set(ticks))
    assert all(u.frame.shape == (16, 16, 3) for u in updates)
