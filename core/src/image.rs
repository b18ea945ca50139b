//! Spectral images and the typed products that pass between pipeline stages.
//!
//! A [`SpectralImage`] is a linear model (§2.A of the paper): `L(x, λ) = Σ_k a_k(x) B_k(λ)`
//! with basis spectra `B_k` and coefficient planes `a_k`. A plain band cube is the case
//! [`SpectralBasis::Bands`], whose basis functions are the piecewise-linear "hats" of the
//! wavelength grid. Wavelength-independent operations (relative illumination, Gaussian blur,
//! pixel integration) act on the planes; wavelength-dependent ones (diffraction) need bands.
use crate::error::CoreError;
use crate::spectrum::{Spectrum, WavelengthGrid};
use rayon::prelude::*;

/// Samples per parallel piece of [`SpectralImage::scale_spatially`] and
/// [`SpectralImage::scale`].
const SCALE_CHUNK: usize = 1 << 16;

/// A single-channel f32 image, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Plane {
    /// Rows (y, top to bottom).
    pub rows: usize,
    /// Columns (x, left to right).
    pub cols: usize,
    /// `rows × cols` values, row-major.
    pub data: Vec<f32>,
}

impl Plane {
    /// A plane filled with `value`.
    pub fn filled(rows: usize, cols: usize, value: f32) -> Self {
        Plane {
            rows,
            cols,
            data: vec![value; rows * cols],
        }
    }
    /// Value at (row, col).
    pub fn at(&self, row: usize, col: usize) -> f32 {
        self.data[row * self.cols + col]
    }
}

/// The spectral meaning of the planes of a [`SpectralImage`].
#[derive(Debug, Clone, PartialEq)]
pub enum SpectralBasis {
    /// One plane per wavelength of the grid (hat basis functions).
    Bands(WavelengthGrid),
    /// Arbitrary basis spectra (linear model); plane k multiplies spectrum k.
    Spectra(Vec<Spectrum>),
}

impl SpectralBasis {
    /// Number of basis terms.
    pub fn len(&self) -> usize {
        match self {
            SpectralBasis::Bands(g) => g.len(),
            SpectralBasis::Spectra(s) => s.len(),
        }
    }

    /// Whether there is no basis term.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Basis spectrum of term `k`.
    pub fn spectrum(&self, k: usize) -> Spectrum {
        match self {
            SpectralBasis::Bands(g) => g.hat(k),
            SpectralBasis::Spectra(s) => s[k].clone(),
        }
    }

    /// `∫ w(λ) B_k(λ) dλ` for every term: the weights that turn an image's planes into the
    /// spatial map of `∫ w(λ) L(x, λ) dλ` (exact for piecewise-linear data).
    pub fn term_integrals(&self, w: &Spectrum) -> Vec<f64> {
        (0..self.len())
            .map(|k| Spectrum::integrate_product(w, &self.spectrum(k)).unwrap_or(0.0))
            .collect()
    }
}

/// A spectral image as basis spectra × coefficient planes.
#[derive(Debug, Clone, PartialEq)]
pub struct SpectralImage {
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// What each plane means spectrally.
    pub basis: SpectralBasis,
    /// One row-major `rows × cols` plane per basis term.
    pub planes: Vec<Vec<f32>>,
}

impl SpectralImage {
    /// A validated image.
    pub fn new(
        rows: usize,
        cols: usize,
        basis: SpectralBasis,
        planes: Vec<Vec<f32>>,
    ) -> Result<Self, CoreError> {
        let k = match &basis {
            SpectralBasis::Bands(g) => g.len(),
            SpectralBasis::Spectra(s) => s.len(),
        };
        if planes.len() != k {
            return Err(CoreError::Image(format!(
                "{} planes for {} basis terms",
                planes.len(),
                k
            )));
        }
        if rows == 0 || cols == 0 {
            return Err(CoreError::Image(format!("empty image {rows}×{cols}")));
        }
        if let Some(p) = planes.iter().position(|p| p.len() != rows * cols) {
            return Err(CoreError::Image(format!(
                "plane {p} has {} values, expected {}×{}",
                planes[p].len(),
                rows,
                cols
            )));
        }
        Ok(SpectralImage {
            rows,
            cols,
            basis,
            planes,
        })
    }

    /// An image whose every pixel has spectrum `s` times `weight(row, col)`.
    pub fn from_single_spectrum(rows: usize, cols: usize, s: Spectrum, plane: Vec<f32>) -> Self {
        SpectralImage {
            rows,
            cols,
            basis: SpectralBasis::Spectra(vec![s]),
            planes: vec![plane],
        }
    }

    /// Number of basis terms (planes).
    pub fn terms(&self) -> usize {
        self.planes.len()
    }

    /// Basis spectrum of term `k`.
    pub fn basis_spectrum(&self, k: usize) -> Spectrum {
        self.basis.spectrum(k)
    }

    /// [`SpectralBasis::term_integrals`] of the image's basis.
    pub fn term_integrals(&self, w: &Spectrum) -> Vec<f64> {
        self.basis.term_integrals(w)
    }

    /// The map `Σ_k weights[k] · plane_k` (f64 accumulation per pixel).
    pub fn combine(&self, weights: &[f64]) -> Vec<f32> {
        let n = self.rows * self.cols;
        let mut out = vec![0f32; n];
        let active: Vec<(usize, f64)> = weights
            .iter()
            .copied()
            .enumerate()
            .filter(|(_, w)| *w != 0.0)
            .collect();
        // (term by term over a chunk: every pixel's sum in the same order, k ascending from
        // 0.0, so the same bits as a per-pixel loop, and the inner loop vectorises)
        out.par_chunks_mut(4096).enumerate().for_each_init(
            Vec::new,
            |acc: &mut Vec<f64>, (ci, chunk)| {
                let off = ci * 4096;
                acc.clear();
                acc.resize(chunk.len(), 0.0);
                for &(k, w) in &active {
                    let src = &self.planes[k][off..off + chunk.len()];
                    acc.iter_mut()
                        .zip(src)
                        .for_each(|(a, &v)| *a += w * v as f64);
                }
                chunk
                    .iter_mut()
                    .zip(acc.iter())
                    .for_each(|(o, &a)| *o = a as f32);
            },
        );
        out
    }

    /// `∫ w(λ) L(x, λ) dλ` per pixel.
    pub fn integrate_against(&self, w: &Spectrum) -> Vec<f32> {
        self.combine(&self.term_integrals(w))
    }

    /// Multiply every pixel's spectrum by `s(λ)`. Exact for a band cube (per band) and for a
    /// constant; otherwise the basis spectra are multiplied ([`Spectrum::multiply`]).
    pub fn scale_spectrally(&mut self, s: &Spectrum) {
        match &mut self.basis {
            SpectralBasis::Bands(g) => {
                let f = s.sample(g);
                self.planes
                    .par_iter_mut()
                    .zip(f.par_iter())
                    .for_each(|(p, &k)| {
                        let k = k as f32;
                        p.iter_mut().for_each(|v| *v *= k);
                    });
            }
            SpectralBasis::Spectra(b) => {
                for bk in b.iter_mut() {
                    *bk = Spectrum::multiply(bk, s);
                }
            }
        }
    }

    /// Multiply every plane by a spatial map (wavelength-independent factor). Parallel over
    /// pieces of `SCALE_CHUNK` (65 536) samples of every plane (a whole-sensor image of one to four
    /// planes keeps every thread busy); each sample's product is the same whatever the split.
    pub fn scale_spatially(&mut self, map: &[f32]) {
        assert_eq!(map.len(), self.rows * self.cols);
        self.planes.par_iter_mut().for_each(|p| {
            p.par_chunks_mut(SCALE_CHUNK)
                .zip(map.par_chunks(SCALE_CHUNK))
                .for_each(|(p, m)| p.iter_mut().zip(m).for_each(|(v, m)| *v *= *m));
        });
    }

    /// Multiply by a scalar (parallel as [`SpectralImage::scale_spatially`]).
    pub fn scale(&mut self, k: f64) {
        let k = k as f32;
        self.planes.par_iter_mut().for_each(|p| {
            p.par_chunks_mut(SCALE_CHUNK)
                .for_each(|p| p.iter_mut().for_each(|v| *v *= k))
        });
    }

    /// Expand to a band cube on `grid` (plane b = L(x, λ_b)). A band image on the same grid is
    /// returned unchanged; on another grid it is re-interpolated.
    pub fn to_bands(&self, grid: &WavelengthGrid) -> SpectralImage {
        if let SpectralBasis::Bands(g) = &self.basis {
            if g == grid {
                return self.clone();
            }
        }
        let weights: Vec<Vec<f64>> = (0..self.terms())
            .map(|k| self.basis_spectrum(k).sample(grid))
            .collect();
        let planes = (0..grid.len())
            .into_par_iter()
            .map(|b| {
                let w: Vec<f64> = weights.iter().map(|wk| wk[b]).collect();
                self.combine(&w)
            })
            .collect();
        SpectralImage {
            rows: self.rows,
            cols: self.cols,
            basis: SpectralBasis::Bands(grid.clone()),
            planes,
        }
    }

    /// The spectrum of pixel (row, col) sampled on `grid`.
    pub fn pixel_spectrum(&self, row: usize, col: usize, grid: &WavelengthGrid) -> Vec<f64> {
        let i = row * self.cols + col;
        let mut out = vec![0.0; grid.len()];
        for k in 0..self.terms() {
            let a = self.planes[k][i] as f64;
            if a == 0.0 {
                continue;
            }
            for (o, &w) in out.iter_mut().zip(&grid.wavelength_nm) {
                *o += a * self.basis_spectrum(k).eval(w);
            }
        }
        out
    }

    /// The spatial mean of every plane.
    pub fn plane_means(&self) -> Vec<f64> {
        self.planes
            .iter()
            .map(|p| p.iter().map(|v| *v as f64).sum::<f64>() / p.len() as f64)
            .collect()
    }

    /// Smallest coefficient of a band image (None for a linear model, whose coefficients may
    /// legitimately be negative).
    pub fn min_band_value(&self) -> Option<f32> {
        match self.basis {
            SpectralBasis::Bands(_) => Some(
                self.planes
                    .iter()
                    .flatten()
                    .copied()
                    .fold(f32::INFINITY, f32::min),
            ),
            SpectralBasis::Spectra(_) => None,
        }
    }
}

/// Scene spectral radiance, photons / (s · sr · m² · nm), sampled on a grid centred on the
/// optical axis whose spacing is given in the image plane.
#[derive(Debug, Clone)]
pub struct SceneRadiance {
    /// The radiance image.
    pub radiance: SpectralImage,
    /// Sample spacing in the image plane (m).
    pub sample_pitch_m: f64,
    /// Object distance (m); None = at infinity (magnification 0).
    pub object_distance_m: Option<f64>,
    /// The illuminant (photons units) when the scene is reflectance × illuminant.
    pub illuminant: Option<Spectrum>,
    /// Planar depth along the viewing axis (m), when known.
    pub depth_m: Option<Plane>,
    /// What each sample stands for (cell average, or the B-spline-filtered target that the
    /// optics' band-limited blurs compensate): [`crate::sample_aperture`].
    pub sample_aperture: crate::sample_aperture::SampleAperture,
}

impl SceneRadiance {
    /// Replace the illuminant: radiance × (new / old), pointwise in wavelength (reflectance is
    /// kept). Errors when the scene has no illuminant.
    pub fn swap_illuminant(&mut self, new_photons: Spectrum) -> Result<(), CoreError> {
        let old = self
            .illuminant
            .as_ref()
            .ok_or_else(|| CoreError::Target("scene has no illuminant to swap".into()))?;
        let ratio = ratio_spectrum(&new_photons, old);
        self.radiance.scale_spectrally(&ratio);
        self.illuminant = Some(new_photons);
        Ok(())
    }

    /// Scale the radiance (and illuminant) by `k`.
    pub fn scale(&mut self, k: f64) {
        self.radiance.scale(k);
        if let Some(i) = &mut self.illuminant {
            *i = i.scaled(k);
        }
    }
}

/// `a / b` sampled at both spectra's breakpoints (1 nm refinement), 0 where b = 0.
pub fn ratio_spectrum(a: &Spectrum, b: &Spectrum) -> Spectrum {
    let (lo, hi) = {
        let (a0, a1) = a.support_nm();
        let (b0, b1) = b.support_nm();
        (a0.max(b0).max(100.0), a1.min(b1).min(3000.0))
    };
    if hi <= lo {
        return Spectrum::Sampled {
            wavelength_nm: vec![lo.max(1.0)],
            values: vec![0.0],
        };
    }
    let n = ((hi - lo) / 1.0).ceil() as usize;
    let w: Vec<f64> = (0..=n)
        .map(|i| lo + (hi - lo) * i as f64 / n as f64)
        .collect();
    let v = w
        .iter()
        .map(|&x| {
            let d = b.eval(x);
            if d != 0.0 {
                a.eval(x) / d
            } else {
                0.0
            }
        })
        .collect();
    Spectrum::Sampled {
        wavelength_nm: w,
        values: v,
    }
}

/// Spectral irradiance at the sensor surface, photons / (s · m² · nm), on a grid centred on
/// the optical axis.
#[derive(Debug, Clone)]
pub struct SensorIrradiance {
    /// The irradiance image.
    pub irradiance: SpectralImage,
    /// Sample spacing on the sensor (m).
    pub sample_pitch_m: f64,
}

/// A raw mosaic frame in digital numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct RawFrame {
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// ADC bit depth.
    pub adc_bits: u32,
    /// `rows × cols` DN values, row 0 first.
    pub dn: Vec<u16>,
    /// What the values mean (CFA tile, channel names, black and white level), when known: set
    /// by the sensor stage and by readers of formats that store it (DNG); `None` for a bare
    /// PNG, TIFF or headerless raw frame, whose layout comes from the camera file.
    pub layout: Option<RawLayout>,
}

/// The layout of a raw frame: which channel each pixel carries and where black and white are.
#[derive(Debug, Clone, PartialEq)]
pub struct RawLayout {
    /// Channel index per colour-filter tile position, row-major (`cfa_tile[r][c]`); the tile
    /// repeats from pixel (0, 0).
    pub cfa_tile: Vec<Vec<usize>>,
    /// Channel names (index = channel index of the tile), e.g. `["r", "g", "b"]`.
    pub channel_names: Vec<String>,
    /// Value at zero signal (DN).
    pub black_dn: f64,
    /// Largest usable value (DN), normally `2^bits − 1`.
    pub white_dn: f64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// [`SpectralImage::combine`] (term by term over chunks) is, bit for bit, the per-pixel
    /// sum `Σ_k w_k a_k` in f64 with k ascending from 0.0 and the zero weights skipped, on an
    /// image larger than one chunk (4096 samples) whose size is not a multiple of it.
    #[test]
    fn combine_is_the_per_pixel_sum_bit_for_bit() {
        let (rows, cols, terms) = (71, 97, 9);
        let planes: Vec<Vec<f32>> = (0..terms)
            .map(|k| {
                (0..rows * cols)
                    .map(|i| {
                        let v = (i as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15 ^ (k as u64));
                        (v >> 40) as f32 / (1u64 << 20) as f32 - 3.0
                    })
                    .collect()
            })
            .collect();
        let img = SpectralImage::new(
            rows,
            cols,
            SpectralBasis::Spectra(vec![Spectrum::constant(1.0); terms]),
            planes.clone(),
        )
        .unwrap();
        let w: Vec<f64> = (0..terms)
            .map(|k| if k == 4 { 0.0 } else { 0.37 * k as f64 - 1.1 })
            .collect();
        let got: Vec<u32> = img.combine(&w).iter().map(|v| v.to_bits()).collect();
        let want: Vec<u32> = (0..rows * cols)
            .map(|i| {
                let mut acc = 0.0f64;
                for (k, &wk) in w.iter().enumerate() {
                    if wk != 0.0 {
                        acc += wk * planes[k][i] as f64;
                    }
                }
                (acc as f32).to_bits()
            })
            .collect();
        assert_eq!(got, want);
    }

    #[test]
    fn linear_model_and_band_cube_integrate_alike() {
        let s = Spectrum::sampled(vec![400.0, 700.0], vec![1.0, 2.0]).unwrap();
        let img = SpectralImage::from_single_spectrum(
            2,
            3,
            s.clone(),
            vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
        );
        let g = WavelengthGrid::regular(400.0, 700.0, 10.0).unwrap();
        let bands = img.to_bands(&g);
        let qe = Spectrum::sampled(vec![450.0, 550.0, 650.0], vec![0.0, 1.0, 0.0]).unwrap();
        let a = img.integrate_against(&qe);
        let b = bands.integrate_against(&qe);
        for (x, y) in a.iter().zip(&b) {
            assert_relative_eq!(*x, *y, max_relative = 1e-5);
        }
        // exact: ∫ (1 + (λ-400)/300) · tri(450,550,650) = 100 · (1 + 150/300) = 150
        assert_relative_eq!(a[0], 150.0, max_relative = 1e-6);
    }

    #[test]
    fn swap_illuminant_keeps_reflectance() {
        let d = Spectrum::constant(2.0);
        let refl = Spectrum::sampled(vec![400.0, 700.0], vec![0.5, 0.5]).unwrap();
        let rad = Spectrum::multiply(&refl, &d);
        let mut scene = SceneRadiance {
            radiance: SpectralImage::from_single_spectrum(1, 1, rad, vec![1.0]),
            sample_pitch_m: 1e-6,
            object_distance_m: None,
            illuminant: Some(Spectrum::sampled(vec![400.0, 700.0], vec![2.0, 2.0]).unwrap()),
            depth_m: None,
            sample_aperture: Default::default(),
        };
        let new = Spectrum::sampled(vec![400.0, 700.0], vec![4.0, 8.0]).unwrap();
        scene.swap_illuminant(new).unwrap();
        let v = scene.radiance.basis_spectrum(0).eval(550.0) * scene.radiance.planes[0][0] as f64;
        assert_relative_eq!(v, 0.5 * 6.0, max_relative = 1e-9);
    }
}
