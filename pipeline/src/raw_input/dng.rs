//! DNG mosaics (Adobe Digital Negative 1.x, a TIFF): the raw CFA image of IFD 0 or of one of
//! its SubIFDs, read with a minimal TIFF 6.0 directory parser (classic TIFF, either byte
//! order; the `tiff` crate's decoder refuses the CFA PhotometricInterpretation 32803) — no
//! LGPL/AGPL dependency.
//!
//! Supported: uncompressed (`Compression` = 1) CFA images (`PhotometricInterpretation` =
//! 32803), 8- or 16-bit samples, strips or tiles, either byte order. The frame returned is the
//! `ActiveArea` (DN as stored: the black level is *not* subtracted); `CFARepeatPatternDim` /
//! `CFAPattern`, `BlackLevelRepeatDim` / `BlackLevel` / `BlackLevelDeltaH` / `BlackLevelDeltaV`
//! and `WhiteLevel` are reported in [`DngInfo`], with their patterns' origin at the active
//! area's top-left corner (DNG spec). Compressed DNG (lossless JPEG, deflate, …) is not
//! supported: convert with Adobe DNG Converter's "uncompressed" option.
use crate::error::CliError;
use camsim_core::RawFrame;
use std::path::Path;

/// DNG / TIFF-EP tag numbers used here.
pub mod tags {
    /// NewSubFileType (0 = main image, 1 = reduced resolution preview).
    pub const NEW_SUBFILE_TYPE: u16 = 254;
    /// CFARepeatPatternDim (rows, cols).
    pub const CFA_REPEAT_PATTERN_DIM: u16 = 33421;
    /// CFAPattern (colour codes, row-major).
    pub const CFA_PATTERN: u16 = 33422;
    /// DNGVersion.
    pub const DNG_VERSION: u16 = 50706;
    /// UniqueCameraModel.
    pub const UNIQUE_CAMERA_MODEL: u16 = 50708;
    /// CFAPlaneColor.
    pub const CFA_PLANE_COLOR: u16 = 50710;
    /// CFALayout (1 = rectangular).
    pub const CFA_LAYOUT: u16 = 50711;
    /// BlackLevelRepeatDim (rows, cols).
    pub const BLACK_LEVEL_REPEAT_DIM: u16 = 50713;
    /// BlackLevel.
    pub const BLACK_LEVEL: u16 = 50714;
    /// BlackLevelDeltaH (per column of the active area).
    pub const BLACK_LEVEL_DELTA_H: u16 = 50715;
    /// BlackLevelDeltaV (per row of the active area).
    pub const BLACK_LEVEL_DELTA_V: u16 = 50716;
    /// WhiteLevel.
    pub const WHITE_LEVEL: u16 = 50717;
    /// ActiveArea (top, left, bottom, right).
    pub const ACTIVE_AREA: u16 = 50829;
    /// PhotometricInterpretation value of a CFA image.
    pub const PHOTOMETRIC_CFA: u16 = 32803;
    /// PhotometricInterpretation value of a demosaicked "linear raw" image.
    pub const PHOTOMETRIC_LINEAR_RAW: u16 = 34892;
}

/// What a DNG says about its mosaic.
#[derive(Debug, Clone, PartialEq)]
pub struct DngInfo {
    /// Which directory held the raw image (`"IFD0"` or `"IFD0 SubIFD[k]"`).
    pub ifd: String,
    /// Stored image rows × columns (before the active-area crop).
    pub stored_rows: usize,
    /// Stored columns.
    pub stored_cols: usize,
    /// ActiveArea (top, left, bottom, right); the whole image when absent.
    pub active_area: [usize; 4],
    /// Bits per stored sample.
    pub bits_per_sample: u16,
    /// CFA tile from the active area's top-left, one string per row, camsim letters
    /// (r, g, b, c, m, y, w for DNG codes 0–6).
    pub cfa: Vec<String>,
    /// Black level repeat cell (rows, cols).
    pub black_repeat: (usize, usize),
    /// Black level per cell position, row-major (DN).
    pub black_level_dn: Vec<f64>,
    /// BlackLevelDeltaH per active-area column (empty when absent).
    pub black_delta_h: Vec<f64>,
    /// BlackLevelDeltaV per active-area row (empty when absent).
    pub black_delta_v: Vec<f64>,
    /// WhiteLevel (DN); 2^bits − 1 when absent.
    pub white_level: u32,
}

/// The frame's layout when the DNG stores one black level for every pixel (no repeat cell
/// variation, no row/column deltas); `None` otherwise (use [`DngInfo::black_level_at`]).
/// Channel indices follow the letters' first appearance in the tile, row-major.
fn frame_layout(
    cfa: &[String],
    black: &[f64],
    delta_h: &[f64],
    delta_v: &[f64],
    white: f64,
) -> Option<camsim_core::RawLayout> {
    let b0 = *black.first()?;
    if black.iter().any(|&b| b != b0) || delta_h.iter().chain(delta_v).any(|&d| d != 0.0) {
        return None;
    }
    let mut names: Vec<String> = Vec::new();
    let cfa_tile = cfa
        .iter()
        .map(|row| {
            row.chars()
                .map(|ch| {
                    let n = ch.to_string();
                    names.iter().position(|x| *x == n).unwrap_or_else(|| {
                        names.push(n);
                        names.len() - 1
                    })
                })
                .collect()
        })
        .collect();
    Some(camsim_core::RawLayout {
        cfa_tile,
        channel_names: names,
        black_dn: b0,
        white_dn: white,
    })
}

impl DngInfo {
    /// Black level (DN) at active-area pixel (row, col): the repeat cell plus the deltas.
    pub fn black_level_at(&self, row: usize, col: usize) -> f64 {
        let (br, bc) = self.black_repeat;
        self.black_level_dn[(row % br) * bc + col % bc]
            + self.black_delta_v.get(row).copied().unwrap_or(0.0)
            + self.black_delta_h.get(col).copied().unwrap_or(0.0)
    }
    /// Mean black level over the active area (DN).
    pub fn mean_black_level_dn(&self) -> f64 {
        let cell = self.black_level_dn.iter().sum::<f64>() / self.black_level_dn.len() as f64;
        let mean = |v: &[f64]| {
            if v.is_empty() {
                0.0
            } else {
                v.iter().sum::<f64>() / v.len() as f64
            }
        };
        cell + mean(&self.black_delta_h) + mean(&self.black_delta_v)
    }
}

/// A DNG's active-area mosaic and its metadata.
#[derive(Debug, Clone, PartialEq)]
pub struct DngFrame {
    /// The active area, DN as stored; `adc_bits` = the bits needed for the WhiteLevel.
    pub frame: RawFrame,
    /// Metadata.
    pub info: DngInfo,
    /// Every numeric tag of IFD0 and of the raw image's directory (the latter wins), e.g. the
    /// colour tags ColorMatrix1 (50721) or AsShotNeutral (50728), for `camsim develop`.
    pub tags: std::collections::BTreeMap<u16, Vec<f64>>,
}

/// camsim letter of a DNG CFA colour code.
pub fn cfa_letter(code: u8) -> Option<char> {
    ['r', 'g', 'b', 'c', 'm', 'y', 'w']
        .get(code as usize)
        .copied()
}

fn tag_name(t: u16) -> &'static str {
    use tags::*;
    match t {
        254 => "NewSubFileType",
        256 => "ImageWidth",
        257 => "ImageLength",
        258 => "BitsPerSample",
        259 => "Compression",
        262 => "PhotometricInterpretation",
        273 => "StripOffsets",
        277 => "SamplesPerPixel",
        278 => "RowsPerStrip",
        279 => "StripByteCounts",
        322 => "TileWidth",
        323 => "TileLength",
        324 => "TileOffsets",
        325 => "TileByteCounts",
        330 => "SubIFDs",
        CFA_REPEAT_PATTERN_DIM => "CFARepeatPatternDim",
        CFA_PATTERN => "CFAPattern",
        CFA_LAYOUT => "CFALayout",
        CFA_PLANE_COLOR => "CFAPlaneColor",
        BLACK_LEVEL_REPEAT_DIM => "BlackLevelRepeatDim",
        BLACK_LEVEL => "BlackLevel",
        BLACK_LEVEL_DELTA_H => "BlackLevelDeltaH",
        BLACK_LEVEL_DELTA_V => "BlackLevelDeltaV",
        WHITE_LEVEL => "WhiteLevel",
        ACTIVE_AREA => "ActiveArea",
        _ => "tag",
    }
}

/// Tags of one directory, read into numbers.
struct Dir {
    name: String,
    values: std::collections::BTreeMap<u16, Vec<f64>>,
}

impl Dir {
    fn get(&self, t: u16) -> Option<&Vec<f64>> {
        self.values.get(&t)
    }
    fn one(&self, t: u16) -> Option<f64> {
        self.get(t).and_then(|v| v.first().copied())
    }
}

/// A classic TIFF in memory (TIFF 6.0 §2: header, IFDs of 12-byte entries).
struct Tiff<'a> {
    bytes: &'a [u8],
    little: bool,
}

impl Tiff<'_> {
    fn u16_at(&self, off: usize) -> Option<u16> {
        let b = self.bytes.get(off..off + 2)?;
        Some(if self.little {
            u16::from_le_bytes([b[0], b[1]])
        } else {
            u16::from_be_bytes([b[0], b[1]])
        })
    }
    fn u32_at(&self, off: usize) -> Option<u32> {
        let b = self.bytes.get(off..off + 4)?;
        let a = [b[0], b[1], b[2], b[3]];
        Some(if self.little {
            u32::from_le_bytes(a)
        } else {
            u32::from_be_bytes(a)
        })
    }
    fn u64_at(&self, off: usize) -> Option<u64> {
        let b = self.bytes.get(off..off + 8)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Some(if self.little {
            u64::from_le_bytes(a)
        } else {
            u64::from_be_bytes(a)
        })
    }
    /// One value of TIFF type `ty` at `off` as a number (None for ASCII/unknown types).
    fn value(&self, ty: u16, off: usize) -> Option<f64> {
        Some(match ty {
            1 | 7 => *self.bytes.get(off)? as f64,
            6 => *self.bytes.get(off)? as i8 as f64,
            3 => self.u16_at(off)? as f64,
            8 => self.u16_at(off)? as i16 as f64,
            4 | 13 => self.u32_at(off)? as f64,
            9 => self.u32_at(off)? as i32 as f64,
            5 => {
                let d = self.u32_at(off + 4)?;
                if d == 0 {
                    return None;
                }
                self.u32_at(off)? as f64 / d as f64
            }
            10 => {
                let d = self.u32_at(off + 4)? as i32;
                if d == 0 {
                    return None;
                }
                self.u32_at(off)? as i32 as f64 / d as f64
            }
            11 => f32::from_bits(self.u32_at(off)?) as f64,
            12 => f64::from_bits(self.u64_at(off)?),
            _ => return None,
        })
    }
    /// The numeric tags of the directory at `off`.
    fn dir(&self, off: usize, name: String) -> Result<Dir, String> {
        let n = self.u16_at(off).ok_or_else(|| {
            format!(
                "{name}: directory offset {off} is beyond the file's {} bytes",
                self.bytes.len()
            )
        })? as usize;
        if off + 2 + 12 * n + 4 > self.bytes.len() {
            return Err(format!(
                "{name}: directory of {n} entries at byte {off} runs past the end of the file ({} bytes): truncated?",
                self.bytes.len()
            ));
        }
        let mut values = std::collections::BTreeMap::new();
        for k in 0..n {
            let e = off + 2 + 12 * k;
            let (tag, ty) = (self.u16_at(e).unwrap_or(0), self.u16_at(e + 2).unwrap_or(0));
            let count = self.u32_at(e + 4).unwrap_or(0) as usize;
            let size = match ty {
                1 | 2 | 6 | 7 => 1,
                3 | 8 => 2,
                4 | 9 | 11 | 13 => 4,
                5 | 10 | 12 => 8,
                _ => continue, // unknown types may be skipped (TIFF 6.0 §2)
            };
            if ty == 2 {
                continue;
            }
            let total = count
                .checked_mul(size)
                .filter(|&t| t <= self.bytes.len())
                .ok_or_else(|| {
                    format!(
                        "{name}: {} ({tag}) has {count} values, more than the file holds",
                        tag_name(tag)
                    )
                })?;
            let at = if total <= 4 {
                e + 8
            } else {
                self.u32_at(e + 8).unwrap_or(0) as usize
            };
            if at + total > self.bytes.len() {
                return Err(format!(
                    "{name}: {} ({tag}) points to bytes {at}..{} beyond the file's {}",
                    tag_name(tag),
                    at + total,
                    self.bytes.len()
                ));
            }
            let v: Option<Vec<f64>> = (0..count).map(|i| self.value(ty, at + i * size)).collect();
            if let Some(v) = v {
                values.insert(tag, v);
            }
        }
        Ok(Dir { name, values })
    }
}

/// Read the raw CFA image of a DNG (see the module documentation for what is supported).
/// Errors name the file, the directory and the tag.
pub fn read_dng(path: &Path) -> Result<DngFrame, CliError> {
    crate::staging::protect_input(path);
    let err = |m: String| CliError::input(path, m);
    let bytes = std::fs::read(path).map_err(|e| err(format!("cannot open frame: {e}")))?;
    let little = match bytes.get(0..4) {
        Some([b'I', b'I', 42, 0]) => true,
        Some([b'M', b'M', 0, 42]) => false,
        Some([b'I', b'I', 43, 0]) | Some([b'M', b'M', 0, 43]) => {
            return Err(err(
                "not a readable DNG/TIFF: BigTIFF is not supported (DNG is classic TIFF)".into(),
            ))
        }
        _ => {
            return Err(err(
                "not a readable DNG/TIFF: no TIFF header (\"II*\\0\" or \"MM\\0*\")".into(),
            ))
        }
    };
    let tiff = Tiff {
        bytes: &bytes,
        little,
    };
    let ifd0 = tiff.u32_at(4).unwrap_or(0) as usize;
    let d0 = tiff
        .dir(ifd0, "IFD0".into())
        .map_err(|m| err(format!("not a readable DNG/TIFF: {m}")))?;
    if d0.get(tags::DNG_VERSION).is_none() {
        return Err(err("IFD0 has no DNGVersion tag (50706): not a DNG".into()));
    }
    let subs: Vec<usize> = d0
        .get(330)
        .map(|v| v.iter().map(|&x| x as usize).collect())
        .unwrap_or_default();
    let mut dirs = vec![d0];
    for (k, p) in subs.into_iter().enumerate() {
        dirs.push(
            tiff.dir(p, format!("IFD0 SubIFD[{k}]"))
                .map_err(|m| err(format!("not a readable DNG/TIFF: {m}")))?,
        );
    }
    // the full-resolution CFA image: NewSubFileType 0 (absent = 0), Photometric 32803
    let is_main = |d: &Dir| d.one(tags::NEW_SUBFILE_TYPE).unwrap_or(0.0) == 0.0;
    let Some(d) = dirs
        .iter()
        .find(|d| is_main(d) && d.one(262) == Some(tags::PHOTOMETRIC_CFA as f64))
    else {
        let linear = dirs
            .iter()
            .any(|d| d.one(262) == Some(tags::PHOTOMETRIC_LINEAR_RAW as f64));
        return Err(err(if linear {
            "the DNG holds a demosaicked LinearRaw image (PhotometricInterpretation 34892), not a CFA mosaic: not supported".into()
        } else {
            format!(
                "no full-resolution CFA image (NewSubFileType 0, PhotometricInterpretation 32803) in {}",
                dirs.iter().map(|d| d.name.as_str()).collect::<Vec<_>>().join(", ")
            )
        }));
    };
    let need = |t: u16| -> Result<&Vec<f64>, CliError> {
        d.get(t)
            .ok_or_else(|| err(format!("{}: {} ({t}) is missing", d.name, tag_name(t))))
    };
    let bad = |t: u16, what: String| err(format!("{}: {} ({t}) {what}", d.name, tag_name(t)));
    let compression = d.one(259).unwrap_or(1.0);
    if compression != 1.0 {
        return Err(bad(
            259,
            format!(
                "= {compression}{}: compressed DNG not supported (only Compression = 1, uncompressed; re-save with Adobe DNG Converter's uncompressed option)",
                match compression as u32 {
                    7 => " (lossless JPEG)",
                    8 => " (deflate)",
                    34892 => " (lossy JPEG)",
                    52546 => " (JPEG XL)",
                    _ => "",
                }
            ),
        ));
    }
    let cols = need(256)?[0] as usize;
    let rows = need(257)?[0] as usize;
    let spp = d.one(277).unwrap_or(1.0);
    if spp != 1.0 {
        return Err(bad(
            277,
            format!("= {spp}; a CFA image has 1 sample per pixel"),
        ));
    }
    let bits = d.get(258).and_then(|v| v.first().copied()).unwrap_or(1.0) as u16;
    if bits != 8 && bits != 16 {
        return Err(bad(
            258,
            format!("= {bits}: only 8- and 16-bit samples are supported"),
        ));
    }
    if let Some(l) = d.one(tags::CFA_LAYOUT) {
        if l != 1.0 {
            return Err(bad(
                tags::CFA_LAYOUT,
                format!("= {l}: only rectangular CFAs (1) are supported"),
            ));
        }
    }
    // CFA
    let dim = need(tags::CFA_REPEAT_PATTERN_DIM)?;
    if dim.len() != 2 || dim[0] < 1.0 || dim[1] < 1.0 {
        return Err(bad(
            tags::CFA_REPEAT_PATTERN_DIM,
            format!("= {dim:?}: expected two positive numbers (rows, cols)"),
        ));
    }
    let (pr, pc) = (dim[0] as usize, dim[1] as usize);
    let pat = need(tags::CFA_PATTERN)?;
    if pat.len() != pr * pc {
        return Err(bad(
            tags::CFA_PATTERN,
            format!(
                "has {} entries but CFARepeatPatternDim is {pr}×{pc}",
                pat.len()
            ),
        ));
    }
    // CFAPattern holds TIFF-EP colour codes; CFAPlaneColor only orders LinearRaw planes.
    let mut cfa = Vec::with_capacity(pr);
    for r in 0..pr {
        let mut row = String::new();
        for c in 0..pc {
            let code = pat[r * pc + c] as u8;
            row.push(cfa_letter(code).ok_or_else(|| {
                bad(
                    tags::CFA_PATTERN,
                    format!("has colour code {code} (known: 0–6 = R, G, B, C, M, Y, W)"),
                )
            })?);
        }
        cfa.push(row);
    }
    // ActiveArea
    let aa = match d.get(tags::ACTIVE_AREA) {
        None => [0, 0, rows, cols],
        Some(v) if v.len() == 4 => [v[0] as usize, v[1] as usize, v[2] as usize, v[3] as usize],
        Some(v) => {
            return Err(bad(
                tags::ACTIVE_AREA,
                format!(
                    "has {} values; expected 4 (top, left, bottom, right)",
                    v.len()
                ),
            ))
        }
    };
    if !(aa[0] < aa[2] && aa[1] < aa[3] && aa[2] <= rows && aa[3] <= cols) {
        return Err(bad(
            tags::ACTIVE_AREA,
            format!("= {aa:?} does not lie inside the {rows}×{cols} image"),
        ));
    }
    let (ar, ac) = (aa[2] - aa[0], aa[3] - aa[1]);
    // black and white levels
    let (br, bc) = match d.get(tags::BLACK_LEVEL_REPEAT_DIM) {
        None => (1, 1),
        Some(v) if v.len() == 2 && v[0] >= 1.0 && v[1] >= 1.0 => (v[0] as usize, v[1] as usize),
        Some(v) => {
            return Err(bad(
                tags::BLACK_LEVEL_REPEAT_DIM,
                format!("= {v:?}: expected two positive numbers"),
            ))
        }
    };
    if br > rows || bc > cols {
        return Err(bad(
            tags::BLACK_LEVEL_REPEAT_DIM,
            format!("= {br}×{bc} is larger than the {rows}×{cols} image"),
        ));
    }
    let black = match d.get(tags::BLACK_LEVEL) {
        None => vec![0.0; br * bc],
        Some(v) if v.len() == br * bc => v.clone(),
        Some(v) if v.len() == 1 => vec![v[0]; br * bc],
        Some(v) => {
            return Err(bad(
                tags::BLACK_LEVEL,
                format!(
                    "has {} values but BlackLevelRepeatDim is {br}×{bc}",
                    v.len()
                ),
            ))
        }
    };
    let delta = |t: u16, n: usize| -> Result<Vec<f64>, CliError> {
        match d.get(t) {
            None => Ok(Vec::new()),
            Some(v) if v.len() == n => Ok(v.clone()),
            Some(v) => Err(bad(
                t,
                format!("has {} values; the active area needs {n}", v.len()),
            )),
        }
    };
    let black_delta_h = delta(tags::BLACK_LEVEL_DELTA_H, ac)?;
    let black_delta_v = delta(tags::BLACK_LEVEL_DELTA_V, ar)?;
    let max_code = ((1u64 << bits) - 1) as f64;
    let white = d.one(tags::WHITE_LEVEL).unwrap_or(max_code);
    if !(white >= 1.0 && white <= max_code) {
        return Err(bad(
            tags::WHITE_LEVEL,
            format!("= {white} is outside 1–{max_code} for {bits}-bit samples"),
        ));
    }
    // sample data: strips or tiles, uncompressed
    let bps = (bits / 8) as usize;
    let file_len = bytes.len() as u64;
    // Checked before allocating: the samples must fit in the file (uncompressed).
    if rows as f64 * cols as f64 * bps.max(1) as f64 > file_len as f64 {
        return Err(bad(
            257,
            format!("= {rows} rows × {cols} columns of {bits}-bit samples do not fit in the {file_len}-byte file"),
        ));
    }
    let mut stored = vec![0u16; rows * cols];
    let read_at = |off: f64, n: usize, t: u16| -> Result<&[u8], CliError> {
        let off = off as u64;
        match off.checked_add(n as u64) {
            Some(end) if end <= file_len => Ok(&bytes[off as usize..end as usize]),
            _ => Err(bad(
                t,
                format!(
                    "points to bytes {off}..{} beyond the file's {file_len}",
                    off + n as u64
                ),
            )),
        }
    };
    let sample = |b: &[u8], i: usize| -> u16 {
        if bps == 1 {
            b[i] as u16
        } else if little {
            u16::from_le_bytes([b[2 * i], b[2 * i + 1]])
        } else {
            u16::from_be_bytes([b[2 * i], b[2 * i + 1]])
        }
    };
    if let Some(offsets) = d.get(324) {
        let tw = need(322)?[0] as usize;
        let tl = need(323)?[0] as usize;
        if tw == 0 || tl == 0 {
            return Err(bad(322, "TileWidth/TileLength must be positive".into()));
        }
        let across = cols.div_ceil(tw);
        let down = rows.div_ceil(tl);
        if offsets.len() != across * down {
            return Err(bad(
                324,
                format!(
                    "has {} tiles; a {rows}×{cols} image in {tl}×{tw} tiles needs {}",
                    offsets.len(),
                    across * down
                ),
            ));
        }
        for (k, &off) in offsets.iter().enumerate() {
            let b = read_at(off, tw * tl * bps, 324)?;
            let (ty, tx) = (k / across * tl, k % across * tw);
            for y in 0..tl.min(rows - ty) {
                for x in 0..tw.min(cols - tx) {
                    stored[(ty + y) * cols + tx + x] = sample(&b, y * tw + x);
                }
            }
        }
    } else {
        let offsets = need(273)?.clone();
        let counts = need(279)?.clone();
        let rps = d
            .one(278)
            .map(|v| v as usize)
            .unwrap_or(rows)
            .clamp(1, rows);
        let n_strips = rows.div_ceil(rps);
        if offsets.len() != n_strips || counts.len() != n_strips {
            return Err(bad(
                273,
                format!(
                    "has {} offsets and {} byte counts; {rows} rows at RowsPerStrip {rps} need {n_strips}",
                    offsets.len(),
                    counts.len()
                ),
            ));
        }
        for (k, &off) in offsets.iter().enumerate() {
            let r0 = k * rps;
            let nr = rps.min(rows - r0);
            let need_bytes = nr * cols * bps;
            if (counts[k] as usize) < need_bytes {
                return Err(bad(
                    279,
                    format!(
                        "strip {k} has {} bytes but {nr} rows × {cols} × {bps} need {need_bytes}",
                        counts[k]
                    ),
                ));
            }
            let b = read_at(off, need_bytes, 273)?;
            for i in 0..nr * cols {
                stored[r0 * cols + i] = sample(&b, i);
            }
        }
    }
    let mut dn = Vec::with_capacity(ar * ac);
    for r in aa[0]..aa[2] {
        dn.extend_from_slice(&stored[r * cols + aa[1]..r * cols + aa[3]]);
    }
    let adc_bits = (64 - (white as u64).leading_zeros()).max(1);
    let mut all_tags = dirs[0].values.clone();
    all_tags.extend(d.values.iter().map(|(k, v)| (*k, v.clone())));
    let layout = frame_layout(&cfa, &black, &black_delta_h, &black_delta_v, white as f64);
    Ok(DngFrame {
        tags: all_tags,
        frame: RawFrame {
            rows: ar,
            cols: ac,
            adc_bits,
            dn,
            layout,
        },
        info: DngInfo {
            ifd: d.name.clone(),
            stored_rows: rows,
            stored_cols: cols,
            active_area: aa,
            bits_per_sample: bits,
            cfa,
            black_repeat: (br, bc),
            black_level_dn: black,
            black_delta_h,
            black_delta_v,
            white_level: white as u32,
        },
    })
}
