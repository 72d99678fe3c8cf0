"""Compares two techniques on the same edits from Python: both sessions get every edit batch,
and each tick prints both tick times and how far the frames are apart (relative mean square
difference, from the raw float frames).

    pip install ./clients/python
    python3 examples/python_compare.py --url http://127.0.0.1:8080 --a path --b photon_reuse
"""
import argparse

import numpy as np

from relume_client import Client


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--url", default="http://127.0.0.1:8080")
    ap.add_argument("--scene", default="cornell-box")
    ap.add_argument("--a", default="path")
    ap.add_argument("--b", default="photon_reuse")
    ap.add_argument("--ticks", type=int, default=20)
    args = ap.parse_args()
    with Client(args.url) as c:
        sessions = [c.create_session(args.scene, technique={"id": t}, width=128, height=128) for t in (args.a, args.b)]
        for k in range(args.ticks):
            edit = [{"target": "camera", "position": [278, 273, -800 + 5 * k]}]
            stats = []
            for s in sessions:
                s.edit(edit)
                stats.append(s.tick())
            a, b = (s.frame() for s in sessions)
            rel = float(np.mean((a - b) ** 2 / (b * b + 1e-2)))
            print(f"tick {k}: {args.a} {stats[0].times['total_ms']:.1f} ms, "
                  f"{args.b} {stats[1].times['total_ms']:.1f} ms, relMSE between them {rel:.4f}")
        for s in sessions:
            s.delete()


if __name__ == "__main__":
    main()
