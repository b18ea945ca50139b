//! Refractive index n(λ) of optical glasses.
//!
//! Glass data are the refractiveindex.info YAML files (CC0) of the Schott, Ohara, Hoya and CDGM
//! Zemax catalogues, a copy of which lives in `lenses/glass/<vendor>/<NAME>.yml` (see
//! `lenses/glass/README.md`). The dispersion formulas are those of the refractiveindex.info
//! "Dispersion formulas" document, λ in µm, indices relative to air (as the catalogues give them):
//!
//! * formula 1, Sellmeier: n² − 1 = C1 + Σ C(2i)·λ² / (λ² − C(2i+1)²)
//! * formula 2, Sellmeier-2 (Schott "Sellmeier 1"): n² − 1 = C1 + Σ C(2i)·λ² / (λ² − C(2i+1))
//! * formula 3, polynomial (Schott power series): n² = C1 + Σ C(2i)·λ^C(2i+1)
//! * formula 4, RII mixed: n² = C1 + C2·λ^C3/(λ² − C4^C5) + C6·λ^C7/(λ² − C8^C9) + Σ C(2i)·λ^C(2i+1) (i ≥ 5)
//! * formula 5, Cauchy: n = C1 + Σ C(2i)·λ^C(2i+1)
//! * formula 6, gases: n − 1 = C1 + Σ C(2i) / (C(2i+1) − λ⁻²)
//! * tabulated n: linear interpolation, clamped at the ends.
//!
//! A glass given only by (n_d, V_d) uses the two-term Cauchy model n(λ) = A + B/λ² fitted so that
//! n(λ_d) = n_d and n(λ_F) − n(λ_C) = (n_d − 1)/V_d exactly (Smith, "Modern Optical Engineering",
//! §7.2 for the definition of V_d; the Cauchy form is the lowest-order dispersion law with a
//! normal, decreasing n(λ)). Partial dispersions are therefore "normal-glass"-like only roughly.
use crate::error::LensError;
use std::path::{Path, PathBuf};

/// Fraunhofer d line (He), nm.
pub const LAMBDA_D_NM: f64 = 587.5618;
/// Fraunhofer F line (H), nm.
pub const LAMBDA_F_NM: f64 = 486.1327;
/// Fraunhofer C line (H), nm.
pub const LAMBDA_C_NM: f64 = 656.2725;

/// A dispersion law n(λ).
#[derive(Debug, Clone, PartialEq)]
pub enum Dispersion {
    /// A refractiveindex.info formula (number 1–6) with its coefficients, λ in µm.
    Formula {
        /// refractiveindex.info formula number.
        number: u8,
        /// Coefficients C1, C2, … as written in the file.
        coefficients: Vec<f64>,
    },
    /// Tabulated (λ µm, n) rows, linearly interpolated.
    Tabulated {
        /// Increasing wavelengths, µm.
        wavelength_um: Vec<f64>,
        /// Index at each wavelength.
        n: Vec<f64>,
    },
    /// Two-term Cauchy n = a + b/λ² (λ in µm), the (n_d, V_d) model.
    Cauchy {
        /// Constant term.
        a: f64,
        /// Coefficient of λ⁻² (µm²).
        b: f64,
    },
    /// The same index at every wavelength.
    Constant(f64),
}

impl Dispersion {
    /// The index at `wavelength_nm` (no range check: formulas are evaluated as written).
    pub fn index(&self, wavelength_nm: f64) -> f64 {
        let l = wavelength_nm * 1e-3;
        let l2 = l * l;
        match self {
            Dispersion::Constant(n) => *n,
            Dispersion::Cauchy { a, b } => a + b / l2,
            Dispersion::Tabulated { wavelength_um, n } => interp(wavelength_um, n, l),
            Dispersion::Formula {
                number,
                coefficients: c,
            } => {
                let g = |i: usize| c.get(i).copied().unwrap_or(0.0);
                match number {
                    1 => {
                        let mut s = 1.0 + g(0);
                        for i in (1..c.len().saturating_sub(1)).step_by(2) {
                            s += g(i) * l2 / (l2 - g(i + 1) * g(i + 1));
                        }
                        s.sqrt()
                    }
                    2 => {
                        let mut s = 1.0 + g(0);
                        for i in (1..c.len().saturating_sub(1)).step_by(2) {
                            s += g(i) * l2 / (l2 - g(i + 1));
                        }
                        s.sqrt()
                    }
                    3 => {
                        let mut s = g(0);
                        for i in (1..c.len().saturating_sub(1)).step_by(2) {
                            s += g(i) * l.powf(g(i + 1));
                        }
                        s.sqrt()
                    }
                    4 => {
                        let mut s = g(0)
                            + g(1) * l.powf(g(2)) / (l2 - g(3).powf(g(4)))
                            + g(5) * l.powf(g(6)) / (l2 - g(7).powf(g(8)));
                        for i in (9..c.len().saturating_sub(1)).step_by(2) {
                            s += g(i) * l.powf(g(i + 1));
                        }
                        s.sqrt()
                    }
                    5 => {
                        let mut s = g(0);
                        for i in (1..c.len().saturating_sub(1)).step_by(2) {
                            s += g(i) * l.powf(g(i + 1));
                        }
                        s
                    }
                    6 => {
                        let mut s = 1.0 + g(0);
                        for i in (1..c.len().saturating_sub(1)).step_by(2) {
                            s += g(i) / (g(i + 1) - 1.0 / l2);
                        }
                        s
                    }
                    _ => f64::NAN,
                }
            }
        }
    }
}

fn interp(x: &[f64], y: &[f64], v: f64) -> f64 {
    if x.is_empty() {
        return f64::NAN;
    }
    if v <= x[0] {
        return y[0];
    }
    if v >= x[x.len() - 1] {
        return y[y.len() - 1];
    }
    let i = x.partition_point(|&a| a <= v) - 1;
    let t = (v - x[i]) / (x[i + 1] - x[i]);
    y[i] + t * (y[i + 1] - y[i])
}

/// An optical glass: dispersion law plus the catalogue's n_d and V_d (when given).
#[derive(Debug, Clone, PartialEq)]
pub struct Glass {
    /// Name as in the catalogue (e.g. "N-BK7").
    pub name: String,
    /// Catalogue / vendor ("schott", …), or "model" for (n_d, V_d) glasses.
    pub catalog: String,
    /// n(λ).
    pub dispersion: Dispersion,
    /// Validity range of the formula (µm), if given.
    pub range_um: Option<(f64, f64)>,
    /// Catalogue n_d, if given.
    pub catalog_nd: Option<f64>,
    /// Catalogue V_d, if given.
    pub catalog_vd: Option<f64>,
}

impl Glass {
    /// n at `wavelength_nm`.
    pub fn index(&self, wavelength_nm: f64) -> f64 {
        self.dispersion.index(wavelength_nm)
    }

    /// n_d computed from the dispersion law.
    pub fn nd(&self) -> f64 {
        self.index(LAMBDA_D_NM)
    }

    /// Abbe number V_d = (n_d − 1)/(n_F − n_C) computed from the dispersion law.
    pub fn vd(&self) -> f64 {
        (self.nd() - 1.0) / (self.index(LAMBDA_F_NM) - self.index(LAMBDA_C_NM))
    }

    /// The (n_d, V_d) model glass (two-term Cauchy, see the module docs).
    pub fn from_nd_vd(nd: f64, vd: f64) -> Result<Glass, LensError> {
        let name = format!("nd={nd} vd={vd}");
        if !(nd.is_finite() && nd >= 1.0) {
            return Err(LensError::Glass {
                name,
                msg: format!("nd = {nd} must be ≥ 1"),
            });
        }
        let dispersion = if vd == 0.0 || vd.is_infinite() {
            // V_d = 0 is the Zemax/rayoptics convention for "no dispersion".
            Dispersion::Constant(nd)
        } else if vd.is_finite() && vd > 0.0 {
            let inv2 = |nm: f64| 1.0 / (nm * 1e-3).powi(2);
            let b = (nd - 1.0) / vd / (inv2(LAMBDA_F_NM) - inv2(LAMBDA_C_NM));
            Dispersion::Cauchy {
                a: nd - b * inv2(LAMBDA_D_NM),
                b,
            }
        } else {
            return Err(LensError::Glass {
                name,
                msg: format!("vd = {vd} must be > 0 (or 0 = no dispersion)"),
            });
        };
        Ok(Glass {
            name,
            catalog: "model".into(),
            dispersion,
            range_um: None,
            catalog_nd: Some(nd),
            catalog_vd: if vd > 0.0 { Some(vd) } else { None },
        })
    }

    /// Parse a refractiveindex.info YAML file (the subset those files use: `DATA` blocks of
    /// `type: formula N` / `tabulated n` with `coefficients`, `wavelength_range`, `data`, and
    /// `SPECS` with `nd`, `Vd`). The first n-block is used.
    pub fn from_refractiveindex_yaml(
        name: &str,
        catalog: &str,
        text: &str,
    ) -> Result<Glass, LensError> {
        let err = |msg: String| LensError::Glass {
            name: name.to_string(),
            msg,
        };
        let mut dispersion: Option<Dispersion> = None;
        let mut range_um = None;
        let mut nd = None;
        let mut vd = None;
        let mut lines = text.lines().peekable();
        let mut current: Option<String> = None; // type of the current DATA block
        while let Some(line) = lines.next() {
            let t = line.trim();
            if let Some(rest) = t.strip_prefix("- type:") {
                current = Some(rest.trim().trim_matches('"').to_string());
                continue;
            }
            if let Some(rest) = t.strip_prefix("nd:") {
                nd = rest.trim().parse::<f64>().ok();
                continue;
            }
            if let Some(rest) = t.strip_prefix("Vd:") {
                vd = rest.trim().parse::<f64>().ok();
                continue;
            }
            let Some(kind) = current.clone() else {
                continue;
            };
            if dispersion.is_some() && !kind.starts_with("formula") && kind != "tabulated n" {
                continue;
            }
            if let Some(rest) = t.strip_prefix("wavelength_range:") {
                if dispersion.is_none() {
                    let v = parse_nums(rest).map_err(|e| err(format!("wavelength_range: {e}")))?;
                    if v.len() == 2 {
                        range_um = Some((v[0], v[1]));
                    }
                }
            } else if let Some(rest) = t.strip_prefix("coefficients:") {
                if dispersion.is_none() {
                    if let Some(num) = kind.strip_prefix("formula ") {
                        let number: u8 = num
                            .trim()
                            .parse()
                            .map_err(|_| err(format!("bad formula type '{kind}'")))?;
                        if !(1..=6).contains(&number) {
                            return Err(err(format!(
                                "refractiveindex.info formula {number} is not supported"
                            )));
                        }
                        let coefficients =
                            parse_nums(rest).map_err(|e| err(format!("coefficients: {e}")))?;
                        dispersion = Some(Dispersion::Formula {
                            number,
                            coefficients,
                        });
                    }
                }
            } else if t.starts_with("data:") && dispersion.is_none() && kind == "tabulated n" {
                let mut wl = Vec::new();
                let mut nn = Vec::new();
                while let Some(l) = lines.peek() {
                    let v = match parse_nums(l) {
                        Ok(v) if v.len() >= 2 => v,
                        _ => break,
                    };
                    wl.push(v[0]);
                    nn.push(v[1]);
                    lines.next();
                }
                if wl.len() < 2 {
                    return Err(err("tabulated n has fewer than 2 rows".into()));
                }
                range_um = Some((wl[0], wl[wl.len() - 1]));
                dispersion = Some(Dispersion::Tabulated {
                    wavelength_um: wl,
                    n: nn,
                });
            }
        }
        let dispersion = dispersion.ok_or_else(|| err("no formula or tabulated n block".into()))?;
        Ok(Glass {
            name: name.to_string(),
            catalog: catalog.to_string(),
            dispersion,
            range_um,
            catalog_nd: nd,
            catalog_vd: vd,
        })
    }
}

fn parse_nums(s: &str) -> Result<Vec<f64>, String> {
    s.split_whitespace()
        .map(|w| {
            w.parse::<f64>()
                .map_err(|_| format!("'{w}' is not a number"))
        })
        .collect()
}

/// Vendors searched, in order, when a glass is named without a catalogue.
pub const VENDORS: [&str; 4] = ["schott", "ohara", "hoya", "cdgm"];

include!(concat!(env!("OUT_DIR"), "/embedded_glass.rs"));

/// A glass catalogue: the bundled one (embedded in the binary) or a folder of
/// refractiveindex.info glass files laid out as `<vendor>/<NAME>.yml`.
#[derive(Debug, Clone)]
pub struct GlassCatalog {
    /// The folder holding one sub-folder per vendor.
    pub root: PathBuf,
}

impl GlassCatalog {
    /// A catalogue rooted at `root`.
    pub fn new(root: impl Into<PathBuf>) -> Self {
        GlassCatalog { root: root.into() }
    }

    /// The glass folder shipped with the workspace (`lenses/glass`).
    pub fn bundled() -> Self {
        GlassCatalog::new(Path::new(env!("CARGO_MANIFEST_DIR")).join("../lenses/glass"))
    }

    /// Look up `name` (case-insensitive) in `catalog` (a vendor folder name, case-insensitive)
    /// or, if `None`, in [`VENDORS`] order.
    pub fn glass(&self, name: &str, catalog: Option<&str>) -> Result<Glass, LensError> {
        let vendors: Vec<String> = match catalog {
            Some(c) => vec![c.to_lowercase()],
            None => VENDORS.iter().map(|s| s.to_string()).collect(),
        };
        let bundled = self.root == GlassCatalog::bundled().root;
        for v in &vendors {
            if bundled {
                // the bundled catalogue is embedded in the binary: no files needed at run time
                if let Some((_, stem, text)) = EMBEDDED_GLASS.iter().find(|(vendor, stem, _)| {
                    vendor.eq_ignore_ascii_case(v) && stem.eq_ignore_ascii_case(name)
                }) {
                    return Glass::from_refractiveindex_yaml(stem, v, text);
                }
                continue;
            }
            let dir = self.root.join(v);
            let Ok(rd) = std::fs::read_dir(&dir) else {
                continue;
            };
            for e in rd.flatten() {
                let fname = e.file_name().to_string_lossy().to_string();
                if let Some(stem) = fname.strip_suffix(".yml") {
                    if stem.eq_ignore_ascii_case(name) {
                        let text =
                            std::fs::read_to_string(e.path()).map_err(|x| LensError::Io {
                                path: e.path().display().to_string(),
                                msg: x.to_string(),
                            })?;
                        return Glass::from_refractiveindex_yaml(stem, v, &text);
                    }
                }
            }
        }
        Err(LensError::Glass {
            name: name.to_string(),
            msg: format!(
                "not found in catalogue(s) {:?} under {}",
                vendors,
                self.root.display()
            ),
        })
    }
}
