//! Timing of the lens crate for bench/lens.sh: real-ray trace rate and field-model build.
//!
//! `cargo run --release -p camsim-lens --example lens_bench -- LENS.json [RAYS] [REPEATS]`
//! prints one JSON object: the rays/s of the batch tracer (rays generated from normalised
//! pupil points of the 0.7 field at the primary wavelength in blocks of 2048 (one reused batch per worker), traced to the
//! image plane, no clipping; wall and process CPU time), of the scalar tracer, and the wall
//! time of a 16-field × 31-wavelength field model with 128² pupil wave PSFs. Run by
//! bench/lens.sh.
use camsim_lens::{
    Clipping, FieldModel, FieldModelOptions, GlassCatalog, LensPrescription, RayBatch,
};
use std::time::Instant;

/// CPU time of this process (user + system, s) from /proc/self/stat (Linux; 0 elsewhere).
fn cpu_s() -> f64 {
    let Ok(t) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let rest = &t[t.rfind(')').map_or(0, |i| i + 2)..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|x| x.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) / 100.0
}

/// CPU time of all threads of this process (s) from /proc/self/task/*/schedstat (ns
/// resolution; Linux; falls back to [`cpu_s`]).
fn cpu_ns_s() -> f64 {
    let Ok(dir) = std::fs::read_dir("/proc/self/task") else {
        return cpu_s();
    };
    let mut ns = 0u64;
    for e in dir.flatten() {
        if let Ok(t) = std::fs::read_to_string(e.path().join("schedstat")) {
            ns += t
                .split_whitespace()
                .next()
                .and_then(|x| x.parse::<u64>().ok())
                .unwrap_or(0);
        }
    }
    ns as f64 * 1e-9
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args
        .get(1)
        .expect("usage: lens_bench LENS.json [RAYS] [REPEATS]");
    let n_rays: usize = args.get(2).map_or(4_000_000, |s| s.parse().unwrap());
    let repeats: usize = args.get(3).map_or(5, |s| s.parse().unwrap());
    let lens = LensPrescription::from_json_file(path, &GlassCatalog::bundled()).unwrap();
    let lens = lens.focused(lens.primary_nm).unwrap();
    let w = lens.primary_nm;
    let max = lens.fields_deg.iter().cloned().fold(0.0, f64::max);
    let fo = lens.first_order(w).unwrap();
    let aim = lens.aim_field(0.7 * max, w, &fo).unwrap();
    // Pupil points: a deterministic low-discrepancy (golden-angle spiral) fill of the disc.
    let pupil: Vec<[f64; 2]> = (0..n_rays)
        .map(|i| {
            let r = ((i as f64 + 0.5) / n_rays as f64).sqrt();
            let a = i as f64 * 2.399_963_229_728_653;
            [r * a.cos(), r * a.sin()]
        })
        .collect();
    let sys = lens.trace_system(w);
    let median = |mut v: Vec<f64>| {
        v.sort_by(|a, b| a.partial_cmp(b).unwrap());
        v[v.len() / 2]
    };
    let mut times = Vec::new();
    let mut alive = 0;
    let mut cpu = Vec::new();
    for _ in 0..repeats {
        let t0 = Instant::now();
        let c0 = cpu_ns_s();
        // Streamed in blocks of 2048 rays into one reused batch per worker: generate from
        // the pupil points, trace, count (no allocation per block).
        use rayon::prelude::*;
        alive = pupil
            .par_chunks(2048)
            .map_init(
                || RayBatch::with_capacity(2048),
                |b, c| {
                    sys.trace_pupil_into(&aim, c, Clipping::None, b);
                    b.count_alive()
                },
            )
            .sum();
        times.push(t0.elapsed().as_secs_f64());
        cpu.push(cpu_ns_s() - c0);
    }
    let batch_cpu_s = cpu.iter().cloned().fold(f64::INFINITY, f64::min);
    let batch_s = median(times);
    if std::env::var_os("LENS_BENCH_TRACE_ONLY").is_some() {
        // A/B runs of the batch tracer alone: min CPU time per ray over the repeats.
        println!(
            "{{\"threads\": {}, \"rays\": {n_rays}, \"rays_alive\": {alive}, \"batch_trace_s\": {batch_s}, \"batch_trace_cpu_s\": {batch_cpu_s}, \"cpu_ns_per_ray\": {}}}",
            rayon::current_num_threads(),
            batch_cpu_s * 1e9 / n_rays as f64
        );
        return;
    }
    // Scalar tracer on a tenth of the rays (ray generation included as well).
    let ns = (n_rays / 10).max(1);
    let mut times = Vec::new();
    for _ in 0..repeats.min(3) {
        let t0 = Instant::now();
        use rayon::prelude::*;
        let k = pupil[..ns]
            .par_iter()
            .filter(|p| {
                lens.trace(&aim.ray(p[0], p[1]), w, Clipping::None)
                    .is_some()
            })
            .count();
        times.push(t0.elapsed().as_secs_f64());
        assert!(k > 0);
    }
    let scalar_s = median(times);
    // Field model: 16 fields × 31 wavelengths (400–700 nm), 128² pupil wave PSFs.
    let opts = FieldModelOptions {
        n_fields: 16,
        wavelengths_nm: Some((0..31).map(|i| 400.0 + 10.0 * i as f64).collect()),
        pupil_n: 128,
        pad: 2,
        psf_n: 33,
        psf_pitch_um: 1.0,
        ri_grid_n: 64,
        ..Default::default()
    };
    let mut times = Vec::new();
    for _ in 0..repeats.min(3) {
        let t0 = Instant::now();
        let m = FieldModel::compute(&lens, &opts).unwrap();
        times.push(t0.elapsed().as_secs_f64());
        assert_eq!(m.tables[0].psf.len(), 16);
    }
    let fm_s = median(times);
    println!(
        "{{\"lens\": {:?}, \"threads\": {}, \"rays\": {n_rays}, \"rays_alive\": {alive}, \"batch_trace_s\": {batch_s}, \"batch_trace_cpu_s\": {batch_cpu_s}, \"batch_rays_per_s\": {}, \"scalar_rays\": {ns}, \"scalar_trace_s\": {scalar_s}, \"scalar_rays_per_s\": {}, \"field_model_16x31_128_s\": {fm_s}, \"surfaces\": {}}}",
        lens.name,
        rayon::current_num_threads(),
        n_rays as f64 / batch_s,
        ns as f64 / scalar_s,
        lens.surfaces.len()
    );
}
