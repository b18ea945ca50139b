//! Development micro-benchmark: random rays inside a glTF scene (closest hit and occlusion).
use camsim_render::gltf_load::load_gltf;
use glam::Vec3;
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let s = load_gltf(std::path::Path::new(&a[1])).unwrap();
    let mut rng = camsim_core::rng::stream(1, &[1]);
    use rand::Rng;
    let mut f = || (rng.next_u32() >> 8) as f32 / 16777216.0;
    let n = 2_000_000;
    let rays: Vec<(Vec3, Vec3)> = (0..n)
        .map(|_| {
            let o = s.bounds_center + Vec3::new(f() - 0.5, f() - 0.5, f() - 0.5) * s.bounds_radius;
            let d = Vec3::new(f() - 0.5, f() - 0.5, f() - 0.5).normalize();
            (o, d)
        })
        .collect();
    let t = std::time::Instant::now();
    let mut hits = 0;
    for (o, d) in &rays {
        if s.intersect(*o, *d, 0.0, f32::INFINITY).is_some() {
            hits += 1;
        }
    }
    let dt = t.elapsed().as_secs_f64();
    println!("closest: {:.1} ns/ray ({hits} hits)", dt / n as f64 * 1e9);
    let t = std::time::Instant::now();
    let mut miss = 0;
    for (o, d) in &rays {
        if s.unoccluded(*o, *d, 0.0, 0.5) {
            miss += 1;
        }
    }
    let dt = t.elapsed().as_secs_f64();
    println!("occlusion: {:.1} ns/ray ({miss} unoccluded)", dt / n as f64 * 1e9);
}
