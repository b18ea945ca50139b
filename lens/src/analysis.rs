//! Image-quality analyses built on the real-ray trace.
//!
//! Conventions follow /work/shared/tools/optics_ref/ref_lens.py so results are comparable:
//! * pupil sampling for spots: the n×n grid ((i + ½)/n·2 − 1) clipped to the unit disc;
//! * RMS spot radius about the centroid; the image plane is the lens's own (last thickness)
//!   plus `defocus_mm`, reached by propagating the traced rays (no re-trace);
//! * distortion % = 100 (|y_real| − |y_parax|)/|y_parax| with the real chief ray aimed at the
//!   stop centre at the primary wavelength and y_parax the paraxial chief-ray height
//!   (= EFL·tan θ at the focal plane for an object at infinity);
//! * lateral colour = y_chief(shortest λ) − y_chief(longest λ), the same entrance-pupil start
//!   point (aimed at the primary wavelength) traced at each wavelength;
//! * wave PSF: pupil function P = A·exp(2πi W/λ) on the linspace(−1, 1, n)² entrance-pupil grid
//!   with W the OPD against the reference sphere centred on the chief-ray image point through
//!   the paraxial exit pupil (Goodman, "Introduction to Fourier Optics" §6.4; Born & Wolf §9.1);
//!   PSF = |FFT(P zero-padded)|², normalised to sum 1; MTF = |FFT(PSF)| / its DC value, with
//!   the paraxial scaling ν_cut = 1/(λ N_w) (a shift of one pupil diameter = ν_cut).
//! * relative illumination: fraction of a fixed entrance-pupil grid transmitted when rays are
//!   clipped at the semi-diameters (mechanical vignetting) × cos⁴ of the real image-space
//!   chief-ray angle (natural fall-off, Smith §9.2), at a given wavelength (refraction, hence
//!   vignetting, changes with it); both factors are reported separately.
use crate::error::LensError;
use crate::paraxial::FirstOrder;
use crate::prescription::LensPrescription;
use crate::trace::AimedChief;
use crate::trace::{Clipping, FieldAim, TracedRay};
use rustfft::{num_complex::Complex64, FftPlanner};

/// Normalised pupil coordinates of the n×n grid ((i + ½)/n·2 − 1) clipped to the unit disc.
pub fn pupil_grid(n: usize) -> Vec<[f64; 2]> {
    let v: Vec<f64> = (0..n)
        .map(|i| (i as f64 + 0.5) / n as f64 * 2.0 - 1.0)
        .collect();
    let mut out = Vec::new();
    for &py in &v {
        for &px in &v {
            if px * px + py * py <= 1.0 {
                out.push([px, py]);
            }
        }
    }
    out
}

/// A spot diagram at one field and wavelength.
#[derive(Debug, Clone, PartialEq)]
pub struct SpotDiagram {
    /// Field angle (degrees).
    pub field_deg: f64,
    /// Wavelength (nm).
    pub wavelength_nm: f64,
    /// Image-plane points (x, y) in mm of the rays that got through.
    pub points_mm: Vec<[f64; 2]>,
    /// Centroid (mm).
    pub centroid_mm: [f64; 2],
    /// RMS radius about the centroid (mm).
    pub rms_radius_mm: f64,
    /// Rays launched.
    pub n_launched: usize,
}

fn rms_about_centroid(pts: &[[f64; 2]]) -> ([f64; 2], f64) {
    let n = pts.len().max(1) as f64;
    let cx = pts.iter().map(|p| p[0]).sum::<f64>() / n;
    let cy = pts.iter().map(|p| p[1]).sum::<f64>() / n;
    let s = pts
        .iter()
        .map(|p| (p[0] - cx).powi(2) + (p[1] - cy).powi(2))
        .sum::<f64>()
        / n;
    ([cx, cy], s.sqrt())
}

/// Rays of one field and wavelength traced through a pupil grid (`None` = lost).
#[derive(Debug, Clone)]
pub struct RayFan {
    /// Field aim used.
    pub aim: FieldAim,
    /// Wavelength (nm).
    pub wavelength_nm: f64,
    /// Pupil coordinates.
    pub pupil: Vec<[f64; 2]>,
    /// Result per pupil point.
    pub rays: Vec<Option<TracedRay>>,
}

impl RayFan {
    /// Image points after moving the image plane by `defocus_mm` (propagation along the rays).
    pub fn points_at(&self, defocus_mm: f64) -> Vec<[f64; 2]> {
        self.rays
            .iter()
            .flatten()
            .map(|r| {
                let s = defocus_mm / r.direction[2];
                [
                    r.image_mm[0] + s * r.direction[0],
                    r.image_mm[1] + s * r.direction[1],
                ]
            })
            .collect()
    }

    /// The spot diagram at `defocus_mm`.
    pub fn spot(&self, defocus_mm: f64) -> SpotDiagram {
        let pts = self.points_at(defocus_mm);
        let (c, rms) = rms_about_centroid(&pts);
        SpotDiagram {
            field_deg: self.aim.field_deg,
            wavelength_nm: self.wavelength_nm,
            points_mm: pts,
            centroid_mm: c,
            rms_radius_mm: rms,
            n_launched: self.pupil.len(),
        }
    }
}

/// Distortion and chief-ray heights at one field.
#[derive(Debug, Clone, PartialEq)]
pub struct DistortionPoint {
    /// Field angle (degrees).
    pub field_deg: f64,
    /// Paraxial chief-ray image height (mm).
    pub paraxial_height_mm: f64,
    /// Real chief-ray image height at the primary wavelength (mm).
    pub real_height_mm: f64,
    /// 100 (|y_real| − |y_parax|)/|y_parax| (0 on axis).
    pub distortion_pct: f64,
    /// |y_chief| per wavelength (same order as the lens's `wavelengths_nm`).
    pub chief_height_by_wavelength_mm: Vec<f64>,
    /// y_chief(shortest λ) − y_chief(longest λ) (µm).
    pub lateral_colour_um: f64,
}

/// Relative illumination at one field.
#[derive(Debug, Clone, PartialEq)]
pub struct RelativeIllumination {
    /// Field angle (degrees).
    pub field_deg: f64,
    /// Transmitted fraction of the entrance-pupil grid relative to the axis (vignetting).
    pub vignetting_factor: f64,
    /// cos⁴ of the real image-space chief-ray angle.
    pub cos4_factor: f64,
    /// Product of the two.
    pub relative_illumination: f64,
}

/// A sampled PSF (row-major, y rows, centred at index n/2), sum 1.
#[derive(Debug, Clone, PartialEq)]
pub struct Psf {
    /// Samples per side.
    pub n: usize,
    /// Sample pitch in the image plane (mm).
    pub sample_mm: f64,
    /// Values, row-major `[iy * n + ix]`, summing to 1.
    pub values: Vec<f64>,
}

/// OPD map on the linspace(−1, 1, n)² pupil grid (waves; NaN outside the pupil or for lost rays).
#[derive(Debug, Clone, PartialEq)]
pub struct OpdMap {
    /// Samples per side.
    pub n: usize,
    /// OPD W = OPL_chief − OPL_ray to the reference sphere, in waves, row-major (y rows).
    pub waves: Vec<f64>,
    /// RMS about the mean over valid samples (waves).
    pub rms_waves: f64,
    /// Peak-to-valley (waves).
    pub pv_waves: f64,
}

/// Tangential (y) and sagittal (x) MTF at one frequency.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MtfPoint {
    /// Spatial frequency (cycles/mm).
    pub freq_cyc_per_mm: f64,
    /// Tangential MTF.
    pub tangential: f64,
    /// Sagittal MTF.
    pub sagittal: f64,
}

/// Wave-optics PSF and MTF of one field and wavelength.
#[derive(Debug, Clone, PartialEq)]
pub struct WaveOptics {
    /// OPD map used.
    pub opd: OpdMap,
    /// PSF (sum 1).
    pub psf: Psf,
    /// MTF at the requested frequencies.
    pub mtf: Vec<MtfPoint>,
}

impl LensPrescription {
    /// Trace the pupil grid `pupil` for `field_deg` at `wavelength_nm`, the chief ray aimed at
    /// `aim_wavelength_nm`.
    pub fn ray_fan(
        &self,
        field_deg: f64,
        wavelength_nm: f64,
        aim_wavelength_nm: f64,
        pupil: &[[f64; 2]],
        clipping: Clipping,
    ) -> Result<RayFan, LensError> {
        let fo = self.first_order(aim_wavelength_nm)?;
        let aim = self.aim_field(field_deg, aim_wavelength_nm, &fo)?;
        let b = self
            .trace_system(wavelength_nm)
            .trace_pupil(&aim, pupil, clipping);
        let rays = (0..b.len()).map(|i| b.get(i)).collect();
        Ok(RayFan {
            aim,
            wavelength_nm,
            pupil: pupil.to_vec(),
            rays,
        })
    }

    /// Spot diagram on the `grid_n`² pupil grid, chief ray aimed at the primary wavelength.
    pub fn spot_diagram(
        &self,
        field_deg: f64,
        wavelength_nm: f64,
        grid_n: usize,
        defocus_mm: f64,
        clipping: Clipping,
    ) -> Result<SpotDiagram, LensError> {
        Ok(self
            .ray_fan(
                field_deg,
                wavelength_nm,
                self.primary_nm,
                &pupil_grid(grid_n),
                clipping,
            )?
            .spot(defocus_mm))
    }

    /// RMS spot radius (mm) of all wavelengths pooled, at `defocus_mm`.
    pub fn polychromatic_rms_mm(&self, fans: &[RayFan], defocus_mm: f64) -> f64 {
        let pts: Vec<[f64; 2]> = fans.iter().flat_map(|f| f.points_at(defocus_mm)).collect();
        rms_about_centroid(&pts).1
    }

    /// Image-plane shift (mm) minimising the polychromatic RMS spot of `fans`, searched in
    /// ±`span_mm` by golden-section (the RMS is unimodal near focus).
    pub fn best_focus_shift_mm(&self, fans: &[RayFan], span_mm: f64) -> f64 {
        let f = |z: f64| self.polychromatic_rms_mm(fans, z);
        let g = (5f64.sqrt() - 1.0) / 2.0;
        let (mut a, mut b) = (-span_mm, span_mm);
        let mut c = b - g * (b - a);
        let mut d = a + g * (b - a);
        let (mut fc, mut fd) = (f(c), f(d));
        while (b - a).abs() > 1e-7 {
            if fc < fd {
                b = d;
                d = c;
                fd = fc;
                c = b - g * (b - a);
                fc = f(c);
            } else {
                a = c;
                c = d;
                fc = fd;
                d = a + g * (b - a);
                fd = f(d);
            }
        }
        (a + b) / 2.0
    }

    /// Distortion and lateral colour at `field_deg` (see module docs).
    pub fn distortion(&self, field_deg: f64) -> Result<DistortionPoint, LensError> {
        let fo = self.first_order(self.primary_nm)?;
        let aim = self.aim_field(field_deg, self.primary_nm, &fo)?;
        let ray = aim.ray(0.0, 0.0);
        let lost = |w: f64| LensError::Aiming {
            field_deg,
            msg: format!("chief ray lost at {w} nm"),
        };
        let mut by_wl = Vec::new();
        for &w in &self.wavelengths_nm {
            let t = self.trace(&ray, w, Clipping::None).ok_or_else(|| lost(w))?;
            by_wl.push(t.image_mm[1].abs());
        }
        let real = self
            .trace(&ray, self.primary_nm, Clipping::None)
            .ok_or_else(|| lost(self.primary_nm))?;
        let real_height_mm = real.image_mm[1].abs();
        let paraxial_height_mm = self
            .paraxial_chief_height_mm(field_deg, self.primary_nm)?
            .abs();
        let distortion_pct = if field_deg == 0.0 {
            0.0
        } else {
            100.0 * (real_height_mm - paraxial_height_mm) / paraxial_height_mm
        };
        let (mut imin, mut imax) = (0, 0);
        for (i, w) in self.wavelengths_nm.iter().enumerate() {
            if *w < self.wavelengths_nm[imin] {
                imin = i;
            }
            if *w > self.wavelengths_nm[imax] {
                imax = i;
            }
        }
        Ok(DistortionPoint {
            field_deg,
            paraxial_height_mm,
            real_height_mm,
            distortion_pct,
            lateral_colour_um: 1000.0 * (by_wl[imin] - by_wl[imax]),
            chief_height_by_wavelength_mm: by_wl,
        })
    }

    /// Relative illumination at `field_deg` relative to the axis at `wavelength_nm` (see module
    /// docs), sampled with the `grid_n`² grid on the paraxial entrance pupil at that wavelength,
    /// the chief ray aimed at the stop centre at that wavelength. (The film-side integral of
    /// [`crate::pupil::film_relative_illumination`] adds the pupil's aberrations.)
    pub fn relative_illumination(
        &self,
        field_deg: f64,
        wavelength_nm: f64,
        grid_n: usize,
    ) -> Result<RelativeIllumination, LensError> {
        let grid = pupil_grid(grid_n);
        let count = |f: f64| -> Result<(usize, f64), LensError> {
            let fan = self.ray_fan(
                f,
                wavelength_nm,
                wavelength_nm,
                &grid,
                Clipping::SemiDiameters,
            )?;
            let chief = self.aimed_chief_ray(f, wavelength_nm)?.chief;
            Ok((fan.rays.iter().flatten().count(), chief.direction[2]))
        };
        let (n0, _) = count(0.0)?;
        let (n1, cos_t) = count(field_deg)?;
        let vignetting_factor = if n0 == 0 { 0.0 } else { n1 as f64 / n0 as f64 };
        let cos4_factor = cos_t.powi(4);
        Ok(RelativeIllumination {
            field_deg,
            vignetting_factor,
            cos4_factor,
            relative_illumination: vignetting_factor * cos4_factor,
        })
    }

    /// OPD map (waves) of `field_deg` at `wavelength_nm` on the linspace(−1, 1, n)² grid, chief
    /// ray aimed at `wavelength_nm`, against the reference sphere through the paraxial exit
    /// pupil centred on the chief ray's image point (on the lens's own image plane).
    pub fn opd_map(
        &self,
        field_deg: f64,
        wavelength_nm: f64,
        n: usize,
    ) -> Result<OpdMap, LensError> {
        let AimedChief {
            first_order: fo,
            aim,
            chief,
        } = self.aimed_chief_ray(field_deg, wavelength_nm)?;
        let n_img = self.surfaces.last().unwrap().medium.index(wavelength_nm);
        let p = chief.image_mm;
        let dc = chief.direction;
        let s_e = (p[2] - fo.exit_pupil_z_mm) / dc[2]; // image point → exit pupil along the chief ray
        let radius = s_e;
        let to_sphere = |r: &TracedRay| -> f64 {
            let w = [
                r.image_mm[0] - p[0],
                r.image_mm[1] - p[1],
                r.image_mm[2] - p[2],
            ];
            let wd = w[0] * r.direction[0] + w[1] * r.direction[1] + w[2] * r.direction[2];
            let ww = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
            let disc = (wd * wd - ww + radius * radius).max(0.0);
            // root nearest s_e (the sheet of the sphere at the exit pupil)
            let s = if radius >= 0.0 {
                wd + disc.sqrt()
            } else {
                wd - disc.sqrt()
            };
            r.opl_mm - n_img * s
        };
        let opl_chief = to_sphere(&chief);
        let wl_mm = wavelength_nm * 1e-6;
        let v: Vec<f64> = (0..n)
            .map(|i| {
                if n == 1 {
                    0.0
                } else {
                    -1.0 + 2.0 * i as f64 / (n - 1) as f64
                }
            })
            .collect();
        // In-disc grid points traced as one batch.
        let idx: Vec<usize> = (0..n * n)
            .filter(|&k| v[k % n] * v[k % n] + v[k / n] * v[k / n] <= 1.0)
            .collect();
        let pts: Vec<[f64; 2]> = idx.iter().map(|&k| [v[k % n], v[k / n]]).collect();
        let b = self
            .trace_system(wavelength_nm)
            .trace_pupil(&aim, &pts, Clipping::None);
        let mut waves = vec![f64::NAN; n * n];
        for (i, &k) in idx.iter().enumerate() {
            if let Some(r) = b.get(i) {
                waves[k] = (opl_chief - to_sphere(&r)) / wl_mm;
            }
        }
        let ok: Vec<f64> = waves.iter().copied().filter(|w| w.is_finite()).collect();
        let mean = ok.iter().sum::<f64>() / ok.len().max(1) as f64;
        let rms =
            (ok.iter().map(|w| (w - mean).powi(2)).sum::<f64>() / ok.len().max(1) as f64).sqrt();
        let pv = ok.iter().cloned().fold(f64::MIN, f64::max)
            - ok.iter().cloned().fold(f64::MAX, f64::min);
        Ok(OpdMap {
            n,
            waves,
            rms_waves: rms,
            pv_waves: pv,
        })
    }

    /// Wave-optics PSF and MTF (see module docs): OPD on an `n`² grid, zero-padded by `pad`.
    pub fn wave_optics(
        &self,
        field_deg: f64,
        wavelength_nm: f64,
        n: usize,
        pad: usize,
        freqs_cyc_per_mm: &[f64],
    ) -> Result<WaveOptics, LensError> {
        let fo: FirstOrder = self.first_order(wavelength_nm)?;
        let opd = self.opd_map(field_deg, wavelength_nm, n)?;
        let m = n * pad.max(1);
        let mut field = vec![Complex64::new(0.0, 0.0); m * m];
        for iy in 0..n {
            for ix in 0..n {
                let w = opd.waves[iy * n + ix];
                if w.is_finite() {
                    field[iy * m + ix] = Complex64::from_polar(1.0, 2.0 * std::f64::consts::PI * w);
                }
            }
        }
        let mut planner = FftPlanner::new();
        fft2(&mut planner, &mut field, m);
        let mut psf_raw: Vec<f64> = field.iter().map(|c| c.norm_sqr()).collect();
        let total: f64 = psf_raw.iter().sum();
        psf_raw.iter_mut().for_each(|v| *v /= total);
        // fftshift the PSF so the zero-offset sample sits at (m/2, m/2).
        let mut values = vec![0.0; m * m];
        for iy in 0..m {
            for ix in 0..m {
                values[((iy + m / 2) % m) * m + (ix + m / 2) % m] = psf_raw[iy * m + ix];
            }
        }
        let sample_mm = wavelength_nm * 1e-6 * fo.working_f_number * (n as f64 - 1.0) / m as f64;
        if freqs_cyc_per_mm.is_empty() {
            // No MTF asked for: skip the OTF transform.
            return Ok(WaveOptics {
                opd,
                psf: Psf {
                    n: m,
                    sample_mm,
                    values,
                },
                mtf: Vec::new(),
            });
        }
        // OTF from the (unshifted) PSF.
        let mut otf: Vec<Complex64> = psf_raw.iter().map(|&v| Complex64::new(v, 0.0)).collect();
        fft2(&mut planner, &mut otf, m);
        let dc = otf[0].norm();
        let nu_cut = 1.0 / (wavelength_nm * 1e-6 * fo.working_f_number);
        let dnu = nu_cut / (n as f64 - 1.0);
        let tan: Vec<f64> = (0..m / 2).map(|k| otf[k * m].norm() / dc).collect();
        let sag: Vec<f64> = (0..m / 2).map(|k| otf[k].norm() / dc).collect();
        let at = |arr: &[f64], f: f64| {
            let x = f / dnu;
            // Beyond the sampled band (and the cutoff) the MTF is 0; checked in f64 so that a
            // huge frequency cannot overflow the index.
            if !(x >= 0.0 && x + 1.0 < arr.len() as f64) {
                return 0.0;
            }
            let i = x.floor() as usize;
            let t = x - i as f64;
            arr[i] * (1.0 - t) + arr[i + 1] * t
        };
        let mtf = freqs_cyc_per_mm
            .iter()
            .map(|&f| MtfPoint {
                freq_cyc_per_mm: f,
                tangential: at(&tan, f),
                sagittal: at(&sag, f),
            })
            .collect();
        Ok(WaveOptics {
            opd,
            psf: Psf {
                n: m,
                sample_mm,
                values,
            },
            mtf,
        })
    }

    /// Geometric PSF: the spot of `field_deg` at `wavelength_nm` (`grid_n`² pupil grid) binned
    /// into an `n`×`n` histogram of pitch `sample_mm` centred on the centroid, normalised to sum 1.
    pub fn geometric_psf(
        &self,
        field_deg: f64,
        wavelength_nm: f64,
        grid_n: usize,
        n: usize,
        sample_mm: f64,
    ) -> Result<Psf, LensError> {
        let spot = self.spot_diagram(
            field_deg,
            wavelength_nm,
            grid_n,
            0.0,
            Clipping::SemiDiameters,
        )?;
        let mut values = vec![0.0; n * n];
        let mut inside = 0.0;
        for p in &spot.points_mm {
            let ix = ((p[0] - spot.centroid_mm[0]) / sample_mm + n as f64 / 2.0).floor();
            let iy = ((p[1] - spot.centroid_mm[1]) / sample_mm + n as f64 / 2.0).floor();
            if ix >= 0.0 && iy >= 0.0 && (ix as usize) < n && (iy as usize) < n {
                values[iy as usize * n + ix as usize] += 1.0;
                inside += 1.0;
            }
        }
        if inside > 0.0 {
            values.iter_mut().for_each(|v| *v /= inside);
        }
        Ok(Psf {
            n,
            sample_mm,
            values,
        })
    }
}

/// In-place 2-D FFT of an m×m row-major array.
fn fft2(planner: &mut FftPlanner<f64>, data: &mut [Complex64], m: usize) {
    let fft = planner.plan_fft_forward(m);
    for row in data.chunks_mut(m) {
        fft.process(row);
    }
    let mut col = vec![Complex64::new(0.0, 0.0); m];
    for x in 0..m {
        for y in 0..m {
            col[y] = data[y * m + x];
        }
        fft.process(&mut col);
        for y in 0..m {
            data[y * m + x] = col[y];
        }
    }
}
