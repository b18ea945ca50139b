//! Render outputs: the spectral OpenEXR (Fichet, Pacanowski & Wilkie, "An OpenEXR Layout for
//! Spectral Images", JCGT 10(3), 2021: channels `S0.<λ>nm` at the band centres holding the
//! band-averaged value, `emissiveUnits`, `spectralLayoutVersion`), the planar depth `Z` (m),
//! optional variance channels `variance.S0.<λ>nm`, and — for the Mitsuba harness — the same
//! data under its names `band_LLLL_HHHH`, `depth.T`, `depth_center.T`; and the in-memory
//! [`SceneRadiance`] (photon units, with depth) that the optics stage takes.
use crate::camera::OutputQuantity;
use crate::error::RenderError;
use crate::integrator::RenderOutput;
use camsim_core::constants::SI;
use camsim_core::exr_io::{channel_name, write_atomically, IRRADIANCE_UNITS, RADIANCE_UNITS};
use camsim_core::image::{Plane, SpectralBasis, SpectralImage};
use camsim_core::spectrum::WavelengthGrid;
use camsim_core::SceneRadiance;
use exr::prelude::{
    AnyChannel, AnyChannels, AttributeValue, FlatSamples, Image, Layer, LayerAttributes,
    Text, WritableImage,
};
use std::path::Path;

/// Which channels to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ExrChannels {
    /// Also write `band_LLLL_HHHH`, `depth.T`, `depth_center.T` (Mitsuba harness names).
    pub mitsuba: bool,
    /// Write `variance.S0.<λ>nm` (and `band_…​.variance` with `mitsuba`) when available.
    pub variance: bool,
}

/// The band-centre wavelength grid of an output.
pub fn band_grid(out: &RenderOutput) -> WavelengthGrid {
    WavelengthGrid::new(
        (0..out.bands.count)
            .map(|b| out.bands.center_nm(b))
            .collect(),
    )
    .expect("band centres increase")
}

/// Write the render as a spectral EXR (atomically: temp file + rename).
pub fn write_exr(path: &Path, out: &RenderOutput, ch: ExrChannels) -> Result<(), RenderError> {
    let mut channels: Vec<AnyChannel<FlatSamples>> = Vec::new();
    for b in 0..out.bands.count {
        let c = out.bands.center_nm(b);
        channels.push(AnyChannel::new(
            channel_name(c).as_str(),
            FlatSamples::F32(out.band_planes[b].clone()),
        ));
        if ch.mitsuba {
            channels.push(AnyChannel::new(
                out.bands.mitsuba_name(b).as_str(),
                FlatSamples::F32(out.band_planes[b].clone()),
            ));
        }
        if ch.variance {
            if let Some(v) = &out.variance_planes {
                channels.push(AnyChannel::new(
                    format!("variance.{}", channel_name(c)).as_str(),
                    FlatSamples::F32(v[b].clone()),
                ));
                if ch.mitsuba {
                    channels.push(AnyChannel::new(
                        format!("{}.variance", out.bands.mitsuba_name(b)).as_str(),
                        FlatSamples::F32(v[b].clone()),
                    ));
                }
            }
        }
    }
    channels.push(AnyChannel::new(
        "Z",
        FlatSamples::F32(out.depth_z_m.clone()),
    ));
    if ch.mitsuba {
        channels.push(AnyChannel::new(
            "depth_center.T",
            FlatSamples::F32(out.depth_center_m.clone()),
        ));
        if !out.depth_mean_m.is_empty() {
            channels.push(AnyChannel::new(
                "depth.T",
                FlatSamples::F32(out.depth_mean_m.clone()),
            ));
        }
    }
    // One custom attribute per attribute map (the `exr` crate keeps them in a HashMap whose
    // iteration order, and so the header's bytes, changes from process to process); the
    // render settings go into the standard `comments` attribute.
    let mut attrs = LayerAttributes::default();
    let units = match out.quantity {
        OutputQuantity::Radiance => RADIANCE_UNITS,
        OutputQuantity::SensorIrradiance => IRRADIANCE_UNITS,
    };
    attrs.other.insert(
        Text::from("emissiveUnits"),
        AttributeValue::Text(Text::from(units)),
    );
    attrs.comments = Some(Text::from(
        format!(
            "camsimRender spp={} bands={}:{}:{} band-averaged",
            out.spp,
            out.bands.lo_nm,
            out.bands.hi_nm(),
            out.bands.step_nm
        )
        .as_str(),
    ));
    let layer = Layer::new(
        (out.width, out.height),
        attrs,
        camsim_core::exr_io::DETERMINISTIC_ENCODING,
        AnyChannels::sort(channels.into_iter().collect()),
    );
    let mut img = Image::from_layer(layer);
    img.attributes.other.insert(
        Text::from("spectralLayoutVersion"),
        AttributeValue::Text(Text::from("1.0")),
    );
    write_atomically(path, |tmp| {
        img.write()
            .to_file(tmp)
            .map_err(|e| std::io::Error::other(e.to_string()))
    })
    .map_err(|e| RenderError::Output {
        path: path.display().to_string(),
        msg: e.to_string(),
    })
}

/// The band image in energy units (W per m²·sr·nm or m²·nm) on the band-centre grid.
pub fn band_image(out: &RenderOutput) -> SpectralImage {
    SpectralImage::new(
        out.height,
        out.width,
        SpectralBasis::Bands(band_grid(out)),
        out.band_planes.clone(),
    )
    .expect("consistent sizes")
}

/// The core [`SceneRadiance`] (photons/(s·sr·m²·nm), band centres) of a radiance render,
/// with planar depth, for the optics stage. `sample_pitch_m` is the spacing the optics stage
/// should assume in the image plane (the sensor pixel pitch when one render pixel maps to one
/// sensor pixel); `object_distance_m` as in [`SceneRadiance`].
pub fn scene_radiance(
    out: &RenderOutput,
    sample_pitch_m: f64,
    object_distance_m: Option<f64>,
) -> Result<SceneRadiance, RenderError> {
    if out.quantity != OutputQuantity::Radiance {
        return Err(RenderError::Settings(
            "this camera renders sensor irradiance, not scene radiance".into(),
        ));
    }
    let mut img = band_image(out);
    camsim_core::exr_io::bands_energy_to_photons(&mut img, &SI, false);
    Ok(SceneRadiance {
        radiance: img,
        sample_pitch_m,
        object_distance_m,
        illuminant: None,
        depth_m: Some(Plane {
            rows: out.height,
            cols: out.width,
            data: out.depth_z_m.clone(),
        }),
    })
}

/// Write named single-channel planes of `width × height` as one EXR (atomically), e.g. the
/// light-field sub-aperture views `u<u>v<v>.S0.<λ>nm`.
pub fn write_planes_exr(
    path: &Path,
    width: usize,
    height: usize,
    planes: Vec<(String, Vec<f32>)>,
    units: &str,
) -> Result<(), RenderError> {
    let channels: Vec<AnyChannel<FlatSamples>> = planes
        .into_iter()
        .map(|(n, p)| AnyChannel::new(n.as_str(), FlatSamples::F32(p)))
        .collect();
    let mut attrs = LayerAttributes::default();
    attrs.other.insert(
        Text::from("emissiveUnits"),
        AttributeValue::Text(Text::from(units)),
    );
    let layer = Layer::new(
        (width, height),
        attrs,
        camsim_core::exr_io::DETERMINISTIC_ENCODING,
        AnyChannels::sort(channels.into_iter().collect()),
    );
    let img = Image::from_layer(layer);
    write_atomically(path, |tmp| {
        img.write()
            .to_file(tmp)
            .map_err(|e| std::io::Error::other(e.to_string()))
    })
    .map_err(|e| RenderError::Output {
        path: path.display().to_string(),
        msg: e.to_string(),
    })
}
