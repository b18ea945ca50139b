//! Demosaicking for any colour-filter-array tile: linear minimum-mean-square-error
//! interpolation by ordinary co-kriging, and the quad-Bayer binning and remosaic paths.
//!
//! # The estimator
//! Each missing value `x_k(p)` (channel `k` at pixel `p`) is estimated as a weighted sum of the
//! mosaic samples `y_i = x_{c_i}(q_i)` in an `n × n` window centred on `p`. The weights are the
//! best linear unbiased estimator (ordinary co-kriging: Cressie, *Statistics for Spatial Data*,
//! 1993, §3.2.3; Journel & Huijbregts, *Mining Geostatistics*, 1978, §V.C) under a separable
//! spectral–spatial covariance model
//!
//! ```text
//! Cov(x_j(q), x_k(p)) = C[j][k] · exp(−|q − p| / L)
//! ```
//!
//! (the LMMSE demosaicking model of Trussell & Hartwig, "Mathematics for demosaicking",
//! IEEE Trans. Image Processing 11(4), 2002, with an exponential spatial correlation). `C` is
//! the channel covariance, `L` the correlation length in pixels. The channel means are unknown:
//! the weights minimise the estimation variance subject to `Σ_{i: c_i = j} w_i = δ_{jk}` for every
//! channel `j`, i.e. they solve the Lagrange (KKT) system
//!
//! ```text
//! [ K   A ] [w]   [k ]        K_{ii'} = C[c_i][c_i'] e^{−|q_i−q_i'|/L} + ν δ_{ii'} C[c_i][c_i]
//! [ Aᵀ  0 ] [λ] = [e_k]       k_i = C[c_i][k] e^{−|q_i−p|/L},  A_{ij} = [c_i = j]
//! ```
//!
//! (`ν` is a small relative nugget, the white-noise share of the variance). Because of the
//! constraints a field of constant colour (every channel constant) is reproduced exactly,
//! whatever `C` and `L`, and the other channels enter only through zero-sum (high-pass)
//! weights — the principled form of Malvar's gradient correction. One set of weights is
//! solved per tile phase and channel, so the cost is that of a fixed linear filter.
//!
//! `C` is estimated from the image itself: the covariance across tiles of the per-tile channel
//! means (plus 10⁻³ of the mean variance on the diagonal). At a pixel's own channel the
//! measured value is kept.
//!
//! # Borders
//! Window samples outside the image are replaced by the nearest sample of the *same tile
//! phase* inside it (a shift by whole tile periods), so every sample keeps its channel and
//! constant colour stays exact up to the border.
use crate::demosaic::{demosaic_channels, DemosaicMethod};
use crate::mosaic::{rgb_index_of_name, Mosaic, RgbImage};
use crate::IspError;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// Full-resolution planes, one per mosaic channel (channel order of the mosaic).
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelPlanes {
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// `planes[k]` is channel `k`, `rows × cols` values row-major.
    pub planes: Vec<Vec<f32>>,
    /// Channel names (as in the mosaic).
    pub names: Vec<String>,
}

impl ChannelPlanes {
    /// Number of channels.
    pub fn channels(&self) -> usize {
        self.planes.len()
    }

    /// The three planes named r, g, b as an RGB image, or None when a colour is missing.
    pub fn rgb(&self) -> Option<RgbImage> {
        let mut idx = [usize::MAX; 3];
        for (k, n) in self.names.iter().enumerate() {
            if let Some(c) = rgb_index_of_name(n) {
                idx[c] = k;
            }
        }
        if idx.contains(&usize::MAX) {
            return None;
        }
        Some(RgbImage {
            rows: self.rows,
            cols: self.cols,
            data: (0..self.rows * self.cols)
                .map(|i| idx.map(|k| self.planes[k][i]))
                .collect(),
        })
    }

    /// Mean of each channel over a rectangle `[row0, row1) × [col0, col1)`.
    pub fn mean_in(&self, row0: usize, row1: usize, col0: usize, col1: usize) -> Vec<f64> {
        let n = ((row1 - row0) * (col1 - col0)).max(1) as f64;
        self.planes
            .iter()
            .map(|p| {
                let mut s = 0.0f64;
                for r in row0..row1 {
                    for c in col0..col1 {
                        s += p[r * self.cols + c] as f64;
                    }
                }
                s / n
            })
            .collect()
    }
}

/// The covariance model of the co-kriging estimator (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct CoKrigingModel {
    /// Channel covariance `C[j][k]` (symmetric positive definite, channel order of the mosaic).
    pub channel_covariance: Vec<Vec<f64>>,
    /// Spatial correlation length `L` (pixels) of `exp(−d / L)`.
    pub correlation_length_px: f64,
    /// Nugget `ν`: white-noise share of each channel's variance (regularises the solve).
    pub nugget: f64,
}

/// Default correlation length (pixels). Chosen on the dead-leaves test image of
/// docs/isp.md, where PSNR is flat within 0.3 dB between L = 2 and L = 8.
pub const DEFAULT_CORRELATION_LENGTH_PX: f64 = 4.0;
/// Default nugget.
pub const DEFAULT_NUGGET: f64 = 1e-3;

impl CoKrigingModel {
    /// The model with the channel covariance estimated from the mosaic: covariance across
    /// complete tiles of the per-tile channel means, plus 10⁻³ of the mean variance on the
    /// diagonal (the identity when the image has no variance at all).
    pub fn from_mosaic(m: &Mosaic) -> Self {
        let k = m.channel_names.len();
        let (tr, tc) = (m.tile_rows(), m.tile_cols());
        let mut count = vec![0usize; k];
        for row in &m.tile {
            for &c in row {
                count[c] += 1;
            }
        }
        let mut sum = vec![0.0f64; k];
        let mut sum2 = vec![vec![0.0f64; k]; k];
        let mut n = 0.0f64;
        let present: Vec<usize> = (0..k).filter(|&c| count[c] > 0).collect();
        for tr0 in (0..m.rows.saturating_sub(tr - 1)).step_by(tr) {
            for tc0 in (0..m.cols.saturating_sub(tc - 1)).step_by(tc) {
                let mut mean = vec![0.0f64; k];
                for r in 0..tr {
                    for c in 0..tc {
                        mean[m.tile[r][c]] += m.at(tr0 + r, tc0 + c) as f64;
                    }
                }
                for &c in &present {
                    mean[c] /= count[c] as f64;
                }
                for &a in &present {
                    sum[a] += mean[a];
                    for &b in &present {
                        sum2[a][b] += mean[a] * mean[b];
                    }
                }
                n += 1.0;
            }
        }
        let mut cov = vec![vec![0.0f64; k]; k];
        if n >= 2.0 {
            for a in 0..k {
                for b in 0..k {
                    cov[a][b] = (sum2[a][b] - sum[a] * sum[b] / n) / (n - 1.0);
                }
            }
        }
        let mean_var = (0..k).map(|a| cov[a][a]).sum::<f64>() / k as f64;
        if !(mean_var > 0.0 && mean_var.is_finite()) {
            for (a, row) in cov.iter_mut().enumerate() {
                for (b, x) in row.iter_mut().enumerate() {
                    *x = if a == b { 1.0 } else { 0.0 };
                }
            }
        } else {
            for (a, row) in cov.iter_mut().enumerate() {
                row[a] += 1e-3 * mean_var;
            }
        }
        CoKrigingModel {
            channel_covariance: cov,
            correlation_length_px: DEFAULT_CORRELATION_LENGTH_PX,
            nugget: DEFAULT_NUGGET,
        }
    }
}

/// Window side (odd) for a tile: at least 5 and at least `2·max(tile side) − 1`, so the
/// window holds every channel of the tile.
fn window_side(m: &Mosaic) -> usize {
    let t = m.tile_rows().max(m.tile_cols());
    (2 * t - 1).max(5) | 1
}

/// An index moved into `0..n` by whole periods `t` (keeps the tile phase). Needs `n ≥ t`.
#[inline]
fn fold(i: isize, n: usize, t: usize) -> usize {
    let (n, t) = (n as isize, t as isize);
    if i < 0 {
        i.rem_euclid(t) as usize
    } else if i >= n {
        let k = (i - (n - 1) + t - 1) / t;
        (i - k * t) as usize
    } else {
        i as usize
    }
}

/// Co-kriging weights for every tile phase and channel: `w[phase][k]` over the window offsets.
fn weights(
    m: &Mosaic,
    model: &CoKrigingModel,
    offsets: &[(isize, isize)],
) -> Result<Vec<Vec<Vec<f64>>>, IspError> {
    let kch = m.channel_names.len();
    let (tr, tc) = (m.tile_rows(), m.tile_cols());
    let l = model.correlation_length_px;
    let cov = &model.channel_covariance;
    let s = |dr: f64, dc: f64| (-(dr * dr + dc * dc).sqrt() / l).exp();
    let mut out = Vec::with_capacity(tr * tc);
    for pr in 0..tr {
        for pc in 0..tc {
            let ch: Vec<usize> = offsets
                .iter()
                .map(|&(dr, dc)| {
                    m.tile[(pr as isize + dr).rem_euclid(tr as isize) as usize]
                        [(pc as isize + dc).rem_euclid(tc as isize) as usize]
                })
                .collect();
            let present: Vec<usize> = (0..kch).filter(|c| ch.contains(c)).collect();
            let n = offsets.len();
            let q = present.len();
            let mut a = DMatrix::<f64>::zeros(n + q, n + q);
            for i in 0..n {
                for j in 0..n {
                    let (di, dj) = (offsets[i], offsets[j]);
                    a[(i, j)] = cov[ch[i]][ch[j]] * s((di.0 - dj.0) as f64, (di.1 - dj.1) as f64)
                        + if i == j {
                            model.nugget * cov[ch[i]][ch[i]]
                        } else {
                            0.0
                        };
                }
                for (jj, &c) in present.iter().enumerate() {
                    if ch[i] == c {
                        a[(i, n + jj)] = 1.0;
                        a[(n + jj, i)] = 1.0;
                    }
                }
            }
            let lu = a.lu();
            let mut per_k = Vec::with_capacity(kch);
            for k in 0..kch {
                if !present.contains(&k) {
                    per_k.push(vec![]);
                    continue;
                }
                let mut b = DVector::<f64>::zeros(n + q);
                for i in 0..n {
                    b[i] = cov[ch[i]][k] * s(offsets[i].0 as f64, offsets[i].1 as f64);
                }
                let kk = present.iter().position(|&c| c == k).expect("present");
                b[n + kk] = 1.0;
                let x = lu.solve(&b).ok_or_else(|| IspError::InvalidParameter {
                    name: "co-kriging system".into(),
                    value: format!("tile phase ({pr}, {pc}), channel {k}"),
                    reason: "singular (is the channel covariance positive definite?)".into(),
                })?;
                per_k.push((0..n).map(|i| x[i]).collect());
            }
            out.push(per_k);
        }
    }
    Ok(out)
}

fn check_model(m: &Mosaic, model: &CoKrigingModel) -> Result<(), IspError> {
    let k = m.channel_names.len();
    if model.channel_covariance.len() != k || model.channel_covariance.iter().any(|r| r.len() != k)
    {
        return Err(IspError::InvalidParameter {
            name: "channel_covariance".into(),
            value: format!("{} rows", model.channel_covariance.len()),
            reason: format!("must be {k} × {k} (one per mosaic channel)"),
        });
    }
    if !(model.correlation_length_px > 0.0 && model.correlation_length_px.is_finite()) {
        return Err(IspError::InvalidParameter {
            name: "correlation_length_px".into(),
            value: format!("{}", model.correlation_length_px),
            reason: "must be a positive finite number".into(),
        });
    }
    if !(model.nugget >= 0.0 && model.nugget.is_finite()) {
        return Err(IspError::InvalidParameter {
            name: "nugget".into(),
            value: format!("{}", model.nugget),
            reason: "must be a finite number ≥ 0".into(),
        });
    }
    if m.rows < m.tile_rows() || m.cols < m.tile_cols() {
        return Err(IspError::InvalidMosaic(format!(
            "image {}×{} is smaller than its CFA tile {}×{}",
            m.rows,
            m.cols,
            m.tile_rows(),
            m.tile_cols()
        )));
    }
    Ok(())
}

/// Demosaic any CFA tile by co-kriging (module documentation) with a given model.
pub fn demosaic_cokriging(m: &Mosaic, model: &CoKrigingModel) -> Result<ChannelPlanes, IspError> {
    check_model(m, model)?;
    let kch = m.channel_names.len();
    let (tr, tc) = (m.tile_rows(), m.tile_cols());
    let side = window_side(m) as isize;
    let h = side / 2;
    let offsets: Vec<(isize, isize)> = (-h..=h)
        .flat_map(|dr| (-h..=h).map(move |dc| (dr, dc)))
        .collect();
    let w = weights(m, model, &offsets)?;
    let mut planes = vec![vec![0f32; m.rows * m.cols]; kch];
    // row-parallel: each worker fills one row of every plane
    let rows: Vec<Vec<Vec<f32>>> = (0..m.rows)
        .into_par_iter()
        .map(|r| {
            let mut out = vec![vec![0f32; m.cols]; kch];
            let mut win = vec![0f64; offsets.len()];
            for c in 0..m.cols {
                for (i, &(dr, dc)) in offsets.iter().enumerate() {
                    let rr = fold(r as isize + dr, m.rows, tr);
                    let cc = fold(c as isize + dc, m.cols, tc);
                    win[i] = m.at(rr, cc) as f64;
                }
                let phase = (r % tr) * tc + c % tc;
                let own = m.channel_at(r, c);
                for k in 0..kch {
                    out[k][c] = if k == own {
                        m.at(r, c)
                    } else {
                        let wk = &w[phase][k];
                        wk.iter().zip(&win).map(|(a, b)| a * b).sum::<f64>() as f32
                    };
                }
            }
            out
        })
        .collect();
    for (r, row) in rows.into_iter().enumerate() {
        for (k, v) in row.into_iter().enumerate() {
            planes[k][r * m.cols..(r + 1) * m.cols].copy_from_slice(&v);
        }
    }
    Ok(ChannelPlanes {
        rows: m.rows,
        cols: m.cols,
        planes,
        names: m.channel_names.clone(),
    })
}

/// The 2×2 Bayer tile of a quad-Bayer mosaic: a 4×4 tile made of 2×2 blocks of one channel
/// whose block pattern is an RGB Bayer tile. Errors say what is wrong.
pub fn quad_bayer_blocks(m: &Mosaic) -> Result<Vec<Vec<usize>>, String> {
    if m.tile_rows() != 4 || m.tile_cols() != 4 {
        return Err(format!(
            "quad Bayer needs a 4×4 tile, this one is {}×{}",
            m.tile_rows(),
            m.tile_cols()
        ));
    }
    let blocks: Vec<Vec<usize>> = (0..2)
        .map(|a| (0..2).map(|b| m.tile[2 * a][2 * b]).collect())
        .collect();
    for r in 0..4 {
        for c in 0..4 {
            if m.tile[r][c] != blocks[r / 2][c / 2] {
                return Err(format!(
                    "tile[{r}][{c}] is '{}' but its 2×2 block is '{}'",
                    m.channel_names[m.tile[r][c]],
                    m.channel_names[blocks[r / 2][c / 2]]
                ));
            }
        }
    }
    let probe = Mosaic::new(2, 2, vec![0.0; 4], blocks.clone(), m.channel_names.clone())
        .map_err(|e| e.to_string())?;
    probe.bayer_layout()?;
    Ok(blocks)
}

/// Quad-Bayer 2×2 binning: each 2×2 block of one colour becomes one pixel (the mean of its
/// four samples), giving a half-resolution RGB Bayer mosaic (odd last row/column dropped).
pub fn bin_quad_bayer(m: &Mosaic) -> Result<Mosaic, IspError> {
    let blocks = quad_bayer_blocks(m).map_err(|reason| IspError::NotBayer {
        method: "quad_binning".into(),
        reason,
    })?;
    let (rows, cols) = (m.rows / 2, m.cols / 2);
    let data = (0..rows * cols)
        .map(|i| {
            let (r, c) = (2 * (i / cols), 2 * (i % cols));
            0.25 * (m.at(r, c) + m.at(r, c + 1) + m.at(r + 1, c) + m.at(r + 1, c + 1))
        })
        .collect();
    Mosaic::new(rows, cols, data, blocks, m.channel_names.clone())
}

/// Quad-Bayer remosaic: co-kriging estimates, at every pixel, the channel a standard Bayer
/// tile (the quad tile's block pattern) would have there; the result is a full-resolution
/// RGB Bayer mosaic for the Bayer-specific methods.
pub fn remosaic_quad_bayer(m: &Mosaic) -> Result<Mosaic, IspError> {
    let blocks = quad_bayer_blocks(m).map_err(|reason| IspError::NotBayer {
        method: "quad_remosaic".into(),
        reason,
    })?;
    let planes = demosaic_cokriging(m, &CoKrigingModel::from_mosaic(m))?;
    let data = (0..m.rows * m.cols)
        .map(|i| {
            let (r, c) = (i / m.cols, i % m.cols);
            planes.planes[blocks[r % 2][c % 2]][i]
        })
        .collect();
    Mosaic::new(m.rows, m.cols, data, blocks, m.channel_names.clone())
}

/// Demosaic to one full plane per mosaic channel with any method: the Bayer methods need an
/// RGB Bayer tile; `lmmse` takes any tile; the quad methods need a quad-Bayer tile and run
/// Malvar–He–Cutler on the binned (half-resolution) or remosaicked mosaic.
pub fn demosaic_planes(m: &Mosaic, method: DemosaicMethod) -> Result<ChannelPlanes, IspError> {
    let (mm, bayer_method) = match method {
        DemosaicMethod::Lmmse => {
            return demosaic_cokriging(m, &CoKrigingModel::from_mosaic(m));
        }
        DemosaicMethod::QuadBinning => (bin_quad_bayer(m)?, DemosaicMethod::Malvar),
        DemosaicMethod::QuadRemosaic => (remosaic_quad_bayer(m)?, DemosaicMethod::Malvar),
        other => (m.clone(), other),
    };
    let planes = demosaic_channels(&mm, bayer_method)?;
    Ok(ChannelPlanes {
        rows: mm.rows,
        cols: mm.cols,
        planes,
        names: mm.channel_names.clone(),
    })
}
