//! Issue 17 §4, the uncropped optical image as a camera-file option
//! (`optics.uncropped_optical_image`, ISETCam `oiCompute` with `crop = false`), through the one
//! chain (`camsim_pipeline::chain::optical_image`).
//!
//! Set-up: a 48 × 48 sensor (2 µm pixels, f = 3 mm, no relative illumination) and a white
//! picture whose field of view covers the central 24 × 24 pixels (W = 48 µm = 2 f tan(F/2)),
//! blurred by a Gaussian PSF (σ = 1.5 µm, a `blur.kind = "psf"` file sampled at the simulation
//! pitch, 0.5 µm). ISETCam's documented procedure for the scene image of n = 96 samples per
//! side: zero-pad by round(n/8) = 12 samples (6 µm) each side, convolve periodically (FFT) over
//! the padded period P = 120 samples = 60 µm, keep the padded image. For the box [−a, a]²
//! (a = 24 µm) of plateau E₀ this is, in closed form,
//!
//! `E(x, y) = E₀ · B(x) · B(y)`, `B(x) = Σ_k ½ [erf((a − x + kP)/(σ√2)) + erf((a + x − kP)/(σ√2))]`
//!
//! (k = −1, 0, 1; farther copies add < 1e-30) on the padded image, zero beyond it, averaged
//! over each pixel with ∫ erf(u) du = u erf(u) + e^{−u²}/√π. The pixel's electron rate is then
//! E₀-plateau rate × the pixel means of B(x) and B(y). Tolerance 5e-3 of the plateau: the
//! simulation convolves cell samples with the sampled Gaussian (σ = 3 samples) and integrates
//! 4 × 4 samples per pixel, two midpoint rules of error ≲ (Δ²/24)·|E''| ≈ 1e-3 each.
use crate::cli::{camera, write_set};
use camsim_core::colorimetry::luminance_weight_for_photons;
use camsim_core::constants::SI;
use camsim_core::spectrum::WavelengthGrid;
use serde_json::json;
use statrs::function::erf::erf;
use std::f64::consts::PI;

const N_PX: usize = 48;
const P_UM: f64 = 2.0;
const SIGMA_UM: f64 = 1.5;
const A_UM: f64 = 24.0; // half-width of the scene image
const PERIOD_UM: f64 = 60.0; // (96 + 2·12) samples of 0.5 µm

/// ∫ erf(u) du.
fn erf_int(u: f64) -> f64 {
    u * erf(u) + (-u * u).exp() / PI.sqrt()
}

/// Mean of B(x) over [x0, x1] (µm): the periodic, Gaussian-blurred box of the doc comment.
fn box_mean(x0: f64, x1: f64) -> f64 {
    let s = SIGMA_UM * 2f64.sqrt();
    let mut sum = 0.0;
    for k in -1..=1 {
        let sh = k as f64 * PERIOD_UM;
        // ∫ erf((a − x + sh)/s) dx = s [F(u0) − F(u1)], u = (a − x + sh)/s
        let (u0, u1) = ((A_UM - x0 + sh) / s, (A_UM - x1 + sh) / s);
        // ∫ erf((a + x − sh)/s) dx = s [F(v1) − F(v0)], v = (a + x − sh)/s
        let (v0, v1) = ((A_UM + x0 - sh) / s, (A_UM + x1 - sh) / s);
        sum += 0.5 * s * (erf_int(u0) - erf_int(u1) + erf_int(v1) - erf_int(v0));
    }
    sum / (x1 - x0)
}

/// The padded image ends 6 µm outside the scene image: pixels 9…38 (of 0…47) hold light.
fn in_padded_image(i: usize) -> bool {
    (9..39).contains(&i)
}

/// Electron rates (row-major) of the shot with `uncropped` (None: key absent) and `blur`.
fn rates(uncropped: Option<bool>, gaussian: bool) -> Vec<f64> {
    shot(uncropped, gaussian).0
}

/// The electron rates and the luminous power on the whole simulation grid (Σ luminance ×
/// sample area, arbitrary units) of the irradiance.
fn shot(uncropped: Option<bool>, gaussian: bool) -> (Vec<f64>, f64) {
    shot_psf(uncropped, gaussian, false)
}

/// [`shot`], or with `delta` a one-sample PSF file (no blur, the same band-image path).
fn shot_psf(uncropped: Option<bool>, gaussian: bool, delta: bool) -> (Vec<f64>, f64) {
    let dir = tempfile::tempdir().unwrap();
    image::RgbImage::from_raw(16, 16, vec![255u8; 16 * 16 * 3])
        .unwrap()
        .save(dir.path().join("w.png"))
        .unwrap();
    // PSF file: the Gaussian sampled at 0.5 µm, ±8 µm (5.3 σ), one wavelength.
    let h = 16;
    let psf: Vec<Vec<f64>> = (0..=2 * h)
        .map(|i| {
            (0..=2 * h)
                .map(|j| {
                    let (y, x) = ((i as f64 - h as f64) * 0.5, (j as f64 - h as f64) * 0.5);
                    (-(x * x + y * y) / (2.0 * SIGMA_UM * SIGMA_UM)).exp()
                })
                .collect()
        })
        .collect();
    let psf = if delta { vec![vec![1.0]] } else { psf };
    std::fs::write(
        dir.path().join("psf.json"),
        json!({"wavelength_nm": [550], "sample_spacing_um": 0.5, "psf": [psf]}).to_string(),
    )
    .unwrap();
    let mut cam = camera(N_PX, N_PX);
    cam["optics"]["relative_illumination"] = json!("none");
    cam["optics"]["blur"] = if gaussian {
        json!({"kind": "psf", "psf_file": "psf.json"})
    } else {
        json!({"kind": "none"})
    };
    if let Some(u) = uncropped {
        cam["optics"]["uncropped_optical_image"] = json!(u);
    }
    // W = 2 f tan(F/2) = 48 µm: the picture covers pixels 12…35.
    let fov_deg = 2.0 * (0.5 * 48e-6 / 3e-3f64).atan().to_degrees();
    let caps = json!({"camera": "camera.json", "shots": [
        {"id": "w", "exposure_s": 0.01, "frames": ["a.png"],
         "target": {"kind": "image", "file": "w.png", "display": "lcdExample",
                    "fov_deg": fov_deg}}]});
    write_set(dir.path(), &cam, &caps);
    let set =
        camsim_pipeline::config::load_captures(&dir.path().join("captures.json"), None).unwrap();
    let grid = WavelengthGrid::regular(400.0, 700.0, 10.0).unwrap();
    if gaussian {
        let scene = camsim_pipeline::chain::shot_scene(&set, 0, &grid).unwrap();
        assert!(
            (scene.sample_pitch_m - 0.5e-6).abs() < 1e-15,
            "the PSF file is sampled at the simulation pitch: {}",
            scene.sample_pitch_m
        );
    }
    let r = camsim_pipeline::chain::shot_electron_rate(&set, 0, &grid).unwrap();
    assert_eq!((r.rows, r.cols), (N_PX, N_PX));
    let irr = camsim_pipeline::chain::shot_irradiance(&set, 0, &grid).unwrap();
    let lum = irr
        .irradiance
        .integrate_against(&luminance_weight_for_photons(&SI));
    let power = lum.iter().map(|v| *v as f64).sum::<f64>() * irr.sample_pitch_m.powi(2);
    (r.electrons_per_s.iter().map(|v| *v as f64).collect(), power)
}

#[test]
fn uncropped_image_key_gives_isetcams_blurred_ring_around_a_small_scene() {
    let (none, _) = shot(None, false);
    // the same band-image path without blur (a one-sample PSF), for the power balance
    let (_, p_delta) = shot_psf(Some(true), true, true);
    let plateau = none[24 * N_PX + 24];
    assert!(plateau > 0.0);
    let (on, p_on) = shot(Some(true), true);
    let (mut worst, mut ring_min) = (0.0f64, f64::INFINITY);
    for i in 0..N_PX {
        let y0 = (i as f64 - 24.0) * P_UM;
        let by = box_mean(y0, y0 + P_UM);
        for j in 0..N_PX {
            let got = on[i * N_PX + j];
            if !(in_padded_image(i) && in_padded_image(j)) {
                assert_eq!(got, 0.0, "pixel ({i}, {j}) beyond the padded image");
                continue;
            }
            let x0 = (j as f64 - 24.0) * P_UM;
            let want = plateau * by * box_mean(x0, x0 + P_UM);
            worst = worst.max((got - want).abs() / plateau);
        }
        // the ring: the pixel just outside the scene image, middle row/column
        if i == 24 {
            for j in [11, 36] {
                ring_min = ring_min.min(on[i * N_PX + j] / plateau);
            }
        }
    }
    eprintln!(
        "uncropped: max |rate − closed form| = {worst:.2e} of the plateau; ring pixel \
         {ring_min:.3} of the plateau"
    );
    assert!(worst < 5e-3, "{worst}");
    assert!(ring_min > 0.1, "the ring holds light: {ring_min}");
    // Power: the periodic blur keeps every photon of the scene image on the padded image
    // (OTF(0) = 1), which the grid holds whole: the irradiance's luminous power equals the
    // unblurred one (a one-sample PSF on the same band path: the band image's luminance
    // differs from the linear-model scene's by ~1e-3, issue 17 §1).
    assert!(
        (p_on / p_delta - 1.0).abs() < 1e-5,
        "power {p_on} vs {p_delta}"
    );
    let (s_on, s_none) = (on.iter().sum::<f64>(), none.iter().sum::<f64>());
    eprintln!("Σ rates: uncropped / unblurred = {:.6}", s_on / s_none);
}

#[test]
fn uncropped_image_key_off_is_the_default_and_refuses_non_fft_blurs() {
    // Absent and false are the same (the spec's optics); camsim's default convolves the whole
    // sensor grid linearly, so it too spreads the scene image's light past its edge — but not
    // periodically and with no bound at round(n/8), and it has no light beyond the blur's
    // reach: far from the scene image both read zero.
    let absent = rates(None, true);
    let off = rates(Some(false), true);
    assert_eq!(absent, off, "absent ≡ false");
    let on = rates(Some(true), true);
    let plateau = rates(None, false)[24 * N_PX + 24];
    for k in [0, 5] {
        // ≥ 12 µm = 8σ from the edge, beyond the PSF file's ±8 µm: zero up to FFT round-off
        let v = off[24 * N_PX + k] / plateau;
        assert!(
            v.abs() < 1e-6,
            "pixel (24, {k}) far from the scene image: {v}"
        );
    }
    let diff = off
        .iter()
        .zip(&on)
        .map(|(a, b)| (a - b).abs() / plateau)
        .fold(0.0, f64::max);
    eprintln!(
        "default vs uncropped, Gaussian σ = 1.5 µm (4σ inside the ring): max diff {diff:.2e}; \
         default ring pixel (24, 11) {:.3} of the plateau",
        off[24 * N_PX + 11] / plateau
    );
    // A Gaussian blur kind is not ISETCam's FFT optical image: refused, naming the key.
    let dir = tempfile::tempdir().unwrap();
    let mut cam = camera(8, 8);
    cam["optics"]["blur"] = json!({"kind": "gaussian", "sigma_um": 1.0});
    cam["optics"]["uncropped_optical_image"] = json!(true);
    let caps = json!({"camera": "camera.json", "shots": [
        {"id": "d", "exposure_s": 0.01, "frames": ["a.png"], "target": {"kind": "dark"}}]});
    write_set(dir.path(), &cam, &caps);
    let e = camsim_pipeline::config::load_captures(&dir.path().join("captures.json"), None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("optics.uncropped_optical_image") && e.contains("camera.json"),
        "{e}"
    );
}
