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
use camsim_core::exr_io::{
    channel_name, write_exr_channels, ExrChannel, ExrHeader, IRRADIANCE_UNITS, RADIANCE_UNITS,
};
use camsim_core::image::{Plane, SpectralBasis, SpectralImage};
use camsim_core::spectrum::WavelengthGrid;
use camsim_core::SceneRadiance;
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
    let mut channels: Vec<ExrChannel> = Vec::new();
    for b in 0..out.bands.count {
        let c = out.bands.center_nm(b);
        channels.push(ExrChannel::new(channel_name(c), out.band_planes[b].clone()));
        if ch.mitsuba {
            channels.push(ExrChannel::new(
                out.bands.mitsuba_name(b),
                out.band_planes[b].clone(),
            ));
        }
        if ch.variance {
            if let Some(v) = &out.variance_planes {
                channels.push(ExrChannel::new(
                    format!("variance.{}", channel_name(c)),
                    v[b].clone(),
                ));
                if ch.mitsuba {
                    channels.push(ExrChannel::new(
                        format!("{}.variance", out.bands.mitsuba_name(b)),
                        v[b].clone(),
                    ));
                }
            }
        }
    }
    channels.push(ExrChannel::new("Z", out.depth_z_m.clone()));
    if ch.mitsuba {
        channels.push(ExrChannel::new(
            "depth_center.T",
            out.depth_center_m.clone(),
        ));
        if !out.depth_mean_m.is_empty() {
            channels.push(ExrChannel::new("depth.T", out.depth_mean_m.clone()));
        }
    }
    let units = match out.quantity {
        OutputQuantity::Radiance => RADIANCE_UNITS,
        OutputQuantity::SensorIrradiance => IRRADIANCE_UNITS,
    };
    let note = format!(
        "spp={} bands={}:{}:{} band-averaged",
        out.spp,
        out.bands.lo_nm,
        out.bands.hi_nm(),
        out.bands.step_nm
    );
    write_exr_channels(
        path,
        out.width,
        out.height,
        channels,
        &ExrHeader {
            emissive_units: Some(units.to_string()),
            spectral_layout: true,
            comments: Some(format!("camsimRender {note}")),
        },
    )
    .map_err(|msg| RenderError::Output {
        path: path.display().to_string(),
        msg,
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
        sample_aperture: Default::default(),
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
    let channels = planes
        .into_iter()
        .map(|(n, p)| ExrChannel::new(n, p))
        .collect();
    write_exr_channels(
        path,
        width,
        height,
        channels,
        &ExrHeader {
            emissive_units: Some(units.to_string()),
            ..ExrHeader::default()
        },
    )
    .map_err(|msg| RenderError::Output {
        path: path.display().to_string(),
        msg,
    })
}
