//! Every technique's memory estimate (`technique/budget.rs`), made before anything is
//! allocated, against the memory the technique reports holding after its first tick.
mod common;
use common::*;
use relume::technique::instant_cache::InstantCacheConfig;
use relume::technique::particle_gi::ParticleGiConfig;
use relume::technique::photon_reuse::PhotonReuseConfig;
use relume::technique::TechniqueConfig;

#[test]
fn every_estimate_covers_what_the_first_tick_holds() {
    // The estimate must not be exceeded (a structure it forgot would exceed it), and must not
    // be wildly above it either, or the budget would refuse sessions that fit. Negative
    // control: the estimate of half the photon paths falls short of what the full count holds.
    let configs = [
        TechniqueConfig::Bdpt(relume::technique::bdpt::BdptConfig::default()),
        TechniqueConfig::PhotonReuse(PhotonReuseConfig { paths: 40_000, ..PhotonReuseConfig::default() }),
        TechniqueConfig::InstantCache(InstantCacheConfig::default()),
        TechniqueConfig::InstantCache(InstantCacheConfig { audit: true, vpls: 64, ..InstantCacheConfig::default() }),
        TechniqueConfig::ParticleGi(ParticleGiConfig { particles: Some(4000), ..ParticleGiConfig::default() }),
        TechniqueConfig::ParticleGi(ParticleGiConfig { particle_area: Some(4000.0), ..ParticleGiConfig::default() }),
    ];
    for scene_name in ["cornell-box.json", "bunnies-1.json"] {
        let mut scene = load(scene_name);
        scene.set_resolution(32, 32);
        for config in &configs {
            let estimate = config.resident_estimate(&scene, 32 * 32).expect("within the limits");
            let held = render(scene.clone(), config.clone(), 1, 1, 2).stats.detail.memory().total_bytes;
            assert!(held > 0, "{scene_name} {}: nothing reported", config.id());
            assert!(estimate.bytes >= held, "{scene_name} {config:?}: estimate {} < held {held}", estimate.bytes);
            assert!(estimate.bytes <= 64 * held, "{scene_name} {config:?}: estimate {} vs held {held}", estimate.bytes);
        }
        let full = TechniqueConfig::PhotonReuse(PhotonReuseConfig { paths: 40_000, ..PhotonReuseConfig::default() });
        let half = TechniqueConfig::PhotonReuse(PhotonReuseConfig { paths: 20_000, ..PhotonReuseConfig::default() });
        let held = render(scene.clone(), full, 1, 1, 2).stats.detail.memory().total_bytes;
        assert!(half.resident_estimate(&scene, 32 * 32).unwrap().bytes < held, "{scene_name}: the control passed");
    }
}
