//! Benchmark (not a test): diffraction-limited optics on a 1024 × 1024 × 31-band scene.
//! Prints one JSON line `{"median_s": …, "min_s": …}`; bench/bench.py compares it with numpy.
use camsim_core::image::{SceneRadiance, SpectralBasis, SpectralImage};
use camsim_core::spectrum::{Spectrum, WavelengthGrid};
use camsim_optics::{form_image, Blur, CameraEquation, OpticsModel, Padding, RelativeIllumination};
use std::time::Instant;

fn main() {
    let (rows, cols) = (1024usize, 1024usize);
    let grid = WavelengthGrid::regular(400.0, 700.0, 10.0).unwrap();
    // deterministic pseudo-random content (xorshift) so the FFT sees a generic image
    let mut s = 0x2545_F491_4F6C_DD1Du64;
    let planes: Vec<Vec<f32>> = (0..grid.len())
        .map(|_| {
            (0..rows * cols)
                .map(|_| {
                    s ^= s << 13;
                    s ^= s >> 7;
                    s ^= s << 17;
                    (s >> 40) as f32 / (1u64 << 24) as f32
                })
                .collect()
        })
        .collect();
    let scene = SceneRadiance {
        radiance: SpectralImage::new(rows, cols, SpectralBasis::Bands(grid.clone()), planes)
            .unwrap(),
        sample_pitch_m: 1e-6,
        object_distance_m: None,
        illuminant: None,
        depth_m: None,
        sample_aperture: Default::default(),
    };
    let optics = OpticsModel {
        f_number: 4.0,
        focal_length_m: 4e-3,
        transmittance: Spectrum::constant(1.0),
        relative_illumination: RelativeIllumination::Cos4,
        camera_equation: CameraEquation::Baseline,
        blur: Blur::Diffraction,
        diffuser: None,
        padding: Padding::Replicate,
        effects: Default::default(),
    };
    let mut times = Vec::new();
    for _ in 0..5 {
        let t0 = Instant::now();
        let out = form_image(&optics, &scene, &grid).unwrap();
        times.push(t0.elapsed().as_secs_f64());
        std::hint::black_box(out);
    }
    times.sort_by(|a, b| a.partial_cmp(b).unwrap());
    println!(
        "{{\"median_s\": {:.4}, \"min_s\": {:.4}}}",
        times[times.len() / 2],
        times[0]
    );
}
