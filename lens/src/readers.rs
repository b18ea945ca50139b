//! Readers for foreign lens formats.
//!
//! ISET / pbrt `.dat` (pbrt-v4 `RealisticCamera`, ISETCam `lensC`): comment lines start with
//! `#`; each data row is `radius  thickness  index  aperture` in mm, listed from the scene side;
//! `thickness` is the axial distance to the next row, `index` the medium after the surface
//! (0 = air for the stop row), `aperture` the clear **diameter**; a radius of 0 marks the
//! aperture stop (flat). ISETCam `.dat` files put the nominal focal length (mm) on a line of its
//! own before the table; such a single-number line is skipped. The last row's thickness is the distance to the film (often 0 in the
//! files; the caller refocuses). The entrance pupil follows from the stop diameter.
//!
//! ISET lens JSON (ISETCam `lensC` JSON export, e.g. `shared/data/iset/lenses/*.json`):
//! `{"name", "surfaces": [{"radius", "thickness", "ior", "semi_aperture"}], "metadata":
//! {"focalLength" (m), "fNumber"}}`, the same conventions as the `.dat` rows except that
//! `semi_aperture` is already a semi-diameter ([`read_iset_json`]).
//!
//! Zemax `.zmx` (sequential mode), see [`read_zmx`].
use crate::error::LensError;
use crate::glass::GlassCatalog;
use crate::paraxial::ynu_trace;
use crate::prescription::{
    ApertureFile, CoordinateBreak, LensPrescription, MaterialFile, PrescriptionFile, SurfaceFile,
};

/// Parse an ISET/pbrt `.dat` lens. The EPD is set so the paraxial marginal ray of an object at
/// infinity fills the stop row's aperture (at `wavelength_nm`; the indices are dispersionless).
pub fn read_iset_dat(text: &str, name: &str) -> Result<PrescriptionFile, LensError> {
    let err = |line: usize, msg: String| LensError::Reader {
        format: "ISET .dat",
        line,
        msg,
    };
    let mut surfaces = Vec::new();
    let mut stop_sd = None;
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let v: Vec<f64> = t
            .split_whitespace()
            .map(|w| {
                w.parse::<f64>()
                    .map_err(|_| err(i + 1, format!("'{w}' is not a number")))
            })
            .collect::<Result<_, _>>()?;
        if v.len() == 1 && surfaces.is_empty() {
            // ISETCam files carry the nominal focal length (mm) on a line of its own before
            // the table; it is not part of the prescription.
            continue;
        }
        if v.len() != 4 {
            return Err(err(
                i + 1,
                format!(
                    "expected 4 columns (radius thickness index aperture), got {}",
                    v.len()
                ),
            ));
        }
        let (r, t_mm, n, ap) = (v[0], v[1], v[2], v[3]);
        let stop = r == 0.0;
        if stop {
            if stop_sd.is_some() {
                return Err(err(i + 1, "second stop row (radius 0)".into()));
            }
            stop_sd = Some(ap / 2.0);
        }
        let material = if n == 0.0 || n == 1.0 {
            MaterialFile::Name("air".into())
        } else {
            MaterialFile::Model { nd: n, vd: 0.0 }
        };
        surfaces.push(SurfaceFile {
            radius_mm: if stop { None } else { Some(r) },
            thickness_mm: t_mm,
            material,
            semi_diameter_mm: Some(ap / 2.0),
            conic: 0.0,
            aspheric_coeffs: vec![],
            odd_aspheric_coeffs: vec![],
            stop,
        });
    }
    let stop_sd = stop_sd.ok_or_else(|| err(0, "no stop row (radius 0)".into()))?;
    let mut f = PrescriptionFile {
        name: name.to_string(),
        units: "mm".into(),
        surfaces,
        object_distance_mm: None,
        fields_deg: vec![0.0],
        wavelengths_nm: vec![crate::glass::LAMBDA_D_NM],
        primary_nm: None,
        aperture: ApertureFile::Epd { epd_mm: 1.0 },
        provenance: None,
        coordinate_breaks: Vec::new(),
    };
    // Unit-height parallel ray → its stop height gives EPD = 2 sd / |y_stop|.
    let l = LensPrescription::from_file_form(&f, &GlassCatalog::bundled())?;
    let a = ynu_trace(&l, l.primary_nm, 1.0, 0.0);
    let ys = a.y_mm[l.stop_index].abs();
    if ys < 1e-12 {
        return Err(err(0, "the stop is at a focus of the front group".into()));
    }
    f.aperture = ApertureFile::Epd {
        epd_mm: 2.0 * stop_sd / ys,
    };
    Ok(f)
}

/// Parse an ISETCam lens JSON file (see the module docs): `radius` 0 marks the stop, `ior` is
/// the medium after the surface (0 = air), `semi_aperture` the clear semi-diameter (mm).
/// `metadata.focalLength` (metres) is not used for the optics; read it with
/// [`iset_json_focal_length_mm`]. The EPD is set as for [`read_iset_dat`].
pub fn read_iset_json(text: &str, name: &str) -> Result<PrescriptionFile, LensError> {
    let err = |msg: String| LensError::Reader {
        format: "ISET JSON",
        line: 0,
        msg,
    };
    let v: serde_json::Value = serde_json::from_str(text)?;
    let surfs = v
        .get("surfaces")
        .and_then(|s| s.as_array())
        .ok_or_else(|| err("no \"surfaces\" array".into()))?;
    let mut dat = String::new();
    for (i, s) in surfs.iter().enumerate() {
        let num = |k: &str| -> Result<f64, LensError> {
            s.get(k)
                .and_then(|x| x.as_f64())
                .ok_or_else(|| err(format!("surface {i}: missing or non-numeric \"{k}\"")))
        };
        // Reuse the .dat row semantics (aperture column = diameter).
        dat.push_str(&format!(
            "{:e} {:e} {:e} {:e}\n",
            num("radius")?,
            num("thickness")?,
            num("ior")?,
            2.0 * num("semi_aperture")?
        ));
    }
    let mut f = read_iset_dat(&dat, name).map_err(|e| match e {
        LensError::Reader { line, msg, .. } => err(if line > 0 {
            format!("surface {}: {msg}", line - 1)
        } else {
            msg
        }),
        e => e,
    })?;
    let file_name = v.get("name").and_then(|n| n.as_str()).unwrap_or("").trim();
    if f.name.is_empty() {
        f.name = file_name.to_string();
    }
    Ok(f)
}

/// `metadata.focalLength` of an ISET lens JSON, converted from metres to mm (`None` if absent).
pub fn iset_json_focal_length_mm(text: &str) -> Result<Option<f64>, LensError> {
    let v: serde_json::Value = serde_json::from_str(text)?;
    Ok(v.get("metadata")
        .and_then(|m| m.get("focalLength"))
        .and_then(|x| x.as_f64())
        .map(|m| m * 1000.0))
}

/// Decode a text file that may be UTF-16 (LE or BE, with or without BOM), UTF-8 (with or
/// without BOM) or latin-1. Zemax writes UTF-16LE with a BOM by default, older versions
/// ANSI (latin-1) text.
pub fn decode_text(bytes: &[u8]) -> String {
    let utf16 = |b: &[u8], le: bool| -> String {
        let units: Vec<u16> = b
            .chunks_exact(2)
            .map(|c| {
                if le {
                    u16::from_le_bytes([c[0], c[1]])
                } else {
                    u16::from_be_bytes([c[0], c[1]])
                }
            })
            .collect();
        String::from_utf16_lossy(&units)
    };
    if let Some(b) = bytes.strip_prefix(&[0xFF, 0xFE]) {
        return utf16(b, true);
    }
    if let Some(b) = bytes.strip_prefix(&[0xFE, 0xFF]) {
        return utf16(b, false);
    }
    if let Some(b) = bytes.strip_prefix(&[0xEF, 0xBB, 0xBF]) {
        return String::from_utf8_lossy(b).into_owned();
    }
    // UTF-16 without BOM: ASCII text then has a zero in every other byte.
    if bytes.len() >= 4 {
        let n = bytes.len().min(400) / 2 * 2;
        let zeros_odd = bytes[..n]
            .iter()
            .skip(1)
            .step_by(2)
            .filter(|&&b| b == 0)
            .count();
        let zeros_even = bytes[..n].iter().step_by(2).filter(|&&b| b == 0).count();
        if zeros_odd * 4 > n && zeros_even == 0 {
            return utf16(&bytes[..bytes.len() / 2 * 2], true);
        }
        if zeros_even * 4 > n && zeros_odd == 0 {
            return utf16(&bytes[..bytes.len() / 2 * 2], false);
        }
    }
    match std::str::from_utf8(bytes) {
        Ok(s) => s.to_string(),
        // latin-1: every byte is the code point.
        Err(_) => bytes.iter().map(|&b| b as char).collect(),
    }
}

/// Options of [`read_zmx`].
#[derive(Debug, Clone)]
pub struct ZmxOptions {
    /// Glass catalogue used to resolve `GLAS` names (the bundled tables, plus any `.agf`
    /// catalogues added with [`GlassCatalog::with_agf`], e.g. by `--glass-catalog`).
    pub catalog: GlassCatalog,
    /// Explicit replacements for glass names that are not in the catalogue, matched
    /// case-insensitively. Nothing is ever substituted silently: a glass that is neither
    /// found, nor a `_MOLD` variant of a catalogue glass (see [`read_zmx`]), nor listed here
    /// is an error.
    pub substitutions: Vec<(String, MaterialFile)>,
    /// Folders searched for `<GCAT name>.agf` when a `GCAT` catalogue is not bundled (the
    /// .zmx file's own folder is added by [`read_zmx_file`]).
    pub agf_dirs: Vec<std::path::PathBuf>,
}

impl Default for ZmxOptions {
    fn default() -> Self {
        ZmxOptions {
            catalog: GlassCatalog::bundled(),
            substitutions: Vec::new(),
            agf_dirs: Vec::new(),
        }
    }
}

impl ZmxOptions {
    /// Add a substitution `from` → catalogue glass `to` of vendor `vendor`.
    pub fn substitute(mut self, from: &str, to: &str, vendor: &str) -> Self {
        self.substitutions.push((
            from.to_string(),
            MaterialFile::Catalog {
                glass: to.to_string(),
                catalog: Some(vendor.to_string()),
            },
        ));
        self
    }
}

/// Zemax catalogue name (`GCAT`) → table of the bundled catalogue.
fn zemax_vendor(gcat: &str) -> Option<&'static str> {
    let u = gcat.to_ascii_uppercase();
    // Zemax ships dated variants such as SUMITA_AUG2011 or OHARA_2017.
    let base = u.split('_').next().unwrap_or("");
    match base {
        "SCHOTT" => Some("schott"),
        "OHARA" => Some("ohara"),
        "HOYA" => Some("hoya"),
        "CDGM" => Some("cdgm"),
        "SUMITA" => Some("sumita"),
        "HIKARI" => Some("hikari"),
        "MISC" | "INFRARED" => Some("misc"),
        _ => None,
    }
}

/// `opts.catalog` plus the `.agf` files of the `GCAT` catalogues that are not bundled, looked
/// up as `<name>.agf` (case-insensitive) in `opts.agf_dirs`; also the GCAT names not found.
fn catalog_with_gcat(
    gcat: &[String],
    opts: &ZmxOptions,
) -> Result<(GlassCatalog, Vec<String>), LensError> {
    let mut catalog = opts.catalog.clone();
    let mut missing = Vec::new();
    for g in gcat {
        if zemax_vendor(g).is_some() || catalog.agf.iter().any(|(c, _)| c.eq_ignore_ascii_case(g)) {
            continue;
        }
        let found = opts.agf_dirs.iter().find_map(|d| {
            let rd = std::fs::read_dir(d).ok()?;
            let mut ps: Vec<_> = rd.flatten().map(|e| e.path()).collect();
            ps.sort();
            ps.into_iter().find(|p| {
                p.extension().is_some_and(|x| x.eq_ignore_ascii_case("agf"))
                    && p.file_stem()
                        .is_some_and(|s| s.eq_ignore_ascii_case(g.as_str()))
            })
        });
        match found {
            Some(p) => catalog = catalog.with_agf(&p)?,
            None => missing.push(g.clone()),
        }
    }
    Ok((catalog, missing))
}

/// The glass catalogue a `.zmx` file's glasses resolve in: `opts.catalog` plus the `.agf`
/// files of its `GCAT` line found in `opts.agf_dirs`. Pass it to
/// [`LensPrescription::from_file_form`] with the [`read_zmx`] result.
pub fn zmx_glass_catalog(bytes: &[u8], opts: &ZmxOptions) -> Result<GlassCatalog, LensError> {
    let text = decode_text(bytes);
    let gcat: Vec<String> = text
        .lines()
        .find_map(|l| l.strip_prefix("GCAT"))
        .map(|r| r.split_whitespace().map(|s| s.to_string()).collect())
        .unwrap_or_default();
    Ok(catalog_with_gcat(&gcat, opts)?.0)
}

#[derive(Default)]
struct ZSurf {
    number: usize,
    line: usize,
    kind: String,
    curv: f64,
    disz: Option<f64>, // None = INFINITY
    glass: Option<(String, Vec<f64>, usize)>,
    diam: Option<f64>,
    conic: f64,
    parm: Vec<(usize, f64)>,
    stop: bool,
}

/// Parse a sequential Zemax `.zmx` file (bytes in any encoding [`decode_text`] handles).
///
/// Supported: `UNIT` (MM, CM, METER, IN), surfaces of `TYPE STANDARD` and `EVENASPH` with
/// `CURV` (curvature, mm⁻¹), `DISZ` (thickness, `INFINITY` allowed for the object), `GLAS`
/// (catalogue name, or `___BLANK` with n_d, V_d in fields 4–5 = the model glass), `DIAM`
/// (semi-diameter), `CONI`, `PARM` 2…8 (even-asphere r⁴…r¹⁶ coefficients; `PARM 1`, the r²
/// term, must be 0), `TYPE ODDASPHE` (odd asphere: `PARM k` = β_k of r^k; every `PARM k`
/// given, k = 1…240, is read), `STOP`; the aperture lines `ENPD` (EPD), `FNUM` (image-space F/# at
/// infinity), `OBNA` (object-space NA, finite objects) and `FLOA` (float by stop size: the
/// stop's `DIAM` is filled); `FTYP` (field type 0 = angle, 1 = object height, 2 = paraxial
/// image height, 3 = real image height, used as paraxial; number of fields; number of
/// wavelengths), `YFLN`/`XFLN` (fields: the radial distance √(x² + y²) is used, the lens being
/// rotationally symmetric), `WAVM`/`WAVL` (µm) and `PWAV`.
/// Surface 0 is the object (its `DISZ` is the object distance); the last surface is the image
/// plane. Everything else (solves, pickups, merit function, tolerances…) is ignored.
///
/// `GLAS MIRROR` surfaces reflect and `TYPE COORDBRK` surfaces (`PARM 1`–`6`: decentre x, y,
/// tilt x, y, z, order) move the local frame, both with Zemax's conventions ([`crate::fold`]).
///
/// Errors name the surface number (Zemax numbering) and cause: an unsupported `TYPE` (e.g.
/// `TOROIDAL`), a glass not in
/// the catalogue nor in `opts.substitutions`, a missing or repeated stop.
pub fn read_zmx(
    bytes: &[u8],
    name: &str,
    opts: &ZmxOptions,
) -> Result<PrescriptionFile, LensError> {
    let text = decode_text(bytes);
    let err = |line: usize, msg: String| LensError::Reader {
        format: "Zemax .zmx",
        line,
        msg,
    };
    let num = |w: Option<&str>, line: usize, key: &str| -> Result<f64, LensError> {
        let w = w.ok_or_else(|| err(line, format!("{key}: missing value")))?;
        if w.eq_ignore_ascii_case("INFINITY") {
            return Ok(f64::INFINITY);
        }
        w.parse::<f64>()
            .map_err(|_| err(line, format!("{key}: '{w}' is not a number")))
    };
    let mut unit_scale: f64 = 1.0;
    let mut surfs: Vec<ZSurf> = Vec::new();
    let mut gcat: Vec<String> = Vec::new();
    enum Ap {
        Epd(f64),
        Fno(f64),
        ObjNa(f64),
        Float,
    }
    let mut aperture: Option<Ap> = None;
    let mut field_type = 0usize;
    let mut n_fields: Option<usize> = None;
    let mut n_waves: Option<usize> = None;
    let mut xfln: Vec<f64> = Vec::new();
    let mut yfln: Vec<f64> = Vec::new();
    let mut waves: Vec<(usize, f64)> = Vec::new();
    let mut wavl: Vec<f64> = Vec::new();
    let mut pwav = 1usize;
    let mut title = String::new();
    let mut mode_seq = true;
    for (i, raw) in text.lines().enumerate() {
        let ln = i + 1;
        let indented = raw.starts_with(' ') || raw.starts_with('\t');
        let t = raw.trim();
        let mut w = t.split_whitespace();
        let Some(key) = w.next() else { continue };
        if !indented {
            match key {
                "SURF" => {
                    let n = num(w.next(), ln, "SURF")? as usize;
                    surfs.push(ZSurf {
                        number: n,
                        line: ln,
                        kind: "STANDARD".into(),
                        disz: Some(0.0),
                        ..Default::default()
                    });
                }
                "MODE" => mode_seq = w.next().is_some_and(|m| m.eq_ignore_ascii_case("SEQ")),
                "NAME" => title = t[4..].trim().to_string(),
                "UNIT" => {
                    unit_scale = match w.next().map(|u| u.to_ascii_uppercase()).as_deref() {
                        Some("MM") | None => 1.0,
                        Some("CM") => 10.0,
                        Some("METER") | Some("M") => 1000.0,
                        Some("IN") => 25.4,
                        Some(u) => return Err(err(ln, format!("UNIT '{u}' is not supported"))),
                    }
                }
                "GCAT" => gcat = w.map(|s| s.to_string()).collect(),
                "ENPD" => aperture = Some(Ap::Epd(num(w.next(), ln, key)?)),
                "FNUM" => aperture = Some(Ap::Fno(num(w.next(), ln, key)?)),
                "OBNA" => aperture = Some(Ap::ObjNa(num(w.next(), ln, key)?)),
                "FLOA" => aperture = Some(Ap::Float),
                "FTYP" => {
                    let v: Vec<&str> = w.collect();
                    field_type = v.first().and_then(|s| s.parse().ok()).unwrap_or(0);
                    n_fields = v.get(2).and_then(|s| s.parse().ok());
                    n_waves = v.get(3).and_then(|s| s.parse().ok());
                }
                "XFLN" | "YFLN" => {
                    let v = w
                        .map(|s| num(Some(s), ln, key))
                        .collect::<Result<Vec<_>, _>>()?;
                    if key == "XFLN" {
                        xfln = v
                    } else {
                        yfln = v
                    }
                }
                "WAVM" => {
                    let k = num(w.next(), ln, key)? as usize;
                    let l = num(w.next(), ln, key)?;
                    waves.push((k, l));
                }
                "WAVL" => {
                    wavl = w
                        .map(|s| num(Some(s), ln, key))
                        .collect::<Result<Vec<_>, _>>()?
                }
                "PWAV" => pwav = num(w.next(), ln, key)? as usize,
                _ => {}
            }
            continue;
        }
        let Some(s) = surfs.last_mut() else { continue };
        match key {
            "TYPE" => s.kind = w.next().unwrap_or("").to_string(),
            "STOP" => s.stop = true,
            "CURV" => s.curv = num(w.next(), ln, key)?,
            "DISZ" => {
                let v = num(w.next(), ln, key)?;
                s.disz = if v.is_infinite() { None } else { Some(v) };
            }
            "GLAS" => {
                let g = w.next().unwrap_or("").to_string();
                let rest: Vec<f64> = w.filter_map(|x| x.parse().ok()).collect();
                s.glass = Some((g, rest, ln));
            }
            "DIAM" => s.diam = Some(num(w.next(), ln, key)?),
            "CONI" => s.conic = num(w.next(), ln, key)?,
            "PARM" => {
                let k = num(w.next(), ln, key)? as usize;
                let v = num(w.next(), ln, key)?;
                s.parm.push((k, v));
            }
            _ => {}
        }
    }
    if !mode_seq {
        return Err(err(
            0,
            "only sequential (MODE SEQ) files are supported".into(),
        ));
    }
    if surfs.len() < 3 {
        return Err(err(
            0,
            format!(
                "{} SURF blocks (need object, ≥ 1 surface, image)",
                surfs.len()
            ),
        ));
    }
    // Glass resolution.
    let (catalog, missing_gcat) = catalog_with_gcat(&gcat, opts)?;
    let vendors: Vec<String> = {
        let mut v: Vec<String> = Vec::new();
        for g in &gcat {
            let name = match zemax_vendor(g) {
                Some(b) => b.to_string(),
                None => g.to_lowercase(),
            };
            if !v.contains(&name) {
                v.push(name);
            }
        }
        for x in catalog.catalog_names() {
            if !v.contains(&x) {
                v.push(x);
            }
        }
        v
    };
    let mut notes: Vec<String> = Vec::new();
    let mut resolve = |s: &ZSurf| -> Result<MaterialFile, LensError> {
        let Some((g, rest, ln)) = &s.glass else {
            return Ok(MaterialFile::Name("air".into()));
        };
        let sn = s.number;
        if g.eq_ignore_ascii_case("MIRROR") {
            return Ok(MaterialFile::Name("mirror".into()));
        }
        if g.is_empty() || g.eq_ignore_ascii_case("AIR") {
            return Ok(MaterialFile::Name("air".into()));
        }
        if g == "___BLANK" {
            // GLAS ___BLANK <solve> <pickup> nd vd dPgF …
            let (nd, vd) = (rest.get(2).copied(), rest.get(3).copied());
            return match (nd, vd) {
                (Some(nd), Some(vd)) => Ok(MaterialFile::Model { nd, vd }),
                _ => Err(err(
                    *ln,
                    format!("surface {sn}: ___BLANK glass without nd, vd"),
                )),
            };
        }
        if let Some((_, m)) = opts
            .substitutions
            .iter()
            .find(|(from, _)| from.eq_ignore_ascii_case(g))
        {
            return Ok(m.clone());
        }
        let lookup = |name: &str| -> Result<Option<crate::glass::Glass>, LensError> {
            for v in &vendors {
                if let Some(found) = catalog.find(name, Some(v))? {
                    return Ok(Some(found));
                }
            }
            Ok(None)
        };
        if let Some(found) = lookup(g)? {
            return Ok(MaterialFile::Catalog {
                glass: found.name,
                catalog: Some(found.catalog),
            });
        }
        // Zemax catalogues list precision-moulding glasses twice: NAME and NAME_MOLD, the
        // latter with the index after the moulding process (n_d lower by a few 1e-4 to 1e-3).
        // The refractiveindex.info data have only NAME; it is used, and a note says so.
        if let Some(base) = g.strip_suffix("_MOLD").or_else(|| g.strip_suffix("_mold")) {
            if let Some(found) = lookup(base)? {
                notes.push(format!(
                    "surface {sn}: glass {g} read as {}/{} (no moulded-state data; n_d may \
                     differ by ~1e-3)",
                    found.catalog, found.name
                ));
                return Ok(MaterialFile::Catalog {
                    glass: found.name,
                    catalog: Some(found.catalog),
                });
            }
        }
        // GLAS name solve pickup nd vd …: nd/vd as Zemax stored them (1.5 / 40 are the
        // placeholders rayoptics writes).
        let near = match (rest.get(2), rest.get(3)) {
            (Some(&nd), Some(&vd)) if nd > 1.0 && vd > 0.0 && !(nd == 1.5 && vd == 40.0) => {
                let n = catalog.nearest(nd, vd, 3);
                format!(
                    "; nearest by (nd {nd}, Vd {vd}): {}",
                    n.iter()
                        .map(|x| format!("{}/{} ({:.5}, {:.2})", x.catalog, x.name, x.nd, x.vd))
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            }
            _ => String::new(),
        };
        let similar = catalog.similar_names(g, 4);
        Err(err(
            *ln,
            format!(
                "surface {sn}: glass '{g}' is not in the catalogues {vendors:?}{}{near}{}; \
                 give its .agf with --glass-catalog or substitute it with --glass-sub",
                if missing_gcat.is_empty() {
                    String::new()
                } else {
                    format!(" (GCAT {missing_gcat:?}: no .agf found)")
                },
                if similar.is_empty() {
                    String::new()
                } else {
                    format!("; similar names: {}", similar.join(", "))
                }
            ),
        ))
    };
    let nsurf = surfs.len();
    let mut out = Vec::new();
    let mut breaks: Vec<CoordinateBreak> = Vec::new();
    for s in &surfs[1..nsurf - 1] {
        let kind = s.kind.to_ascii_uppercase();
        if kind == "COORDBRK" {
            // PARM 1, 2: decentre x, y; 3, 4, 5: tilt about x, y, z (degrees); 6: order.
            let mut a = [0.0f64; 7];
            for &(k, v) in &s.parm {
                if (1..=6).contains(&k) {
                    a[k] = v;
                }
            }
            if s.stop {
                return Err(err(
                    s.line,
                    format!(
                        "surface {}: a COORDBRK surface cannot be the stop",
                        s.number
                    ),
                ));
            }
            let t = s.disz.ok_or_else(|| {
                err(
                    s.line,
                    format!("surface {}: DISZ INFINITY inside the lens", s.number),
                )
            })?;
            breaks.push(CoordinateBreak {
                surface: out.len(),
                decenter_x_mm: a[1] * unit_scale,
                decenter_y_mm: a[2] * unit_scale,
                tilt_x_deg: a[3],
                tilt_y_deg: a[4],
                tilt_z_deg: a[5],
                tilt_first: a[6] != 0.0,
            });
            out.push(SurfaceFile {
                radius_mm: None,
                thickness_mm: t * unit_scale,
                material: MaterialFile::Name("air".into()),
                semi_diameter_mm: None,
                conic: 0.0,
                aspheric_coeffs: Vec::new(),
                odd_aspheric_coeffs: Vec::new(),
                stop: false,
            });
            continue;
        }
        // Zemax writes the odd asphere's type as ODDASPHE (8 characters).
        let odd = kind == "ODDASPHE" || kind == "ODDASPH";
        if kind != "STANDARD" && kind != "EVENASPH" && !odd {
            return Err(err(
                s.line,
                format!(
                    "surface {}: surface type {} is not supported (STANDARD, EVENASPH, \
                     ODDASPHE, COORDBRK only)",
                    s.number, s.kind
                ),
            ));
        }
        let mut odd_coeffs = Vec::new();
        if odd {
            // PARM k multiplies r^k (k ≥ 1); unit scaling: β·r^k with r in file units.
            let n = s.parm.iter().map(|&(k, _)| k).max().unwrap_or(0);
            if n > 240 {
                return Err(err(
                    s.line,
                    format!(
                        "surface {}: ODDASPHE PARM {n}: expected a term index 1…240 (r^k)",
                        s.number
                    ),
                ));
            }
            odd_coeffs = vec![0.0f64; n];
            for &(k, v) in &s.parm {
                if k == 0 {
                    continue;
                }
                odd_coeffs[k - 1] = v * unit_scale.powi(1 - k as i32);
            }
            while odd_coeffs.last() == Some(&0.0) {
                odd_coeffs.pop();
            }
        }
        let mut coeffs = Vec::new();
        if kind == "EVENASPH" {
            let mut a = [0.0f64; 9];
            for &(k, v) in &s.parm {
                if (1..=8).contains(&k) {
                    a[k] = v;
                }
            }
            if a[1] != 0.0 {
                return Err(err(
                    s.line,
                    format!(
                        "surface {}: EVENASPH r² coefficient (PARM 1 = {}) is not supported",
                        s.number, a[1]
                    ),
                ));
            }
            // PARM k multiplies r^(2k); unit scaling: A·r^(2k) with r in file units.
            coeffs = (2..=8)
                .map(|k| a[k] * unit_scale.powi(1 - 2 * k as i32))
                .collect();
            while coeffs.last() == Some(&0.0) {
                coeffs.pop();
            }
        }
        let t = s.disz.ok_or_else(|| {
            err(
                s.line,
                format!("surface {}: DISZ INFINITY inside the lens", s.number),
            )
        })?;
        out.push(SurfaceFile {
            radius_mm: if s.curv == 0.0 {
                None
            } else {
                Some(unit_scale / s.curv)
            },
            thickness_mm: t * unit_scale,
            material: resolve(s)?,
            semi_diameter_mm: s.diam.filter(|d| *d > 0.0).map(|d| d * unit_scale),
            conic: s.conic,
            aspheric_coeffs: coeffs,
            odd_aspheric_coeffs: odd_coeffs,
            stop: s.stop,
        });
    }
    if surfs[nsurf - 1].stop {
        return Err(err(
            surfs[nsurf - 1].line,
            "the image surface is the stop".into(),
        ));
    }
    if !out.iter().any(|s| s.stop) {
        return Err(err(0, "no STOP surface".into()));
    }
    let object_distance_mm = surfs[0].disz.map(|d| d * unit_scale);
    let glass_notes = notes.join("; ");
    // Wavelengths.
    let mut wl_um: Vec<f64> = if !waves.is_empty() {
        waves.sort_by_key(|w| w.0);
        let n = n_waves.unwrap_or(waves.len()).min(waves.len());
        waves.iter().take(n).map(|w| w.1).collect()
    } else {
        wavl.clone()
    };
    if wl_um.is_empty() {
        wl_um = vec![crate::glass::LAMBDA_D_NM * 1e-3];
    }
    let primary_nm = wl_um
        .get(pwav.saturating_sub(1))
        .copied()
        .unwrap_or(wl_um[0])
        * 1e3;
    let wavelengths_nm: Vec<f64> = wl_um.iter().map(|w| w * 1e3).collect();
    let nf = n_fields
        .unwrap_or(yfln.len().max(xfln.len()))
        .min(yfln.len().max(xfln.len()));
    let raw_fields: Vec<f64> = (0..nf)
        .map(|k| {
            let x = xfln.get(k).copied().unwrap_or(0.0);
            let y = yfln.get(k).copied().unwrap_or(0.0);
            x.hypot(y)
        })
        .collect();
    let mut f = PrescriptionFile {
        name: if title.is_empty() {
            name.to_string()
        } else {
            format!("{name} ({title})")
        },
        units: "mm".into(),
        surfaces: out,
        object_distance_mm,
        fields_deg: vec![0.0],
        wavelengths_nm,
        primary_nm: Some(primary_nm),
        aperture: ApertureFile::Epd { epd_mm: 1.0 },
        provenance: (!glass_notes.is_empty()).then(|| format!("Zemax .zmx; {glass_notes}")),
        coordinate_breaks: breaks,
    };
    // First-order data of the lens with a provisional aperture, for the aperture and field
    // conversions.
    let l = LensPrescription::from_file_form(&f, &catalog)?;
    let fo = l.first_order(l.primary_nm)?;
    let a = ynu_trace(&l, l.primary_nm, 1.0, 0.0);
    f.aperture = match aperture {
        Some(Ap::Epd(d)) => ApertureFile::Epd {
            epd_mm: d * unit_scale,
        },
        Some(Ap::Fno(n)) => ApertureFile::FNumber { f_number: n },
        Some(Ap::ObjNa(na)) => {
            let d = object_distance_mm
                .ok_or_else(|| err(0, "OBNA with an object at infinity".into()))?;
            let u = na.asin().tan();
            ApertureFile::Epd {
                epd_mm: 2.0 * u * (d + fo.entrance_pupil_z_mm),
            }
        }
        Some(Ap::Float) | None => {
            let s = l.stop_index;
            let sd = f.surfaces[s].semi_diameter_mm.ok_or_else(|| {
                err(
                    0,
                    "float-by-stop-size aperture but the stop has no DIAM".into(),
                )
            })?;
            // Height at the stop of the paraxial marginal ray per unit EPD radius.
            let per = match object_distance_mm {
                None => a.y_mm[s].abs(),
                Some(d) => {
                    let u = 1.0 / (d + fo.entrance_pupil_z_mm);
                    ynu_trace(&l, l.primary_nm, d * u, u).y_mm[s].abs()
                }
            };
            ApertureFile::Epd {
                epd_mm: 2.0 * sd / per,
            }
        }
    };
    // Fields → object-space chief-ray angles.
    let efl = fo.efl_mm;
    f.fields_deg = raw_fields
        .iter()
        .map(|&h| match field_type {
            0 => h,
            1 => {
                let h = h * unit_scale;
                match object_distance_mm {
                    Some(d) => (h / (d + fo.entrance_pupil_z_mm)).atan().to_degrees(),
                    None => 0.0,
                }
            }
            _ => {
                let h = h * unit_scale;
                match object_distance_mm {
                    // image height → object height through the paraxial magnification
                    Some(d) if fo.magnification != 0.0 => {
                        (h / fo.magnification / (d + fo.entrance_pupil_z_mm))
                            .abs()
                            .atan()
                            .to_degrees()
                    }
                    _ => (h / efl).abs().atan().to_degrees(),
                }
            }
        })
        .collect();
    if f.fields_deg.is_empty() {
        f.fields_deg = vec![0.0];
    }
    Ok(f)
}

/// Read a `.zmx` file from disk (see [`read_zmx`]); the lens is named after the file stem.
pub fn read_zmx_file(
    path: impl AsRef<std::path::Path>,
    opts: &ZmxOptions,
) -> Result<PrescriptionFile, LensError> {
    let p = path.as_ref();
    let bytes = std::fs::read(p).map_err(|e| LensError::Io {
        path: p.display().to_string(),
        msg: e.to_string(),
    })?;
    let stem = p
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_default();
    let mut opts = opts.clone();
    if let Some(dir) = p.parent() {
        opts.agf_dirs.push(if dir.as_os_str().is_empty() {
            std::path::PathBuf::from(".")
        } else {
            dir.to_path_buf()
        });
    }
    read_zmx(&bytes, &stem, &opts).map_err(|e| match e {
        LensError::Reader { format, line, msg } => LensError::Reader {
            format,
            line,
            msg: format!("{}: {msg}", p.display()),
        },
        e => e,
    })
}
