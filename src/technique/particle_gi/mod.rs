//! `particle_gi`: diffuse interreflection in two particle spaces.
//!
//! Paper: B. Chang, S. Park, I. Ihm, "Diffuse Global Illumination in Particle Spaces",
//! Multimedia Tools and Applications 74(13):4987–5006, 2015, doi:10.1007/s11042-014-2132-x.
//!
//! # Algorithm
//! 1. Geometry stage (§4.1; when geometry changes): area particles over the diffuse surfaces
//!    (`particles.rs`, §3.1), n_s × n_s scattering links traced with Embree (`links.rs`) for the
//!    particles the lighting walks can reach, so sides never lit cost none, and gathering links
//!    the first time a particle is gathered, so sides never seen cost none (beyond the paper,
//!    which built all up front); and the implicit radiance particles of the tessellated triangles
//!    (`radiance.rs`, §3.2). When objects move, only links that may have changed are retraced
//!    (beyond the paper, which rebuilt all links in seconds): those of particles on a moved object
//!    (carried by its transform, not resampled; their gathering links are forgotten and traced
//!    again when next gathered), those ending on one or with their hit in a moved surface's
//!    old bounds, and, only up to their old hit, those whose segment touches a moved surface's
//!    new bounds (kept if nothing lies before it); only the moved objects' grids are rebuilt. Only the
//!    estimation lists on moved objects are dropped (a list holds its own object's particles).
//!    A change of scale keeps every object's point count while each stays within a factor 2 of
//!    its area's share (`particles::Layout`): the object's particles keep their indices and get
//!    new areas, and it alone is re-tessellated; otherwise all is resampled.
//! 2. Lighting stage (§4.2; when lights, materials or geometry change, `lighting.rs`):
//!    emission to the particles, the first bounce through all scattering links, n_b more
//!    bounces through one random link each, and L = ρ/π · φ/ΔA. Beyond the paper, the field
//!    is kept per light (up to 8 shares): an intensity or colour edit scales its light's share
//!    (no rays), a light move redoes that share only, a material edit re-scatters the kept
//!    direct flux without emission rays, and a tick without such edits does no lighting work.
//! 3. Ray-tracing stage (§4.3, every tick; `samples.rs`): camera samples through mirrors and
//!    glass to their diffuse hits (the preliminary trace, which marks the radiance particles
//!    needed); lists are built for needed radiance particles that have none; gathering through
//!    the 16 × 16 links for the area particles in those lists and radiance estimation (`gather.rs`), only
//!    for radiance particles without a cached estimate (the cache holds while the field and
//!    the lists do, scales with an intensity edit, and after any other lighting change the
//!    estimates cached since the camera last moved are gathered again in place); final
//!    shading with direct light by shadow rays plus ρ/π times the indirect irradiance
//!    interpolated over the hit's subtriangle. Optional adaptive supersampling re-samples
//!    pixels that differ from a neighbour by more than a relative contrast.
//!
//! # Parameters (defaults)
//! | field | default | meaning |
//! |---|---|---|
//! | `particles` | 0.15 per pixel, ≥ 2 000 | area particles (two per sampled point, one per side) |
//! | `particle_area` | none | ΔA in m² instead of a count |
//! | `scatter_links` / `gather_links` | 4 / 16 | n_s of each link set |
//! | `bounces` | from ρ_S | n_b; by default the least with ρ_S^(n_b+2) < `admitted_truncation` (0.01) |
//! | `estimation_radius` | 2 | R, in particle spacings √ΔA |
//! | `estimation_cosine` | 0.9 | least normal cosine within a list |
//! | `subtriangle_edge` | 1.5 | tessellation edge, in particle spacings |
//! | `emission_samples` | 4 | samples per area light per particle |
//! | `incremental` | true | update links incrementally (false: rebuild all when objects move) |
//! | `supersample` | 0 | extra samples per aliased pixel (0: off); `supersample_contrast` 0.1 |
//!
//! # Bias
//! Biased and consistent only in the limit of particle density and link count: flux is
//! attributed to the nearest particle (light spreads by about a spacing), radiance is averaged
//! over R (blurs corners, where the paper's Figure 7 shows the error), the walk after the
//! first bounce is truncated at n_b + 1 bounces plus the gather, links carry diffuse transport
//! only (no caustics; light reaching a mirror is lost), and emission to a particle close to a
//! light uses its centre's distance. Direct light is exact (shadow rays).
//!
//! # Smooth shading
//! On smooth-shaded meshes a particle keeps its geometric normal (its side, its links' frame)
//! and also its shading normal: flux it receives, from a light or along a link, is weighted by
//! the shading factor of the direction it arrives from (`Normals::diffuse_factor`), and so is
//! each gathering link's radiance. Flat scenes skip this.
//!
//! # Light from outside
//! Particles are lit by the sun and the environment as by any light (shadow rays; the
//! environment sampled cosine-weighted about the particle's normal), so an edit that only
//! dims them stays a rescale of the particles' flux.
//!
//! # Failure modes
//! Thin features below the particle spacing get their neighbours' light; link ends and lists
//! keep to one object and one side of its winding, so a mesh wound inconsistently loses
//! neighbours at its seams (and could leak through a wall thinner than R there, where a
//! consistently wound one cannot); a scene made mostly of mirrors gets no indirect light.
mod config;
pub use config::DESCRIPTION;
mod gather;
mod grid;
mod lighting;
mod links;
mod particles;
mod radiance;
mod samples;
mod strata;

pub use config::{ParticleGiConfig, ParticleStats, MAX_PARTICLES};

use super::path::max_path_length;
use super::{RayCounts, RenderContext, RenderStats, Technique, TechniqueError, TechniqueStats, UpdateStats};
use crate::core::Rgb;
use crate::film::Film;
use crate::scene::edits::{Aabb, SceneDelta};
use crate::scene::{Scene, SurfaceId};
use crate::technique::box_tree::{widened, BoxTree, BOX_SLACK};
use gather::Estimates;
use glam::Vec3;
use grid::ObjectGrids;
use lighting::{Inputs, Lighting};
use links::{LinkSet, Moves, Target};
use particles::{AreaParticles, Layout};
use radiance::{EstimationLists, RadianceKey, Tessellation};
use std::time::Instant;

/// Particle grid cells, in particle spacings: about eight points a cell, so most nearest-
/// particle queries end in their own cell.
const GRID_CELL: f32 = 2.0;

/// Salts of the two link sets' direction streams.
const SCATTER_SALT: u64 = 0x5343_4154_5445_5200;
const GATHER_SALT: u64 = 0x4741_5448_4552_0000;

/// Everything the geometry stage builds.
struct Geometry {
    particles: AreaParticles,
    /// Nearest-particle grids per object and side.
    grids: ObjectGrids,
    scatter: LinkSet,
    gather: LinkSet,
    tessellation: Tessellation,
    lists: EstimationLists,
    /// √ΔA (m) and the scene diagonal at build time (m).
    spacing: f32,
    diagonal: f32,
    /// Each object's stable scale when the particles were sampled.
    scales: Vec<Vec3>,
}

/// The `particle_gi` technique.
pub struct ParticleGi {
    config: ParticleGiConfig,
    geometry: Option<Geometry>,
    /// Points per object, kept across rebuilds while it holds (`particles::Layout`).
    layout: Option<Layout>,
    lighting: Option<Lighting>,
    /// Estimates per radiance particle, valid while `lighting` and the lists hold.
    estimates: Estimates,
    passes: u64,
}

impl ParticleGi {
    pub fn new(config: ParticleGiConfig, _scene: &Scene) -> Result<ParticleGi, TechniqueError> {
        config.validate()?;
        Ok(ParticleGi {
            config,
            geometry: None,
            layout: None,
            lighting: None,
            estimates: Estimates::default(),
            passes: 0,
        })
    }

    fn bounces(&self, scene: &Scene) -> u32 {
        self.config.bounces.unwrap_or_else(|| {
            max_path_length(scene.mean_reflectance(), self.config.admitted_truncation).saturating_sub(2).clamp(1, 64)
        })
    }

    /// Builds particles, links and the tessellation from scratch.
    fn build_geometry(&mut self, ctx: &RenderContext) {
        let c = &self.config;
        let layout = match self.layout.take() {
            Some(l) if l.holds(ctx.scene) => l,
            _ => Layout::plan(ctx.scene, c.particle_count(ctx.scene), c.particle_area),
        };
        let particles = AreaParticles::sample(ctx.scene, &layout, c.seed);
        self.layout = Some(layout);
        let spacing = particles.area.max(f32::MIN_POSITIVE).sqrt();
        let grids = ObjectGrids::build(&particles, ctx.scene.objects.len(), GRID_CELL * spacing);
        let diagonal = ctx.accel.scene().bounds().map_or(1.0, |(lo, hi)| (hi - lo).length().max(f32::MIN_POSITIVE));
        // Scattering links are traced for the particles walks reach (`update_lighting`), and
        // gathering links when a particle is first gathered (`estimate_missing`).
        let scatter = LinkSet::empty(c.scatter_links, c.seed ^ SCATTER_SALT, particles.len());
        let gather = LinkSet::empty(c.gather_links, c.seed ^ GATHER_SALT, particles.len());
        let tessellation = Tessellation::build(ctx.scene, c.subtriangle_edge * spacing);
        let lists = EstimationLists::new(&tessellation);
        self.estimates = Estimates::new(&tessellation, lighting::share_count(ctx.scene.lights.len()));
        self.geometry = Some(Geometry {
            particles,
            grids,
            scatter,
            gather,
            tessellation,
            lists,
            spacing,
            diagonal,
            scales: (0..ctx.scene.objects.len()).map(|i| particles::stable_scale(ctx.scene, i)).collect(),
        });
    }

    /// Carries the particles of moved objects, rescales those of `rescaled` ones (their
    /// subtriangles and cached estimates start over), and retraces the links that may have
    /// changed.
    fn update_geometry(
        &mut self,
        ctx: &RenderContext,
        delta: &SceneDelta,
        rescaled: &[usize],
        stats: &mut ParticleStats,
    ) {
        let Some(g) = self.geometry.as_mut() else { return };
        let mut moved = vec![false; ctx.scene.objects.len()];
        for m in &delta.moved {
            if let SurfaceId::Object(i) = m.surface {
                moved[i as usize] = true;
            }
        }
        for &o in rescaled {
            g.particles.rescale_object(ctx.scene, o);
            g.tessellation.build_object(ctx.scene, o, self.config.subtriangle_edge * g.spacing);
            self.estimates.reset_object(o, g.tessellation.counts[o]);
            g.lists.reset_object(o, g.tessellation.counts[o]);
            g.scales[o] = particles::stable_scale(ctx.scene, o);
            moved[o] = true;
        }
        stats.objects_rescaled += rescaled.len() as u64;
        let carried: Vec<usize> = (0..g.particles.len()).filter(|&i| moved[g.particles.object[i] as usize]).collect();
        if let (Some(&first), Some(&last)) = (carried.first(), carried.last()) {
            // Particles are grouped by object; re-place the span, which covers every carried one.
            g.particles.place(ctx.scene, first..last + 1);
        }
        for object in (0..moved.len()).filter(|&o| moved[o]) {
            g.grids.rebuild(&g.particles, object);
        }
        let slack = BOX_SLACK * g.diagonal;
        let bounds = |old: bool| -> Vec<Aabb> {
            delta.moved.iter().map(|m| widened(if old { &m.old_bounds } else { &m.new_bounds }, slack)).collect()
        };
        let spans = delta.moved.iter().map(|m| widened(&m.old_bounds.union(&m.new_bounds), slack)).collect();
        let moves = Moves { moved: &moved, spans, old: BoxTree::new(bounds(true)), new: BoxTree::new(bounds(false)) };
        // A moved particle's gathering links are traced again only if it is gathered again.
        g.gather.forget(|i| moved[g.particles.object[i as usize] as usize]);
        let target = Target::new(ctx, &g.particles, &g.grids);
        for set in [&mut g.scatter, &mut g.gather] {
            let (traced, tests) = set.update(target, &moves);
            stats.links_traced += traced;
            stats.link_box_tests += tests;
        }
        g.lists.invalidate(&moved);
    }

    /// Builds or updates the geometry stage as `delta` requires. Returns whether it changed.
    fn update_geometry_stage(&mut self, ctx: &RenderContext, delta: &SceneDelta, stats: &mut ParticleStats) -> bool {
        let toggled = delta
            .materials
            .iter()
            .zip(&delta.previous_materials)
            .any(|(&m, old)| ctx.scene.materials[m].is_specular() != old.is_specular());
        let moved = !delta.moved.is_empty() || toggled;
        // Particles and subtriangles follow rigid motion; a change of scale rescales the
        // object's particles in place while the layout holds, and resamples all otherwise.
        let rescaled: Vec<usize> = self.geometry.as_ref().map_or(Vec::new(), |g| {
            (0..ctx.scene.objects.len()).filter(|&i| particles::stable_scale(ctx.scene, i) != g.scales[i]).collect()
        });
        // Checked only on a change of scale: it walks every object's triangles.
        let resample = !rescaled.is_empty() && !self.layout.as_ref().is_some_and(|l| l.holds(ctx.scene));
        if self.geometry.is_none() || toggled || resample || (moved && !self.config.incremental) {
            self.build_geometry(ctx);
            true
        } else if moved || !rescaled.is_empty() {
            self.update_geometry(ctx, delta, &rescaled, stats);
            true
        } else {
            false
        }
    }

    /// Runs the lighting stage where `delta` requires it (see `lighting.rs`): everything after
    /// a geometry change; a re-scatter from the kept direct flux after a material edit; per
    /// light edit, its share scaled (an intensity edit of a light alone in its share) or
    /// re-emitted and re-scattered. Scattering links are built first for every particle the
    /// walks can reach. Cached estimates follow: scaled with their share, or, after any other
    /// change of the field, gathered again in place if fresh for the view and their lists held
    /// (the rest are forgotten, `gather.rs`).
    fn update_lighting(
        &mut self,
        ctx: &RenderContext,
        delta: &SceneDelta,
        geometry_changed: bool,
        stats: &mut ParticleStats,
    ) {
        let bounces = self.bounces(ctx.scene);
        let Some((emit, scatter)) = self.lighting_plan(ctx, delta, geometry_changed, stats) else { return };
        let (Some(g), Some(lighting)) = (self.geometry.as_mut(), self.lighting.as_mut()) else { return };
        let (samples, seed) = (self.config.emission_samples, self.config.seed);
        let inputs = Inputs { scene: ctx.scene, accel: ctx.accel, particles: &g.particles, samples, bounces, seed };
        let emitted = lighting.emit(&inputs, &emit);
        let t = Instant::now();
        let lit = lighting.lit(&scatter);
        let reached = g.scatter.ensure_reached(Target::new(ctx, &g.particles, &g.grids), &lit);
        let geometry_ms = t.elapsed().as_secs_f64() * 1e3;
        let work = lighting.scatter(&inputs, &g.scatter, &scatter);
        // Fresh estimates whose lists held are gathered again in place; the rest go.
        let keys: Vec<RadianceKey> = self.estimates.fresh_keys().into_iter().filter(|&k| g.lists.contains(k)).collect();
        stats.links_traced += reached;
        stats.links_built_lazily += reached;
        stats.geometry_ms += geometry_ms;
        stats.record(emitted);
        stats.record(work);
        self.estimates.invalidate();
        self.gather_and_store(ctx, &keys, stats);
    }

    /// Which shares to re-emit and re-scatter, with intensity edits applied as scales (`None`:
    /// no lighting work). A geometry change, or no field yet, starts a new field.
    fn lighting_plan(
        &mut self,
        ctx: &RenderContext,
        delta: &SceneDelta,
        geometry_changed: bool,
        stats: &mut ParticleStats,
    ) -> Option<(Vec<bool>, Vec<bool>)> {
        let g = self.geometry.as_ref()?;
        let (lights, shares) = (ctx.scene.lights.len(), lighting::share_count(ctx.scene.lights.len()));
        let lighting = match self.lighting.as_mut() {
            Some(lighting) if !geometry_changed && lighting.shares == shares => lighting,
            _ => {
                self.lighting = Some(Lighting::new(g.particles.len(), lights));
                return Some((vec![true; shares], vec![true; shares]));
            }
        };
        let mut emit = vec![false; shares];
        for change in &delta.lights {
            let share = change.light % shares;
            match change.rescale {
                Some(f) if !change.moved && lighting::alone_in_share(change.light, lights) => {
                    lighting.scale(share, f);
                    self.estimates.scale(share, f);
                    stats.lights_rescaled += 1;
                }
                _ => emit[share] = true,
            }
        }
        let scatter = if delta.materials.is_empty() { emit.clone() } else { vec![true; shares] };
        scatter.contains(&true).then_some((emit, scatter))
    }
}

impl Technique for ParticleGi {
    fn id(&self) -> &'static str {
        "particle_gi"
    }

    fn update(&mut self, ctx: &RenderContext, delta: &SceneDelta) -> Result<UpdateStats, TechniqueError> {
        let mut stats = ParticleStats::default();
        let t = Instant::now();
        let geometry_changed = self.update_geometry_stage(ctx, delta, &mut stats);
        stats.geometry_ms += t.elapsed().as_secs_f64() * 1e3;
        if delta.camera {
            self.estimates.age();
        }
        self.update_lighting(ctx, delta, geometry_changed, &mut stats);
        if !delta.is_empty() {
            self.passes = 0;
        }
        Ok(UpdateStats::new(stats))
    }

    fn render(
        &mut self,
        ctx: &RenderContext,
        film: &mut Film,
        update: UpdateStats,
    ) -> Result<RenderStats, TechniqueError> {
        let mut stats: ParticleStats = update.take();
        let scene = ctx.scene;
        let width = scene.camera.width as usize;
        let pixels = width * scene.camera.height as usize;
        let pass = self.passes * (1 + self.config.supersample as u64);
        let first: Vec<(usize, u64)> = (0..pixels).map(|i| (i, pass)).collect();
        let mut shaded = self.shade(ctx, &first, &mut stats);
        if self.config.supersample > 0 {
            let aliased = self.aliased(&shaded, width);
            stats.supersampled_pixels = aliased.len() as u64;
            let extra: Vec<(usize, u64)> = aliased
                .iter()
                .flat_map(|&i| (1..=self.config.supersample as u64).map(move |k| (i, pass + k)))
                .collect();
            shaded.extend(self.shade(ctx, &extra, &mut stats));
        }
        let mut sums = vec![(Rgb::BLACK, 0.0f64); pixels];
        for s in shaded {
            sums[s.pixel].0 += s.radiance;
            sums[s.pixel].1 += 1.0;
        }
        film.accumulate_chunks(
            width,
            |first, chunk| {
                for (k, px) in chunk.iter_mut().enumerate() {
                    let (sum, count) = sums[first + k];
                    // Supersampled pixels count once, as their mean.
                    px.add(sum / count.max(1.0) as f32);
                    px.count += 1.0;
                }
            },
            |(), ()| (),
        );
        self.passes += 1;
        film.passes += 1;
        if let Some(g) = &self.geometry {
            stats.area_particles = g.particles.len() as u64;
            stats.particle_area = g.particles.area as f64;
            stats.radiance_particles = g.tessellation.total;
            stats.links_total = (g.scatter.len() + g.gather.len()) as u64;
            stats.scattering_links = g.scatter.len() as u64;
            stats.lists_cached = g.lists.len() as u64;
            stats.estimates_cached = self.estimates.cached();
            let memory = &mut stats.memory;
            memory.set("particles", g.particles.memory_bytes() + g.tessellation.memory_bytes());
            memory.set("scatter_links", g.scatter.memory_bytes());
            memory.set("gather_links", g.gather.memory_bytes());
            memory.set("lists", g.lists.memory_bytes());
            memory.set("grid", g.grids.memory_bytes());
            memory.set("estimates", self.estimates.memory_bytes());
            memory.set("field", self.lighting.as_ref().map_or(0, Lighting::memory_bytes));
        }
        stats.bounces = self.bounces(scene);
        let rays = RayCounts {
            primary: stats.camera_rays,
            secondary: stats.specular_rays + stats.links_traced,
            shadow: stats.shadow_rays + stats.emission_rays,
        };
        Ok(RenderStats { rays, detail: TechniqueStats::ParticleGi(Box::new(stats)) })
    }
}
