//! ISETCam-compatible variants, for oracle tests only (never the camsim default).
//!
//! ISETCam (Stanford, MIT licence) differs from the baseline of `spec/capture-format.md` in:
//!
//! * **spectral integration**: a Riemann sum `Σ_b E(λ_b) QE(λ_b) Δλ` on the image's band grid
//!   instead of the exact integral of the piecewise-linear spectra (the two differ at the
//!   end bands, where the trapezoid weight is Δλ/2);
//! * **pixel sampling**: each pixel takes the *bilinear interpolation* of its own channel's
//!   map at the pixel centre (zero outside the outermost sample centres) instead of the area
//!   average over the pixel square. ISETCam first blurs with a Gaussian of
//!   `ceil(pixel / sample spacing)` samples; only the case pixel ≤ spacing (1 × 1 kernel, no
//!   blur) is implemented, anything else is [`SensorError::Unsupported`];
//! * **auto-exposure** (`autoExposure(…, 'luminance')`): the brightest-illuminance 2 × 2 region
//!   of the irradiance is stretched over a small sensor of 8 × the CFA tile and the exposure
//!   set so that its largest noiseless 1 s voltage reaches `level` × swing
//!   ([`auto_exposure_isetcam_s`]);
//! * the elementary charge q = 1.602177e-19 C ([`ISETCAM_Q`]); it cancels between current
//!   density and volts, and is kept only to mirror the computation.
use crate::integrate::channel_maps;
use crate::{ElectronRate, SensorError, SensorModel};
use camsim_core::constants::ISETCAM;
use camsim_core::{SensorIrradiance, SpectralBasis, SpectralImage, Spectrum, WavelengthGrid};
use rayon::prelude::*;

/// ISETCam's elementary charge (C).
pub const ISETCAM_Q: f64 = ISETCAM.elementary_charge_c;

/// ISETCam's spectral weights of the image's basis terms for a QE spectrum: for a band image,
/// `QE(λ_b) · Δλ` (Riemann sum, Δλ the grid step, or the trapezoid weight on an irregular
/// grid); for a linear-model image, the exact integrals.
pub fn riemann_weights(img: &SpectralImage, qe: &Spectrum) -> Vec<f64> {
    match &img.basis {
        SpectralBasis::Bands(g) => {
            let q = qe.sample(g);
            let dl: Vec<f64> = match g.step_nm() {
                Some(s) => vec![s; g.len()],
                None => g.trapezoid_weights_nm(),
            };
            q.iter().zip(&dl).map(|(a, b)| a * b).collect()
        }
        SpectralBasis::Spectra(_) => img.term_integrals(qe),
    }
}

/// Bilinear interpolation of a row-major `rows × cols` map at fractional index (uy, ux);
/// zero outside `[0, rows−1] × [0, cols−1]` (Matlab `interp2` outside → 0 in ISETCam).
pub fn bilinear_zero_outside(map: &[f32], rows: usize, cols: usize, uy: f64, ux: f64) -> f64 {
    const EPS: f64 = 1e-9;
    let axis = |u: f64, n: usize| -> Option<(usize, f64)> {
        if u < -EPS || u > (n - 1) as f64 + EPS {
            return None;
        }
        if n == 1 {
            return Some((0, 0.0));
        }
        let u = u.clamp(0.0, (n - 1) as f64);
        let i = (u.floor() as usize).min(n - 2);
        Some((i, u - i as f64))
    };
    let (Some((y0, fy)), Some((x0, fx))) = (axis(uy, rows), axis(ux, cols)) else {
        return 0.0;
    };
    let y1 = (y0 + 1).min(rows - 1);
    let x1 = (x0 + 1).min(cols - 1);
    let m = |y: usize, x: usize| map[y * cols + x] as f64;
    (1.0 - fy) * ((1.0 - fx) * m(y0, x0) + fx * m(y0, x1))
        + fy * ((1.0 - fx) * m(y1, x0) + fx * m(y1, x1))
}

/// ISETCam's noiseless electron rate: per channel the Riemann map `Σ_b E_b QE_c(λ_b) Δλ`
/// (photons/(s·m²)), bilinearly interpolated at each pixel centre of that channel, times
/// `p² · FF`. (ISETCam's signal current density is q times the map and its volts
/// `current · p² · FF · t · g / q`, i.e. this rate × t × g.)
pub fn electron_rate_isetcam_bilinear(
    sensor: &SensorModel,
    irradiance: &SensorIrradiance,
) -> Result<ElectronRate, SensorError> {
    let img = &irradiance.irradiance;
    let s = irradiance.sample_pitch_m;
    if sensor.pixel_pitch_m > s * (1.0 + 1e-12) {
        return Err(SensorError::Unsupported(format!(
            "ISETCam pre-blur for pixel pitch {} m > irradiance sample spacing {} m",
            sensor.pixel_pitch_m, s
        )));
    }
    let maps = channel_maps(sensor, |qe| img.combine(&riemann_weights(img, qe)));
    let k = sensor.pixel_pitch_m * sensor.pixel_pitch_m * sensor.fill_factor;
    let (p, rows, cols) = (sensor.pixel_pitch_m, sensor.rows, sensor.cols);
    let mut out = vec![0f32; rows * cols];
    out.par_chunks_mut(cols).enumerate().for_each(|(r, row)| {
        // Centred grids: position (i − (n−1)/2)·pitch → index of the irradiance sample.
        let y = (r as f64 - (rows as f64 - 1.0) / 2.0) * p;
        let uy = y / s + (img.rows as f64 - 1.0) / 2.0;
        for (c, o) in row.iter_mut().enumerate() {
            let x = (c as f64 - (cols as f64 - 1.0) / 2.0) * p;
            let ux = x / s + (img.cols as f64 - 1.0) / 2.0;
            let m = maps[sensor.cfa.channel_at(r, c)].as_ref().expect("map");
            let current_density_a_per_m2 =
                ISETCAM_Q * bilinear_zero_outside(m, img.rows, img.cols, uy, ux);
            *o = (k * current_density_a_per_m2 / ISETCAM_Q) as f32;
        }
    });
    Ok(ElectronRate {
        rows,
        cols,
        electrons_per_s: out,
    })
}

/// ISETCam's default auto-exposure (`autoExposure` 'luminance', `oiExtractBright`):
///
/// 1. the irradiance sample of maximum illuminance ∝ `Σ_b E_b ȳ(λ_b) / λ_b` (photons →
///    energy; the first maximum in column-major order, as Matlab's `max`);
/// 2. the 2 × 2 samples starting there (clamped at the image border, where ISETCam would
///    crop fewer);
/// 3. a sensor of 8 × the CFA tile pixels views that 2 × 2 image stretched to twice the
///    sensor's width (sample spacing = sensor width; ISETCam sets the field of view to twice
///    the sensor's, which differs from this by a relative ~(w/2f)² ≈ 3e-5 in spacing);
/// 4. noiseless 1 s volts with ISETCam's bilinear sampling; `t = level · swing / max volts`.
///
/// Dark current and analog gain are ignored (ISETCam's noiseless sensor at gain 1).
/// `ybar_energy` is the CIE ȳ in the energy basis.
pub fn auto_exposure_isetcam_s(
    sensor: &SensorModel,
    irradiance: &SensorIrradiance,
    ybar_energy: &Spectrum,
    level: f64,
) -> Result<f64, SensorError> {
    let img0 = &irradiance.irradiance;
    let img = match &img0.basis {
        SpectralBasis::Bands(_) => img0.clone(),
        SpectralBasis::Spectra(_) => img0.to_bands(&WavelengthGrid::default_visible()),
    };
    let SpectralBasis::Bands(grid) = &img.basis else {
        unreachable!()
    };
    // Step 1: illuminance up to a constant factor.
    let w: Vec<f64> = grid
        .wavelength_nm
        .iter()
        .map(|&l| ybar_energy.eval(l) / l)
        .collect();
    let lum = img.combine(&w);
    let (mut best, mut br, mut bc) = (f32::NEG_INFINITY, 0usize, 0usize);
    for c in 0..img.cols {
        for r in 0..img.rows {
            let v = lum[r * img.cols + c];
            if v > best {
                (best, br, bc) = (v, r, c);
            }
        }
    }
    // Step 2: 2 × 2 crop.
    let rs = [br, (br + 1).min(img.rows - 1)];
    let cs = [bc, (bc + 1).min(img.cols - 1)];
    let planes: Vec<Vec<f32>> = img
        .planes
        .iter()
        .map(|p| {
            let mut v = Vec::with_capacity(4);
            for &r in &rs {
                for &c in &cs {
                    v.push(p[r * img.cols + c]);
                }
            }
            v
        })
        .collect();
    let small = SpectralImage {
        rows: 2,
        cols: 2,
        basis: img.basis.clone(),
        planes,
    };
    // Step 3: small sensor of 8 × the tile; the 2 × 2 image spans twice its width.
    let mut ss = sensor.clone();
    ss.rows = 8 * sensor.cfa.tile_rows();
    ss.cols = 8 * sensor.cfa.tile_cols();
    let spacing = ss.cols as f64 * sensor.pixel_pitch_m;
    let rate = electron_rate_isetcam_bilinear(
        &ss,
        &SensorIrradiance {
            irradiance: small,
            sample_pitch_m: spacing,
        },
    )?;
    // Step 4: 1 s volts (no swing clip), t = level · swing / max.
    let max_v = rate.electrons_per_s.iter().fold(0f64, |m, &r| {
        m.max(r as f64 * sensor.conversion_gain_v_per_e)
    });
    if max_v <= 0.0 {
        return Err(SensorError::Unsupported(
            "auto-exposure of a dark image".into(),
        ));
    }
    Ok(level * sensor.voltage_swing_v / max_v)
}

/// Pixel SNR in dB and its components at one mean signal level (ISETCam `pixelSNR` /
/// `sensorSNR` convention, in electrons: S = V/g, variances shot = S, read = (read_V/g)²,
/// DSNU = (dsnu_V/g)², PRNU = (prnu·S)²). A component with zero variance is +∞ dB.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SnrComponentsDb {
    /// Total SNR `10 log10(S² / Σ variances)`.
    pub snr_db: f64,
    /// Shot-noise-only SNR.
    pub shot_db: f64,
    /// Read-noise-only SNR.
    pub read_db: f64,
    /// DSNU-only SNR.
    pub dsnu_db: f64,
    /// PRNU-only SNR.
    pub prnu_db: f64,
}

/// SNR and its components for a mean signal of `signal_v` volts (before analog gain) on
/// `sensor` (uses conversion gain, read noise, DSNU and PRNU; dark current excluded, as
/// ISETCam's `pixelSNR`).
pub fn snr_components_db(sensor: &SensorModel, signal_v: f64) -> SnrComponentsDb {
    let g = sensor.conversion_gain_v_per_e;
    let s = signal_v / g;
    let var_shot = s;
    let var_read = (sensor.read_noise_v / g).powi(2);
    let var_dsnu = (sensor.dsnu_sigma_v / g).powi(2);
    let var_prnu = (sensor.prnu_sigma_percent / 100.0 * s).powi(2);
    let db = |var: f64| 10.0 * (s * s / var).log10();
    SnrComponentsDb {
        snr_db: db(var_shot + var_read + var_dsnu + var_prnu),
        shot_db: db(var_shot),
        read_db: db(var_read),
        dsnu_db: db(var_dsnu),
        prnu_db: db(var_prnu),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_basics() {
        let m = [0f32, 1.0, 2.0, 3.0]; // 2×2
        assert_eq!(bilinear_zero_outside(&m, 2, 2, 0.5, 0.5), 1.5);
        assert_eq!(bilinear_zero_outside(&m, 2, 2, 1.0, 1.0), 3.0);
        assert_eq!(bilinear_zero_outside(&m, 2, 2, 0.0, 0.25), 0.25);
        assert_eq!(bilinear_zero_outside(&m, 2, 2, 1.01, 0.5), 0.0);
        assert_eq!(bilinear_zero_outside(&m, 2, 2, 0.5, -0.1), 0.0);
    }

    #[test]
    fn riemann_weights_use_step_at_every_band() {
        let g = WavelengthGrid::regular(400.0, 700.0, 10.0).unwrap();
        let img =
            SpectralImage::new(1, 1, SpectralBasis::Bands(g.clone()), vec![vec![1.0]; 31]).unwrap();
        let w = riemann_weights(&img, &Spectrum::constant(1.0));
        assert!(w.iter().all(|&x| x == 10.0));
    }
}
