//! Camera RGB → linear sRGB from DNG colour metadata (Adobe DNG Specification 1.6, chapter 6
//! "Mapping Camera Color Space to CIE XYZ Space"), for 3-colour cameras.
//!
//! * `ColorMatrix1/2` (XYZ → camera) and `ForwardMatrix1/2` (white-balanced camera → XYZ D50)
//!   are interpolated linearly in inverse correlated colour temperature between the two
//!   calibration illuminants: `g = (1/T − 1/T₂) / (1/T₁ − 1/T₂)` clamped to [0, 1].
//! * The white's chromaticity is found from the camera neutral (`AsShotNeutral`) by fixed-point
//!   iteration: `XYZ = (AB · CM(T(xy)))⁻¹ · neutral`, `xy ← XYZ` (20 steps from D50); `T(xy)` is
//!   McCamy's cubic (C. S. McCamy, "Correlated color temperature as an explicit function of
//!   chromaticity coordinates", Color Res. Appl. 17, 1992).
//! * Without a forward matrix: `camera → XYZ = CA(white → D65) · (AB · CM)⁻¹`; with one:
//!   `camera → XYZ = CA(D50 → D65) · FM · diag(AB⁻¹ · neutral)⁻¹ · AB⁻¹`. `CA` is the linear
//!   Bradford chromatic adaptation (von Kries scaling in the Bradford cone space; Lam 1985, as
//!   in ICC.1 Annex E). The D50 profile connection space of the spec is passed through
//!   implicitly: `CA(D50 → D65) · CA(white → D50) = CA(white → D65)`.
//! * Alternatively ([`WhiteAdaptation::CameraSpace`], the dcraw/LibRaw convention): the white
//!   balance alone adapts (von Kries in camera space) and the matrix is the one for D65,
//!   `(diag(1/s) · CM · M_sRGB→XYZ)⁻¹` with `s = CM · M_sRGB→XYZ · (1, 1, 1)` (dcraw's
//!   `cam_xyz_coeff`); it equals the Bradford path when the neutral is the D65 neutral.
//! * White-balance gains are `max(neutral) / neutral_k` (the channel with the largest neutral
//!   keeps gain 1, as in dcraw/LibRaw), and the matrix is scaled so that white-balanced
//!   (1, 1, 1) has luminance Y = 1: a neutral that just saturates its strongest channel
//!   renders as sRGB white (no auto-brightening).
use crate::color::{ColorMatrix, XYZ_TO_LINEAR_SRGB};
use crate::IspError;

/// Bradford cone-response matrix (Lam 1985; ICC.1:2010 Annex E), `cone = B · XYZ`.
pub const BRADFORD: [[f64; 3]; 3] = [
    [0.8951, 0.2664, -0.1614],
    [-0.7502, 1.7135, 0.0367],
    [0.0389, -0.0685, 1.0296],
];
/// CIE D50 chromaticity (x, y) as the DNG/ICC profile connection space uses it.
pub const D50_XY: [f64; 2] = [0.3457, 0.3585];
/// CIE D65 chromaticity (x, y) of sRGB (IEC 61966-2-1).
pub const D65_XY: [f64; 2] = [0.3127, 0.3290];

/// XYZ with Y = 1 of a chromaticity.
pub fn xy_to_xyz(xy: [f64; 2]) -> [f64; 3] {
    [xy[0] / xy[1], 1.0, (1.0 - xy[0] - xy[1]) / xy[1]]
}

fn inv(m: &ColorMatrix, what: &str) -> Result<ColorMatrix, IspError> {
    crate::isetcam::invert(m).map_err(|_| IspError::InvalidParameter {
        name: what.into(),
        value: format!("{:?}", m.m),
        reason: "is singular".into(),
    })
}

/// Linear Bradford adaptation from white `src_xy` to white `dst_xy` (XYZ → XYZ).
pub fn bradford(src_xy: [f64; 2], dst_xy: [f64; 2]) -> ColorMatrix {
    let b = ColorMatrix { m: BRADFORD };
    let bi = crate::isetcam::invert(&b).expect("Bradford is invertible");
    let (s, d) = (b.apply(xy_to_xyz(src_xy)), b.apply(xy_to_xyz(dst_xy)));
    let diag = ColorMatrix {
        m: [
            [d[0] / s[0], 0.0, 0.0],
            [0.0, d[1] / s[1], 0.0],
            [0.0, 0.0, d[2] / s[2]],
        ],
    };
    bi.after(&diag).after(&b)
}

/// McCamy's CCT (kelvin) of a chromaticity: `n = (x − 0.3320)/(0.1858 − y)`,
/// `T = 449 n³ + 3525 n² + 6823.3 n + 5520.33`.
pub fn mccamy_cct_k(xy: [f64; 2]) -> f64 {
    let n = (xy[0] - 0.3320) / (0.1858 - xy[1]);
    449.0 * n.powi(3) + 3525.0 * n.powi(2) + 6823.3 * n + 5520.33
}

/// CCT (kelvin) of an EXIF/DNG `CalibrationIlluminant` code (EXIF 2.3 LightSource table), or
/// None for codes without a defined temperature.
pub fn calibration_illuminant_cct_k(code: u32) -> Option<f64> {
    Some(match code {
        17 | 3 => 2856.0,     // standard light A, tungsten
        24 => 3200.0,         // ISO studio tungsten
        18 => 4874.0,         // standard light B
        19 => 6774.0,         // standard light C
        20 => 5503.0,         // D55
        21 | 1 | 9 => 6504.0, // D65, daylight, fine weather
        22 => 7504.0,         // D75
        23 => 5003.0,         // D50
        10 => 6500.0,         // cloudy
        11 => 7500.0,         // shade
        12 => 6430.0,         // daylight fluorescent (F1)
        13 => 5000.0,         // day white fluorescent
        14 => 4150.0,         // cool white fluorescent (F2)
        15 => 3450.0,         // white fluorescent
        16 => 2940.0,         // warm white fluorescent
        2 => 4150.0,          // fluorescent
        _ => return None,
    })
}

/// How the scene white is adapted to the D65 white of sRGB.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WhiteAdaptation {
    /// DNG specification: Bradford adaptation in XYZ from the white found from the neutral.
    Bradford,
    /// dcraw/LibRaw: white-balance gains in camera space, then the D65 matrix.
    CameraSpace,
}

/// One calibration of a DNG: matrices for one illuminant.
#[derive(Debug, Clone, PartialEq)]
pub struct DngCalibration {
    /// ColorMatrix (XYZ → camera).
    pub color_matrix: ColorMatrix,
    /// ForwardMatrix (white-balanced camera → XYZ D50), if given.
    pub forward_matrix: Option<ColorMatrix>,
    /// CCT (kelvin) of the calibration illuminant.
    pub cct_k: f64,
}

/// The colour metadata of a 3-colour DNG.
#[derive(Debug, Clone, PartialEq)]
pub struct DngColor {
    /// One or two calibrations.
    pub calibrations: Vec<DngCalibration>,
    /// AnalogBalance (1, 1, 1 when absent).
    pub analog_balance: [f64; 3],
    /// AsShotNeutral (camera coordinates of a neutral under the scene light).
    pub neutral: [f64; 3],
}

/// Result of [`dng_camera_to_srgb`].
#[derive(Debug, Clone, PartialEq)]
pub struct DngRendering {
    /// White-balance gains applied to the camera channels (largest-neutral channel = 1).
    pub gains: [f64; 3],
    /// White-balanced camera RGB → linear sRGB.
    pub matrix: ColorMatrix,
    /// Chromaticity of the scene white found from the neutral.
    pub white_xy: [f64; 2],
    /// Its CCT (kelvin, McCamy).
    pub white_cct_k: f64,
    /// Weight of calibration 1 in the interpolation (1 with a single calibration).
    pub weight_1: f64,
    /// Whether forward matrices were used.
    pub used_forward_matrix: bool,
}

fn mix(a: &ColorMatrix, b: &ColorMatrix, g: f64) -> ColorMatrix {
    let mut m = a.m;
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = g * a.m[i][j] + (1.0 - g) * b.m[i][j];
        }
    }
    ColorMatrix { m }
}

/// The white-balance gains and camera → linear sRGB matrix of a DNG (module documentation),
/// Bradford adaptation.
pub fn dng_camera_to_srgb(c: &DngColor) -> Result<DngRendering, IspError> {
    dng_camera_to_srgb_with(c, WhiteAdaptation::Bradford)
}

/// As [`dng_camera_to_srgb`] with a chosen white adaptation.
pub fn dng_camera_to_srgb_with(
    c: &DngColor,
    adaptation: WhiteAdaptation,
) -> Result<DngRendering, IspError> {
    let bad = |name: &str, v: String, why: &str| IspError::InvalidParameter {
        name: name.into(),
        value: v,
        reason: why.into(),
    };
    if c.calibrations.is_empty() || c.calibrations.len() > 2 {
        return Err(bad(
            "ColorMatrix",
            format!("{} calibrations", c.calibrations.len()),
            "need ColorMatrix1 (and optionally ColorMatrix2)",
        ));
    }
    if c.neutral.iter().any(|&x| !(x > 0.0 && x.is_finite())) {
        return Err(bad(
            "AsShotNeutral",
            format!("{:?}", c.neutral),
            "must be three positive numbers",
        ));
    }
    if c.analog_balance
        .iter()
        .any(|&x| !(x > 0.0 && x.is_finite()))
    {
        return Err(bad(
            "AnalogBalance",
            format!("{:?}", c.analog_balance),
            "must be three positive numbers",
        ));
    }
    let ab = ColorMatrix {
        m: [
            [c.analog_balance[0], 0.0, 0.0],
            [0.0, c.analog_balance[1], 0.0],
            [0.0, 0.0, c.analog_balance[2]],
        ],
    };
    let weight = |cct: f64| -> f64 {
        if c.calibrations.len() == 1 {
            return 1.0;
        }
        let (t1, t2) = (c.calibrations[0].cct_k, c.calibrations[1].cct_k);
        if t1 == t2 {
            return 1.0;
        }
        ((1.0 / cct - 1.0 / t2) / (1.0 / t1 - 1.0 / t2)).clamp(0.0, 1.0)
    };
    let cm_at = |g: f64| -> ColorMatrix {
        if c.calibrations.len() == 1 {
            c.calibrations[0].color_matrix
        } else {
            mix(
                &c.calibrations[0].color_matrix,
                &c.calibrations[1].color_matrix,
                g,
            )
        }
    };
    // white chromaticity by fixed-point iteration from D50
    let mut xy = D50_XY;
    let mut g = 1.0;
    for _ in 0..20 {
        g = weight(mccamy_cct_k(xy).clamp(1000.0, 50000.0));
        let xyz = inv(&ab.after(&cm_at(g)), "ColorMatrix")?.apply(c.neutral);
        let s = xyz[0] + xyz[1] + xyz[2];
        if !(s > 0.0) {
            return Err(bad(
                "AsShotNeutral",
                format!("{:?}", c.neutral),
                "maps to a non-physical white through ColorMatrix",
            ));
        }
        xy = [xyz[0] / s, xyz[1] / s];
    }
    let ab_inv = inv(&ab, "AnalogBalance")?;
    let fms: Vec<Option<ColorMatrix>> = c.calibrations.iter().map(|k| k.forward_matrix).collect();
    let use_fm = fms.iter().all(|f| f.is_some());
    let cam_to_xyz_d65 = if adaptation == WhiteAdaptation::CameraSpace {
        // dcraw: rows of CM · M_sRGB→XYZ normalised to sum 1, inverted; gains undone below
        let srgb_to_xyz = inv(
            &ColorMatrix {
                m: XYZ_TO_LINEAR_SRGB,
            },
            "sRGB matrix",
        )?;
        let cam_rgb = ab.after(&cm_at(g)).after(&srgb_to_xyz);
        let srow = cam_rgb.apply([1.0, 1.0, 1.0]);
        if srow.iter().any(|&x| !(x > 0.0)) {
            return Err(bad(
                "ColorMatrix",
                format!("{:?}", c.calibrations[0].color_matrix.m),
                "gives a non-positive camera response to the D65 white",
            ));
        }
        let norm = ColorMatrix {
            m: [
                [1.0 / srow[0], 0.0, 0.0],
                [0.0, 1.0 / srow[1], 0.0],
                [0.0, 0.0, 1.0 / srow[2]],
            ],
        };
        // white-balanced camera → linear sRGB, expressed as raw camera → XYZ
        let nmax = c.neutral.iter().cloned().fold(0.0, f64::max);
        let gains = ColorMatrix {
            m: [
                [nmax / c.neutral[0], 0.0, 0.0],
                [0.0, nmax / c.neutral[1], 0.0],
                [0.0, 0.0, nmax / c.neutral[2]],
            ],
        };
        srgb_to_xyz
            .after(&inv(&norm.after(&cam_rgb), "ColorMatrix")?)
            .after(&gains)
    } else if use_fm {
        let fm = if fms.len() == 1 {
            fms[0].expect("checked")
        } else {
            mix(&fms[0].expect("checked"), &fms[1].expect("checked"), g)
        };
        let rn = ab_inv.apply(c.neutral);
        let d = ColorMatrix {
            m: [
                [1.0 / rn[0], 0.0, 0.0],
                [0.0, 1.0 / rn[1], 0.0],
                [0.0, 0.0, 1.0 / rn[2]],
            ],
        };
        bradford(D50_XY, D65_XY).after(&fm).after(&d).after(&ab_inv)
    } else {
        bradford(xy, D65_XY).after(&inv(&ab.after(&cm_at(g)), "ColorMatrix")?)
    };
    let nmax = c.neutral.iter().cloned().fold(0.0, f64::max);
    let gains = c.neutral.map(|n| nmax / n);
    // white-balanced camera → XYZ: undo the gains first
    let ungain = ColorMatrix {
        m: [
            [1.0 / gains[0], 0.0, 0.0],
            [0.0, 1.0 / gains[1], 0.0],
            [0.0, 0.0, 1.0 / gains[2]],
        ],
    };
    let wb_to_xyz = cam_to_xyz_d65.after(&ungain);
    let y_white = wb_to_xyz.apply([1.0, 1.0, 1.0])[1];
    if !(y_white > 0.0 && y_white.is_finite()) {
        return Err(bad(
            "ColorMatrix",
            format!("{:?}", c.calibrations[0].color_matrix.m),
            "gives a white with no luminance",
        ));
    }
    let matrix = ColorMatrix {
        m: XYZ_TO_LINEAR_SRGB,
    }
    .after(&wb_to_xyz)
    .scaled(1.0 / y_white);
    Ok(DngRendering {
        gains,
        matrix,
        white_xy: xy,
        white_cct_k: mccamy_cct_k(xy),
        weight_1: g,
        used_forward_matrix: use_fm && adaptation == WhiteAdaptation::Bradford,
    })
}
