//! Development check: render a glTF and print per-band image means (optionally next to a
//! reference EXR's `band_*` means). `cargo run --release -p camsim-render --example quick --
//! SCENE.gltf [REF.exr] [spp] [width]`
use camsim_render::job::{prepare, CameraChoice, RenderJob};
use camsim_render::{render, RenderSettings};
use std::path::PathBuf;

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let spp: u32 = a.get(3).and_then(|s| s.parse().ok()).unwrap_or(16);
    let width: u32 = a.get(4).and_then(|s| s.parse().ok()).unwrap_or(128);
    let job = RenderJob {
        scene: PathBuf::from(&a[1]),
        camera_name: None,
        camera: CameraChoice::Auto,
        width,
        height: None,
        aperture_radius_m: None,
        focus_distance_m: None,
        yfov_rad: None,
        settings: RenderSettings {
            spp,
            bands: camsim_render::Bands::parse("380:780:20").unwrap(),
            ..Default::default()
        },
    };
    let t = std::time::Instant::now();
    let p = prepare(&job).unwrap();
    eprintln!(
        "load {:.3}s: {}",
        t.elapsed().as_secs_f64(),
        p.camera_description
    );
    let out = render(
        &p.scene,
        p.camera.as_ref(),
        p.camera_to_world,
        &job.settings,
        None,
    );
    eprintln!(
        "render {:.3}s, {:.3} M samples/s",
        out.render_s,
        out.samples_per_s() / 1e6
    );
    let refm: Option<Vec<(String, f64)>> = a.get(2).filter(|s| s.ends_with(".exr")).map(|r| {
        let (_, _, ch, _) = camsim_core::exr_io::read_channels(std::path::Path::new(r)).unwrap();
        ch.iter()
            .filter(|(n, _)| n.starts_with("band_") || n.starts_with("depth"))
            .map(|(n, v)| {
                (
                    n.clone(),
                    v.iter().map(|x| *x as f64).sum::<f64>() / v.len() as f64,
                )
            })
            .collect()
    });
    for b in 0..out.bands.count {
        let m: f64 = out.band_planes[b].iter().map(|x| *x as f64).sum::<f64>()
            / out.band_planes[b].len() as f64;
        let name = out.bands.mitsuba_name(b);
        let r = refm
            .as_ref()
            .and_then(|v| v.iter().find(|(n, _)| *n == name).map(|x| x.1));
        match r {
            Some(r) => println!("{name} ours {m:.5} ref {r:.5} ratio {:.4}", m / r),
            None => println!("{name} ours {m:.5}"),
        }
    }
    let dc: f64 =
        out.depth_center_m.iter().map(|x| *x as f64).sum::<f64>() / out.depth_center_m.len() as f64;
    let dm: f64 =
        out.depth_mean_m.iter().map(|x| *x as f64).sum::<f64>() / out.depth_mean_m.len() as f64;
    println!("depth_center mean {dc:.5} depth.T mean {dm:.5}");
    if let Some(v) = &refm {
        for (n, m) in v.iter().filter(|(n, _)| n.starts_with("depth")) {
            println!("ref {n} {m:.5}");
        }
    }
}
