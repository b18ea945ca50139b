//! ISETCam spectral and device data embedded in the binary (MIT, Stanford Center for Image
//! Systems Engineering; see data/iset/README.md for attribution and measurement sources).
//!
//! Files keep their layout (`wavelength_nm`, `names`, `values`, `units`); look them up by their
//! path under data/iset without `.json`, e.g. `"lights/D65"`, `"human/XYZ"`.
use crate::error::CoreError;
use crate::spectrum::Spectrum;
use serde_json::Value;

include!(concat!(env!("OUT_DIR"), "/embedded_data.rs"));

/// Names of every embedded file.
pub fn names() -> impl Iterator<Item = &'static str> {
    EMBEDDED.iter().map(|(n, _)| *n)
}

/// The raw JSON text of an embedded file.
pub fn text(name: &str) -> Result<&'static str, CoreError> {
    EMBEDDED
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, t)| *t)
        .ok_or_else(|| CoreError::Data(name.into(), "no such embedded file".into()))
}

/// The parsed JSON of an embedded file.
pub fn json(name: &str) -> Result<Value, CoreError> {
    serde_json::from_str(text(name)?).map_err(|e| CoreError::Data(name.into(), e.to_string()))
}

/// A spectral data file: its channel names and one spectrum per channel.
#[derive(Debug, Clone)]
pub struct SpectralData {
    /// Channel names, in file order.
    pub names: Vec<String>,
    /// `units` field of the file (energy, photons, qe, reflectance, transmittance, …).
    pub units: String,
    /// One spectrum per channel.
    pub spectra: Vec<Spectrum>,
}

impl SpectralData {
    /// The channel called `name`.
    pub fn channel(&self, name: &str) -> Option<&Spectrum> {
        self.names
            .iter()
            .position(|n| n == name)
            .map(|i| &self.spectra[i])
    }
}

/// Load an embedded spectral file (`wavelength_nm` + `values[channel][wavelength]`).
pub fn spectral(name: &str) -> Result<SpectralData, CoreError> {
    let v = json(name)?;
    let bad = |m: &str| CoreError::Data(name.into(), m.into());
    let wl: Vec<f64> = v["wavelength_nm"]
        .as_array()
        .ok_or_else(|| bad("no wavelength_nm"))?
        .iter()
        .map(|x| x.as_f64().ok_or_else(|| bad("non-numeric wavelength")))
        .collect::<Result<_, _>>()?;
    let values = v["values"].as_array().ok_or_else(|| bad("no values"))?;
    let names: Vec<String> = match v["names"].as_array() {
        Some(a) => a
            .iter()
            .map(|n| n.as_str().unwrap_or("").to_string())
            .collect(),
        None => (0..values.len()).map(|i| format!("channel_{i}")).collect(),
    };
    let mut spectra = Vec::with_capacity(values.len());
    for ch in values {
        let vals: Vec<f64> = ch
            .as_array()
            .ok_or_else(|| bad("values must be a list per channel"))?
            .iter()
            .map(|x| x.as_f64().unwrap_or(f64::NAN))
            .collect();
        // drop samples that are null (non-finite) in the source table
        // a few source tables are unsorted or repeat a wavelength: sort, keep the first
        let mut pairs: Vec<(f64, f64)> = wl
            .iter()
            .zip(&vals)
            .filter(|(_, y)| y.is_finite())
            .map(|(a, b)| (*a, *b))
            .collect();
        pairs.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap());
        pairs.dedup_by(|a, b| a.0 == b.0);
        let (w, vv): (Vec<f64>, Vec<f64>) = pairs.into_iter().unzip();
        spectra.push(Spectrum::sampled(w, vv).map_err(|e| bad(&e.to_string()))?);
    }
    Ok(SpectralData {
        names,
        units: v["units"].as_str().unwrap_or("").to_string(),
        spectra,
    })
}

/// Illuminant names usable in configs and their embedded files.
pub const ILLUMINANTS: &[(&str, &str)] = &[
    ("D50", "lights/D50"),
    ("D55", "lights/D55"),
    ("D65", "lights/D65"),
    ("D75", "lights/D75"),
    ("A", "lights/illuminantA"),
    ("B", "lights/illuminantB"),
    ("C", "lights/illuminantC"),
    ("tungsten", "lights/Tungsten"),
    ("fluorescent", "lights/Fluorescent"),
    ("F2", "lights/Fluorescent2"),
    ("F7", "lights/Fluorescent7"),
    ("F11", "lights/Fluorescent11"),
    ("equal_energy", "lights/equalEnergy"),
    ("equal_photons", "lights/equalPhotons"),
];

/// A named illuminant (energy units, relative scale), e.g. `"D65"`, `"tungsten"`, or any
/// embedded `lights/...` file.
pub fn illuminant(name: &str) -> Result<Spectrum, CoreError> {
    let file = ILLUMINANTS
        .iter()
        .find(|(n, _)| n.eq_ignore_ascii_case(name))
        .map(|(_, f)| f.to_string())
        .unwrap_or_else(|| name.to_string());
    let d = spectral(&file).map_err(|_| {
        CoreError::Data(
            name.into(),
            format!(
                "unknown illuminant; expected one of {} or an embedded lights/... file",
                ILLUMINANTS
                    .iter()
                    .map(|(n, _)| *n)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )
    })?;
    Ok(d.spectra[0].clone())
}

/// The 24 Macbeth ColorChecker reflectances in chart reading order (row-major: dark skin,
/// light skin, …, black), from ISETCam macbethChart (column-major in the file).
pub fn macbeth_reflectances_row_major() -> Result<Vec<Spectrum>, CoreError> {
    let d = spectral("surfaces/reflectances/macbethChart")?;
    // file index 4*c + r holds chart (row r, col c)
    let mut out = Vec::with_capacity(24);
    for r in 0..4 {
        for c in 0..6 {
            out.push(d.spectra[4 * c + r].clone());
        }
    }
    Ok(out)
}

/// CIE 1931 colour-matching functions x̄, ȳ, z̄ for energy spectra (ISETCam XYZ.json).
pub fn cie1931_xyz() -> Result<[Spectrum; 3], CoreError> {
    let d = spectral("human/XYZ")?;
    Ok([
        d.spectra[0].clone(),
        d.spectra[1].clone(),
        d.spectra[2].clone(),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_files_parse() {
        assert!(names().count() > 50);
        let d65 = illuminant("D65").unwrap();
        assert!(d65.eval(560.0) > 0.0);
        let m = macbeth_reflectances_row_major().unwrap();
        assert_eq!(m.len(), 24);
        // white (row 3, col 0) is brighter than black (row 3, col 5)
        assert!(m[18].eval(550.0) > 0.8 && m[23].eval(550.0) < 0.1);
        for n in names() {
            let v = json(n).unwrap();
            if v.get("wavelength_nm").is_some()
                && v.get("values").is_some()
                && v.get("spd").is_none()
            {
                spectral(n).unwrap_or_else(|e| panic!("{n}: {e}"));
            }
        }
    }
}
