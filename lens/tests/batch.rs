//! The batch (vectorised) tracer against the scalar tracer: the same rays, the same losses.
use camsim_lens::analysis::pupil_grid;
use camsim_lens::batch::RayBatch;
use camsim_lens::{Clipping, GlassCatalog, LensPrescription};

fn bundled(name: &str) -> LensPrescription {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../lenses")
        .join(name);
    let l = LensPrescription::from_json_file(p, &GlassCatalog::bundled()).unwrap();
    l.focused(l.primary_nm).unwrap()
}

#[test]
fn batch_trace_equals_the_scalar_trace() {
    // Spheres (double Gauss), an even asphere (US 8,427,765), a finite object (US 5,831,776)
    // and a wide-angle fisheye, with and without clipping at the semi-diameters, over a pupil
    // grid overfilling the entrance pupil (so some rays are lost in every way).
    let mut pupil = pupil_grid(41);
    pupil.extend(pupil_grid(23).iter().map(|p| [1.3 * p[0], 1.3 * p[1]]));
    let mut checked = 0;
    for name in [
        "double_gauss_50mm_f2.json",
        "zmx_us8427765_aspheric.json",
        "zmx_us5831776_lithography.json",
        "pbrt_fisheye_10mm_f4.json",
    ] {
        let l = bundled(name);
        let max = l.fields_deg.iter().cloned().fold(0.0, f64::max);
        for frac in [0.0, 0.6, 1.0] {
            for &w in &l.wavelengths_nm {
                let fo = l.first_order(w).unwrap();
                let aim = l.aim_field(frac * max, w, &fo).unwrap();
                let sys = l.trace_system(w);
                for clip in [Clipping::None, Clipping::SemiDiameters] {
                    let b = sys.trace_pupil(&aim, &pupil, clip);
                    // The streaming entry point (rays generated straight into the lane
                    // vectors for collimated fields, blocks of ≤ 2048) gives the same rays.
                    let mut bs = RayBatch::with_capacity(0);
                    for (k, chunk) in pupil.chunks(1000).enumerate() {
                        sys.trace_pupil_into(&aim, chunk, clip, &mut bs);
                        for i in 0..chunk.len() {
                            assert_eq!(bs.get(i), b.get(k * 1000 + i), "{name}: streamed");
                        }
                    }
                    for (i, p) in pupil.iter().enumerate() {
                        let s = l.trace(&aim.ray(p[0], p[1]), w, clip);
                        let t = b.get(i);
                        match (s, t) {
                            (None, None) => {}
                            (Some(s), Some(t)) => {
                                for k in 0..3 {
                                    assert!(
                                        (s.image_mm[k] - t.image_mm[k]).abs() < 1e-9
                                            && (s.direction[k] - t.direction[k]).abs() < 1e-12,
                                        "{name} {frac} {w} {clip:?} ray {p:?}: {s:?} vs {t:?}"
                                    );
                                }
                                assert!((s.opl_mm - t.opl_mm).abs() < 1e-9, "{name}: OPL");
                                assert!((0..3).all(|k| (s.stop_mm[k] - t.stop_mm[k]).abs() < 1e-9));
                                checked += 1;
                            }
                            (s, t) => panic!(
                                "{name} {frac} {w} {clip:?} ray {p:?}: scalar {s:?} batch {t:?}"
                            ),
                        }
                    }
                }
            }
        }
    }
    assert!(checked > 20_000, "{checked}");
}

#[test]
fn batch_trace_does_not_depend_on_the_thread_count() {
    let l = bundled("double_gauss_50mm_f2.json");
    let w = l.primary_nm;
    let fo = l.first_order(w).unwrap();
    let aim = l.aim_field(14.0, w, &fo).unwrap();
    let pupil = pupil_grid(257);
    let run = |threads: usize| -> RayBatch {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                l.trace_system(w)
                    .trace_pupil(&aim, &pupil, Clipping::SemiDiameters)
            })
    };
    let (a, b) = (run(1), run(3));
    // Bit for bit (lost rays may carry NaN, so compare the bit patterns).
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    for (u, v) in [
        (&a.x, &b.x),
        (&a.y, &b.y),
        (&a.z, &b.z),
        (&a.l, &b.l),
        (&a.m, &b.m),
        (&a.n, &b.n),
        (&a.opl, &b.opl),
        (&a.stop_x, &b.stop_x),
        (&a.stop_y, &b.stop_y),
        (&a.stop_z, &b.stop_z),
    ] {
        assert_eq!(bits(u), bits(v));
    }
    assert_eq!(a.alive, b.alive);
    assert!(a.count_alive() < pupil.len(), "some rays are vignetted");
    assert!(a.count_alive() > 1000);
}

#[test]
fn streaming_into_a_reused_batch_equals_one_batch() {
    // 10 000 rays overfilling the pupil (vignetted: ~46 % pass; parallel fill and trace) against blocks of varying size streamed through
    // one reused batch (serial path, buffers shrinking and growing): identical rays.
    let l = bundled("double_gauss_50mm_f2.json");
    let w = l.primary_nm;
    let fo = l.first_order(w).unwrap();
    let max = l.fields_deg.iter().cloned().fold(0.0, f64::max);
    let aim = l.aim_field(0.7 * max, w, &fo).unwrap();
    let sys = l.trace_system(w);
    let n = 10_000;
    let pupil: Vec<[f64; 2]> = (0..n)
        .map(|i| {
            let r = 1.1 * ((i as f64 + 0.5) / n as f64).sqrt();
            let a = i as f64 * 2.399_963_229_728_653;
            [r * a.cos(), r * a.sin()]
        })
        .collect();
    let whole = sys.trace_pupil(&aim, &pupil, Clipping::SemiDiameters);
    let alive = whole.count_alive();
    assert!(alive > n / 4 && alive < n, "alive {alive} of {n}");
    let mut b = RayBatch::with_capacity(0);
    let mut start = 0;
    for size in [2048usize, 17, 5000, 1, 2048].iter().cycle() {
        if start >= n {
            break;
        }
        let end = (start + size).min(n);
        sys.trace_pupil_into(&aim, &pupil[start..end], Clipping::SemiDiameters, &mut b);
        assert_eq!(b.len(), end - start);
        for i in 0..b.len() {
            assert_eq!(b.get(i), whole.get(start + i), "ray {}", start + i);
        }
        start = end;
    }
}
