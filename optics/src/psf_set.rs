//! Per-wavelength sampled PSFs (e.g. exported by a lens design program).
use crate::error::OpticsError;
use crate::kernels::SampledPsf;
use serde::Deserialize;
use std::path::Path;

/// A set of sampled PSFs, one per wavelength, each normalised to sum 1. Sample (i, j) of a
/// `rows × cols` PSF lies at `((i − (rows−1)/2)·s, (j − (cols−1)/2)·s)` from the PSF centre.
#[derive(Debug, Clone, PartialEq)]
pub struct PsfSet {
    /// Strictly increasing wavelengths (nm).
    pub wavelength_nm: Vec<f64>,
    /// Sample spacing of the PSFs (m).
    pub sample_spacing_m: f64,
    /// Rows of every PSF.
    pub rows: usize,
    /// Columns of every PSF.
    pub cols: usize,
    /// One row-major `rows × cols` PSF per wavelength, each summing to 1.
    pub psf: Vec<Vec<f64>>,
}

#[derive(Deserialize)]
struct PsfFile {
    wavelength_nm: Vec<f64>,
    sample_spacing_um: f64,
    psf: Vec<Vec<Vec<f64>>>,
}

impl PsfSet {
    /// A validated set from `psf[wavelength][row][col]`; every PSF is normalised to sum 1.
    pub fn new(
        wavelength_nm: Vec<f64>,
        sample_spacing_um: f64,
        psf: Vec<Vec<Vec<f64>>>,
    ) -> Result<Self, OpticsError> {
        let err = |m: String| Err(OpticsError::Psf(m));
        if wavelength_nm.is_empty() {
            return err("no wavelengths".into());
        }
        if let Some(i) = wavelength_nm
            .iter()
            .position(|w| !w.is_finite() || *w <= 0.0)
        {
            return err(format!(
                "wavelength_nm[{i}] = {} is not a positive number",
                wavelength_nm[i]
            ));
        }
        if let Some(i) = wavelength_nm.windows(2).position(|w| w[1] <= w[0]) {
            return err(format!(
                "wavelength_nm must be strictly increasing: wavelength_nm[{}] = {} follows {}",
                i + 1,
                wavelength_nm[i + 1],
                wavelength_nm[i]
            ));
        }
        if !(sample_spacing_um.is_finite() && sample_spacing_um > 0.0) {
            return err(format!(
                "sample_spacing_um = {sample_spacing_um} must be > 0"
            ));
        }
        if psf.len() != wavelength_nm.len() {
            return err(format!(
                "{} PSFs for {} wavelengths",
                psf.len(),
                wavelength_nm.len()
            ));
        }
        let rows = psf[0].len();
        let cols = psf[0].first().map_or(0, |r| r.len());
        if rows == 0 || cols == 0 {
            return err("PSF 0 is empty".into());
        }
        let mut out = Vec::with_capacity(psf.len());
        for (k, p) in psf.iter().enumerate() {
            if p.len() != rows {
                return err(format!("PSF {k} has {} rows, PSF 0 has {rows}", p.len()));
            }
            let mut flat = Vec::with_capacity(rows * cols);
            for (i, r) in p.iter().enumerate() {
                if r.len() != cols {
                    return err(format!(
                        "PSF {k} row {i} has {} columns, expected {cols}",
                        r.len()
                    ));
                }
                for (j, &v) in r.iter().enumerate() {
                    if !v.is_finite() || v < 0.0 {
                        return err(format!(
                            "PSF {k} ({} nm) value [{i}][{j}] = {v} is not a finite number >= 0",
                            wavelength_nm[k]
                        ));
                    }
                }
                flat.extend_from_slice(r);
            }
            let s: f64 = flat.iter().sum();
            if s <= 0.0 {
                return err(format!("PSF {k} ({} nm) sums to 0", wavelength_nm[k]));
            }
            flat.iter_mut().for_each(|v| *v /= s);
            out.push(flat);
        }
        Ok(PsfSet {
            wavelength_nm,
            sample_spacing_m: sample_spacing_um * 1e-6,
            rows,
            cols,
            psf: out,
        })
    }

    /// Parse the JSON format
    /// `{"wavelength_nm": [..], "sample_spacing_um": s, "psf": [[[..row..], ..], ..]}`
    /// (`psf[wavelength][row][col]`).
    pub fn from_json_str(text: &str) -> Result<Self, OpticsError> {
        let f: PsfFile = serde_json::from_str(text).map_err(|e| OpticsError::Psf(e.to_string()))?;
        PsfSet::new(f.wavelength_nm, f.sample_spacing_um, f.psf)
    }

    /// Read [`PsfSet::from_json_str`] from a file; errors name the file.
    pub fn from_json_file(path: &Path) -> Result<Self, OpticsError> {
        let pe = |msg: String| OpticsError::PsfFile {
            path: path.display().to_string(),
            msg,
        };
        let text = std::fs::read_to_string(path).map_err(|e| pe(e.to_string()))?;
        PsfSet::from_json_str(&text).map_err(|e| match e {
            OpticsError::Psf(m) => pe(m),
            other => other,
        })
    }

    /// The PSF at `wavelength_nm` (row-major, sum 1): linear interpolation between the two
    /// neighbouring wavelengths; the first/last PSF outside the tabulated range.
    pub fn at_wavelength(&self, wavelength_nm: f64) -> Vec<f64> {
        let w = &self.wavelength_nm;
        let n = w.len();
        if wavelength_nm <= w[0] {
            return self.psf[0].clone();
        }
        if wavelength_nm >= w[n - 1] {
            return self.psf[n - 1].clone();
        }
        let i = w.partition_point(|x| *x <= wavelength_nm); // w[i-1] <= λ < w[i]
        let t = (wavelength_nm - w[i - 1]) / (w[i] - w[i - 1]);
        self.psf[i - 1]
            .iter()
            .zip(&self.psf[i])
            .map(|(a, b)| (1.0 - t) * a + t * b)
            .collect()
    }

    /// The PSF at `wavelength_nm` re-sampled to a centred grid of pitch `pitch_m`, sum 1.
    /// Coarser target: every source sample's weight is split bilinearly among the four nearest
    /// target samples (conserves the weight and centroid). Finer target: bilinear
    /// interpolation of the source, then normalisation.
    pub fn resampled(&self, wavelength_nm: f64, pitch_m: f64) -> SampledPsf {
        let src = self.at_wavelength(wavelength_nm);
        let s = self.sample_spacing_m;
        let (cy, cx) = (
            (self.rows as f64 - 1.0) / 2.0,
            (self.cols as f64 - 1.0) / 2.0,
        );
        let hr = (cy * s / pitch_m).ceil() as usize + 1;
        let hc = (cx * s / pitch_m).ceil() as usize + 1;
        let (nr, nc) = (2 * hr + 1, 2 * hc + 1);
        let mut data = vec![0.0; nr * nc];
        if pitch_m >= s {
            for i in 0..self.rows {
                for j in 0..self.cols {
                    let v = src[i * self.cols + j];
                    if v == 0.0 {
                        continue;
                    }
                    let ty = (i as f64 - cy) * s / pitch_m + hr as f64;
                    let tx = (j as f64 - cx) * s / pitch_m + hc as f64;
                    let (y0, x0) = (ty.floor(), tx.floor());
                    let (fy, fx) = (ty - y0, tx - x0);
                    let (y0, x0) = (y0 as usize, x0 as usize);
                    data[y0 * nc + x0] += v * (1.0 - fy) * (1.0 - fx);
                    data[y0 * nc + x0 + 1] += v * (1.0 - fy) * fx;
                    data[(y0 + 1) * nc + x0] += v * fy * (1.0 - fx);
                    data[(y0 + 1) * nc + x0 + 1] += v * fy * fx;
                }
            }
        } else {
            let get = |i: isize, j: isize| -> f64 {
                if i < 0 || j < 0 || i >= self.rows as isize || j >= self.cols as isize {
                    0.0
                } else {
                    src[i as usize * self.cols + j as usize]
                }
            };
            for i in 0..nr {
                for j in 0..nc {
                    let sy = (i as f64 - hr as f64) * pitch_m / s + cy;
                    let sx = (j as f64 - hc as f64) * pitch_m / s + cx;
                    let (y0, x0) = (sy.floor(), sx.floor());
                    let (fy, fx) = (sy - y0, sx - x0);
                    let (y0, x0) = (y0 as isize, x0 as isize);
                    data[i * nc + j] = get(y0, x0) * (1.0 - fy) * (1.0 - fx)
                        + get(y0, x0 + 1) * (1.0 - fy) * fx
                        + get(y0 + 1, x0) * fy * (1.0 - fx)
                        + get(y0 + 1, x0 + 1) * fy * fx;
                }
            }
        }
        let mut p = SampledPsf {
            half_rows: hr,
            half_cols: hc,
            pitch_m,
            data,
        };
        if p.sum() <= 0.0 {
            p.data.iter_mut().for_each(|v| *v = 0.0);
            p.data[hr * nc + hc] = 1.0;
        }
        p.normalise();
        p
    }
}
