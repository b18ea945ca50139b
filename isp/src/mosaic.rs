//! The linear mosaic handed to the image processor, and linear RGB images.
use crate::IspError;
use camsim_core::RawFrame;

/// A single-plane colour-filter-array image of linear signal (one value per pixel).
///
/// The CFA tile repeats from pixel (0, 0): pixel (r, c) carries channel
/// `tile[r % tile_rows][c % tile_cols]`, whose name is `channel_names[channel]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Mosaic {
    /// Rows (y, top to bottom).
    pub rows: usize,
    /// Columns (x, left to right).
    pub cols: usize,
    /// `rows × cols` linear values, row-major.
    pub data: Vec<f32>,
    /// Channel index per tile position, row-major (`tile[r][c]`).
    pub tile: Vec<Vec<usize>>,
    /// Channel names (index = channel index of the tile), e.g. `["r", "g", "b"]`.
    pub channel_names: Vec<String>,
}

/// A linear RGB image (channel order R, G, B), row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbImage {
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// `rows × cols` pixels, row-major.
    pub data: Vec<[f32; 3]>,
}

impl RgbImage {
    /// An image filled with one colour.
    pub fn filled(rows: usize, cols: usize, rgb: [f32; 3]) -> Self {
        RgbImage {
            rows,
            cols,
            data: vec![rgb; rows * cols],
        }
    }
    /// Pixel (row, col).
    #[inline]
    pub fn at(&self, row: usize, col: usize) -> [f32; 3] {
        self.data[row * self.cols + col]
    }
    /// Largest channel value over the image.
    pub fn max_value(&self) -> f32 {
        self.data
            .iter()
            .flatten()
            .copied()
            .fold(f32::NEG_INFINITY, f32::max)
    }
}

/// Which 2×2 tile positions hold red and blue in an RGB Bayer mosaic (the two greens are on
/// the other diagonal), and the channel index of each colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BayerLayout {
    /// Tile position (row, col) of red.
    pub red_pos: (usize, usize),
    /// Tile position (row, col) of blue.
    pub blue_pos: (usize, usize),
    /// Channel index of red, green, blue in the mosaic.
    pub channel_of: [usize; 3],
}

impl BayerLayout {
    /// The conventional name of the layout ("RGGB", "GRBG", "GBRG" or "BGGR").
    pub fn name(&self) -> &'static str {
        match self.red_pos {
            (0, 0) => "RGGB",
            (0, 1) => "GRBG",
            (1, 0) => "GBRG",
            _ => "BGGR",
        }
    }
}

/// Index 0/1/2 of a channel named red/green/blue (case-insensitive `r`, `red`, …).
pub(crate) fn rgb_index_of_name(name: &str) -> Option<usize> {
    match name.trim().to_ascii_lowercase().as_str() {
        "r" | "red" => Some(0),
        "g" | "green" => Some(1),
        "b" | "blue" => Some(2),
        _ => None,
    }
}

impl Mosaic {
    /// A validated mosaic.
    pub fn new(
        rows: usize,
        cols: usize,
        data: Vec<f32>,
        tile: Vec<Vec<usize>>,
        channel_names: Vec<String>,
    ) -> Result<Self, IspError> {
        if rows == 0 || cols == 0 {
            return Err(IspError::InvalidMosaic(format!(
                "empty image {rows}×{cols}"
            )));
        }
        if data.len() != rows * cols {
            return Err(IspError::InvalidMosaic(format!(
                "{} values for a {rows}×{cols} image",
                data.len()
            )));
        }
        let tc = tile.first().map_or(0, |r| r.len());
        if tile.is_empty() || tc == 0 {
            return Err(IspError::InvalidMosaic("empty CFA tile".into()));
        }
        if let Some(r) = tile.iter().position(|r| r.len() != tc) {
            return Err(IspError::InvalidMosaic(format!(
                "CFA tile row {r} has {} entries, row 0 has {tc}",
                tile[r].len()
            )));
        }
        for (r, row) in tile.iter().enumerate() {
            for (c, &ch) in row.iter().enumerate() {
                if ch >= channel_names.len() {
                    return Err(IspError::InvalidMosaic(format!(
                        "tile[{r}][{c}] = {ch} but there are {} channel names",
                        channel_names.len()
                    )));
                }
            }
        }
        if let Some(i) = data.iter().position(|v| !v.is_finite()) {
            return Err(IspError::InvalidMosaic(format!(
                "pixel {i} (row {}, col {}) = {} is not finite",
                i / cols,
                i % cols,
                data[i]
            )));
        }
        Ok(Mosaic {
            rows,
            cols,
            data,
            tile,
            channel_names,
        })
    }

    /// Subtract the black level and divide by the usable range, so that `black_level_dn` maps
    /// to 0 and `white_dn` (normally `2^bits − 1`) to 1. Values below black stay negative
    /// (read noise is symmetric; clipping would bias dark means).
    pub fn from_raw(
        raw: &RawFrame,
        tile: Vec<Vec<usize>>,
        channel_names: Vec<String>,
        black_level_dn: f64,
        white_dn: f64,
    ) -> Result<Self, IspError> {
        if !(white_dn.is_finite() && black_level_dn.is_finite() && white_dn > black_level_dn) {
            return Err(IspError::InvalidParameter {
                name: "white_dn".into(),
                value: format!("{white_dn}"),
                reason: format!("must be finite and above black_level_dn = {black_level_dn}"),
            });
        }
        if raw.dn.len() != raw.rows * raw.cols {
            return Err(IspError::InvalidMosaic(format!(
                "raw frame has {} values for {}×{}",
                raw.dn.len(),
                raw.rows,
                raw.cols
            )));
        }
        let scale = 1.0 / (white_dn - black_level_dn);
        let data = raw
            .dn
            .iter()
            .map(|&d| ((d as f64 - black_level_dn) * scale) as f32)
            .collect();
        Mosaic::new(raw.rows, raw.cols, data, tile, channel_names)
    }

    /// [`Mosaic::from_raw`] with the layout the frame carries (CFA tile, channel names,
    /// black and white level); an error when it carries none (a bare PNG/TIFF/raw read
    /// without its camera).
    pub fn from_frame(raw: &RawFrame) -> Result<Self, IspError> {
        let l = raw.layout.as_ref().ok_or_else(|| {
            IspError::InvalidMosaic(
                "the raw frame carries no layout (CFA tile, black and white level); give its camera"
                    .into(),
            )
        })?;
        Mosaic::from_raw(
            raw,
            l.cfa_tile.clone(),
            l.channel_names.clone(),
            l.black_dn,
            l.white_dn,
        )
    }

    /// Sample an RGB image through a CFA whose channels are named r/g/b (used to simulate a
    /// mosaic from a full-colour reference, e.g. in demosaic tests).
    pub fn sample_rgb(
        img: &RgbImage,
        tile: Vec<Vec<usize>>,
        channel_names: Vec<String>,
    ) -> Result<Self, IspError> {
        let idx: Vec<usize> = channel_names
            .iter()
            .map(|n| {
                rgb_index_of_name(n).ok_or_else(|| {
                    IspError::InvalidMosaic(format!("channel name '{n}' is not r, g or b"))
                })
            })
            .collect::<Result<_, _>>()?;
        let probe = Mosaic::new(1, 1, vec![0.0], tile.clone(), channel_names.clone())?;
        let data = (0..img.rows * img.cols)
            .map(|i| img.data[i][idx[probe.channel_at(i / img.cols, i % img.cols)]])
            .collect();
        Mosaic::new(img.rows, img.cols, data, tile, channel_names)
    }

    /// Tile rows.
    pub fn tile_rows(&self) -> usize {
        self.tile.len()
    }

    /// Tile columns.
    pub fn tile_cols(&self) -> usize {
        self.tile[0].len()
    }

    /// Channel index of pixel (row, col).
    #[inline]
    pub fn channel_at(&self, row: usize, col: usize) -> usize {
        let t = &self.tile[row % self.tile.len()];
        t[col % t.len()]
    }

    /// Value at (row, col).
    #[inline]
    pub fn at(&self, row: usize, col: usize) -> f32 {
        self.data[row * self.cols + col]
    }

    /// For each of R, G, B the channel index whose name is r/g/b. Errors when a colour is
    /// missing or named twice.
    pub fn rgb_channels(&self) -> Result<[usize; 3], String> {
        let mut out = [usize::MAX; 3];
        for (ch, n) in self.channel_names.iter().enumerate() {
            if let Some(k) = rgb_index_of_name(n) {
                if out[k] != usize::MAX {
                    return Err(format!("two channels are named '{n}'"));
                }
                out[k] = ch;
            }
        }
        if let Some(k) = out.iter().position(|&c| c == usize::MAX) {
            return Err(format!(
                "no channel named '{}' among {:?}",
                ["r", "g", "b"][k],
                self.channel_names
            ));
        }
        Ok(out)
    }

    /// The Bayer layout of a 2×2 RGB tile: one red, one blue and two greens on a diagonal.
    pub fn bayer_layout(&self) -> Result<BayerLayout, String> {
        if self.tile_rows() != 2 || self.tile_cols() != 2 {
            return Err(format!("tile is {}×{}", self.tile_rows(), self.tile_cols()));
        }
        let ch = self.rgb_channels()?;
        let mut red = None;
        let mut blue = None;
        let mut greens = vec![];
        for r in 0..2 {
            for c in 0..2 {
                let k = self.tile[r][c];
                if k == ch[0] {
                    red = red.map_or(Some((r, c)), |_| Some((9, 9)));
                } else if k == ch[2] {
                    blue = blue.map_or(Some((r, c)), |_| Some((9, 9)));
                } else if k == ch[1] {
                    greens.push((r, c));
                } else {
                    return Err(format!(
                        "tile[{r}][{c}] is channel '{}', not r, g or b",
                        self.channel_names[k]
                    ));
                }
            }
        }
        match (red, blue, greens.len()) {
            (Some(rp), Some(bp), 2)
                if rp != (9, 9) && bp != (9, 9) && rp.0 != bp.0 && rp.1 != bp.1 =>
            {
                Ok(BayerLayout {
                    red_pos: rp,
                    blue_pos: bp,
                    channel_of: ch,
                })
            }
            _ => Err(format!(
                "tile {:?} with channels {:?} is not one r, one b and two diagonal g",
                self.tile, self.channel_names
            )),
        }
    }
}
