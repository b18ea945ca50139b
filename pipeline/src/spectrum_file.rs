//! Spectra as written in camsim's files (camera, captures, targets): a bare number or
//! `{"wavelength_nm": [...], "values": [...]}`, and the energy → photon conversion applied when
//! they are read.
use camsim_core::constants::SI;
use camsim_core::spectrum::Spectrum;
use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use serde_json::Value;

/// A spectrum as written in a file: a bare number or `{"wavelength_nm": [...], "values": [...]}`.
#[derive(Debug, Clone, PartialEq)]
pub struct SpectrumValue(pub Spectrum);

impl<'de> Deserialize<'de> for SpectrumValue {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v = Value::deserialize(d)?;
        spectrum_from_value(&v)
            .map(SpectrumValue)
            .map_err(D::Error::custom)
    }
}

impl Serialize for SpectrumValue {
    /// A constant as a bare number, a sampled spectrum as `{"wavelength_nm", "values"}`
    /// (the file format); an affine spectrum with a slope has no file form and is an error.
    fn serialize<S: Serializer>(&self, ser: S) -> Result<S::Ok, S::Error> {
        use serde::ser::{Error as _, SerializeMap};
        match &self.0 {
            Spectrum::Affine {
                offset,
                slope_per_nm,
            } if *slope_per_nm == 0.0 => ser.serialize_f64(*offset),
            Spectrum::Affine { .. } => Err(S::Error::custom(
                "a spectrum with a slope has no JSON form; sample it on a wavelength list",
            )),
            Spectrum::Sampled {
                wavelength_nm,
                values,
            } => {
                let mut m = ser.serialize_map(Some(2))?;
                m.serialize_entry("wavelength_nm", wavelength_nm)?;
                m.serialize_entry("values", values)?;
                m.end()
            }
        }
    }
}

pub(crate) fn spectrum_from_value(v: &Value) -> Result<Spectrum, String> {
    match v {
        Value::Number(n) => Ok(Spectrum::constant(n.as_f64().unwrap_or(f64::NAN))),
        Value::Object(m) => {
            for k in m.keys() {
                if k != "wavelength_nm" && k != "values" {
                    return Err(format!(
                        "unknown key `{k}` in a spectrum (expected `wavelength_nm` and `values`)"
                    ));
                }
            }
            let list = |key: &str| -> Result<Vec<f64>, String> {
                let a = m
                    .get(key)
                    .ok_or_else(|| format!("a spectrum needs `{key}`"))?
                    .as_array()
                    .ok_or_else(|| format!("`{key}` must be a list of numbers"))?;
                a.iter()
                    .enumerate()
                    .map(|(i, x)| {
                        x.as_f64()
                            .ok_or_else(|| format!("`{key}[{i}]` is not a number"))
                    })
                    .collect()
            };
            Spectrum::sampled(list("wavelength_nm")?, list("values")?).map_err(|e| e.to_string())
        }
        _ => Err(
            "a spectrum must be a number or {\"wavelength_nm\": [...], \"values\": [...]}".into(),
        ),
    }
}

/// Energy (W) spectra → photons with the SI constants.
pub fn to_photons(s: &Spectrum) -> Spectrum {
    s.energy_to_photons(&SI)
}
