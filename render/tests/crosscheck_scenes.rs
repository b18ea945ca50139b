//! The glTF scenes of the depth-aware optics cross-checks (issue 18, acceptance 1), shared by
//! `depth_crosscheck` (thin lens) and `real_lens_crosscheck` (the double Gauss): fronto-parallel
//! emitter cards at 0.5, 1.5 and 5 m (a depth range of 10×) placed by their pinhole projection,
//! with their straight depth edges, and the edge statistics.
use camsim_render::gltf_load::load_gltf;
use camsim_render::gltf_write::{flat_spectrum, quad, GltfBuilder, MeshData};
use camsim_render::scene::Scene;
use camsim_render::{Bands, RenderSettings};
use serde_json::json;

/// The card depths (m).
pub const DEPTHS_M: [f64; 3] = [0.5, 1.5, 5.0];

/// What covers a pixel rectangle at a depth.
#[derive(Clone, Copy)]
pub enum Fill {
    /// One emitter (material index).
    Uniform(usize),
    /// A checker of 4-px cells (period 8 px) of two emitters, phase at the pixel origin.
    Checker(usize, usize),
}

/// A fronto-parallel emitter covering pixels [x0, x1) × [y0, y1) (pinhole projection) at z.
#[derive(Clone, Copy)]
pub struct Card {
    pub x0: i32,
    pub x1: i32,
    pub y0: i32,
    pub y1: i32,
    pub z_m: f64,
    pub fill: Fill,
}

/// A straight depth edge: vertical (`x` = column boundary) or horizontal, the rows (or
/// columns) [lo, hi) to average over (whole periods), the side of the nearer surface.
#[derive(Clone, Copy, Debug)]
pub struct Edge {
    pub vertical: bool,
    pub at: usize,
    pub lo: usize,
    pub hi: usize,
    pub near_z_m: f64,
}

pub struct SceneSpec {
    pub name: &'static str,
    pub cards: Vec<Card>,
    pub edges: Vec<Edge>,
}

/// Pinhole focal length in pixels, H/(2 tan(θ_y/2)), of a film `h` px high with vertical
/// field of view `yfov_deg`.
pub fn k_px(h: usize, yfov_deg: f64) -> f64 {
    camsim_render::depth_optics::pinhole_pixels_per_tan(yfov_deg.to_radians(), h)
}

/// The emitters (material index = position): name and spectral radiance (W m⁻² sr⁻¹ nm⁻¹)
/// at 360 and 830 nm, linear in between — spectrally distinct so that every band differs.
pub const EMITTERS: [(&str, [f64; 2]); 6] = [
    ("warm", [0.2, 2.0]),
    ("cool", [2.0, 0.3]),
    ("grey", [1.0, 1.0]),
    ("dark", [0.15, 0.15]),
    ("bright", [3.0, 3.0]),
    ("bright_cool", [4.0, 1.5]),
];

/// Emitters: [`EMITTERS`] as glTF materials.
pub fn materials(b: &mut GltfBuilder) {
    for (name, v) in EMITTERS {
        b.material(json!({"name": name, "doubleSided": true,
            "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
            "extras": {"spectral_reflectance": flat_spectrum(0.0),
                "spectral_emission": {"wavelength_nm": [360.0, 830.0], "values": v}}}));
    }
}

/// Band radiance of emitter `material` ([`EMITTERS`]) over [`lo_nm`, `hi_nm`] (inside
/// 360–830 nm): the mean of a linear spectrum over the band is its value at the band centre.
/// This is what the renderer's band planes estimate (uniform wavelength density, per-band
/// means; `Bands::sample_wavelengths`).
pub fn band_radiance(material: usize, lo_nm: f64, hi_nm: f64) -> f64 {
    let [a, b] = EMITTERS[material].1;
    let t = (0.5 * (lo_nm + hi_nm) - 360.0) / (830.0 - 360.0);
    a + (b - a) * t
}

/// The band radiance a pinhole sees at pixel (`x`, `y`) of `spec`: the nearest card covering
/// it; for a checker the mean of its two emitters, which is what a profile averaged along an
/// edge over whole checker periods sees (also through a lens: shifting the pixel by one px
/// along the edge shifts every ray's hit on a fronto-parallel card by one px of its pinhole
/// projection). None where no card covers the pixel.
pub fn visible_band_radiance(
    spec: &SceneSpec,
    x: i32,
    y: i32,
    lo_nm: f64,
    hi_nm: f64,
) -> Option<f64> {
    let card = spec
        .cards
        .iter()
        .filter(|c| c.x0 <= x && x < c.x1 && c.y0 <= y && y < c.y1)
        .min_by(|a, b| a.z_m.total_cmp(&b.z_m))?;
    Some(match card.fill {
        Fill::Uniform(m) => band_radiance(m, lo_nm, hi_nm),
        Fill::Checker(m0, m1) => {
            0.5 * (band_radiance(m0, lo_nm, hi_nm) + band_radiance(m1, lo_nm, hi_nm))
        }
    })
}

/// The glTF of `spec` for a pinhole camera of vertical field `yfov_deg` at the origin on a
/// `w × h` film (cards placed by their pinhole projection).
pub fn build(spec: &SceneSpec, w: usize, h: usize, yfov_deg: f64) -> GltfBuilder {
    let mut b = GltfBuilder::new();
    materials(&mut b);
    let k = k_px(h, yfov_deg);
    let (wc, hc) = (w as f64 / 2.0, h as f64 / 2.0);
    for (ci, c) in spec.cards.iter().enumerate() {
        let z = c.z_m;
        let corner = |px: i32, py: i32| -> [f32; 2] {
            [
                ((px as f64 - wc) * z / k) as f32,
                ((hc - py as f64) * z / k) as f32,
            ]
        };
        let rect = |x0: i32, x1: i32, y0: i32, y1: i32| -> MeshData {
            let (a, bb) = (corner(x0, y1), corner(x1, y0));
            let zz = -z as f32;
            quad([
                [a[0], a[1], zz],
                [bb[0], a[1], zz],
                [bb[0], bb[1], zz],
                [a[0], bb[1], zz],
            ])
        };
        match c.fill {
            Fill::Uniform(m) => {
                let mesh = b.mesh(&format!("card{ci}"), &rect(c.x0, c.x1, c.y0, c.y1), m);
                b.node(json!({"name": format!("card{ci}"), "mesh": mesh}), true);
            }
            Fill::Checker(m0, m1) => {
                let mut parts = [MeshData::default(), MeshData::default()];
                let mut y = c.y0;
                while y < c.y1 {
                    let mut x = c.x0;
                    while x < c.x1 {
                        let which = ((x.div_euclid(4) + y.div_euclid(4)) & 1) as usize;
                        parts[which].append(&rect(x, (x + 4).min(c.x1), y, (y + 4).min(c.y1)));
                        x += 4;
                    }
                    y += 4;
                }
                for (p, m) in parts.iter().zip([m0, m1]) {
                    let mesh = b.mesh(&format!("card{ci}_{m}"), p, m);
                    b.node(json!({"name": format!("card{ci}_{m}"), "mesh": mesh}), true);
                }
            }
        }
    }
    let cam = b.camera(
        "camera",
        yfov_deg.to_radians(),
        Some(w as f64 / h as f64),
        0.01,
    );
    b.node(json!({"name": "camera", "camera": cam}), true);
    b
}

/// The f32 depths (m) the renderer gives the cells of a checker at 5 m (each cell its own pair
/// of triangles): a plane's depth jitter.
pub const JITTERED_5M: [f32; 5] = [5.0, 4.999_999_5, 5.000_000_5, 4.999_999, 5.000_001];

/// A `w × h` plane of 4-px checker cells valued `hi` and `lo` (phase at the pixel origin).
pub fn checker_plane(w: usize, h: usize, hi: f32, lo: f32) -> Vec<f32> {
    (0..w * h)
        .map(|q| {
            if ((q % w) / 4 + (q / w) / 4) % 2 == 0 {
                hi
            } else {
                lo
            }
        })
        .collect()
}

/// [`JITTERED_5M`] spread over 4-px cells of a `w`-wide image: the depth of pixel `q`.
pub fn jittered_5m_depth(w: usize, q: usize) -> f32 {
    JITTERED_5M[((q % w) / 4 * 7 + (q / w) / 4 * 3) % JITTERED_5M.len()]
}

/// The three scenes on a `w × h` film (multiples of 8; the cards extend 16 px past the frame,
/// which a lens sees).
pub fn scenes(w: usize, h: usize) -> Vec<SceneSpec> {
    let (wi, hi) = (w as i32, h as i32);
    let bg = Card {
        x0: -16,
        x1: wi + 16,
        y0: -16,
        y1: hi + 16,
        z_m: 5.0,
        fill: Fill::Checker(2, 3),
    };
    let third = |n: usize| (w * n / 24) * 8; // column multiple of 8
    let rows = (8, h - 8);
    vec![
        // a near uniform card over the far checker
        SceneSpec {
            name: "near_card",
            cards: vec![
                bg,
                Card {
                    x0: -16,
                    x1: third(1) as i32,
                    y0: -16,
                    y1: hi + 16,
                    z_m: 0.5,
                    fill: Fill::Uniform(4),
                },
            ],
            edges: vec![Edge {
                vertical: true,
                at: third(1),
                lo: rows.0,
                hi: rows.1,
                near_z_m: 0.5,
            }],
        },
        // an in-focus checker at 1.5 m over the far one, a near card over the in-focus one
        SceneSpec {
            name: "steps",
            cards: vec![
                bg,
                Card {
                    x0: third(1) as i32,
                    x1: wi + 16,
                    y0: -16,
                    y1: hi + 16,
                    z_m: 1.5,
                    fill: Fill::Checker(0, 1),
                },
                Card {
                    x0: third(2) as i32,
                    x1: wi + 16,
                    y0: -16,
                    y1: hi + 16,
                    z_m: 0.5,
                    fill: Fill::Uniform(5),
                },
            ],
            edges: vec![
                Edge {
                    vertical: true,
                    at: third(1),
                    lo: rows.0,
                    hi: rows.1,
                    near_z_m: 1.5,
                },
                Edge {
                    vertical: true,
                    at: third(2),
                    lo: rows.0,
                    hi: rows.1,
                    near_z_m: 0.5,
                },
            ],
        },
        // a near frame (top and bottom bars) over an in-focus checker and the far one
        SceneSpec {
            name: "window",
            cards: vec![
                bg,
                Card {
                    x0: (w / 2) as i32,
                    x1: wi + 16,
                    y0: -16,
                    y1: hi + 16,
                    z_m: 1.5,
                    fill: Fill::Checker(0, 1),
                },
                Card {
                    x0: -16,
                    x1: wi + 16,
                    y0: -16,
                    y1: (h / 4) as i32 / 8 * 8,
                    z_m: 0.5,
                    fill: Fill::Uniform(4),
                },
                Card {
                    x0: -16,
                    x1: wi + 16,
                    y0: (3 * h / 4) as i32 / 8 * 8 + 8,
                    y1: hi + 16,
                    z_m: 0.5,
                    fill: Fill::Uniform(5),
                },
            ],
            edges: vec![
                Edge {
                    vertical: false,
                    at: h / 4 / 8 * 8,
                    lo: 8,
                    hi: w / 2 - 8,
                    near_z_m: 0.5,
                },
                Edge {
                    vertical: false,
                    at: 3 * h / 4 / 8 * 8 + 8,
                    lo: w / 2 + 8,
                    hi: w - 8,
                    near_z_m: 0.5,
                },
                Edge {
                    vertical: true,
                    at: w / 2,
                    lo: h / 4 / 8 * 8 + 16,
                    hi: 3 * h / 4 / 8 * 8,
                    near_z_m: 1.5,
                },
            ],
        },
    ]
}

/// Fraction of a disc of radius `c` on the side x < `u` of a line at signed offset `u` (the
/// disc ESF); a step for c = 0.
pub fn disc_esf(u: f64, c: f64) -> f64 {
    if c <= 1e-12 {
        return if u > 0.0 {
            1.0
        } else if u < 0.0 {
            0.0
        } else {
            0.5
        };
    }
    let t = (u / c).clamp(-1.0, 1.0);
    0.5 + (t * (1.0 - t * t).sqrt() + t.asin()) / std::f64::consts::PI
}

/// [`disc_esf`] averaged over u in [`u0`, `u0` + 1] (a pixel, film coordinates uniform over
/// it), exactly: A(u0 + 1) − A(u0) with the antiderivative A(u) = ∫₀ᵘ disc_esf, which for
/// |u| ≤ c is u/2 + (c/π)(t·asin t + √(1−t²) − (1−t²)^{3/2}/3 − 2/3), t = u/c (from
/// ∫asin t dt = t·asin t + √(1−t²) and ∫t√(1−t²) dt = −(1−t²)^{3/2}/3), −2c/(3π) below −c
/// and u − 2c/(3π) above c; for c = 0, A(u) = max(u, 0).
pub fn disc_esf_pixel(u0: f64, c: f64) -> f64 {
    let a = |u: f64| -> f64 {
        if c <= 1e-12 {
            return u.max(0.0);
        }
        let k = 2.0 * c / (3.0 * std::f64::consts::PI);
        if u <= -c {
            -k
        } else if u >= c {
            u - k
        } else {
            let t = u / c;
            let r = (1.0 - t * t).max(0.0);
            0.5 * u
                + c / std::f64::consts::PI
                    * (t * t.asin() + r.sqrt() - r * r.sqrt() / 3.0 - 2.0 / 3.0)
        }
    };
    a(u0 + 1.0) - a(u0)
}

/// 10–90 % width (px) of a rising or falling profile sampled at unit spacing (linear
/// interpolation of the crossings, from the levels at the ends).
pub fn width_10_90(p: &[f64]) -> f64 {
    let (a, b) = (p[0], p[p.len() - 1]);
    let cross = |f: f64| -> f64 {
        let t = a + f * (b - a);
        for i in 0..p.len() - 1 {
            let (u, v) = (
                (p[i] - t) * (b - a).signum(),
                (p[i + 1] - t) * (b - a).signum(),
            );
            if u <= 0.0 && v > 0.0 {
                return i as f64 + (-u) / (v - u);
            }
        }
        f64::NAN
    };
    cross(0.9) - cross(0.1)
}

/// Pixels beside a depth discontinuity: a jump of more than 10 % in 1/z between 4-neighbours
/// (both pixels marked).
pub fn depth_jump_mask(depth_z_m: &[f32], w: usize, h: usize) -> Vec<bool> {
    let inv: Vec<f64> = depth_z_m.iter().map(|z| 1.0 / *z as f64).collect();
    let mut jump = vec![false; w * h];
    for j in 0..h {
        for i in 0..w {
            let a = inv[j * w + i];
            for (di, dj) in [(1, 0), (0, 1)] {
                if i + di < w && j + dj < h {
                    let b = inv[(j + dj) * w + i + di];
                    if (a - b).abs() > 0.1 * a.max(b) {
                        jump[j * w + i] = true;
                        jump[(j + dj) * w + i + di] = true;
                    }
                }
            }
        }
    }
    jump
}

/// Whether the 8 × 8 block at (`x0`, `y0`) lies within `margin` px of a marked pixel of
/// `jump` or of the frame border.
pub fn block_excluded(
    jump: &[bool],
    w: usize,
    h: usize,
    x0: usize,
    y0: usize,
    margin: usize,
) -> bool {
    let near_edge = (y0.saturating_sub(margin)..(y0 + 8 + margin).min(h))
        .any(|y| (x0.saturating_sub(margin)..(x0 + 8 + margin).min(w)).any(|x| jump[y * w + x]));
    near_edge || x0 < margin || y0 < margin || x0 + 8 + margin > w || y0 + 8 + margin > h
}

/// The profile across `e` (offsets −half..half from the edge line) of `img`, averaged along
/// the edge.
pub fn edge_profile(img: &[f32], w: usize, e: &Edge, half: isize) -> Vec<f64> {
    let n_along = (e.hi - e.lo) as f64;
    (-half..half)
        .map(|d| {
            let across = (e.at as isize + d) as usize;
            (e.lo..e.hi)
                .map(|a| {
                    let q = if e.vertical {
                        a * w + across
                    } else {
                        across * w + a
                    };
                    img[q] as f64
                })
                .sum::<f64>()
                / n_along
        })
        .collect()
}

/// χ² survival function: P(X > `chi2`) for `dof` degrees of freedom (1 when `dof` is 0).
pub fn chi2_sf(chi2: f64, dof: usize) -> f64 {
    use statrs::distribution::{ChiSquared, ContinuousCDF};
    if dof == 0 {
        return 1.0;
    }
    1.0 - ChiSquared::new(dof as f64).unwrap().cdf(chi2)
}

/// One 8 × 8 block of [`block_z_tests`].
pub struct BlockZ {
    /// Block origin (px).
    pub x0: usize,
    /// Block origin (px).
    pub y0: usize,
    /// Block mean of image (a).
    pub mean_a: f64,
    /// Block mean of image (b).
    pub mean_b: f64,
    /// Scale of the pinhole variance to (b)'s.
    pub g: f64,
    /// z = (mean_a − mean_b)/σ.
    pub z: f64,
}

/// The block comparison of the cross-checks: 8 × 8 px blocks clear of the depth edges of
/// `jump` and of the border by `margin` px ([`block_excluded`]); per block the means of `a`
/// and `b` and z = Δ/σ, σ² = (Σ var_a + g²·Σ var_pin)/64² + (10⁻⁵·mean_a)², (b)'s variance being
/// that of the pinhole render `pin` it was computed from, scaled by g = mean_b/mean_pin when
/// `scale_pinhole_variance` (b in other units, e.g. irradiance), else g = 1.
#[allow(clippy::too_many_arguments)]
pub fn block_z_tests(
    a: &[f32],
    var_a: &[f32],
    b: &[f32],
    pin: &[f32],
    var_pin: &[f32],
    jump: &[bool],
    (w, h): (usize, usize),
    margin: usize,
    scale_pinhole_variance: bool,
) -> Vec<BlockZ> {
    let mut out = Vec::new();
    for by in 0..h / 8 {
        for bx in 0..w / 8 {
            let (x0, y0) = (bx * 8, by * 8);
            if block_excluded(jump, w, h, x0, y0, margin) {
                continue;
            }
            let (mut sa, mut sb, mut sp, mut va, mut vp) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for y in y0..y0 + 8 {
                for x in x0..x0 + 8 {
                    let q = y * w + x;
                    sa += a[q] as f64;
                    sb += b[q] as f64;
                    sp += pin[q] as f64;
                    va += var_a[q] as f64;
                    vp += var_pin[q] as f64;
                }
            }
            let nn = 64.0;
            let (ma, mb, mp) = (sa / nn, sb / nn, sp / nn);
            let g = if !scale_pinhole_variance {
                1.0
            } else if mp > 0.0 {
                mb / mp
            } else {
                0.0
            };
            let var = (va + g * g * vp) / (nn * nn) + (1e-5 * ma.abs()).powi(2);
            out.push(BlockZ {
                x0,
                y0,
                mean_a: ma,
                mean_b: mb,
                g,
                z: (ma - mb) / var.sqrt(),
            });
        }
    }
    out
}

/// Writes the scene of `spec` (`w × h`, vertical field `yfov_deg`) into `dir` and loads it.
pub fn write_and_load(
    spec: &SceneSpec,
    w: usize,
    h: usize,
    yfov_deg: f64,
    dir: &std::path::Path,
) -> Scene {
    let path = dir.join(format!("{}.gltf", spec.name));
    build(spec, w, h, yfov_deg).write(&path).unwrap();
    load_gltf(&path).unwrap()
}

/// The cross-checks' bands (400–700 nm in 100 nm steps) and their centres (nm).
pub fn xc_bands() -> (Bands, Vec<f64>) {
    let bands = Bands::new(400.0, 700.0, 100.0).unwrap();
    let band_nm = (0..bands.count).map(|b| bands.center_nm(b)).collect();
    (bands, band_nm)
}

/// The cross-checks' render settings: `spp` samples with `seed`, direct light only (the cards
/// are emitters), per-pixel variances, no depth samples.
pub fn xc_settings(bands: &Bands, spp: u32, seed: u64) -> RenderSettings {
    RenderSettings {
        spp,
        seed,
        bands: bands.clone(),
        max_depth: 1,
        variance: true,
        depth_spp: 0,
        ..Default::default()
    }
}
