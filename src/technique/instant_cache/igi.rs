//! Instant global illumination's gather (Wald et al. 2002; the `igi` baseline): every pixel
//! takes a different subset of the VPLs by interleaved sampling in an n×n pattern, and a
//! discontinuity buffer averages each pixel with its n×n neighbours on the same surface, so
//! every VPL counts once per neighbourhood and the structured noise is filtered away.
use super::vpl::{irradiance_from, ray_origin, visibility_ray, Vpl};
use crate::core::Rgb;
use crate::scene::SceneAccel;
use crate::technique::camera_chain::DiffuseHit;
use crate::technique::RenderContext;
use rayon::prelude::*;

/// Neighbours must have normals within this cosine and camera distances within this fraction
/// to be averaged (the discontinuity buffer's tests).
const SAME_SURFACE_COSINE: f32 = 0.9;
const SAME_SURFACE_DEPTH: f32 = 0.1;

/// Indirect irradiance per pixel (`hits`: each pixel's diffuse hit, in raster order) by the
/// n×n interleaved gather and the discontinuity buffer. Returns it and the visibility rays.
pub fn indirect(
    ctx: &RenderContext,
    vpls: &[Vpl],
    hits: &[Option<DiffuseHit>],
    n: usize,
    min_distance: f32,
) -> (Vec<Option<Rgb>>, u64) {
    let width = ctx.scene.camera.width as usize;
    let camera = ctx.scene.camera.ray(0.5 * width as f32, 0.0).origin;
    let hits: Vec<Option<(DiffuseHit, f32)>> = hits.iter().map(|h| h.map(|h| (h, (h.p - camera).length()))).collect();
    let gathered: Vec<(Rgb, u64)> = hits
        .par_iter()
        .enumerate()
        .map(|(i, h)| match h {
            Some((hit, _)) => {
                let subset = (i % width) % n + n * ((i / width) % n);
                subset_irradiance(ctx.accel, vpls, hit, subset, n * n, min_distance)
            }
            None => (Rgb::BLACK, 0),
        })
        .collect();
    let rays = gathered.iter().map(|g| g.1).sum::<u64>();
    let raw: Vec<Rgb> = gathered.into_iter().map(|g| g.0).collect();
    let filtered = filter(&hits, &raw, width, n);
    (hits.iter().zip(filtered).map(|(h, e)| h.map(|_| e)).collect(), rays)
}

/// Irradiance at `hit` from the VPLs of interleaving subset `subset` of `n²`, scaled by n² so
/// it estimates the sum over all VPLs. Returns it and the visibility rays traced.
fn subset_irradiance(
    accel: &SceneAccel,
    vpls: &[Vpl],
    hit: &DiffuseHit,
    subset: usize,
    n2: usize,
    min_distance: f32,
) -> (Rgb, u64) {
    let facing = hit.shading_facing();
    let from = ray_origin(hit.p, facing);
    let (mut e, mut rays) = (Rgb::BLACK, 0);
    for vpl in vpls.iter().skip(subset).step_by(n2) {
        let Some((contribution, _, _)) = irradiance_from(vpl, hit.p, facing, min_distance) else { continue };
        rays += 1;
        if !accel.scene().occluded1(&visibility_ray(from, vpl)) {
            e += contribution;
        }
    }
    (e * n2 as f32, rays)
}

/// The discontinuity buffer: each pixel's irradiance averaged with the neighbours of its n×n
/// window (all n² subsets) that lie on the same surface. `hits[i]` is pixel i's diffuse hit
/// and its distance from the camera; `raw[i]` its subset irradiance.
fn filter(hits: &[Option<(DiffuseHit, f32)>], raw: &[Rgb], width: usize, n: usize) -> Vec<Rgb> {
    let height = hits.len() / width.max(1);
    let lo = (n as isize - 1) / 2;
    (0..hits.len())
        .into_par_iter()
        .map(|i| {
            let Some((hit, depth)) = hits[i] else { return Rgb::BLACK };
            let (x, y) = ((i % width) as isize, (i / width) as isize);
            let (mut sum, mut count) = (Rgb::BLACK, 0u32);
            for dy in -lo..n as isize - lo {
                for dx in -lo..n as isize - lo {
                    let (qx, qy) = (x + dx, y + dy);
                    if qx < 0 || qy < 0 || qx >= width as isize || qy >= height as isize {
                        continue;
                    }
                    let q = qy as usize * width + qx as usize;
                    let Some((other, other_depth)) = hits[q] else { continue };
                    if other.shading_facing().dot(hit.shading_facing()) > SAME_SURFACE_COSINE
                        && (other_depth - depth).abs() <= SAME_SURFACE_DEPTH * depth
                    {
                        sum += raw[q];
                        count += 1;
                    }
                }
            }
            sum / count.max(1) as f32
        })
        .collect()
}
