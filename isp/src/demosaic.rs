//! Demosaicking: bilinear (ISETCam kernels), Malvar–He–Cutler (ICASSP 2004) and a
//! Hamilton–Adams style edge-adaptive method (US patent 5,629,734; Adams & Hamilton 1997).
//!
//! Every method mirrors the image at its borders *excluding* the edge sample
//! (`… c b | a b c … | … b a`, numpy `'reflect'`), which keeps the Bayer phase at the border,
//! so a constant scene is reproduced exactly everywhere.
use crate::mosaic::{BayerLayout, Mosaic, RgbImage};
use crate::IspError;
use rayon::prelude::*;
use std::str::FromStr;

/// A demosaicking algorithm.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DemosaicMethod {
    /// Normalised convolution with ISETCam's kernels: `kG = [[0,1,0],[1,4,1],[0,1,0]]/4` for a
    /// checkerboard channel (Bayer green), `kRB = [[1,2,1],[2,4,2],[1,2,1]]/4` otherwise. Works on
    /// any tile (sparser channels fall back to wider tent kernels where kRB finds no sample).
    Bilinear,
    /// Malvar, He & Cutler, "High-quality linear interpolation for demosaicing of
    /// Bayer-patterned color images", ICASSP 2004: bilinear plus a Laplacian correction from
    /// the centre channel (5×5 kernels with α = 1/2, β = 5/8, γ = 3/4). Bayer only.
    Malvar,
    /// Hamilton–Adams: green by the direction of the smaller gradient (first difference of
    /// green plus second difference of the centre colour) with Laplacian correction, then
    /// red/blue by interpolating colour differences (R − G, B − G). Bayer only.
    EdgeAdaptive,
    /// Linear minimum-mean-square-error demosaicking for any tile by ordinary co-kriging
    /// (see [`crate::cfa_generic`]); the channel covariance is estimated from the image.
    Lmmse,
    /// Quad Bayer: 2×2 same-colour binning to a half-resolution Bayer mosaic, then Malvar.
    QuadBinning,
    /// Quad Bayer: remosaic to a full-resolution Bayer mosaic by co-kriging, then Malvar.
    QuadRemosaic,
}

impl DemosaicMethod {
    /// The configuration name ("bilinear", "malvar", "edge_adaptive").
    pub fn name(&self) -> &'static str {
        match self {
            DemosaicMethod::Bilinear => "bilinear",
            DemosaicMethod::Malvar => "malvar",
            DemosaicMethod::EdgeAdaptive => "edge_adaptive",
            DemosaicMethod::Lmmse => "lmmse",
            DemosaicMethod::QuadBinning => "quad_binning",
            DemosaicMethod::QuadRemosaic => "quad_remosaic",
        }
    }
}

impl FromStr for DemosaicMethod {
    type Err = IspError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "bilinear" => Ok(DemosaicMethod::Bilinear),
            "malvar" => Ok(DemosaicMethod::Malvar),
            "edge_adaptive" => Ok(DemosaicMethod::EdgeAdaptive),
            "lmmse" => Ok(DemosaicMethod::Lmmse),
            "quad_binning" => Ok(DemosaicMethod::QuadBinning),
            "quad_remosaic" => Ok(DemosaicMethod::QuadRemosaic),
            _ => Err(IspError::UnknownDemosaic {
                name: s.to_string(),
            }),
        }
    }
}

/// Mirror index `i` into `0..n` excluding the edge sample (numpy 'reflect'); the period
/// 2(n − 1) is even, so the CFA phase is preserved.
#[inline]
fn reflect(i: isize, n: usize) -> usize {
    if n == 1 {
        return 0;
    }
    let p = 2 * (n as isize - 1);
    let m = i.rem_euclid(p);
    if m < n as isize {
        m as usize
    } else {
        (p - m) as usize
    }
}

/// A read-only f64 plane with mirrored access.
struct Mirror<'a> {
    rows: usize,
    cols: usize,
    v: &'a [f64],
}

impl Mirror<'_> {
    #[inline]
    fn get(&self, r: usize, c: usize, dr: isize, dc: isize) -> f64 {
        let rr = reflect(r as isize + dr, self.rows);
        let cc = reflect(c as isize + dc, self.cols);
        self.v[rr * self.cols + cc]
    }
}

/// Demosaic to full planes, one per mosaic channel (in channel order). Bilinear accepts any
/// tile; Malvar and edge-adaptive need a 2×2 RGB Bayer tile; lmmse accepts any tile; the quad
/// methods need a quad-Bayer tile and `quad_binning` returns half-resolution planes.
pub fn demosaic_channels(m: &Mosaic, method: DemosaicMethod) -> Result<Vec<Vec<f32>>, IspError> {
    match method {
        DemosaicMethod::Bilinear => Ok(bilinear_channels(m)),
        DemosaicMethod::Lmmse | DemosaicMethod::QuadBinning | DemosaicMethod::QuadRemosaic => {
            Ok(crate::cfa_generic::demosaic_planes(m, method)?.planes)
        }
        _ => {
            let layout = m.bayer_layout().map_err(|reason| IspError::NotBayer {
                method: method.name().into(),
                reason,
            })?;
            let rgb = bayer_rgb(m, &layout, method);
            let mut out = vec![vec![0f32; m.rows * m.cols]; m.channel_names.len()];
            for k in 0..3 {
                out[layout.channel_of[k]] = rgb.data.iter().map(|p| p[k]).collect();
            }
            Ok(out)
        }
    }
}

/// Demosaic an RGB mosaic (channels named r/g/b) to a linear RGB image.
pub fn demosaic(m: &Mosaic, method: DemosaicMethod) -> Result<RgbImage, IspError> {
    match method {
        DemosaicMethod::Lmmse | DemosaicMethod::QuadBinning | DemosaicMethod::QuadRemosaic => {
            m.rgb_channels().map_err(IspError::InvalidMosaic)?;
            let p = crate::cfa_generic::demosaic_planes(m, method)?;
            Ok(p.rgb().expect("r, g, b checked"))
        }
        DemosaicMethod::Bilinear => {
            let ch = m.rgb_channels().map_err(IspError::InvalidMosaic)?;
            let planes = bilinear_channels(m);
            let data = (0..m.rows * m.cols)
                .map(|i| [planes[ch[0]][i], planes[ch[1]][i], planes[ch[2]][i]])
                .collect();
            Ok(RgbImage {
                rows: m.rows,
                cols: m.cols,
                data,
            })
        }
        _ => {
            let layout = m.bayer_layout().map_err(|reason| IspError::NotBayer {
                method: method.name().into(),
                reason,
            })?;
            Ok(bayer_rgb(m, &layout, method))
        }
    }
}

/// True when channel `ch` occupies exactly one parity class of a tile with even sides (the
/// Bayer green checkerboard), which ISETCam interpolates with kG.
fn is_checkerboard(m: &Mosaic, ch: usize) -> bool {
    let (tr, tc) = (m.tile_rows(), m.tile_cols());
    if tr % 2 != 0 || tc % 2 != 0 {
        return false;
    }
    let first = (0..tr)
        .flat_map(|r| (0..tc).map(move |c| (r, c)))
        .find(|&(r, c)| m.tile[r][c] == ch);
    match first {
        Some((r0, c0)) => {
            let q = (r0 + c0) % 2;
            (0..tr).all(|r| (0..tc).all(|c| (m.tile[r][c] == ch) == ((r + c) % 2 == q)))
        }
        None => false,
    }
}

const K_G: [[f64; 3]; 3] = [[0.0, 1.0, 0.0], [1.0, 4.0, 1.0], [0.0, 1.0, 0.0]];
const K_RB: [[f64; 3]; 3] = [[1.0, 2.0, 1.0], [2.0, 4.0, 2.0], [1.0, 2.0, 1.0]];

/// Normalised convolution per channel (ISETCam's bilinear for Bayer tiles, where the kernel
/// weights of the present samples always sum to 4, so the normalisation is the /4 of the
/// kernels). The measured value is kept at a channel's own sites.
fn bilinear_channels(m: &Mosaic) -> Vec<Vec<f32>> {
    let v: Vec<f64> = m.data.iter().map(|&x| x as f64).collect();
    let img = Mirror {
        rows: m.rows,
        cols: m.cols,
        v: &v,
    };
    let max_radius = m.tile_rows().max(m.tile_cols()).max(2) as isize;
    (0..m.channel_names.len())
        .map(|ch| {
            let k = if is_checkerboard(m, ch) { &K_G } else { &K_RB };
            let mut out = vec![0f32; m.rows * m.cols];
            out.par_chunks_mut(m.cols).enumerate().for_each(|(r, row)| {
                for (c, o) in row.iter_mut().enumerate() {
                    if m.channel_at(r, c) == ch {
                        *o = m.at(r, c);
                        continue;
                    }
                    let (mut num, mut den) = (0.0, 0.0);
                    for dr in -1..=1isize {
                        for dc in -1..=1isize {
                            let w = k[(dr + 1) as usize][(dc + 1) as usize];
                            let (rr, cc) = (
                                reflect(r as isize + dr, m.rows),
                                reflect(c as isize + dc, m.cols),
                            );
                            if w != 0.0 && m.channel_at(rr, cc) == ch {
                                num += w * img.v[rr * m.cols + cc];
                                den += w;
                            }
                        }
                    }
                    // sparse channels: widen to a tent of radius R until a sample is found
                    let mut radius = 2;
                    while den == 0.0 && radius <= max_radius {
                        for dr in -radius..=radius {
                            for dc in -radius..=radius {
                                let w = ((radius + 1 - dr.abs()) * (radius + 1 - dc.abs())) as f64;
                                let (rr, cc) = (
                                    reflect(r as isize + dr, m.rows),
                                    reflect(c as isize + dc, m.cols),
                                );
                                if m.channel_at(rr, cc) == ch {
                                    num += w * img.v[rr * m.cols + cc];
                                    den += w;
                                }
                            }
                        }
                        radius += 1;
                    }
                    *o = if den > 0.0 { (num / den) as f32 } else { 0.0 };
                }
            });
            out
        })
        .collect()
}

/// Site type of a Bayer pixel.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Site {
    Red,
    Blue,
    /// Green on a row that holds red samples.
    GreenRedRow,
    /// Green on a row that holds blue samples.
    GreenBlueRow,
}

fn site(layout: &BayerLayout, r: usize, c: usize) -> Site {
    let p = (r % 2, c % 2);
    if p == layout.red_pos {
        Site::Red
    } else if p == layout.blue_pos {
        Site::Blue
    } else if r % 2 == layout.red_pos.0 {
        Site::GreenRedRow
    } else {
        Site::GreenBlueRow
    }
}

/// Malvar–He–Cutler kernels, in units of 1/8, as (dr, dc, weight) taps.
/// G at R or B sites (α = 1/2).
const MHC_G_AT_RB: &[(isize, isize, f64)] = &[
    (0, 0, 4.0),
    (-1, 0, 2.0),
    (1, 0, 2.0),
    (0, -1, 2.0),
    (0, 1, 2.0),
    (-2, 0, -1.0),
    (2, 0, -1.0),
    (0, -2, -1.0),
    (0, 2, -1.0),
];
/// R (B) at a green site whose row holds R (B) samples (β = 5/8).
const MHC_ROW: &[(isize, isize, f64)] = &[
    (0, 0, 5.0),
    (0, -1, 4.0),
    (0, 1, 4.0),
    (0, -2, -1.0),
    (0, 2, -1.0),
    (-1, -1, -1.0),
    (-1, 1, -1.0),
    (1, -1, -1.0),
    (1, 1, -1.0),
    (-2, 0, 0.5),
    (2, 0, 0.5),
];
/// R (B) at a green site whose column holds R (B) samples (transpose of [`MHC_ROW`]).
const MHC_COL: &[(isize, isize, f64)] = &[
    (0, 0, 5.0),
    (-1, 0, 4.0),
    (1, 0, 4.0),
    (-2, 0, -1.0),
    (2, 0, -1.0),
    (-1, -1, -1.0),
    (-1, 1, -1.0),
    (1, -1, -1.0),
    (1, 1, -1.0),
    (0, -2, 0.5),
    (0, 2, 0.5),
];
/// R at B sites and B at R sites (γ = 3/4).
const MHC_DIAG: &[(isize, isize, f64)] = &[
    (0, 0, 6.0),
    (-1, -1, 2.0),
    (-1, 1, 2.0),
    (1, -1, 2.0),
    (1, 1, 2.0),
    (-2, 0, -1.5),
    (2, 0, -1.5),
    (0, -2, -1.5),
    (0, 2, -1.5),
];

#[inline]
fn apply_taps(img: &Mirror, r: usize, c: usize, taps: &[(isize, isize, f64)]) -> f64 {
    // The taps are small dyadic numbers: the sum is exact for a constant image.
    taps.iter()
        .map(|&(dr, dc, w)| w * img.get(r, c, dr, dc))
        .sum::<f64>()
        / 8.0
}

fn bayer_rgb(m: &Mosaic, layout: &BayerLayout, method: DemosaicMethod) -> RgbImage {
    let v: Vec<f64> = m.data.iter().map(|&x| x as f64).collect();
    let img = Mirror {
        rows: m.rows,
        cols: m.cols,
        v: &v,
    };
    let mut data = vec![[0f32; 3]; m.rows * m.cols];
    match method {
        DemosaicMethod::Malvar => {
            data.par_chunks_mut(m.cols)
                .enumerate()
                .for_each(|(r, row)| {
                    for (c, o) in row.iter_mut().enumerate() {
                        let x = img.get(r, c, 0, 0);
                        let px = match site(layout, r, c) {
                            Site::Red => [
                                x,
                                apply_taps(&img, r, c, MHC_G_AT_RB),
                                apply_taps(&img, r, c, MHC_DIAG),
                            ],
                            Site::Blue => [
                                apply_taps(&img, r, c, MHC_DIAG),
                                apply_taps(&img, r, c, MHC_G_AT_RB),
                                x,
                            ],
                            Site::GreenRedRow => [
                                apply_taps(&img, r, c, MHC_ROW),
                                x,
                                apply_taps(&img, r, c, MHC_COL),
                            ],
                            Site::GreenBlueRow => [
                                apply_taps(&img, r, c, MHC_COL),
                                x,
                                apply_taps(&img, r, c, MHC_ROW),
                            ],
                        };
                        *o = [px[0] as f32, px[1] as f32, px[2] as f32];
                    }
                });
        }
        DemosaicMethod::EdgeAdaptive => {
            let green = hamilton_adams_green(&img, layout);
            let g = Mirror {
                rows: m.rows,
                cols: m.cols,
                v: &green,
            };
            data.par_chunks_mut(m.cols)
                .enumerate()
                .for_each(|(r, row)| {
                    for (c, o) in row.iter_mut().enumerate() {
                        let x = img.get(r, c, 0, 0);
                        let gc = g.get(r, c, 0, 0);
                        // colour difference (mosaic − green) at an offset
                        let d = |dr: isize, dc: isize| img.get(r, c, dr, dc) - g.get(r, c, dr, dc);
                        let horiz = gc + 0.5 * (d(0, -1) + d(0, 1));
                        let vert = gc + 0.5 * (d(-1, 0) + d(1, 0));
                        let px = match site(layout, r, c) {
                            Site::Red => [x, gc, diagonal(&img, &g, r, c)],
                            Site::Blue => [diagonal(&img, &g, r, c), gc, x],
                            Site::GreenRedRow => [horiz, x, vert],
                            Site::GreenBlueRow => [vert, x, horiz],
                        };
                        *o = [px[0] as f32, px[1] as f32, px[2] as f32];
                    }
                });
        }
        _ => unreachable!("only Malvar and edge-adaptive reach bayer_rgb"),
    }
    RgbImage {
        rows: m.rows,
        cols: m.cols,
        data,
    }
}

/// Hamilton–Adams green: at R/B sites choose the direction with the smaller gradient
/// |ΔG| + |Laplacian of the centre colour|, estimate G as the mean of the two greens plus a
/// quarter of that Laplacian, and average both directions on ties.
fn hamilton_adams_green(img: &Mirror, layout: &BayerLayout) -> Vec<f64> {
    let mut out = vec![0f64; img.rows * img.cols];
    out.par_chunks_mut(img.cols)
        .enumerate()
        .for_each(|(r, row)| {
            for (c, o) in row.iter_mut().enumerate() {
                let x = img.get(r, c, 0, 0);
                *o = match site(layout, r, c) {
                    Site::GreenRedRow | Site::GreenBlueRow => x,
                    _ => {
                        let (gl, gr) = (img.get(r, c, 0, -1), img.get(r, c, 0, 1));
                        let (gu, gd) = (img.get(r, c, -1, 0), img.get(r, c, 1, 0));
                        let lap_h = 2.0 * x - img.get(r, c, 0, -2) - img.get(r, c, 0, 2);
                        let lap_v = 2.0 * x - img.get(r, c, -2, 0) - img.get(r, c, 2, 0);
                        let dh = (gl - gr).abs() + lap_h.abs();
                        let dv = (gu - gd).abs() + lap_v.abs();
                        let gh = 0.5 * (gl + gr) + 0.25 * lap_h;
                        let gv = 0.5 * (gu + gd) + 0.25 * lap_v;
                        if dh < dv {
                            gh
                        } else if dv < dh {
                            gv
                        } else {
                            0.5 * (gh + gv)
                        }
                    }
                };
            }
        });
    out
}

/// The opposite colour at an R or B site from the colour differences along the diagonal with
/// the smaller gradient (Hamilton–Adams second stage).
fn diagonal(img: &Mirror, g: &Mirror, r: usize, c: usize) -> f64 {
    let gc = g.get(r, c, 0, 0);
    let d = |dr: isize, dc: isize| img.get(r, c, dr, dc) - g.get(r, c, dr, dc);
    // NW–SE and NE–SW
    let grad1 = (img.get(r, c, -1, -1) - img.get(r, c, 1, 1)).abs()
        + (2.0 * gc - g.get(r, c, -1, -1) - g.get(r, c, 1, 1)).abs();
    let grad2 = (img.get(r, c, -1, 1) - img.get(r, c, 1, -1)).abs()
        + (2.0 * gc - g.get(r, c, -1, 1) - g.get(r, c, 1, -1)).abs();
    let e1 = gc + 0.5 * (d(-1, -1) + d(1, 1));
    let e2 = gc + 0.5 * (d(-1, 1) + d(1, -1));
    if grad1 < grad2 {
        e1
    } else if grad2 < grad1 {
        e2
    } else {
        0.5 * (e1 + e2)
    }
}
