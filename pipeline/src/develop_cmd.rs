//! `camsim develop FILE --out IMAGE.png`: develop a real raw file (an uncompressed DNG, or a
//! headerless raw with a stated layout) through the same image processor as simulated frames.
//!
//! DNG chain (Adobe DNG Specification 1.6, chapters 5–6): LinearizationTable → BlackLevel
//! (repeat pattern + row/column deltas) and WhiteLevel → the CFA from CFARepeatPatternDim /
//! CFAPattern / CFAPlaneColor → demosaic (`camsim_isp::demosaic_planes`, any method) →
//! AsShotNeutral white balance → highlight clip at the white level (dcraw/LibRaw's default) →
//! ColorMatrix/ForwardMatrix (interpolated by CCT when two are given) → linear sRGB
//! (`camsim_isp::dng_color`) → optional tone curve → sRGB PNG (8 or 16 bit).
//!
//! Headerless raw: `--layout rows=R,cols=C,cfa=RGGB,black=B,white=W[,bits=16][,endian=little]
//! [,header=0]`; colour from `--color-matrix` (nine XYZ→camera numbers, D65 calibration) and
//! `--neutral`, else camera RGB balanced by the chosen white balance (not colorimetric: the
//! summary says so).
//!
//! Any error (unreadable, truncated, wrong or missing tags, compressed data, bad options) is
//! one line naming the file and what was expected, and nothing is written: the image goes to
//! a temporary file beside the output, renamed into place only at the end.
use crate::error::CliError;
use crate::raw_input::dng::read_dng;
use crate::raw_input::{read_raw, RawFormat};
use camsim_core::RawFrame;
use camsim_isp::dng_color::{
    calibration_illuminant_cct_k, dng_camera_to_srgb_with, DngCalibration, DngColor,
    WhiteAdaptation,
};
use camsim_isp::{
    demosaic_planes, to_srgb16, to_srgb8, Bilateral, ChannelBalance, ColorMatrix, DemosaicMethod,
    Mosaic, RgbImage, ToneCurve,
};
use std::path::{Path, PathBuf};

/// How `develop` white-balances.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DevelopBalance {
    /// AsShotNeutral of the DNG (or `--neutral`); the default.
    AsShot,
    /// Grey world on the demosaicked image.
    GreyWorld,
    /// White patch on the demosaicked image.
    WhitePatch,
    /// No gains.
    None,
}

impl std::str::FromStr for DevelopBalance {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "as_shot" => Ok(DevelopBalance::AsShot),
            "grey_world" => Ok(DevelopBalance::GreyWorld),
            "white_patch" => Ok(DevelopBalance::WhitePatch),
            "none" => Ok(DevelopBalance::None),
            _ => Err(format!(
                "unknown white balance '{s}'; expected as_shot, grey_world, white_patch or none"
            )),
        }
    }
}

/// Options of `camsim develop`.
#[derive(Debug, Clone)]
pub struct DevelopOptions {
    /// Demosaic method (default malvar).
    pub demosaic: DemosaicMethod,
    /// White balance (default as_shot).
    pub balance: DevelopBalance,
    /// 8 or 16.
    pub output_bits: u32,
    /// Tone curve (default none: linear up to sRGB encoding).
    pub tone: ToneCurve,
    /// Optional bilateral denoiser on the demosaicked planes.
    pub denoise: Option<Bilateral>,
    /// Clip white-balanced camera values at the white level before the colour matrix.
    pub highlight_clip: bool,
    /// White adaptation: Bradford (DNG specification, default) or camera space (dcraw/LibRaw).
    pub adaptation: WhiteAdaptation,
    /// Layout of a headerless raw file (`--layout`).
    pub layout: Option<String>,
    /// XYZ → camera matrix for a headerless raw (row-major, D65 calibration).
    pub color_matrix: Option<[f64; 9]>,
    /// Camera neutral for a headerless raw.
    pub neutral: Option<[f64; 3]>,
}

impl Default for DevelopOptions {
    fn default() -> Self {
        DevelopOptions {
            demosaic: DemosaicMethod::Malvar,
            balance: DevelopBalance::AsShot,
            output_bits: 8,
            tone: ToneCurve::None,
            denoise: None,
            highlight_clip: true,
            adaptation: WhiteAdaptation::Bradford,
            layout: None,
            color_matrix: None,
            neutral: None,
        }
    }
}

/// What `develop` did.
#[derive(Debug, Clone, PartialEq)]
pub struct DevelopSummary {
    /// Image rows × columns written.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// CFA tile (rows of letters).
    pub cfa: Vec<String>,
    /// Black level (mean, DN) and white level (DN).
    pub black_dn: f64,
    /// White level (DN).
    pub white_dn: f64,
    /// White-balance gains (R, G, B).
    pub gains: [f64; 3],
    /// Camera → linear sRGB matrix after white balance (identity when not colorimetric).
    pub matrix: ColorMatrix,
    /// Where the colour transform came from.
    pub color_source: String,
    /// Scene white CCT (kelvin) found from the neutral, when a ColorMatrix was used.
    pub white_cct_k: Option<f64>,
}

fn parse_layout(path: &Path, s: &str) -> Result<(RawFormat, Vec<String>, f64, f64), CliError> {
    let bad = |m: String| CliError::input(path, format!("--layout: {m}"));
    let mut kv = std::collections::BTreeMap::new();
    for part in s.split(',') {
        let (k, v) = part
            .split_once('=')
            .ok_or_else(|| bad(format!("'{part}' is not key=value")))?;
        kv.insert(k.trim().to_string(), v.trim().to_string());
    }
    let num = |k: &str| -> Result<Option<f64>, CliError> {
        kv.get(k)
            .map(|v| {
                v.parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite() && *x >= 0.0)
                    .ok_or_else(|| bad(format!("{k}={v} is not a number ≥ 0")))
            })
            .transpose()
    };
    for k in kv.keys() {
        if ![
            "rows", "cols", "cfa", "black", "white", "bits", "endian", "header",
        ]
        .contains(&k.as_str())
        {
            return Err(bad(format!(
                "unknown key '{k}' (expected rows, cols, cfa, black, white, bits, endian, header)"
            )));
        }
    }
    let need = |k: &str| -> Result<f64, CliError> {
        num(k)?.ok_or_else(|| bad(format!("{k}= is required (rows, cols, cfa, black, white)")))
    };
    let rows = need("rows")? as usize;
    let cols = need("cols")? as usize;
    let black = need("black")?;
    let white = need("white")?;
    let bits = num("bits")?.unwrap_or(16.0) as usize;
    if bits != 8 && bits != 16 {
        return Err(bad(format!("bits={bits}: expected 8 or 16")));
    }
    let little = match kv.get("endian").map(|s| s.as_str()).unwrap_or("little") {
        "little" => true,
        "big" => false,
        e => return Err(bad(format!("endian={e}: expected little or big"))),
    };
    let cfa_s = kv
        .get("cfa")
        .ok_or_else(|| bad("cfa= is required, e.g. cfa=RGGB or cfa=rg/gb".into()))?
        .to_ascii_lowercase();
    let cfa: Vec<String> = if cfa_s.contains('/') {
        cfa_s.split('/').map(|s| s.to_string()).collect()
    } else if cfa_s.len() == 4 {
        vec![cfa_s[..2].to_string(), cfa_s[2..].to_string()]
    } else {
        return Err(bad(format!(
            "cfa={cfa_s}: give four letters (RGGB) or rows separated by '/' (rg/gb)"
        )));
    };
    if rows == 0 || cols == 0 || !(white > black) {
        return Err(bad(format!(
            "rows={rows}, cols={cols}, black={black}, white={white}: need rows, cols > 0 and white > black"
        )));
    }
    Ok((
        RawFormat {
            rows,
            cols,
            bytes_per_sample: bits / 8,
            little_endian: little,
            header_bytes: num("header")?.unwrap_or(0.0) as u64,
        },
        cfa,
        black,
        white,
    ))
}

/// The mosaic of rows of CFA letters: channels in the order `plane_letters` gives (DNG
/// CFAPlaneColor; r, g, b by default), letters not listed appended.
fn mosaic_of(
    path: &Path,
    data: Vec<f32>,
    rows: usize,
    cols: usize,
    cfa: &[String],
    plane_letters: &[char],
) -> Result<Mosaic, CliError> {
    let mut names: Vec<char> = plane_letters.to_vec();
    for row in cfa {
        for ch in row.chars() {
            if !names.contains(&ch) {
                names.push(ch);
            }
        }
    }
    let tile: Vec<Vec<usize>> = cfa
        .iter()
        .map(|r| {
            r.chars()
                .map(|ch| names.iter().position(|&n| n == ch).expect("added"))
                .collect()
        })
        .collect();
    // drop plane letters that the tile never uses (a tile must use every channel it names)
    let used: Vec<usize> = (0..names.len())
        .filter(|k| tile.iter().flatten().any(|t| t == k))
        .collect();
    let remap: Vec<usize> = (0..names.len())
        .map(|k| used.iter().position(|&u| u == k).unwrap_or(usize::MAX))
        .collect();
    let tile = tile
        .iter()
        .map(|r| r.iter().map(|&k| remap[k]).collect())
        .collect();
    let names: Vec<String> = used.iter().map(|&k| names[k].to_string()).collect();
    Mosaic::new(rows, cols, data, tile, names).map_err(|e| CliError::input(path, e))
}

fn tag3(
    tags: &std::collections::BTreeMap<u16, Vec<f64>>,
    t: u16,
    name: &str,
    path: &Path,
) -> Result<Option<ColorMatrix>, CliError> {
    match tags.get(&t) {
        None => Ok(None),
        Some(v) if v.len() == 9 && v.iter().all(|x| x.is_finite()) => Ok(Some(ColorMatrix {
            m: [[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]],
        })),
        Some(v) => Err(CliError::input(
            path,
            format!(
                "{name} ({t}) has {} values; a 3-colour DNG needs 9 (3 × 3)",
                v.len()
            ),
        )),
    }
}

/// Develop `input` into the PNG `out` (see the module documentation).
pub fn develop(input: &Path, out: &Path, o: &DevelopOptions) -> Result<DevelopSummary, CliError> {
    let ext = input
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    if o.output_bits != 8 && o.output_bits != 16 {
        return Err(CliError::Other(format!(
            "--bits {}: expected 8 or 16",
            o.output_bits
        )));
    }
    if out
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .as_deref()
        != Some("png")
    {
        return Err(CliError::output(out, "the output must be a .png file"));
    }
    // 1. read + linearise → normalised mosaic, colour metadata
    let (mosaic, cfa, black_dn, white_dn, color): (
        Mosaic,
        Vec<String>,
        f64,
        f64,
        Option<DngColor>,
    ) = if ext == "dng" {
        if o.layout.is_some() {
            return Err(CliError::input(
                input,
                "--layout is for headerless raw files; a DNG describes itself",
            ));
        }
        let d = read_dng(input)?;
        let tags = &d.tags;
        let bad = |m: String| CliError::input(input, m);
        let lin = tags.get(&50712);
        if let Some(t) = lin {
            if t.is_empty() {
                return Err(bad("LinearizationTable (50712) is empty".into()));
            }
        }
        let white = d.info.white_level as f64;
        let (rows, cols) = (d.frame.rows, d.frame.cols);
        let mut data = Vec::with_capacity(rows * cols);
        for r in 0..rows {
            for c in 0..cols {
                let dn = d.frame.dn[r * cols + c] as usize;
                let v = match lin {
                    Some(t) => t[dn.min(t.len() - 1)],
                    None => dn as f64,
                };
                let b = d.info.black_level_at(r, c);
                data.push(((v - b) / (white - b)) as f32);
            }
        }
        if !(white > d.info.mean_black_level_dn()) {
            return Err(bad(format!(
                "WhiteLevel (50717) = {white} is not above the black level {}",
                d.info.mean_black_level_dn()
            )));
        }
        let planes: Vec<char> = match tags.get(&50710) {
            None => vec!['r', 'g', 'b'],
            Some(v) => v
                .iter()
                .map(|&x| {
                    crate::raw_input::dng::cfa_letter(x as u8).ok_or_else(|| {
                        bad(format!(
                            "CFAPlaneColor (50710) has colour code {x} (known: 0–6)"
                        ))
                    })
                })
                .collect::<Result<_, _>>()?,
        };
        let m = mosaic_of(input, data, rows, cols, &d.info.cfa, &planes)?;
        // colour tags
        let mut cals = vec![];
        for (cm_t, fm_t, ill_t, k) in [(50721u16, 50964u16, 50778u16, 1), (50722, 50965, 50779, 2)]
        {
            let cm = tag3(tags, cm_t, &format!("ColorMatrix{k}"), input)?;
            let fm = tag3(tags, fm_t, &format!("ForwardMatrix{k}"), input)?;
            if let Some(cm) = cm {
                let code = tags
                    .get(&ill_t)
                    .and_then(|v| v.first().copied())
                    .unwrap_or(21.0) as u32;
                let cct = calibration_illuminant_cct_k(code).ok_or_else(|| {
                        bad(format!(
                            "CalibrationIlluminant{k} ({ill_t}) = {code} has no colour temperature (supported: EXIF light sources 1–3, 9–24)"
                        ))
                    })?;
                cals.push(DngCalibration {
                    color_matrix: cm,
                    forward_matrix: fm,
                    cct_k: cct,
                });
            }
        }
        let color = if cals.is_empty() {
            None
        } else {
            if m.channel_names.len() != 3 {
                return Err(bad(format!(
                        "ColorMatrix1 is given for {} colour planes ({}); camsim develops 3-colour DNGs colorimetrically",
                        m.channel_names.len(),
                        m.channel_names.join("")
                    )));
            }
            let neutral = match tags.get(&50728) {
                Some(v) if v.len() == 3 => [v[0], v[1], v[2]],
                Some(v) => {
                    return Err(bad(format!(
                        "AsShotNeutral (50728) has {} values; expected 3",
                        v.len()
                    )))
                }
                None => {
                    return Err(bad(
                        "AsShotNeutral (50728) is missing (AsShotWhiteXY is not supported)".into(),
                    ))
                }
            };
            let ab = match tags.get(&50727) {
                Some(v) if v.len() == 3 => [v[0], v[1], v[2]],
                Some(v) => {
                    return Err(bad(format!(
                        "AnalogBalance (50727) has {} values; expected 3",
                        v.len()
                    )))
                }
                None => [1.0; 3],
            };
            Some(DngColor {
                calibrations: cals,
                analog_balance: ab,
                neutral,
            })
        };
        (
            m,
            d.info.cfa.clone(),
            d.info.mean_black_level_dn(),
            white,
            color,
        )
    } else {
        let layout = o.layout.as_deref().ok_or_else(|| {
                CliError::input(
                    input,
                    "not a DNG: a headerless raw needs --layout rows=R,cols=C,cfa=RGGB,black=B,white=W[,bits=16,endian=little,header=0]",
                )
            })?;
        let (fmt, cfa, black, white) = parse_layout(input, layout)?;
        let frame: RawFrame = read_raw(input, &fmt)?;
        let data = frame
            .dn
            .iter()
            .map(|&d| ((d as f64 - black) / (white - black)) as f32)
            .collect();
        let m = mosaic_of(input, data, fmt.rows, fmt.cols, &cfa, &['r', 'g', 'b'])?;
        let color = match (o.color_matrix, o.neutral) {
            (Some(cm), Some(n)) => Some(DngColor {
                calibrations: vec![DngCalibration {
                    color_matrix: ColorMatrix {
                        m: [
                            [cm[0], cm[1], cm[2]],
                            [cm[3], cm[4], cm[5]],
                            [cm[6], cm[7], cm[8]],
                        ],
                    },
                    forward_matrix: None,
                    cct_k: 6504.0,
                }],
                analog_balance: [1.0; 3],
                neutral: n,
            }),
            (None, None) => None,
            _ => {
                return Err(CliError::input(
                    input,
                    "--color-matrix and --neutral go together",
                ))
            }
        };
        (m, cfa, black, white, color)
    };
    // 2. demosaic (+ optional denoise)
    let mut planes = demosaic_planes(&mosaic, o.demosaic)
        .map_err(|e| CliError::input(input, format!("demosaic {}: {e}", o.demosaic.name())))?;
    if let Some(b) = &o.denoise {
        b.apply(&mut planes);
    }
    let mut rgb: RgbImage = planes.rgb().ok_or_else(|| {
        CliError::input(
            input,
            format!(
                "the CFA has channels {:?}; develop renders r, g, b mosaics",
                planes.names
            ),
        )
    })?;
    // 3. white balance + colour
    let rendering = match &color {
        Some(c) => {
            Some(dng_camera_to_srgb_with(c, o.adaptation).map_err(|e| CliError::input(input, e))?)
        }
        None => None,
    };
    let gains: [f64; 3] = match (o.balance, &rendering, o.neutral) {
        (DevelopBalance::AsShot, Some(r), _) => r.gains,
        (DevelopBalance::AsShot, None, Some(n)) => {
            let mx = n.iter().cloned().fold(0.0, f64::max);
            n.map(|x| mx / x)
        }
        (DevelopBalance::AsShot, None, None) | (DevelopBalance::GreyWorld, _, _) => {
            let g = ChannelBalance::GreyWorld
                .gains(&planes)
                .map_err(|e| CliError::input(input, e))?;
            let idx = rgb_order(&planes.names);
            idx.map(|k| g[k])
        }
        (DevelopBalance::WhitePatch, _, _) => {
            let g = ChannelBalance::WhitePatch
                .gains(&planes)
                .map_err(|e| CliError::input(input, e))?;
            let idx = rgb_order(&planes.names);
            idx.map(|k| g[k])
        }
        (DevelopBalance::None, _, _) => [1.0; 3],
    };
    // the smallest gain is 1 (dcraw/LibRaw): no channel is darkened before the clip
    let gmin = gains.iter().cloned().fold(f64::INFINITY, f64::min);
    let gains = gains.map(|g| g / gmin);
    let clip = o.highlight_clip;
    rgb.data.iter_mut().for_each(|p| {
        for k in 0..3 {
            let v = p[k] as f64 * gains[k];
            p[k] = if clip { v.min(1.0) as f32 } else { v as f32 };
        }
    });
    let matrix = rendering
        .as_ref()
        .map(|r| r.matrix)
        .unwrap_or_else(ColorMatrix::identity);
    if matrix != ColorMatrix::identity() {
        matrix.apply_image(&mut rgb);
    }
    o.tone.apply(&mut rgb);
    // 4. write atomically
    let bytes = if o.output_bits == 16 {
        encode_png16(&to_srgb16(&rgb), rgb.rows, rgb.cols)
    } else {
        encode_png8(&to_srgb8(&rgb), rgb.rows, rgb.cols)
    }
    .map_err(|e| CliError::output(out, e))?;
    let dir = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if !dir.is_dir() {
        return Err(CliError::output(
            out,
            format!("folder {} does not exist", dir.display()),
        ));
    }
    let tmp: PathBuf = dir.join(format!(
        ".{}.camsim-tmp-{}",
        out.file_name().and_then(|n| n.to_str()).unwrap_or("image"),
        std::process::id()
    ));
    std::fs::write(&tmp, &bytes).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        CliError::output(out, e)
    })?;
    std::fs::rename(&tmp, out).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        CliError::output(out, e)
    })?;
    Ok(DevelopSummary {
        rows: rgb.rows,
        cols: rgb.cols,
        cfa,
        black_dn,
        white_dn,
        gains,
        matrix,
        color_source: match &rendering {
            Some(r) if r.used_forward_matrix => "ForwardMatrix (DNG)".into(),
            Some(_) if ext == "dng" => "ColorMatrix (DNG)".into(),
            Some(_) => "--color-matrix".into(),
            None => "none: camera RGB, not colorimetric".into(),
        },
        white_cct_k: rendering.map(|r| r.white_cct_k),
    })
}

fn rgb_order(names: &[String]) -> [usize; 3] {
    let f = |n: &str| names.iter().position(|x| x == n).unwrap_or(0);
    [f("r"), f("g"), f("b")]
}

fn encode_png8(data: &[u8], rows: usize, cols: usize) -> Result<Vec<u8>, String> {
    let mut buf = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut buf, cols as u32, rows as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header().map_err(|e| e.to_string())?;
        w.write_image_data(data).map_err(|e| e.to_string())?;
        w.finish().map_err(|e| e.to_string())?;
    }
    Ok(buf)
}

fn encode_png16(data: &[u16], rows: usize, cols: usize) -> Result<Vec<u8>, String> {
    let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_be_bytes()).collect();
    let mut buf = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut buf, cols as u32, rows as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Sixteen);
        let mut w = enc.write_header().map_err(|e| e.to_string())?;
        w.write_image_data(&bytes).map_err(|e| e.to_string())?;
        w.finish().map_err(|e| e.to_string())?;
    }
    Ok(buf)
}

fn numbers<const N: usize>(what: &str, s: &str) -> Result<[f64; N], CliError> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            CliError::Other(format!(
                "{what} \"{s}\": expected {N} comma-separated numbers"
            ))
        })?;
    if v.len() != N || v.iter().any(|x| !x.is_finite()) {
        return Err(CliError::Other(format!(
            "{what} \"{s}\": expected {N} finite comma-separated numbers, got {}",
            v.len()
        )));
    }
    let mut a = [0.0; N];
    a.copy_from_slice(&v);
    Ok(a)
}

/// Options from the command line's strings (each error names the option).
#[allow(clippy::too_many_arguments)]
pub fn options_from_args(
    demosaic: &str,
    white_balance: &str,
    bits: u32,
    tone: &str,
    denoise: Option<&str>,
    highlight_clip: bool,
    layout: Option<String>,
    color_matrix: Option<&str>,
    neutral: Option<&str>,
    adaptation: &str,
) -> Result<DevelopOptions, CliError> {
    let adaptation = match adaptation {
        "bradford" => WhiteAdaptation::Bradford,
        "camera" => WhiteAdaptation::CameraSpace,
        a => {
            return Err(CliError::Other(format!(
                "--adaptation {a}: expected bradford (DNG specification) or camera (dcraw/LibRaw)"
            )))
        }
    };
    let demosaic = demosaic
        .parse()
        .map_err(|e| CliError::Other(format!("--demosaic: {e}")))?;
    let balance = white_balance
        .parse()
        .map_err(|e| CliError::Other(format!("--white-balance: {e}")))?;
    let tone = ToneCurve::parse(tone, None).map_err(|e| CliError::Other(format!("--tone: {e}")))?;
    let denoise = match denoise {
        None => None,
        Some(d) => {
            let [s, r] =
                numbers::<2>("--denoise", &d.replace("inf", "Infinity")).or_else(|_| {
                    let p: Vec<&str> = d.split(',').collect();
                    if p.len() == 2 && p[1].trim() == "inf" {
                        Ok([
                            p[0].trim().parse().map_err(|_| {
                                CliError::Other(format!(
                                    "--denoise \"{d}\": expected SIGMA_PX,SIGMA_RANGE"
                                ))
                            })?,
                            f64::INFINITY,
                        ])
                    } else {
                        Err(CliError::Other(format!(
                            "--denoise \"{d}\": expected SIGMA_PX,SIGMA_RANGE"
                        )))
                    }
                })?;
            Some(Bilateral::new(s, r).map_err(|e| CliError::Other(format!("--denoise: {e}")))?)
        }
    };
    Ok(DevelopOptions {
        demosaic,
        balance,
        output_bits: bits,
        tone,
        denoise,
        highlight_clip,
        adaptation,
        layout,
        color_matrix: color_matrix
            .map(|s| numbers::<9>("--color-matrix", s))
            .transpose()?,
        neutral: neutral.map(|s| numbers::<3>("--neutral", s)).transpose()?,
    })
}
