"""Plays a bundled animation through relume from Python: samples its keyframes on the client,
sends each frame's edits, ticks, saves every frame as PNG and the tick times as an SVG plot.

    pip install ./clients/python
    python3 examples/python_play.py --url http://127.0.0.1:8080 --scene bunnies-1 --frames 60 --out play/
"""
import argparse
import json
import pathlib

from relume_client import Client


def lerp(a, b, t):
    return [x + (y - x) * t for x, y in zip(a, b)]


def nlerp(a, b, t):
    if sum(x * y for x, y in zip(a, b)) < 0:
        b = [-y for y in b]
    q = lerp(a, b, t)
    n = sum(x * x for x in q) ** 0.5
    return [x / n for x in q]


def pose(track, time):
    """The transform of an object track at `time` (linear keys, rotations normalised-lerped)."""
    keys = track["keyframes"]
    for k0, k1 in zip(keys, keys[1:]):
        if k0["time"] <= time <= k1["time"]:
            t = (time - k0["time"]) / max(k1["time"] - k0["time"], 1e-9)
            a, b = k0["transform"], k1["transform"]
            return {"translation": lerp(a["translation"], b["translation"], t),
                    "rotation": nlerp(a["rotation"], b["rotation"], t),
                    "scale": lerp(a["scale"], b["scale"], t)}
    return keys[-1]["transform"]


def svg_plot(values, label):
    w, h, top = 600, 200, max(values) or 1.0
    points = " ".join(f"{20 + i * (w - 40) / max(len(values) - 1, 1):.1f},{h - 20 - v / top * (h - 40):.1f}"
                      for i, v in enumerate(values))
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}">'
            f'<polyline fill="none" stroke="#3b82f6" stroke-width="2" points="{points}"/>'
            f'<text x="20" y="14" font-size="12">{label} (max {top:.1f})</text></svg>')


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--url", default="http://127.0.0.1:8080")
    ap.add_argument("--scene", default="bunnies-1")
    ap.add_argument("--technique", default="photon_reuse")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--out", default="play")
    args = ap.parse_args()
    root = pathlib.Path(__file__).resolve().parent.parent
    anim = json.loads((root / "scenes" / f"{args.scene}.anim.json").read_text())
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    times = []
    with Client(args.url) as c:
        s = c.create_session(args.scene, technique={"id": args.technique}, width=256, height=256)
        for k in range(args.frames):
            t = (k / args.fps) % anim["duration"]
            edits = [{"target": "object", "name": tr["name"], "transform": pose(tr, t)}
                     for tr in anim["tracks"] if tr["target"] == "object"]
            s.edit(edits)
            stats = s.tick()
            times.append(stats.times["total_ms"])
            (out / f"frame{k:04}.png").write_bytes(s.frame_png(tick=stats.tick))
            print(f"frame {k}: tick {stats.tick}, {stats.times['total_ms']:.1f} ms, {stats.rays['primary']} primary rays")
        s.delete()
    (out / "tick_ms.svg").write_text(svg_plot(times, f"{args.technique} tick time per frame (ms)"))
    print(f"wrote {args.frames} frames and tick_ms.svg to {out}/")


if __name__ == "__main__":
    main()
