//! ISETCam oracle cases (../shared/oracles/isetcam) for the scene and metrics parts of the
//! core crate. Optics and sensor cases live in their crates' tests.
use crate::util::{case, oracle_dir, values};
use camsim_core::colorimetry::{xyz_from_energy, Quadrature};
use camsim_core::constants::ISETCAM;
use camsim_core::image::{SceneRadiance, SpectralBasis, SpectralImage};
use camsim_core::npy::read_npy;
use camsim_core::scene::{
    blackbody_value, mean_luminance_riemann, render_target, SamplingGrid, Target,
};
use camsim_core::spectrum::{Spectrum, WavelengthGrid};

fn grid() -> WavelengthGrid {
    WavelengthGrid::regular(400.0, 700.0, 10.0).unwrap()
}

#[test]
fn utility_energy_quanta_1d() {
    let c = case("utility_energy_quanta_1d");
    let w = values(&c["inputs"]["wave_nm"]);
    let e = values(&c["inputs"]["energy_W"]);
    let expected = values(&c["expected"]["photons"]);
    let s = Spectrum::sampled(w.clone(), e.clone())
        .unwrap()
        .energy_to_photons(&ISETCAM);
    for ((wl, ex), en) in w.iter().zip(&expected).zip(&e) {
        let got = s.eval(*wl);
        assert!(
            (got - ex).abs() <= 1e-9 * ex.abs(),
            "{wl} nm: {got} vs {ex}"
        );
        let back = got / ISETCAM.photons_per_joule(*wl);
        assert!((back - en).abs() <= 1e-9 * en.abs());
    }
}

#[test]
fn metrics_xyz_from_energy_1d() {
    let c = case("metrics_xyz_from_energy_1d");
    let w = values(&c["inputs"]["wave_nm"]);
    let e = values(&c["inputs"]["energy_W_per_sr_m2_nm"]);
    let expected = values(&c["expected"]["xyz"]);
    let s = Spectrum::sampled(w, e).unwrap();
    let xyz = xyz_from_energy(
        &s,
        Quadrature::RiemannOnGrid {
            start_nm: 400,
            step_nm: 10,
            count: 31,
        },
    );
    for (got, ex) in [xyz.x, xyz.y, xyz.z].iter().zip(&expected) {
        assert!((got - ex).abs() <= 1e-7 * ex.abs(), "{got} vs {ex}");
    }
    // the exact (trapezoid-consistent) integral differs only by the end-point half weights
    let exact = xyz_from_energy(&s, Quadrature::Exact);
    assert!((exact.y / xyz.y - 1.0).abs() < 0.01);
}

/// ISETCam's default Macbeth scene: reflectance (ISETCam column-major patch order) × D65,
/// in photons, scaled to a mean luminance of 100 cd/m² (Riemann sums on 400:10:700 nm).
#[test]
fn scene_macbeth_default() {
    let c = case("scene_macbeth_default");
    let tol = c["tolerance"]["rtol"].as_f64().unwrap();
    let g = grid();
    let d65 = camsim_core::data::illuminant("D65")
        .unwrap()
        .energy_to_photons(&ISETCAM);
    let file = camsim_core::data::spectral("surfaces/reflectances/macbethChart").unwrap();
    // chart (row r, col c) holds file column 4c + r
    let patches: Vec<Spectrum> = (0..24)
        .map(|i| {
            let (r, col) = (i / 6, i % 6);
            Spectrum::multiply(&file.spectra[4 * col + r], &d65)
        })
        .collect();
    let target = Target::Patches {
        rows: 4,
        cols: 6,
        patch_fraction: 1.0,
        background: Spectrum::constant(0.0),
        patches,
    };
    let sg = SamplingGrid::for_sensor(64, 96, 1e-6, 1, 0);
    let img = render_target(&target, &sg).unwrap().to_bands(&g);
    let mut scene = SceneRadiance {
        radiance: img,
        sample_pitch_m: 1e-6,
        object_distance_m: None,
        illuminant: Some(d65),
        depth_m: None,
        sample_aperture: Default::default(),
    };
    let lum = mean_luminance_riemann(&scene, &g, &ISETCAM);
    scene.scale(100.0 / lum);
    let exp = read_npy(&oracle_dir().join("data/scene_macbeth_default__photons.npy")).unwrap();
    assert_eq!(exp.shape, vec![64, 96, 31]);
    let max = exp.data.iter().cloned().fold(0.0, f64::max);
    let mut worst = 0.0f64;
    for r in 0..64 {
        for col in 0..96 {
            for b in 0..31 {
                let e = exp.data[(r * 96 + col) * 31 + b];
                let got = scene.radiance.planes[b][r * 96 + col] as f64;
                let err = (got - e).abs() / (e.abs() + 1e-7 * max);
                worst = worst.max(err);
            }
        }
    }
    assert!(worst <= tol, "worst relative error {worst} > {tol}");
    assert!((mean_luminance_riemann(&scene, &g, &ISETCAM) - 100.0).abs() < 1e-3);
}

#[test]
fn scene_uniform_bb_small() {
    let c = case("scene_uniform_bb_small");
    let tol = c["tolerance"]["rtol"].as_f64().unwrap();
    let g = grid();
    let (c1, c2) = (3.741832e-16, 1.438786e-2);
    let photons: Vec<f64> = g
        .wavelength_nm
        .iter()
        .map(|&w| blackbody_value(4500.0, w, c1, c2) * ISETCAM.photons_per_joule(w))
        .collect();
    let planes: Vec<Vec<f32>> = photons.iter().map(|p| vec![*p as f32; 16 * 16]).collect();
    let img = SpectralImage::new(16, 16, SpectralBasis::Bands(g.clone()), planes).unwrap();
    let mut scene = SceneRadiance {
        radiance: img,
        sample_pitch_m: 1e-6,
        object_distance_m: None,
        illuminant: None,
        depth_m: None,
        sample_aperture: Default::default(),
    };
    let lum = mean_luminance_riemann(&scene, &g, &ISETCAM);
    scene.scale(100.0 / lum);
    let expected = values(&c["expected"]["pixel_spectrum_photons"]);
    for (b, e) in expected.iter().enumerate() {
        let got = scene.radiance.planes[b][5 * 16 + 7] as f64;
        assert!((got - e).abs() <= tol * e, "band {b}: {got} vs {e}");
    }
    let exp = read_npy(&oracle_dir().join("data/scene_uniform_bb_small__photons.npy")).unwrap();
    assert_eq!(exp.shape, vec![16, 16, 31]);
    assert!(
        (exp.data[31 * 17 + 3] - scene.radiance.planes[3][17] as f64).abs()
            <= tol * exp.data[31 * 17 + 3]
    );
}
