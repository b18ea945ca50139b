//! `camsim metric scielab A B`: S-CIELAB (Zhang & Wandell 1996; [`camsim_metrics::scielab()`])
//! between any two pictures shown on a display at a viewing distance. Each 8/16-bit PNG or
//! TIFF (grey, RGB or RGBA) is taken as the display's digital codes; a pixel's CIE 1931 XYZ is
//! `Σ_p g_p(code_p) XYZ_p` (the display's gamma and primaries, black level included), the
//! white the display's full-drive white, and the samples per degree `1 / atan°(pitch / d)`.
//! `--parameters isetcam` uses [`camsim_metrics::ScielabOptions::isetcam`] with the samples
//! per degree rounded as ISETCam's `scParams` does (its 10° opponent matrix is then applied to
//! these 1931 XYZ values, an approximation: ISETCam would use 10° XYZ).
use crate::error::CliError;
use camsim_core::colorimetry::Xyz;
use camsim_display::DisplayModel;
use std::fmt;
use std::path::Path;

/// What `camsim metric scielab` reports.
#[derive(Debug, Clone, PartialEq)]
pub struct ScielabSummary {
    /// `"camsim"` or `"isetcam"`.
    pub parameters: String,
    /// Size of the ΔE map (ISETCam's parameters cut even sides by one).
    pub rows: usize,
    /// Columns of the ΔE map.
    pub cols: usize,
    /// Display samples per degree of visual angle used.
    pub samples_per_degree: f64,
    /// Display white (CIE 1931 XYZ, Y in cd/m²).
    pub white_xyz: Xyz,
    /// Mean ΔE over the map.
    pub mean_delta_e: f64,
    /// 95th percentile of the map.
    pub p95_delta_e: f64,
    /// Maximum of the map.
    pub max_delta_e: f64,
}

impl fmt::Display for ScielabSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "S-CIELAB ({} parameters, {}×{} px, {:.2} samples/deg, white Y {:.2} cd/m²): mean ΔE {:.4}, p95 {:.4}, max {:.4}",
            self.parameters,
            self.rows,
            self.cols,
            self.samples_per_degree,
            self.white_xyz.y,
            self.mean_delta_e,
            self.p95_delta_e,
            self.max_delta_e
        )
    }
}

/// XYZ of every pixel of `path` on `display`.
fn picture_xyz(path: &Path, display: &DisplayModel) -> Result<(usize, usize, Vec<Xyz>), CliError> {
    let pic = crate::scene_files::read_rgb_picture(path).map_err(CliError::Other)?;
    let prim = display.primaries_xyz();
    // Linear intensity of every code of each primary (a lookup table per primary).
    let n_codes = 1usize << pic.bits;
    let lut: Vec<Vec<f64>> = (0..3)
        .map(|p| {
            (0..n_codes)
                .map(|c| display.linear_from_digital(p, c as u32, pic.bits))
                .collect::<Result<Vec<f64>, _>>()
        })
        .collect::<Result<_, _>>()
        .map_err(|e| CliError::input(path, format!("display: {e}")))?;
    let ch = pic.channels;
    let xyz = (0..pic.rows * pic.cols)
        .map(|i| {
            let mut out = Xyz {
                x: 0.0,
                y: 0.0,
                z: 0.0,
            };
            for p in 0..3 {
                let code = pic.codes[i * ch + if ch == 1 { 0 } else { p }] as usize;
                let l = lut[p][code.min(n_codes - 1)];
                out.x += l * prim[p].x;
                out.y += l * prim[p].y;
                out.z += l * prim[p].z;
            }
            out
        })
        .collect();
    Ok((pic.rows, pic.cols, xyz))
}

/// S-CIELAB between pictures `a` and `b` shown on the display `display` (a name of
/// [`DisplayModel::names`]) seen from `viewing_distance_m`, with `parameters` `"camsim"`
/// (the published 1996 filters, mirror borders, ΔE*ab) or `"isetcam"`.
pub fn scielab_pictures(
    a: &Path,
    b: &Path,
    display: &str,
    viewing_distance_m: f64,
    parameters: &str,
) -> Result<ScielabSummary, CliError> {
    if !(viewing_distance_m.is_finite() && viewing_distance_m > 0.0) {
        return Err(CliError::Other(format!(
            "--viewing-distance-m: expected a distance > 0 in metres, got {viewing_distance_m}"
        )));
    }
    let isetcam = match parameters {
        "camsim" => false,
        "isetcam" => true,
        p => {
            return Err(CliError::Other(format!(
                "--parameters: expected camsim or isetcam, got \"{p}\""
            )))
        }
    };
    let d = DisplayModel::load(display)
        .map_err(|e| CliError::Other(format!("--display {display}: {e}")))?;
    if d.n_primaries() != 3 {
        return Err(CliError::Other(format!(
            "--display {display}: has {} primaries; S-CIELAB of RGB pictures needs 3",
            d.n_primaries()
        )));
    }
    let (ra, ca, xa) = picture_xyz(a, &d)?;
    let (rb, cb, xb) = picture_xyz(b, &d)?;
    if (ra, ca) != (rb, cb) {
        return Err(CliError::input(
            b,
            format!("is {rb}×{cb} pixels but {} is {ra}×{ca}", a.display()),
        ));
    }
    let deg_per_px = (d.pixel_pitch_m() / viewing_distance_m).atan().to_degrees();
    let spd = 1.0 / deg_per_px;
    let opts = if isetcam {
        camsim_metrics::ScielabOptions::isetcam(spd.round().max(1.0))
    } else {
        camsim_metrics::ScielabOptions::new(spd)
    };
    let white = d.white_xyz();
    let r = camsim_metrics::scielab_with_options(&xa, &xb, ra, ca, white, &opts)
        .map_err(|e| CliError::input(a, format!("scielab: {e}")))?;
    let mut sorted = r.delta_e_map.clone();
    sorted.sort_by(|x, y| x.total_cmp(y));
    let p95 = sorted[((sorted.len() as f64 * 0.95).ceil() as usize).clamp(1, sorted.len()) - 1];
    Ok(ScielabSummary {
        parameters: parameters.to_string(),
        rows: r.rows,
        cols: r.cols,
        samples_per_degree: opts.samples_per_degree,
        white_xyz: white,
        mean_delta_e: r.mean_delta_e,
        p95_delta_e: p95,
        max_delta_e: *sorted.last().unwrap_or(&0.0),
    })
}
