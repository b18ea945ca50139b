//! The dixel: the repeating subpixel unit of a display and its per-primary intensity maps.
//!
//! A dixel tile spans `pixels_per_dixel = [rows, cols]` display pixels (`[1, 1]` for every
//! embedded display except OLED-Samsung, whose tile holds 2 × 2 pixels) and is sampled on a
//! `rows × cols` grid. The intensity map `s_p(x)` of primary `p` tells how the primary's light
//! is distributed over the tile. The primary SPDs are the spatial average over the screen (what
//! a spectroradiometer reads), so each map is normalised to **mean 1** at load time; ISETCam
//! does the same whenever it resizes a map (`displayGet(d, 'dixel image', sz)`). Every embedded
//! map already has mean 1 except LCD-Samsung-RGBW (mean 0.2 per primary in the file); the
//! file's mean is kept in [`Dixel::file_mean`].
use crate::error::DisplayError;

/// A per-primary map sampled on a regular grid over one dixel tile, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct SubpixelMap {
    /// Rows of samples over the tile.
    pub rows: usize,
    /// Columns of samples over the tile.
    pub cols: usize,
    /// `planes[primary][row * cols + col]`: relative intensity (mean 1 per primary).
    pub planes: Vec<Vec<f64>>,
}

impl SubpixelMap {
    /// The spatial mean of each primary's map.
    pub fn means(&self) -> Vec<f64> {
        self.planes
            .iter()
            .map(|p| p.iter().sum::<f64>() / p.len() as f64)
            .collect()
    }
}

/// The subpixel structure of a display.
#[derive(Debug, Clone, PartialEq)]
pub struct Dixel {
    /// Display pixels covered by one tile, `[rows, cols]`.
    pub pixels_per_dixel: [usize; 2],
    /// The intensity maps at the file's resolution, normalised to mean 1 per primary.
    pub map: SubpixelMap,
    /// Mean of each primary's map as stored in the file (before normalisation).
    pub file_mean: Vec<f64>,
}

/// Overlap weights of a box resampling from `n_old` to `n_new` cells over the same length:
/// `w[new]` lists `(old, weight)` with weights summing to 1 (the average over the new cell).
fn box_weights(n_old: usize, n_new: usize) -> Vec<Vec<(usize, f64)>> {
    let scale = n_old as f64 / n_new as f64; // old cells per new cell
    (0..n_new)
        .map(|i| {
            // new cell i covers [i·n_old/n_new, (i+1)·n_old/n_new] in old-cell units; integer
            // arithmetic for the ends keeps exact boundaries exact
            let a = (i * n_old) as f64 / n_new as f64;
            let b = ((i + 1) * n_old) as f64 / n_new as f64;
            let j0 = a.floor() as usize;
            let j1 = (b.ceil() as usize).min(n_old);
            (j0..j1)
                .filter_map(|j| {
                    let ov = (b.min((j + 1) as f64) - a.max(j as f64)).max(0.0);
                    (ov > 0.0).then_some((j, ov / scale))
                })
                .collect()
        })
        .collect()
}

impl Dixel {
    /// A validated dixel from `intensitymap[primary][row][col]` (finite, non-negative, not all
    /// zero) and the pixels it spans.
    pub fn new(
        intensitymap: Vec<Vec<Vec<f64>>>,
        pixels_per_dixel: [usize; 2],
    ) -> Result<Self, DisplayError> {
        let bad = |field: String, message: String| DisplayError::InvalidData { field, message };
        if pixels_per_dixel.contains(&0) {
            return Err(bad(
                "dixel.n_pixels".into(),
                format!("{pixels_per_dixel:?} must be positive"),
            ));
        }
        if intensitymap.is_empty() {
            return Err(bad("dixel.intensitymap".into(), "no primaries".into()));
        }
        let rows = intensitymap[0].len();
        let cols = intensitymap[0].first().map_or(0, |r| r.len());
        if rows == 0 || cols == 0 {
            return Err(bad(
                "dixel.intensitymap".into(),
                format!("empty map {rows}×{cols}"),
            ));
        }
        let mut planes = Vec::with_capacity(intensitymap.len());
        let mut file_mean = Vec::with_capacity(intensitymap.len());
        for (p, m) in intensitymap.into_iter().enumerate() {
            if m.len() != rows || m.iter().any(|r| r.len() != cols) {
                return Err(bad(
                    format!("dixel.intensitymap[{p}]"),
                    format!("is not {rows}×{cols} like primary 0"),
                ));
            }
            let flat: Vec<f64> = m.into_iter().flatten().collect();
            if let Some(i) = flat.iter().position(|v| !v.is_finite() || *v < 0.0) {
                return Err(bad(
                    format!("dixel.intensitymap[{p}][{}][{}]", i / cols, i % cols),
                    format!("{} is not a finite non-negative number", flat[i]),
                ));
            }
            let mean = flat.iter().sum::<f64>() / flat.len() as f64;
            if mean <= 0.0 {
                return Err(bad(
                    format!("dixel.intensitymap[{p}]"),
                    "is all zero".into(),
                ));
            }
            planes.push(flat.iter().map(|v| v / mean).collect());
            file_mean.push(mean);
        }
        Ok(Dixel {
            pixels_per_dixel,
            map: SubpixelMap { rows, cols, planes },
            file_mean,
        })
    }

    /// Number of primaries.
    pub fn n_primaries(&self) -> usize {
        self.map.planes.len()
    }

    /// Samples per display pixel at the file's resolution, `[rows, cols]` (ISETCam
    /// `displayGet(d, 'over sample')`; may be fractional only if the file's tile is not a
    /// multiple of the pixels it spans).
    pub fn native_samples_per_pixel(&self) -> [f64; 2] {
        [
            self.map.rows as f64 / self.pixels_per_dixel[0] as f64,
            self.map.cols as f64 / self.pixels_per_dixel[1] as f64,
        ]
    }

    /// The maps resampled so that each display pixel holds `n × n` samples (the tile becomes
    /// `n·ppd_rows × n·ppd_cols`). Every new sample is the area-weighted average of the original
    /// samples it overlaps (a box filter; upsampling replicates), so each primary's mean is
    /// preserved exactly up to rounding. `n` equal to the native resolution returns the map
    /// unchanged.
    pub fn resampled(&self, samples_per_pixel: usize) -> Result<SubpixelMap, DisplayError> {
        if samples_per_pixel == 0 {
            return Err(DisplayError::BadSampling(0, "must be at least 1".into()));
        }
        let (r0, c0) = (self.map.rows, self.map.cols);
        let r1 = samples_per_pixel * self.pixels_per_dixel[0];
        let c1 = samples_per_pixel * self.pixels_per_dixel[1];
        if (r1, c1) == (r0, c0) {
            return Ok(self.map.clone());
        }
        let wr = box_weights(r0, r1);
        let wc = box_weights(c0, c1);
        let planes = self
            .map
            .planes
            .iter()
            .map(|src| {
                // columns first: r0 × c1
                let mut tmp = vec![0.0; r0 * c1];
                for r in 0..r0 {
                    for (c, w) in wc.iter().enumerate() {
                        tmp[r * c1 + c] = w.iter().map(|&(j, k)| k * src[r * c0 + j]).sum();
                    }
                }
                let mut out = vec![0.0; r1 * c1];
                for (r, w) in wr.iter().enumerate() {
                    for c in 0..c1 {
                        out[r * c1 + c] = w.iter().map(|&(i, k)| k * tmp[i * c1 + c]).sum();
                    }
                }
                out
            })
            .collect();
        Ok(SubpixelMap {
            rows: r1,
            cols: c1,
            planes,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_weights_sum_to_one_and_cover_each_old_cell_once() {
        for (o, n) in [(20, 3), (20, 20), (3, 7), (160, 5), (80, 40), (1, 4)] {
            let w = box_weights(o, n);
            let mut mass = vec![0.0; o];
            for row in &w {
                let s: f64 = row.iter().map(|x| x.1).sum();
                assert!((s - 1.0).abs() < 1e-12, "{o}->{n}: {s}");
                for &(j, k) in row {
                    mass[j] += k * o as f64 / n as f64;
                }
            }
            for m in mass {
                assert!((m - 1.0).abs() < 1e-12, "{o}->{n}: {m}");
            }
        }
    }

    #[test]
    fn normalises_to_mean_one_and_keeps_the_file_mean() {
        let d = Dixel::new(vec![vec![vec![0.0, 0.4], vec![0.0, 0.4]]], [1, 1]).unwrap();
        assert_eq!(d.file_mean, vec![0.2]);
        assert_eq!(d.map.planes[0], vec![0.0, 2.0, 0.0, 2.0]);
        let m = d.resampled(1).unwrap();
        assert_eq!(m.planes[0], vec![1.0]);
        let m = d.resampled(4).unwrap();
        assert_eq!(
            m.planes[0],
            vec![0., 0., 2., 2., 0., 0., 2., 2., 0., 0., 2., 2., 0., 0., 2., 2.]
        );
        assert!(Dixel::new(vec![vec![vec![0.0, -1.0]]], [1, 1]).is_err());
        assert!(Dixel::new(vec![vec![vec![0.0, 0.0]]], [1, 1]).is_err());
    }
}
