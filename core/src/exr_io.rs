//! Spectral OpenEXR in the layout of Fichet, Pacanowski & Wilkie, "An OpenEXR Layout for
//! Spectral Images" (JCGT 10(3), 2021): one channel per wavelength named
//! `S0.<wavelength><unit>` with a comma as decimal mark (`S0.550,000000nm`), header attribute
//! `spectralLayoutVersion = "1.0"`, values per nm in the unit of `emissiveUnits`; depth, where
//! present, in the standard channel `Z` (metres).
//!
//! All writes go to a temporary file in the destination folder that is renamed into place, so
//! a failure never leaves a half-written file.
use crate::constants::PhysicalConstants;
use crate::error::CoreError;
use crate::image::{Plane, SpectralBasis, SpectralImage};
use crate::spectrum::WavelengthGrid;
use exr::prelude::{
    read, AnyChannel, AnyChannels, AttributeValue, Blocks, Compression, Encoding, FlatSamples,
    Image, Layer, LayerAttributes, LineOrder, ReadChannels, ReadLayers, Text, Vec2, WritableImage,
};
use std::path::Path;

/// `emissiveUnits` of radiance, per nm (W·m⁻²·sr⁻¹).
pub const RADIANCE_UNITS: &str = "W.m^-2.sr^-1";
/// `emissiveUnits` of irradiance, per nm (W·m⁻²).
pub const IRRADIANCE_UNITS: &str = "W.m^-2";

/// A spectral EXR read from disk.
#[derive(Debug, Clone)]
pub struct SpectralExr {
    /// Band image (values as stored: energy per nm in `emissive_units`).
    pub image: SpectralImage,
    /// The wavelengths of the bands.
    pub grid: WavelengthGrid,
    /// The `emissiveUnits` attribute (empty when absent).
    pub emissive_units: String,
    /// Depth channel `Z` (m), when present.
    pub depth_m: Option<Plane>,
}

/// Run `write` on a temporary path beside `path`, then rename it into place.
pub fn write_atomically<E: From<std::io::Error>>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), E> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
    let r = crate::cleanup::gated(|| {
        crate::cleanup::register(&tmp);
        match write(&tmp) {
            Ok(()) => std::fs::rename(&tmp, path).map_err(E::from),
            Err(e) => Err(e),
        }
    });
    if r.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    crate::cleanup::unregister(&tmp);
    r
}

/// The encoding of every EXR camsim writes: RLE in 64×64 tiles (as `DETERMINISTIC_ENCODING`)
/// but with the chunks in increasing line order. `FAST_LOSSLESS` leaves the order unspecified,
/// so the parallel compressor writes chunks in completion order and two identical runs give
/// files that differ byte for byte; `Increasing` makes the writer sort them.
pub const DETERMINISTIC_ENCODING: Encoding = Encoding {
    compression: Compression::RLE,
    blocks: Blocks::Tiles(Vec2(64, 64)),
    line_order: LineOrder::Increasing,
};

/// The channel name of a wavelength: `S0.550,000000nm`.
pub fn channel_name(wavelength_nm: f64) -> String {
    format!("S0.{:.6}nm", wavelength_nm)
        .replace('.', ",")
        .replacen("S0,", "S0.", 1)
}

/// Parse `S0.<number><unit>` into a wavelength in nm (None for other channels).
pub fn parse_channel_name(name: &str) -> Option<f64> {
    let rest = name.strip_prefix("S0.")?;
    let units: [(&str, f64); 5] = [
        ("nm", 1.0),
        ("um", 1e3),
        ("pm", 1e-3),
        ("mm", 1e6),
        ("m", 1e9),
    ];
    for (u, k) in units {
        if let Some(num) = rest.strip_suffix(u) {
            return num.replace(',', ".").parse::<f64>().ok().map(|v| v * k);
        }
    }
    None
}

fn exr_err(path: &Path, e: impl std::fmt::Display) -> CoreError {
    CoreError::Exr {
        path: path.display().to_string(),
        msg: e.to_string(),
    }
}

/// One float32 channel of an EXR file: its name and `width × height` samples, row-major.
#[derive(Debug, Clone)]
pub struct ExrChannel {
    /// Channel name (e.g. `S0.550,000000nm`, `Z`, `Y`).
    pub name: String,
    /// Row-major samples.
    pub data: Vec<f32>,
}

impl ExrChannel {
    /// A named channel.
    pub fn new(name: impl Into<String>, data: Vec<f32>) -> Self {
        ExrChannel {
            name: name.into(),
            data,
        }
    }
}

/// The header of an EXR written by [`write_exr_channels`]. It holds at most one custom
/// attribute per attribute table: the `exr` crate keeps custom attributes in a `HashMap`, whose
/// iteration order (and so the header's bytes) changes from process to process.
#[derive(Debug, Clone, Default)]
pub struct ExrHeader {
    /// The layer attribute `emissiveUnits` (Fichet et al.), when set.
    pub emissive_units: Option<String>,
    /// The image attribute `spectralLayoutVersion = "1.0"`.
    pub spectral_layout: bool,
    /// The standard `comments` attribute, when set.
    pub comments: Option<String>,
}

/// The one EXR writer of the workspace: float32 `channels` of `width × height` with `header`,
/// lossless ([`DETERMINISTIC_ENCODING`]: chunks in increasing line order, so the same pixels
/// give the same bytes), written atomically (temporary file + rename); errors as strings for
/// the caller to wrap.
pub fn write_exr_channels(
    path: &Path,
    width: usize,
    height: usize,
    channels: Vec<ExrChannel>,
    header: &ExrHeader,
) -> Result<(), String> {
    let n = width.checked_mul(height).ok_or("image size overflows")?;
    if let Some(c) = channels.iter().find(|c| c.data.len() != n) {
        return Err(format!(
            "channel {} has {} samples, expected {width} x {height}",
            c.name,
            c.data.len()
        ));
    }
    let channels: Vec<AnyChannel<FlatSamples>> = channels
        .into_iter()
        .map(|c| AnyChannel::new(c.name.as_str(), FlatSamples::F32(c.data)))
        .collect();
    let mut attrs = LayerAttributes::default();
    if let Some(u) = &header.emissive_units {
        attrs.other.insert(
            Text::from("emissiveUnits"),
            AttributeValue::Text(Text::from(u.as_str())),
        );
    }
    if let Some(c) = &header.comments {
        attrs.comments = Some(Text::from(c.as_str()));
    }
    let layer = Layer::new(
        (width, height),
        attrs,
        DETERMINISTIC_ENCODING,
        AnyChannels::sort(channels.into_iter().collect()),
    );
    let mut img = Image::from_layer(layer);
    if header.spectral_layout {
        img.attributes.other.insert(
            Text::from("spectralLayoutVersion"),
            AttributeValue::Text(Text::from("1.0")),
        );
    }
    write_atomically(path, |tmp| {
        img.write()
            .to_file(tmp)
            .map_err(|e| std::io::Error::other(e.to_string()))
    })
    .map_err(|e| e.to_string())
}

/// Write a band image (values per nm in `emissive_units`) with optional depth.
pub fn write_spectral_exr(
    path: &Path,
    image: &SpectralImage,
    emissive_units: &str,
    depth_m: Option<&Plane>,
) -> Result<(), CoreError> {
    let grid = match &image.basis {
        SpectralBasis::Bands(g) => g.clone(),
        SpectralBasis::Spectra(_) => {
            return Err(exr_err(
                path,
                "spectral EXR needs a band image (call to_bands first)",
            ))
        }
    };
    let mut channels: Vec<ExrChannel> = grid
        .wavelength_nm
        .iter()
        .zip(&image.planes)
        .map(|(w, p)| ExrChannel::new(channel_name(*w), p.clone()))
        .collect();
    if let Some(d) = depth_m {
        if d.rows != image.rows || d.cols != image.cols {
            return Err(exr_err(path, "depth plane size differs from the image"));
        }
        channels.push(ExrChannel::new("Z", d.data.clone()));
    }
    write_exr_channels(
        path,
        image.cols,
        image.rows,
        channels,
        &ExrHeader {
            emissive_units: Some(emissive_units.to_string()),
            spectral_layout: true,
            comments: None,
        },
    )
    .map_err(|e| exr_err(path, e))
}

/// Write one float32 channel (e.g. `Y`) atomically.
pub fn write_single_channel_exr(
    path: &Path,
    channel: &str,
    plane: &Plane,
) -> Result<(), CoreError> {
    write_exr_channels(
        path,
        plane.cols,
        plane.rows,
        vec![ExrChannel::new(channel, plane.data.clone())],
        &ExrHeader::default(),
    )
    .map_err(|e| exr_err(path, e))
}

/// The most decoded pixel bytes [`read_channels`] and [`read_spectral_exr`] accept (8 GiB);
/// callers with a memory budget check [`exr_decoded_bytes`] against it first.
pub const MAX_DECODED_BYTES: f64 = 8.0 * (1u64 << 30) as f64;

/// The bytes the pixel data of `path` takes once decoded (4 per sample: f32), from its header
/// alone (nothing is allocated for the pixels): Σ over layers of width × height × channels × 4.
pub fn exr_decoded_bytes(path: &Path) -> Result<f64, CoreError> {
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| exr_err(path, e))?;
    Ok(meta
        .headers
        .iter()
        .map(|h| h.layer_size.0 as f64 * h.layer_size.1 as f64 * h.channels.list.len() as f64 * 4.0)
        .sum())
}

/// Read every channel of the first layer: (name, rows, cols, values). A file whose header
/// claims more than [`MAX_DECODED_BYTES`] of pixels is refused before any pixel is allocated.
pub fn read_channels(
    path: &Path,
) -> Result<(usize, usize, Vec<(String, Vec<f32>)>, Vec<(String, String)>), CoreError> {
    read_channels_within(path, MAX_DECODED_BYTES)
}

/// [`read_channels`] with an explicit limit on the decoded pixel bytes.
pub fn read_channels_within(
    path: &Path,
    max_decoded_bytes: f64,
) -> Result<(usize, usize, Vec<(String, Vec<f32>)>, Vec<(String, String)>), CoreError> {
    let need = exr_decoded_bytes(path)?;
    if !(need <= max_decoded_bytes) {
        return Err(exr_err(
            path,
            format!(
                "the header's data windows hold {:.3e} bytes of pixels, over the limit of {:.3e}",
                need, max_decoded_bytes
            ),
        ));
    }
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .from_file(path)
        .map_err(|e| exr_err(path, e))?;
    let layer = image
        .layer_data
        .first()
        .ok_or_else(|| exr_err(path, "no layers"))?;
    let (cols, rows) = (layer.size.0, layer.size.1);
    let chans = layer
        .channel_data
        .list
        .iter()
        .map(|c| {
            (
                c.name.to_string(),
                c.sample_data.values_as_f32().collect::<Vec<f32>>(),
            )
        })
        .collect();
    let mut attrs = Vec::new();
    for (k, v) in image
        .attributes
        .other
        .iter()
        .chain(layer.attributes.other.iter())
    {
        if let AttributeValue::Text(t) = v {
            attrs.push((k.to_string(), t.to_string()));
        }
    }
    Ok((rows, cols, chans, attrs))
}

/// Read a spectral EXR (Fichet 2021 layout).
pub fn read_spectral_exr(path: &Path) -> Result<SpectralExr, CoreError> {
    read_spectral_exr_within(path, MAX_DECODED_BYTES)
}

/// [`read_spectral_exr`] with an explicit limit on the decoded pixel bytes.
pub fn read_spectral_exr_within(
    path: &Path,
    max_decoded_bytes: f64,
) -> Result<SpectralExr, CoreError> {
    let (rows, cols, chans, attrs) = read_channels_within(path, max_decoded_bytes)?;
    let mut bands: Vec<(f64, Vec<f32>)> = Vec::new();
    let mut depth = None;
    for (name, data) in chans {
        if let Some(w) = parse_channel_name(&name) {
            bands.push((w, data));
        } else if name == "Z" {
            depth = Some(Plane { rows, cols, data });
        }
    }
    if bands.is_empty() {
        return Err(exr_err(
            path,
            "no spectral channels named S0.<wavelength>nm (Fichet 2021 layout)",
        ));
    }
    bands.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap());
    let grid =
        WavelengthGrid::new(bands.iter().map(|b| b.0).collect()).map_err(|e| exr_err(path, e))?;
    let planes: Vec<Vec<f32>> = bands.into_iter().map(|b| b.1).collect();
    if let Some((i, v)) = planes.iter().enumerate().find_map(|(i, p)| {
        p.iter()
            .find(|v| !v.is_finite() || **v < 0.0)
            .map(|v| (i, *v))
    }) {
        return Err(exr_err(
            path,
            format!(
                "band {} nm has an invalid radiance {v} (must be finite and ≥ 0)",
                grid.wavelength_nm[i]
            ),
        ));
    }
    let units = attrs
        .iter()
        .find(|(k, _)| k == "emissiveUnits")
        .map(|(_, v)| v.clone())
        .unwrap_or_default();
    let image = SpectralImage::new(rows, cols, SpectralBasis::Bands(grid.clone()), planes)
        .map_err(|e| exr_err(path, e))?;
    Ok(SpectralExr {
        image,
        grid,
        emissive_units: units,
        depth_m: depth,
    })
}

/// Convert a band image between energy (W per …) and photon units, per band: photons = W·λ/(hc).
pub fn bands_energy_to_photons(image: &mut SpectralImage, c: &PhysicalConstants, inverse: bool) {
    if let SpectralBasis::Bands(g) = &image.basis {
        let f: Vec<f32> = g
            .wavelength_nm
            .iter()
            .map(|&w| {
                let k = c.photons_per_joule(w);
                (if inverse { 1.0 / k } else { k }) as f32
            })
            .collect();
        for (p, k) in image.planes.iter_mut().zip(f) {
            p.iter_mut().for_each(|v| *v *= k);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn channel_names_follow_fichet() {
        assert_eq!(channel_name(550.0), "S0.550,000000nm");
        assert_eq!(parse_channel_name("S0.550,000000nm"), Some(550.0));
        assert_eq!(parse_channel_name("S0.0,55um"), Some(550.0));
        assert_eq!(parse_channel_name("R"), None);
    }

    #[test]
    fn roundtrip_with_depth() {
        let dir = tempfile::tempdir().unwrap();
        let g = WavelengthGrid::regular(400.0, 700.0, 100.0).unwrap();
        let planes: Vec<Vec<f32>> = (0..4)
            .map(|b| (0..6).map(|i| (b * 10 + i) as f32).collect())
            .collect();
        let img =
            SpectralImage::new(2, 3, SpectralBasis::Bands(g.clone()), planes.clone()).unwrap();
        let depth = Plane {
            rows: 2,
            cols: 3,
            data: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
        };
        let p = dir.path().join("a.exr");
        write_spectral_exr(&p, &img, RADIANCE_UNITS, Some(&depth)).unwrap();
        let back = read_spectral_exr(&p).unwrap();
        assert_eq!(back.grid, g);
        assert_eq!(back.image.planes, planes);
        assert_eq!(back.depth_m.unwrap().data, depth.data);
        assert_eq!(back.emissive_units, RADIANCE_UNITS);
        // no temporary file left behind
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
