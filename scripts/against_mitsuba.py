"""relume's `path` against Mitsuba 3's `path` integrator (llvm_ad_rgb), at equal spp, in one run.

Run through scripts/against-mitsuba.sh, which installs Mitsuba when asked. The scene is a relume
JSON scene of OBJ meshes with diffuse materials and rect lights (the Cornell box); anything else
is refused. Both renderers get the same path cap (`--max-depth` scattering vertices: relume's
`max_path_length`, Mitsuba's `max_depth` + 1 segments), Russian roulette from the first bounce,
an independent sampler and a box filter, and both time their render call: relume's `render`
reports the time of its ticks, Mitsuba's `mi.render` is timed after a warm-up render that
compiles and caches its kernels. A third Mitsuba pass mirrors its path loop in Python with a
ray counter (rays per sample); its image mean must agree with `mi.render`'s, which shows that
the mirror makes the same decisions.
"""
import argparse
import json
import math
import os
import re
import subprocess
import sys
import time

import drjit as dr
import mitsuba as mi
import numpy as np

mi.set_variant("llvm_ad_rgb")


def transform(trs):
    t = mi.ScalarTransform4f
    x, y, z, w = trs.get("rotation", [0.0, 0.0, 0.0, 1.0])
    angle = 2.0 * math.degrees(math.acos(max(-1.0, min(1.0, w))))
    s = math.sqrt(max(1.0 - w * w, 0.0))
    axis = [x / s, y / s, z / s] if s > 1e-8 else [1.0, 0.0, 0.0]
    return (
        t.translate(trs.get("translation", [0.0, 0.0, 0.0]))
        @ t.rotate(axis, angle)
        @ t.scale(trs.get("scale", [1.0, 1.0, 1.0]))
    )


def scene_dict(path, width, height, max_depth):
    doc = json.load(open(path))
    root = os.path.dirname(os.path.abspath(path))
    cam = doc["camera"]
    out = {
        "type": "scene",
        # max_depth counts segments: `max_depth` scattering vertices, then the light.
        "integrator": {"type": "path", "max_depth": max_depth + 1, "rr_depth": 1},
        "sensor": {
            "type": "perspective",
            "fov": cam["vfov_deg"],
            "fov_axis": "y",
            # Mitsuba's camera is left-handed: mirror x so the image is relume's.
            "to_world": mi.ScalarTransform4f.look_at(cam["position"], cam["look_at"], cam["up"])
            @ mi.ScalarTransform4f.scale([-1.0, 1.0, 1.0]),
            "sampler": {"type": "independent", "sample_count": 1},
            "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}},
        },
    }
    for name, m in doc["materials"].items():
        if m["type"] != "diffuse":
            sys.exit(f"against-mitsuba: material {name}: only diffuse materials are converted")
        out["mat-" + name] = {
            "type": "twosided",
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": m["reflectance"]}},
        }
    for o in doc["objects"]:
        if o["shape"]["type"] != "mesh":
            sys.exit(f"against-mitsuba: object {o['name']}: only OBJ meshes are converted")
        shape = {"type": "obj", "filename": os.path.join(root, o["shape"]["path"]), "bsdf": {"type": "ref", "id": "mat-" + o["material"]}}
        if "transform" in o:
            shape["to_world"] = transform(o["transform"])
        out["obj-" + o["name"]] = shape
    for light in doc["lights"]:
        e = light["emitter"]
        if e["type"] != "rect":
            sys.exit(f"against-mitsuba: light {light['name']}: only rect lights are converted")
        out["light-" + light["name"]] = {
            "type": "rectangle",
            "to_world": transform(light.get("transform", {})),
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}},
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": e["radiance"]}},
        }
    return out


class CountingPath(mi.SamplingIntegrator):
    """Mitsuba's path.cpp loop in Python, with a ray counter as an AOV: one closest-hit ray per
    iteration and one shadow ray per emitter sample."""

    def __init__(self, props):
        super().__init__(props)
        self.max_depth = props.get("max_depth", -1)
        self.rr_depth = props.get("rr_depth", 5)

    def aov_names(self):
        return ["rays"]

    def sample(self, scene, sampler, ray_, medium=None, active=True):
        ctx = mi.BSDFContext()
        ray = mi.Ray3f(ray_)
        depth, rays = mi.UInt32(0), mi.Float(0.0)
        L, beta, eta = mi.Spectrum(0.0), mi.Spectrum(1.0), mi.Float(1.0)
        active = mi.Bool(active)
        prev_si = dr.zeros(mi.SurfaceInteraction3f)
        prev_pdf, prev_delta = mi.Float(1.0), mi.Bool(True)
        loop = mi.Loop("counting path", lambda: (sampler, ray, depth, rays, L, beta, eta, active, prev_si, prev_pdf, prev_delta))
        loop.set_max_iterations(self.max_depth)
        while loop(active):
            si = scene.ray_intersect(ray, mi.RayFlags.All, dr.eq(depth, 0))
            rays += 1.0
            ds = mi.DirectionSample3f(scene, si, prev_si)
            em_pdf = dr.select(prev_delta, 0.0, scene.pdf_emitter_direction(prev_si, ds, ~prev_delta))
            L = dr.fma(beta, ds.emitter.eval(si) * mis(prev_pdf, em_pdf), L)
            active_next = (depth + 1 < self.max_depth) & si.is_valid()
            bsdf = si.bsdf(ray)
            active_em = active_next & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
            ds, em_weight = scene.sample_emitter_direction(si, sampler.next_2d(), True, active_em)
            rays += dr.select(active_em, 1.0, 0.0)
            active_em &= dr.neq(ds.pdf, 0.0)
            wo = si.to_local(ds.d)
            bsdf_val, bsdf_pdf = bsdf.eval_pdf(ctx, si, wo, active_em)
            w_em = dr.select(ds.delta, 1.0, mis(ds.pdf, bsdf_pdf))
            L[active_em] = dr.fma(beta, bsdf_val * em_weight * w_em, L)
            bs, bsdf_weight = bsdf.sample(ctx, si, sampler.next_1d(), sampler.next_2d(), active_next)
            ray = si.spawn_ray(si.to_world(bs.wo))
            beta *= bsdf_weight
            eta *= bs.eta
            prev_si, prev_pdf = dr.detach(si, True), bs.pdf
            prev_delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
            depth[si.is_valid()] += 1
            beta_max = dr.max(beta)
            rr_prob = dr.minimum(beta_max * dr.sqr(eta), 0.95)
            rr_active = depth >= self.rr_depth
            beta[rr_active] *= dr.rcp(rr_prob)
            rr_continue = sampler.next_1d() < rr_prob
            active = active_next & (~rr_active | rr_continue) & dr.neq(beta_max, 0.0)
        return L, dr.neq(depth, 0), [rays]


def mis(a, b):
    a2 = a * a
    return dr.detach(dr.select(a > 0.0, a2 / (a2 + b * b), 0.0), True)


mi.register_integrator("counting_path", lambda props: CountingPath(props))


def timed_render(scene, spp, seed):
    start = time.perf_counter()
    image = mi.render(scene, spp=spp, seed=seed)
    dr.eval(image)
    dr.sync_thread()
    return image, time.perf_counter() - start


def run_relume(relume, scene, spp, width, height, max_depth):
    out = subprocess.run(
        [relume, "render", scene, "--spp", str(spp), "--width", str(width), "--height", str(height),
         "--technique", f"path:max_path_length={max_depth}", "--out", "/tmp/against-mitsuba-relume.exr"],
        capture_output=True, text=True, check=True,
    )
    m = re.search(r"(\d+) spp in ([0-9.]+) s.*?([0-9.]+) Mrays/s.*mean radiance \[([^\]]+)\]", out.stdout + out.stderr)
    if not m:
        sys.exit(f"against-mitsuba: cannot read relume's timing from: {out.stdout}{out.stderr}")
    seconds = float(m.group(2))
    rays_per_sample = float(m.group(3)) * 1e6 * seconds / (width * height * spp)
    return seconds, rays_per_sample, [float(x) for x in m.group(4).split(",")]


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("scene", nargs="?", default="scenes/cornell-box.json")
    p.add_argument("--relume", required=True)
    p.add_argument("--spp", type=int, default=256)
    p.add_argument("--size", type=int, default=256, help="image width and height")
    p.add_argument("--max-depth", type=int, default=9, help="scattering vertices per path (relume's l_m on the Cornell box)")
    p.add_argument("--json")
    a = p.parse_args()
    d = scene_dict(a.scene, a.size, a.size, a.max_depth)
    scene = mi.load_dict(d)
    timed_render(scene, a.spp, 0)  # compiles and caches the kernels
    image, mitsuba_s = timed_render(scene, a.spp, 1)
    mitsuba_mean = np.asarray(image).reshape(-1, 3).mean(axis=0).tolist()
    relume_s, relume_rays, relume_mean = run_relume(a.relume, a.scene, a.spp, a.size, a.size, a.max_depth)
    d["integrator"]["type"] = "counting_path"
    counted = mi.render(mi.load_dict(d), spp=a.spp, seed=2)
    counted = np.asarray(counted).reshape(-1, 4)
    mirror_mean = counted[:, 0:3].mean(axis=0).tolist()
    rays_per_sample = float(counted[:, 3].mean())
    samples = a.size * a.size * a.spp
    report = {
        "scene": a.scene, "size": a.size, "spp": a.spp, "max_depth": a.max_depth, "threads": os.cpu_count(),
        "mitsuba_version": mi.__version__, "mitsuba_variant": "llvm_ad_rgb",
        "relume_seconds": relume_s, "mitsuba_seconds": mitsuba_s,
        "relume_samples_per_second": samples / relume_s, "mitsuba_samples_per_second": samples / mitsuba_s,
        "relume_over_mitsuba": mitsuba_s / relume_s,
        "mitsuba_rays_per_sample": rays_per_sample, "relume_rays_per_sample": relume_rays,
        "relume_mean": relume_mean, "mitsuba_mean": mitsuba_mean, "mitsuba_mirror_mean": mirror_mean,
    }
    print(f"against-mitsuba: {a.scene} at {a.size}x{a.size}, {a.spp} spp, path cap {a.max_depth}, {os.cpu_count()} threads")
    print(f"  relume path          {relume_s:7.2f} s  {samples / relume_s / 1e6:6.2f} M samples/s  mean {fmt(relume_mean)}")
    print(f"  mitsuba {mi.__version__} llvm   {mitsuba_s:7.2f} s  {samples / mitsuba_s / 1e6:6.2f} M samples/s  mean {fmt(mitsuba_mean)}")
    print(f"  relume / mitsuba samples/s  {mitsuba_s / relume_s:.2f}")
    print(f"  rays per sample             relume {relume_rays:.2f}, mitsuba {rays_per_sample:.2f} (its mirror's mean {fmt(mirror_mean)})")
    if a.json:
        json.dump(report, open(a.json, "w"), indent=2)


def fmt(v):
    return "[" + ", ".join(f"{x:.4f}" for x in v) + "]"


if __name__ == "__main__":
    main()
