//! Study specifications (docs/study.md): a base point document, parameters that patch it at
//! JSON paths, a grid or list sweep, and plots. Loading expands `{"$file": "…"}` references,
//! enumerates the points in spec order and gives each its content hash.
use super::hash::json_hash;
use crate::error::CliError;
use serde::Deserialize;
use serde_json::{Map, Value};
use std::path::{Path, PathBuf};

/// The study file as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct SpecFile {
    #[serde(default)]
    name: Option<String>,
    #[serde(default)]
    title: Option<String>,
    #[serde(default)]
    description: Option<String>,
    point: Value,
    #[serde(default)]
    parameters: Vec<ParameterFile>,
    #[serde(default)]
    sweep: Option<String>,
    #[serde(default)]
    plots: Option<Vec<PlotFile>>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct ParameterFile {
    name: String,
    #[serde(default)]
    path: Option<String>,
    #[serde(default)]
    set: Option<Map<String, Value>>,
    values: Vec<Value>,
    #[serde(default)]
    with: Option<Map<String, Value>>,
    #[serde(default)]
    labels: Option<Vec<String>>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct PlotFile {
    y: Value,
    x: String,
    #[serde(default)]
    series: Option<String>,
    #[serde(default)]
    title: Option<String>,
    #[serde(default, rename = "where")]
    filter: Option<Map<String, Value>>,
}

/// How the parameters combine into points.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sweep {
    /// Cartesian product, the first parameter varying slowest.
    Grid,
    /// Point i takes value i of every parameter (all lists have the same length).
    List,
}

/// One swept parameter.
#[derive(Debug, Clone)]
pub struct Parameter {
    /// Column name in the tables.
    pub name: String,
    /// (JSON path, template) pairs; `"$value"` in a template is replaced by the value.
    pub sets: Vec<(String, Value)>,
    /// The values (with `$file` references expanded).
    pub values: Vec<Value>,
    /// Companion paths with one value per entry of `values`.
    pub with: Vec<(String, Vec<Value>)>,
    /// One label per value (for tables and plots).
    pub labels: Vec<String>,
    /// True when every value is a number (plotted on a numeric axis).
    pub numeric: bool,
}

/// A plot of the report: metric(s) against a parameter, one curve per value of `series`
/// (and per y metric), one figure per combination of the other parameters.
#[derive(Debug, Clone)]
pub struct PlotSpec {
    /// Metric columns on the y axis.
    pub y: Vec<String>,
    /// The parameter on the x axis.
    pub x: String,
    /// The parameter that makes the curves, if any.
    pub series: Option<String>,
    /// Title (default: the metric names).
    pub title: Option<String>,
    /// Only points whose parameters have these value indices: (parameter index, value index).
    pub filter: Vec<(usize, usize)>,
}

/// One point of the sweep.
#[derive(Debug, Clone)]
pub struct PlannedPoint {
    /// Position in spec order.
    pub index: usize,
    /// Value index of each parameter.
    pub coords: Vec<usize>,
    /// The point document (what is hashed and evaluated).
    pub doc: Value,
    /// SHA-256 (hex) of the canonical document.
    pub hash: String,
}

impl PlannedPoint {
    /// The point's folder name under `points/`: the first 16 hex digits of its hash.
    pub fn folder(&self) -> String {
        self.hash[..16].to_string()
    }
}

/// A loaded, validated study.
#[derive(Debug, Clone)]
pub struct Study {
    /// The spec file.
    pub path: PathBuf,
    /// Short name.
    pub name: String,
    /// Title of the report.
    pub title: String,
    /// Free text shown under the title.
    pub description: String,
    /// The swept parameters, in spec order.
    pub parameters: Vec<Parameter>,
    /// Grid or list.
    pub sweep: Sweep,
    /// Plots of the report.
    pub plots: Vec<PlotSpec>,
    /// Every point, in spec order.
    pub points: Vec<PlannedPoint>,
}

fn bad(path: &Path, msg: impl std::fmt::Display) -> CliError {
    CliError::input(path, msg)
}

/// Replace every `{"$file": "x.json"}` in `v` by the parsed contents of x.json (relative to
/// `dir`; references inside it are relative to its own folder), and every
/// `{"$path": "scene.gltf"}` by the absolute path of that file (a file the point reads
/// itself). `key` names the place in messages.
/// An include cycle (a file that includes itself, directly or through others) and chains
/// deeper than [`MAX_INCLUDE_DEPTH`] are refused.
pub fn expand_files(v: &Value, dir: &Path, spec: &Path, key: &str) -> Result<Value, CliError> {
    let mut chain: Vec<PathBuf> = std::fs::canonicalize(spec).into_iter().collect();
    expand_files_in(v, dir, spec, key, &mut chain)
}

/// The deepest chain of `$file` references accepted.
pub const MAX_INCLUDE_DEPTH: usize = 32;

fn expand_files_in(
    v: &Value,
    dir: &Path,
    spec: &Path,
    key: &str,
    chain: &mut Vec<PathBuf>,
) -> Result<Value, CliError> {
    match v {
        Value::Object(m) if m.contains_key("$file") => {
            let f = match (m.len(), m.get("$file")) {
                (1, Some(Value::String(f))) => f,
                _ => {
                    return Err(bad(
                        spec,
                        format!(
                        "{key}: a file reference is {{\"$file\": \"path.json\"}} and nothing else"
                    ),
                    ))
                }
            };
            let p = dir.join(f);
            crate::staging::protect_input(&p);
            let canon = std::fs::canonicalize(&p)
                .map_err(|e| bad(spec, format!("{key}: cannot read {}: {e}", p.display())))?;
            if chain.contains(&canon) {
                return Err(bad(
                    spec,
                    format!("{key}: {} includes itself (a $file cycle)", p.display()),
                ));
            }
            if chain.len() > MAX_INCLUDE_DEPTH {
                return Err(bad(
                    spec,
                    format!("{key}: $file references nested deeper than {MAX_INCLUDE_DEPTH}"),
                ));
            }
            let text = std::fs::read_to_string(&p)
                .map_err(|e| bad(spec, format!("{key}: cannot read {}: {e}", p.display())))?;
            let inner: Value = serde_json::from_str(&text).map_err(|e| {
                bad(
                    spec,
                    format!("{key}: {} is not valid JSON: {e}", p.display()),
                )
            })?;
            let sub = p.parent().unwrap_or(Path::new("."));
            chain.push(canon);
            let r = expand_files_in(&inner, sub, spec, key, chain);
            chain.pop();
            r
        }
        Value::Object(m) if m.contains_key("$path") => match (m.len(), m.get("$path")) {
            // a file the point reads itself (a glTF scene): its absolute path, resolved like
            // a $file reference
            (1, Some(Value::String(f))) => {
                let p = dir.join(f);
                crate::staging::protect_input(&p);
                let canon = std::fs::canonicalize(&p)
                    .map_err(|e| bad(spec, format!("{key}: cannot read {}: {e}", p.display())))?;
                Ok(Value::String(canon.to_string_lossy().into_owned()))
            }
            _ => Err(bad(
                spec,
                format!("{key}: a path reference is {{\"$path\": \"file\"}} and nothing else"),
            )),
        },
        Value::Object(m) => {
            let mut out = Map::new();
            for (k, x) in m {
                out.insert(
                    k.clone(),
                    expand_files_in(x, dir, spec, &format!("{key}.{k}"), chain)?,
                );
            }
            Ok(Value::Object(out))
        }
        Value::Array(a) => Ok(Value::Array(
            a.iter()
                .enumerate()
                .map(|(i, x)| expand_files_in(x, dir, spec, &format!("{key}[{i}]"), chain))
                .collect::<Result<_, _>>()?,
        )),
        other => Ok(other.clone()),
    }
}

/// Set `value` at the dot-separated `path` of `doc` (numeric segments index arrays; missing
/// object keys are created).
pub fn set_path(doc: &mut Value, path: &str, value: Value) -> Result<(), String> {
    let segs: Vec<&str> = path.split('.').collect();
    if path.is_empty() || segs.iter().any(|s| s.is_empty()) {
        return Err(format!("path \"{path}\" has an empty segment"));
    }
    let mut cur = doc;
    for (i, seg) in segs.iter().enumerate() {
        let last = i + 1 == segs.len();
        let here = segs[..i].join(".");
        cur = match cur {
            Value::Object(m) => {
                if last {
                    m.insert(seg.to_string(), value);
                    return Ok(());
                }
                m.entry(seg.to_string())
                    .or_insert_with(|| Value::Object(Map::new()))
            }
            Value::Array(a) => {
                let k: usize = seg.parse().map_err(|_| {
                    format!("path \"{path}\": \"{here}\" is a list, \"{seg}\" is not an index")
                })?;
                let n = a.len();
                let slot = a.get_mut(k).ok_or_else(|| {
                    format!("path \"{path}\": index {k} is outside the list \"{here}\" of {n}")
                })?;
                if last {
                    *slot = value;
                    return Ok(());
                }
                slot
            }
            _ => {
                return Err(format!(
                    "path \"{path}\": \"{here}\" is neither an object nor a list"
                ))
            }
        };
    }
    Ok(())
}

/// `template` with every string equal to `"$value"` replaced by `value`.
fn fill(template: &Value, value: &Value) -> Value {
    match template {
        Value::String(s) if s == "$value" => value.clone(),
        Value::Object(m) => {
            Value::Object(m.iter().map(|(k, v)| (k.clone(), fill(v, value))).collect())
        }
        Value::Array(a) => Value::Array(a.iter().map(|v| fill(v, value)).collect()),
        other => other.clone(),
    }
}

/// A short label for a parameter value.
fn label_of(v: &Value, i: usize) -> String {
    match v {
        Value::Number(n) => n.to_string(),
        Value::String(s) => s.clone(),
        Value::Bool(b) => b.to_string(),
        Value::Object(m) => match m.get("name") {
            Some(Value::String(s)) => s.clone(),
            _ => format!("#{}", i + 1),
        },
        _ => format!("#{}", i + 1),
    }
}

/// Read, validate and expand a study file.
pub fn load_study(path: &Path) -> Result<Study, CliError> {
    crate::staging::protect_input(path);
    let text = std::fs::read_to_string(path).map_err(|e| bad(path, format!("cannot read: {e}")))?;
    let raw: SpecFile =
        serde_json::from_str(&text).map_err(|e| bad(path, format!("invalid: {e}")))?;
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if !raw.point.is_object() {
        return Err(bad(
            path,
            "point: must be an object (the base point document)",
        ));
    }
    let mut base = expand_files(&raw.point, dir, path, "point")?;
    base["camsim_version"] = Value::String(env!("CARGO_PKG_VERSION").into());
    if base.get("kind").is_none() {
        base["kind"] = Value::String("capture".into());
    }
    let sweep = match raw.sweep.as_deref().unwrap_or("grid") {
        "grid" => Sweep::Grid,
        "list" => Sweep::List,
        other => {
            return Err(bad(
                path,
                format!("sweep: unknown value \"{other}\" (expected \"grid\" or \"list\")"),
            ))
        }
    };
    let mut parameters = Vec::new();
    let mut names = std::collections::HashSet::new();
    for (pi, p) in raw.parameters.iter().enumerate() {
        let key = format!("parameters[{pi}] ({})", p.name);
        if p.name.is_empty() || !names.insert(p.name.clone()) {
            return Err(bad(
                path,
                format!("{key}.name: must be non-empty and unique"),
            ));
        }
        if p.values.is_empty() {
            return Err(bad(path, format!("{key}.values: needs at least one value")));
        }
        let mut sets: Vec<(String, Value)> = Vec::new();
        if let Some(pp) = &p.path {
            sets.push((pp.clone(), Value::String("$value".into())));
        }
        for (k, t) in p.set.iter().flatten() {
            sets.push((k.clone(), t.clone()));
        }
        if sets.is_empty() {
            return Err(bad(
                path,
                format!(
                    "{key}: give \"path\" or \"set\" (where the value goes in the point document)"
                ),
            ));
        }
        let values = p
            .values
            .iter()
            .enumerate()
            .map(|(i, v)| expand_files(v, dir, path, &format!("{key}.values[{i}]")))
            .collect::<Result<Vec<_>, _>>()?;
        let mut with = Vec::new();
        for (k, list) in p.with.iter().flatten() {
            let a = list.as_array().ok_or_else(|| {
                bad(
                    path,
                    format!("{key}.with.{k}: must be a list with one value per entry of values"),
                )
            })?;
            if a.len() != values.len() {
                return Err(bad(
                    path,
                    format!(
                        "{key}.with.{k}: has {} values but values has {}",
                        a.len(),
                        values.len()
                    ),
                ));
            }
            let a = a
                .iter()
                .enumerate()
                .map(|(i, v)| expand_files(v, dir, path, &format!("{key}.with.{k}[{i}]")))
                .collect::<Result<Vec<_>, _>>()?;
            with.push((k.clone(), a));
        }
        let labels = match &p.labels {
            Some(l) if l.len() != values.len() => {
                return Err(bad(
                    path,
                    format!(
                        "{key}.labels: has {} labels for {} values",
                        l.len(),
                        values.len()
                    ),
                ))
            }
            Some(l) => l.clone(),
            None => values
                .iter()
                .enumerate()
                .map(|(i, v)| label_of(v, i))
                .collect(),
        };
        let numeric = values.iter().all(|v| v.is_number());
        parameters.push(Parameter {
            name: p.name.clone(),
            sets,
            values,
            with,
            labels,
            numeric,
        });
    }
    // The budget, before the points are enumerated: each planned point holds its own copy
    // of the point document (and its hash and folder name).
    let n_points: f64 = match sweep {
        Sweep::Grid => parameters.iter().map(|p| p.values.len() as f64).product(),
        Sweep::List => parameters.iter().map(|p| p.values.len()).max().unwrap_or(1) as f64,
    };
    let doc_bytes = serde_json::to_string(&base).map_or(1024, |t| t.len()) as f64;
    crate::budget::check_memory(
        Some(path),
        "parameters (the sweep)",
        n_points * (2.0 * doc_bytes + 512.0),
        &format!("{n_points:.3e} points × {doc_bytes} bytes of point document"),
    )?;
    // The points, in spec order.
    let coords: Vec<Vec<usize>> = match sweep {
        Sweep::Grid => {
            let mut all = vec![vec![]];
            for p in &parameters {
                let mut next = Vec::with_capacity(all.len() * p.values.len());
                for c in &all {
                    for i in 0..p.values.len() {
                        let mut c2 = c.clone();
                        c2.push(i);
                        next.push(c2);
                    }
                }
                all = next;
            }
            all
        }
        Sweep::List => {
            let n = parameters.first().map_or(1, |p| p.values.len());
            if let Some(p) = parameters.iter().find(|p| p.values.len() != n) {
                return Err(bad(
                    path,
                    format!(
                        "parameters: a \"list\" sweep needs lists of equal length; \"{}\" has {} values, \"{}\" has {n}",
                        p.name,
                        p.values.len(),
                        parameters[0].name
                    ),
                ));
            }
            (0..n).map(|i| vec![i; parameters.len()]).collect()
        }
    };
    let mut points = Vec::with_capacity(coords.len());
    for (index, c) in coords.into_iter().enumerate() {
        let mut doc = base.clone();
        for (p, &vi) in parameters.iter().zip(&c) {
            let v = &p.values[vi];
            for (pp, t) in &p.sets {
                set_path(&mut doc, pp, fill(t, v))
                    .map_err(|m| bad(path, format!("parameters ({}): {m}", p.name)))?;
            }
            for (pp, list) in &p.with {
                set_path(&mut doc, pp, list[vi].clone())
                    .map_err(|m| bad(path, format!("parameters ({}).with: {m}", p.name)))?;
            }
        }
        let hash = json_hash(&doc);
        points.push(PlannedPoint {
            index,
            coords: c,
            doc,
            hash,
        });
    }
    let plots = match &raw.plots {
        Some(list) => list
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let y: Vec<String> = match &p.y {
                    Value::String(s) => vec![s.clone()],
                    Value::Array(a) => a
                        .iter()
                        .map(|v| v.as_str().map(String::from))
                        .collect::<Option<Vec<_>>>()
                        .ok_or_else(|| bad(path, format!("plots[{i}].y: a metric name or a list of names")))?,
                    _ => return Err(bad(path, format!("plots[{i}].y: a metric name or a list of names"))),
                };
                for (what, name) in [("x", Some(&p.x)), ("series", p.series.as_ref())] {
                    if let Some(n) = name {
                        if !parameters.iter().any(|q| &q.name == n) {
                            return Err(bad(
                                path,
                                format!("plots[{i}].{what}: \"{n}\" is not a parameter (have: {})",
                                    parameters.iter().map(|q| q.name.as_str()).collect::<Vec<_>>().join(", ")),
                            ));
                        }
                    }
                }
                let mut filter = Vec::new();
                for (name, want) in p.filter.iter().flatten() {
                    let qi = parameters.iter().position(|q| &q.name == name).ok_or_else(|| {
                        bad(path, format!("plots[{i}].where.{name}: not a parameter"))
                    })?;
                    let q = &parameters[qi];
                    let vi = (0..q.values.len())
                        .find(|&k| &q.values[k] == want || want.as_str() == Some(q.labels[k].as_str()))
                        .ok_or_else(|| {
                            bad(path, format!("plots[{i}].where.{name}: {want} is none of its values or labels ({})", q.labels.join(", ")))
                        })?;
                    filter.push((qi, vi));
                }
                Ok(PlotSpec {
                    y,
                    x: p.x.clone(),
                    series: p.series.clone(),
                    title: p.title.clone(),
                    filter,
                })
            })
            .collect::<Result<Vec<_>, _>>()?,
        None => Vec::new(),
    };
    let name = raw.name.clone().unwrap_or_else(|| {
        path.file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "study".into())
    });
    Ok(Study {
        path: path.to_path_buf(),
        title: raw.title.clone().unwrap_or_else(|| name.clone()),
        name,
        description: raw.description.clone().unwrap_or_default(),
        parameters,
        sweep,
        plots,
        points,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn set_path_creates_objects_and_indexes_lists() {
        let mut d = json!({"a": {"b": [1, 2, {"c": 3}]}});
        set_path(&mut d, "a.b.2.c", json!(9)).unwrap();
        set_path(&mut d, "a.x.y", json!("new")).unwrap();
        set_path(&mut d, "a.b.0", json!(7)).unwrap();
        assert_eq!(d, json!({"a": {"b": [7, 2, {"c": 9}], "x": {"y": "new"}}}));
        assert!(set_path(&mut d, "a.b.5", json!(0))
            .unwrap_err()
            .contains("index 5"));
        assert!(set_path(&mut d, "a.b.q", json!(0))
            .unwrap_err()
            .contains("not an index"));
        assert!(set_path(&mut d, "a..b", json!(0))
            .unwrap_err()
            .contains("empty"));
    }

    #[test]
    fn grid_and_list_sweeps_in_spec_order() {
        let dir = tempfile::tempdir().unwrap();
        let spec = json!({"point": {"camera": {"x": 1}, "metrics": {}},
            "parameters": [
                {"name": "a", "path": "camera.x", "values": [1, 2]},
                {"name": "b", "set": {"conditions.l": "$value", "conditions.pair": ["$value", 0]},
                 "values": [10, 20, 30], "with": {"camera.w": ["p", "q", "r"]}}]});
        let p = dir.path().join("s.json");
        std::fs::write(&p, spec.to_string()).unwrap();
        let s = load_study(&p).unwrap();
        assert_eq!(s.points.len(), 6);
        let c: Vec<Vec<usize>> = s.points.iter().map(|p| p.coords.clone()).collect();
        assert_eq!(
            c,
            vec![
                vec![0, 0],
                vec![0, 1],
                vec![0, 2],
                vec![1, 0],
                vec![1, 1],
                vec![1, 2]
            ]
        );
        let d = &s.points[4].doc;
        assert_eq!(d["camera"]["x"], json!(2));
        assert_eq!(d["conditions"]["l"], json!(20));
        assert_eq!(d["conditions"]["pair"], json!([20, 0]));
        assert_eq!(d["camera"]["w"], json!("q"));
        assert_eq!(d["kind"], json!("capture"));
        let hashes: std::collections::HashSet<_> = s.points.iter().map(|p| &p.hash).collect();
        assert_eq!(hashes.len(), 6);
        // list sweep: equal lengths required
        let mut spec2 = spec.clone();
        spec2["sweep"] = json!("list");
        std::fs::write(&p, spec2.to_string()).unwrap();
        let e = load_study(&p).unwrap_err().one_line();
        assert!(e.contains("equal length") && e.contains("s.json"), "{e}");
        spec2["parameters"][1]["values"] = json!([10, 20]);
        spec2["parameters"][1]["with"] = json!({"camera.w": ["p", "q"]});
        std::fs::write(&p, spec2.to_string()).unwrap();
        let s = load_study(&p).unwrap();
        assert_eq!(s.points.len(), 2);
        assert_eq!(s.points[1].doc["conditions"]["l"], json!(20));
    }

    #[test]
    fn file_references_are_inlined_relative_to_their_file() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        std::fs::write(
            dir.path().join("sub/cam.json"),
            r#"{"inner": {"$file": "leaf.json"}}"#,
        )
        .unwrap();
        std::fs::write(dir.path().join("sub/leaf.json"), r#"{"v": 3}"#).unwrap();
        let spec = json!({"point": {"camera": {"$file": "sub/cam.json"}}, "parameters": []});
        let p = dir.path().join("s.json");
        std::fs::write(&p, spec.to_string()).unwrap();
        let s = load_study(&p).unwrap();
        assert_eq!(s.points.len(), 1);
        assert_eq!(s.points[0].doc["camera"]["inner"]["v"], json!(3));
        let spec = json!({"point": {"camera": {"$file": "missing.json"}}});
        std::fs::write(&p, spec.to_string()).unwrap();
        let e = load_study(&p).unwrap_err().one_line();
        assert!(
            e.contains("point.camera") && e.contains("missing.json"),
            "{e}"
        );
    }
}
