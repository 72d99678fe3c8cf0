#!/usr/bin/env python3
"""Generates the animated scenes in scenes/ (scene JSON + NAME.anim.json).

Run from the repository root: python3 scripts/make_scenes.py. The output is committed; this
script documents how it was made. Units: meters (bunnies-N reuse the Cornell box's millimetre
numbers). Geometry uses the primitives of proto/scene.schema.json and scenes/meshes/bunny.obj
(unit height, resting on y = 0).
"""
import json
import math
import os

HERE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "scenes")
RES = [256, 256]


def quat_y(angle):
    return [0.0, math.sin(angle / 2), 0.0, math.cos(angle / 2)]


def quat_x(angle):
    return [math.sin(angle / 2), 0.0, 0.0, math.cos(angle / 2)]


def r(v):
    return [round(x, 5) for x in v]


def trs(t=(0, 0, 0), q=(0, 0, 0, 1), s=(1, 1, 1)):
    return {"translation": r(t), "rotation": r(q), "scale": r(s)}


def box(name, material, centre, half, dynamic=False, q=(0, 0, 0, 1)):
    return {"name": name, "shape": {"type": "box"}, "material": material, "transform": trs(centre, q, half), "dynamic": dynamic}


def room(prefix, lo, hi, material, skip=()):
    """Six thin boxes (floor, ceiling, walls) enclosing [lo, hi]; names in skip are left out."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    cx, cy, cz = (x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2
    hx, hy, hz = (x1 - x0) / 2, (y1 - y0) / 2, (z1 - z0) / 2
    t = 0.05
    parts = {
        "floor": ((cx, y0 - t, cz), (hx + t, t, hz + t)),
        "ceiling": ((cx, y1 + t, cz), (hx + t, t, hz + t)),
        "wall-x0": ((x0 - t, cy, cz), (t, hy, hz)),
        "wall-x1": ((x1 + t, cy, cz), (t, hy, hz)),
        "wall-z0": ((cx, cy, z0 - t), (hx, hy, t)),
        "wall-z1": ((cx, cy, z1 + t), (hx, hy, t)),
    }
    return [box(f"{prefix}{k}", material, c, h) for k, (c, h) in parts.items() if k not in skip]


def wall_with_door(prefix, axis_x, z0, z1, y1, door_z0, door_z1, door_h, material):
    """A wall in the plane x = axis_x from z0 to z1 with a door opening [door_z0, door_z1] × [0, door_h]."""
    t = 0.05
    out = []
    if door_z0 > z0:
        out.append(box(f"{prefix}-a", material, (axis_x, y1 / 2, (z0 + door_z0) / 2), (t, y1 / 2, (door_z0 - z0) / 2)))
    if door_z1 < z1:
        out.append(box(f"{prefix}-b", material, (axis_x, y1 / 2, (door_z1 + z1) / 2), (t, y1 / 2, (z1 - door_z1) / 2)))
    out.append(box(f"{prefix}-lintel", material, (axis_x, (door_h + y1) / 2, (door_z0 + door_z1) / 2), (t, (y1 - door_h) / 2, (door_z1 - door_z0) / 2)))
    return out


def write(name, scene, anim):
    with open(os.path.join(HERE, f"{name}.json"), "w") as f:
        json.dump(scene, f, indent=1)
        f.write("\n")
    with open(os.path.join(HERE, f"{name}.anim.json"), "w") as f:
        json.dump(anim, f, indent=1)
        f.write("\n")


MATERIALS = {
    "wall": {"type": "diffuse", "reflectance": [0.7, 0.7, 0.68]},
    "floor": {"type": "diffuse", "reflectance": [0.45, 0.4, 0.35]},
    "red": {"type": "diffuse", "reflectance": [0.7, 0.12, 0.1]},
    "green": {"type": "diffuse", "reflectance": [0.15, 0.55, 0.2]},
    "blue": {"type": "diffuse", "reflectance": [0.15, 0.25, 0.7]},
    "wood": {"type": "diffuse", "reflectance": [0.5, 0.33, 0.2]},
    "bunny": {"type": "diffuse", "reflectance": [0.75, 0.72, 0.65]},
}


def merry_go_round():
    objects = room("room-", (-5, 0, -4), (5, 3, 4), "wall", skip=("floor",))
    objects.append(box("floor", "floor", (0, -0.05, 0), (5.05, 0.05, 4.05)))
    objects.append(box("table-top", "wood", (0, 0.75, 0), (1.2, 0.04, 0.8)))
    objects.append({"name": "table-foot", "shape": {"type": "cylinder", "segments": 24}, "material": "wood",
                    "transform": trs((0, 0, 0), quat_x(-math.pi / 2), (0.15, 0.15, 0.71)), "dynamic": False})
    props = [("prop-sphere", {"type": "sphere", "segments": 32}, "red", (-0.6, 0.99, 0.0), 0.2),
             ("prop-box", {"type": "box"}, "green", (0.0, 0.94, 0.2), 0.15),
             ("prop-cylinder", {"type": "cylinder", "segments": 24}, "blue", (0.6, 0.79, -0.1), 0.15)]
    # The cylinder's axis is its local +Z; stand it up along +Y.
    upright = {"prop-cylinder": quat_x(-math.pi / 2)}

    def prop_rotation(name, angle):
        q = quat_y(angle)
        u = upright.get(name)
        if u is None:
            return q
        # q · u (rotate upright first, then spin about world Y).
        x1, y1, z1, w1 = q
        x2, y2, z2, w2 = u
        return [w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2, w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2]

    for name, shape, mat, pos, s in props:
        objects.append({"name": name, "shape": shape, "material": mat, "transform": trs(pos, prop_rotation(name, 0.0), (s, s, s)), "dynamic": True})
    n, radius, duration = 8, 2.2, 12.0
    for i in range(n):
        a = 2 * math.pi * i / n
        objects.append({"name": f"bunny-{i + 1}", "shape": {"type": "mesh", "path": "meshes/bunny.obj"}, "material": "bunny",
                        "transform": trs((radius * math.cos(a), 0, radius * math.sin(a)), quat_y(-a), (0.45, 0.45, 0.45)), "dynamic": True})
    scene = {
        "camera": {"position": [0, 2.75, 3.85], "look_at": [0, 0.3, -0.2], "vfov_deg": 68, "resolution": RES},
        "materials": MATERIALS,
        "objects": objects,
        "lights": [{"name": "lamp", "emitter": {"type": "disc", "radiance": [60, 57, 51], "segments": 32},
                    "transform": trs((0, 2.95, 0), quat_x(math.pi / 2), (0.5, 0.5, 1))}],
    }
    tracks = []
    steps = 24
    for i in range(n):
        keys = []
        for k in range(steps + 1):
            t = duration * k / steps
            a = 2 * math.pi * i / n + 2 * math.pi * t / duration
            keys.append({"time": round(t, 4), "transform": trs((radius * math.cos(a), 0, radius * math.sin(a)), quat_y(-a), (0.45, 0.45, 0.45))})
        tracks.append({"target": "object", "name": f"bunny-{i + 1}", "keyframes": keys})
    for j, (name, _, _, pos, s) in enumerate(props):
        keys = []
        for k in range(steps + 1):
            t = duration * k / steps
            grow = s * (1.0 + 0.35 * math.sin(2 * math.pi * (t / duration * 2 + j / 3)))
            keys.append({"time": round(t, 4), "transform": trs(pos, prop_rotation(name, 2 * math.pi * t / duration * (j + 1)), (grow, grow, grow))})
        tracks.append({"target": "object", "name": name, "keyframes": keys})
    write("merry-go-round", scene, {"duration": duration, "loop": True, "tracks": tracks})


def walker():
    # A 10 × 3 × 8 room; doors in the x = -5 and x = +5 walls, with short dark corridors behind.
    objects = room("room-", (-5, 0, -4), (5, 3, 4), "wall", skip=("wall-x0", "wall-x1", "floor"))
    objects.append(box("floor", "floor", (0, -0.05, 0), (7.05, 0.05, 4.05)))
    objects += wall_with_door("wall-west", -5.05, -4, 4, 3, -0.6, 0.6, 2.2, "wall")
    objects += wall_with_door("wall-east", 5.05, -4, 4, 3, -0.6, 0.6, 2.2, "wall")
    for side, x in (("west", -6), ("east", 6)):
        objects += room(f"corridor-{side}-", (x - 1, 0, -0.6), (x + 1, 2.2, 0.6), "wall", skip=("floor", "wall-x0" if side == "east" else "wall-x1"))
    objects.append(box("stand", "wood", (0, 0.2, 1.5), (0.6, 0.2, 0.6)))
    objects.append({"name": "walker", "shape": {"type": "mesh", "path": "meshes/bunny.obj"}, "material": "red",
                    "transform": trs((-6.2, 0, 0), quat_y(-math.pi / 2), (1.6, 1.6, 1.6)), "dynamic": True})
    scene = {
        "camera": {"position": [3.5, 2.4, -3.5], "look_at": [-1.0, 0.8, 0.8], "vfov_deg": 70, "resolution": RES},
        "materials": MATERIALS,
        "objects": objects,
        "lights": [{"name": "ceiling-panel", "emitter": {"type": "rect", "radiance": [15, 15, 14]},
                    "transform": trs((0, 2.99, 0), quat_x(math.pi / 2), (1.0, 0.5, 1))}],
    }
    # West door → stand (0..6 s), wait (6..9 s), stand → east door (9..15 s).
    stand = (0, 0.4, 1.5)
    path = [(0, (-6.2, 0, 0), -math.pi / 2), (2, (-4.5, 0, 0), -math.pi / 2), (6, stand, -0.3), (9, stand, 0.3),
            (13, (4.5, 0, 0), math.pi / 2), (15, (6.2, 0, 0), math.pi / 2)]
    keys = [{"time": t, "transform": trs(p, quat_y(a), (1.6, 1.6, 1.6))} for t, p, a in path]
    write("walker", scene, {"duration": 15.0, "loop": True, "tracks": [{"target": "object", "name": "walker", "keyframes": keys}]})


def villa_torch():
    # Room A (x -6..0) holds the torch; room B (x 0..6) is lit only through the doorway.
    objects = room("villa-", (-6, 0, -3), (6, 3, 3), "wall", skip=("floor",))
    objects.append(box("floor", "floor", (0, -0.05, 0), (6.05, 0.05, 3.05)))
    objects += wall_with_door("divider", 0.0, -3, 3, 3, -0.5, 0.5, 2.1, "wall")
    objects.append(box("chest", "wood", (-4.5, 0.4, -2.2), (0.6, 0.4, 0.4)))
    objects.append(box("sofa", "green", (3.5, 0.35, -2.2), (1.2, 0.35, 0.5)))
    objects.append(box("cabinet", "blue", (5.4, 0.9, -0.6), (0.4, 0.9, 0.7)))
    scene = {
        "camera": {"position": [5.5, 1.7, 2.6], "look_at": [0, 1.0, -0.5], "vfov_deg": 70, "resolution": RES},
        "materials": MATERIALS,
        "objects": objects,
        "lights": [{"name": "torch", "emitter": {"type": "disc", "radiance": [3000, 2200, 1200], "segments": 16},
                    "transform": trs((-4.0, 1.6, 1.5), quat_x(math.pi / 2), (0.06, 0.06, 1)), "dynamic": True}],
    }
    pts = [(0, (-4.0, 1.6, 1.5)), (4, (-1.5, 1.6, 1.8)), (8, (-1.2, 1.5, -1.8)), (12, (-4.5, 1.7, -1.0)), (16, (-4.0, 1.6, 1.5))]
    keys = [{"time": t, "transform": trs(p, quat_x(math.pi / 2), (0.06, 0.06, 1))} for t, p in pts]
    write("villa-torch", scene, {"duration": 16.0, "loop": True, "tracks": [{"target": "light", "name": "torch", "keyframes": keys}]})


MAZE = [
    "#########",
    "#...#...#",
    "#.#.#.#.#",
    "#.#...#.#",
    "#.#####.#",
    "#...#...#",
    "###.#.###",
    "#.....#.#",
    "#########",
]


def maze():
    objects = [box("ground", "floor", (0, -0.05, 0), (5, 0.05, 5))]
    cell = 1.0
    n = len(MAZE)
    off = -n * cell / 2
    for j, row in enumerate(MAZE):
        for i, c in enumerate(row):
            if c == "#":
                x, z = off + (i + 0.5) * cell, off + (j + 0.5) * cell
                objects.append(box(f"wall-{j}-{i}", "wall", (x, 0.6, z), (cell / 2, 0.6, cell / 2)))

    def centre(i, j):
        return (off + (i + 0.5) * cell, 0.0, off + (j + 0.5) * cell)

    person = lambda name, mat, pos: {"name": name, "shape": {"type": "cylinder", "segments": 16}, "material": mat,
                                     "transform": trs(pos, quat_x(-math.pi / 2), (0.25, 0.25, 1.7)), "dynamic": True}
    route_a = [(1, 1), (3, 1), (3, 3), (5, 3), (5, 1), (7, 1), (7, 3)]
    route_b = [(1, 7), (5, 7), (5, 5), (7, 5)]
    objects.append(person("person-a", "red", centre(*route_a[0])))
    objects.append(person("person-b", "blue", centre(*route_b[0])))
    scene = {
        "camera": {"position": [0, 9.5, 6.5], "look_at": [0, 0, 0.3], "vfov_deg": 50, "resolution": RES},
        "materials": MATERIALS,
        "objects": objects,
        "lights": [
            {"name": "sky-panel", "emitter": {"type": "rect", "radiance": [4, 4.2, 5]}, "transform": trs((0, 7, 0), quat_x(math.pi / 2), (2, 2, 1))},
            {"name": "lamp", "emitter": {"type": "spot", "intensity": [60, 50, 35], "cone_deg": 35}, "transform": trs((3, 4, 3), quat_x(math.pi / 2 + 0.3), (1, 1, 1))},
        ],
    }

    def track(name, route, duration):
        pts = route + route[-2::-1]
        keys = [{"time": round(duration * k / (len(pts) - 1), 4), "transform": trs(centre(*p), quat_x(-math.pi / 2), (0.25, 0.25, 1.7))} for k, p in enumerate(pts)]
        return {"target": "object", "name": name, "keyframes": keys}

    write("maze", scene, {"duration": 24.0, "loop": True, "tracks": [track("person-a", route_a, 24.0), track("person-b", route_b, 24.0)]})


def bunnies(count):
    with open(os.path.join(HERE, "cornell-box.json")) as f:
        scene = json.load(f)
    scene["objects"] = [o for o in scene["objects"] if "block" not in o["name"]]
    scene["materials"]["bunny"] = MATERIALS["bunny"]
    side = math.ceil(math.sqrt(count))
    spacing = 480.0 / side
    scale = min(150.0, spacing * 0.8)
    tracks = []
    duration = 4.0
    for k in range(count):
        i, j = k % side, k // side
        x, z = 40 + spacing * (i + 0.5), 60 + spacing * (j + 0.5)
        scene["objects"].append({"name": f"bunny-{k + 1}", "shape": {"type": "mesh", "path": "meshes/bunny.obj"}, "material": "bunny",
                                 "transform": trs((x, 0, z), quat_y(0.5 * k), (scale, scale, scale)), "dynamic": True})
        # Bounce: a parabola from the floor up to 1.2 bunny heights and back, phase-shifted.
        keys = []
        steps = 16
        for s in range(steps + 1):
            t = duration * s / steps
            phase = (t / duration + k / max(count, 1)) % 1.0
            height = 4 * 1.2 * scale * phase * (1 - phase)
            keys.append({"time": round(t, 4), "transform": trs((x, height, z), quat_y(0.5 * k + 2 * math.pi * t / duration), (scale, scale, scale))})
        tracks.append({"target": "object", "name": f"bunny-{k + 1}", "keyframes": keys})
    write(f"bunnies-{count}", scene, {"duration": duration, "loop": True, "tracks": tracks})


if __name__ == "__main__":
    merry_go_round()
    walker()
    villa_torch()
    maze()
    for n in (1, 2, 4, 9):
        bunnies(n)
