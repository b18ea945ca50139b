//! Development benchmark of the radiance pass: render a glTF (default: the shared Cornell box)
//! and print camera paths per second. `cargo run --release -p camsim-render --example
//! bench_render -- [SCENE.gltf] [spp] [width] [threads] [rr_depth]`
use camsim_render::job::{prepare, CameraChoice, RenderJob};
use camsim_render::{render, RenderSettings};
use std::path::PathBuf;

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let scene = a
        .get(1)
        .filter(|s| !s.is_empty() && *s != "-")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR"))
                .join("../../shared/tools/mitsuba_ref/cornell.gltf")
        });
    let spp: u32 = a.get(2).and_then(|s| s.parse().ok()).unwrap_or(64);
    let width: u32 = a.get(3).and_then(|s| s.parse().ok()).unwrap_or(256);
    let threads: usize = a.get(4).and_then(|s| s.parse().ok()).unwrap_or(2);
    let rr_depth: u32 = a
        .get(5)
        .and_then(|s| s.parse().ok())
        .unwrap_or(RenderSettings::default().rr_depth);
    let job = RenderJob {
        scene,
        camera_name: None,
        camera: CameraChoice::Auto,
        width,
        height: None,
        aperture_radius_m: None,
        focus_distance_m: None,
        yfov_rad: None,
        settings: RenderSettings {
            spp,
            bands: camsim_render::Bands::parse("380:780:10").unwrap(),
            depth_spp: 0,
            rr_depth,
            ..Default::default()
        },
    };
    let p = prepare(&job).unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    // two seeds: speed of each and the per-pixel noise estimator of bench/render_mitsuba.sh
    // (sqrt(mean((x₁ − x₂)²/2)) / mean per band, averaged over the bands)
    let outs: Vec<_> = (0..2u64)
        .map(|seed| {
            let s = RenderSettings {
                seed,
                ..job.settings.clone()
            };
            let out =
                pool.install(|| render(&p.scene, p.camera.as_ref(), p.camera_to_world, &s, None));
            println!(
                "seed {seed}: render {:.3} s, {:.3} M paths/s",
                out.render_s,
                out.samples_per_s() / 1e6
            );
            out
        })
        .collect();
    let mut rel = Vec::new();
    for b in 0..outs[0].bands.count {
        let (a, c) = (&outs[0].band_planes[b], &outs[1].band_planes[b]);
        let n = a.len() as f64;
        let m: f64 = a
            .iter()
            .zip(c)
            .map(|(x, y)| 0.5 * (*x as f64 + *y as f64))
            .sum::<f64>()
            / n;
        let d2: f64 = a
            .iter()
            .zip(c)
            .map(|(x, y)| (*x as f64 - *y as f64).powi(2) / 2.0)
            .sum::<f64>()
            / n;
        if m > 0.0 {
            rel.push(d2.sqrt() / m);
        }
    }
    let mean: f64 = outs[0]
        .band_planes
        .iter()
        .map(|b| b.iter().map(|x| *x as f64).sum::<f64>())
        .sum::<f64>()
        / (outs[0].band_planes.len() * outs[0].width * outs[0].height) as f64;
    println!(
        "noise (rel., mean over bands) {:.4}, image mean {mean:.6}",
        rel.iter().sum::<f64>() / rel.len() as f64
    );
}
