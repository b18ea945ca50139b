//! The study report: `report.html` with metric-vs-parameter plots (PNG, `figures/`), image
//! strips of the points' images, and the table.
//!
//! A plot puts a parameter on x, draws one curve per value of its `series` parameter (and per
//! y metric), and is repeated for every combination of the remaining parameters (facets).
//! Without `plots` in the spec, every metric is plotted against the first numeric parameter
//! with the next parameter as series.
use super::spec::{PlotSpec, Study};
use super::table::{Cell, Table};
use super::StudySummary;
use crate::error::CliError;
use crate::report::html_escape;
use camsim_core::exr_io::write_atomically;
use serde_json::Value;
use std::path::Path;

/// Most figures per plot spec (facets beyond are left out of the report, not of the table).
const MAX_FACETS: usize = 12;
/// Most rows of an image strip.
const MAX_STRIP_ROWS: usize = 12;

/// The plots to draw: the spec's, or the default ones.
pub fn plot_specs(study: &Study, table: &Table) -> Vec<PlotSpec> {
    if !study.plots.is_empty() {
        return study.plots.clone();
    }
    let Some(x) = study
        .parameters
        .iter()
        .find(|p| p.numeric)
        .or(study.parameters.first())
    else {
        return Vec::new();
    };
    let series = study
        .parameters
        .iter()
        .find(|p| p.name != x.name)
        .map(|p| p.name.clone());
    table
        .metric_columns()
        .iter()
        .map(|m| PlotSpec {
            y: vec![m.clone()],
            x: x.name.clone(),
            series: series.clone(),
            title: None,
            filter: Vec::new(),
        })
        .collect()
}

/// Parameter indices of a plot: x, series, and the facet parameters.
struct Roles {
    x: usize,
    series: Option<usize>,
    facets: Vec<usize>,
}

fn roles(study: &Study, p: &PlotSpec) -> Roles {
    let idx = |n: &str| study.parameters.iter().position(|q| q.name == n);
    let x = idx(&p.x).expect("validated");
    let series = p.series.as_deref().and_then(idx);
    let facets = (0..study.parameters.len())
        .filter(|&i| i != x && Some(i) != series)
        .collect();
    Roles { x, series, facets }
}

/// Distinct facet combinations (value indices of the facet parameters) in spec order.
fn facet_keys(study: &Study, facets: &[usize], filter: &[(usize, usize)]) -> Vec<Vec<usize>> {
    let mut keys: Vec<Vec<usize>> = Vec::new();
    for p in &study.points {
        if filter.iter().any(|&(q, v)| p.coords[q] != v) {
            continue;
        }
        let k: Vec<usize> = facets.iter().map(|&f| p.coords[f]).collect();
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    keys
}

fn facet_label(study: &Study, facets: &[usize], key: &[usize]) -> String {
    facets
        .iter()
        .zip(key)
        .map(|(&f, &i)| {
            let q = &study.parameters[f];
            format!("{} = {}", q.name, q.labels[i])
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Draw the figures; returns (file relative to `out`, caption).
fn figures(out: &Path, study: &Study, table: &Table) -> Result<Vec<(String, String)>, CliError> {
    let dir = out.join("figures");
    std::fs::create_dir_all(&dir).map_err(|e| CliError::output(&dir, e))?;
    let mut figs = Vec::new();
    for (pi, ps) in plot_specs(study, table).iter().enumerate() {
        let ycols: Vec<usize> = ps.y.iter().filter_map(|m| table.col(m)).collect();
        if ycols.is_empty() {
            continue;
        }
        let r = roles(study, ps);
        let xp = &study.parameters[r.x];
        let keys = facet_keys(study, &r.facets, &ps.filter);
        for (fi, key) in keys.iter().take(MAX_FACETS).enumerate() {
            let mut series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
            let n_series = r.series.map_or(1, |s| study.parameters[s].values.len());
            for &yc in &ycols {
                // One curve per series value; a metric that does not depend on the series
                // parameter (e.g. the pixel-aperture limit) is drawn once.
                let curves: Vec<(String, Vec<(f64, f64)>)> = (0..n_series)
                    .map(|si| {
                        let mut pts: Vec<(f64, f64)> = Vec::new();
                        for (p, row) in study.points.iter().zip(&table.rows) {
                            let fk: Vec<usize> = r.facets.iter().map(|&f| p.coords[f]).collect();
                            if &fk != key
                                || r.series.is_some_and(|s| p.coords[s] != si)
                                || ps.filter.iter().any(|&(q, v)| p.coords[q] != v)
                            {
                                continue;
                            }
                            let x = if xp.numeric {
                                xp.values[p.coords[r.x]].as_f64().unwrap_or(f64::NAN)
                            } else {
                                p.coords[r.x] as f64
                            };
                            if let Cell::Num(y) = row[yc] {
                                pts.push((x, y));
                            }
                        }
                        pts.sort_by(|a, b| {
                            a.0.partial_cmp(&b.0).unwrap_or(std::cmp::Ordering::Equal)
                        });
                        pts.dedup_by(|a, b| a.0 == b.0);
                        let name = match r.series {
                            Some(s) => {
                                let q = &study.parameters[s];
                                format!("{} = {}", q.name, q.labels[si])
                            }
                            None => String::new(),
                        };
                        (name, pts)
                    })
                    .filter(|c| !c.1.is_empty())
                    .collect();
                let same = curves.windows(2).all(|w| w[0].1 == w[1].1);
                if same && curves.len() > 1 {
                    series.push((table.columns[yc].clone(), curves[0].1.clone()));
                    continue;
                }
                for (name, pts) in curves {
                    let name = match (name.is_empty(), ycols.len() > 1) {
                        (true, _) => table.columns[yc].clone(),
                        (false, true) => format!("{name}, {}", table.columns[yc]),
                        (false, false) => name,
                    };
                    series.push((name, pts));
                }
            }
            if series.is_empty() {
                continue;
            }
            let ylabel = ps.y.join(", ");
            let xlabel = if xp.numeric {
                xp.name.clone()
            } else {
                format!("{} ({})", xp.name, xp.labels.join(" | "))
            };
            let facet = facet_label(study, &r.facets, key);
            // Title: the spec's (or the metrics), then the values of the facet parameters
            // that vary between the figures.
            let varying: Vec<String> = r
                .facets
                .iter()
                .zip(key)
                .filter(|(&f, _)| {
                    keys.iter().any(|k2| {
                        k2 != key && {
                            let j = r.facets.iter().position(|&g| g == f).expect("facet");
                            k2[j] != key[j]
                        }
                    })
                })
                .map(|(&f, &i)| study.parameters[f].labels[i].clone())
                .collect();
            let mut title = ps.title.clone().unwrap_or_else(|| ylabel.clone());
            if !varying.is_empty() {
                title = format!("{title} — {}", varying.join(", "));
            }
            if title.chars().count() > 64 {
                title = title.chars().take(63).collect::<String>() + "…";
            }
            let file = format!("figures/plot{pi:02}_{fi:02}.png");
            crate::plots::line_plot(&out.join(&file), &title, &series, (&xlabel, &ylabel))?;
            let caption = if facet.is_empty() {
                format!("{ylabel} against {}", xp.name)
            } else {
                format!("{ylabel} against {} ({facet})", xp.name)
            };
            figs.push((file, caption));
        }
    }
    Ok(figs)
}

/// Write `report.html` (and its figures) into `out`.
pub fn write(
    out: &Path,
    study: &Study,
    table: &Table,
    results: &[Option<Value>],
    summary: &StudySummary,
) -> Result<(), CliError> {
    let figs = figures(out, study, table)?;
    let mut h = String::new();
    h.push_str(&format!(
        "<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title>",
        html_escape(&study.title)
    ));
    h.push_str("<style>body{font-family:sans-serif;max-width:1300px;margin:2em auto;color:#222}figure{display:inline-block;margin:6px;vertical-align:top}figure img{max-width:600px;border:1px solid #ccc}.strip img{width:96px;image-rendering:pixelated;border:1px solid #ccc}.strip figure{margin:2px;font-size:11px;text-align:center}table{border-collapse:collapse;font-size:12px}td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}th{background:#f3f3f3}</style></head><body>");
    h.push_str(&format!("<h1>{}</h1>", html_escape(&study.title)));
    if !study.description.is_empty() {
        h.push_str(&format!("<p>{}</p>", html_escape(&study.description)));
    }
    h.push_str(&format!(
        "<p>Study <code>{}</code>: {} points ({} sweep); this run evaluated {}, reused {} finished; {} pending. Tables: <a href=\"table.csv\">table.csv</a>, <a href=\"table.json\">table.json</a>. Definitions of the metrics: docs/study.md.</p>",
        html_escape(&study.name),
        summary.points,
        match study.sweep { super::spec::Sweep::Grid => "grid", super::spec::Sweep::List => "list" },
        summary.evaluated,
        summary.reused,
        summary.pending
    ));
    h.push_str("<h2>Parameters</h2><table><tr><th>parameter</th><th>values</th></tr>");
    for p in &study.parameters {
        h.push_str(&format!(
            "<tr><th style=\"text-align:left\">{}</th><td style=\"text-align:left\">{}</td></tr>",
            html_escape(&p.name),
            html_escape(&p.labels.join(", "))
        ));
    }
    h.push_str("</table><h2>Plots</h2>");
    for (f, c) in &figs {
        h.push_str(&format!(
            "<figure><img src=\"{}\" alt=\"{}\"><figcaption>{}</figcaption></figure>",
            html_escape(f),
            html_escape(c),
            html_escape(c)
        ));
    }
    // Image strips: per image kind, one row per combination of the non-x parameters.
    let mut kinds: Vec<(String, String)> = Vec::new();
    for r in results.iter().flatten() {
        for im in r["images"].as_array().into_iter().flatten() {
            let f = im["file"].as_str().unwrap_or("").to_string();
            if !f.is_empty() && !kinds.iter().any(|k| k.0 == f) {
                kinds.push((f, im["caption"].as_str().unwrap_or("").to_string()));
            }
        }
    }
    if !kinds.is_empty() && !study.parameters.is_empty() {
        // Along the x of the first plot (else the first numeric parameter).
        let x = plot_specs(study, table)
            .first()
            .and_then(|p| study.parameters.iter().position(|q| q.name == p.x))
            .or_else(|| study.parameters.iter().position(|p| p.numeric))
            .unwrap_or(0);
        let others: Vec<usize> = (0..study.parameters.len()).filter(|&i| i != x).collect();
        h.push_str("<h2>Images</h2>");
        for (file, caption) in &kinds {
            h.push_str(&format!(
                "<h3>{} — along {}</h3>",
                html_escape(caption),
                html_escape(&study.parameters[x].name)
            ));
            for key in facet_keys(study, &others, &[]).iter().take(MAX_STRIP_ROWS) {
                h.push_str(&format!(
                    "<div class=\"strip\"><div>{}</div>",
                    html_escape(&facet_label(study, &others, key))
                ));
                for (p, r) in study.points.iter().zip(results) {
                    let k: Vec<usize> = others.iter().map(|&f| p.coords[f]).collect();
                    if &k != key || r.is_none() {
                        continue;
                    }
                    let src = format!("points/{}/{}", p.folder(), file);
                    if !out.join(&src).exists() {
                        continue;
                    }
                    let q = &study.parameters[x];
                    h.push_str(&format!(
                        "<figure><img src=\"{}\" alt=\"{}\"><figcaption>{}</figcaption></figure>",
                        html_escape(&src),
                        html_escape(file),
                        html_escape(&format!("{} = {}", q.name, q.labels[p.coords[x]]))
                    ));
                }
                h.push_str("</div>");
            }
        }
    }
    h.push_str("<h2>Table</h2><table><tr>");
    for c in &table.columns {
        h.push_str(&format!("<th>{}</th>", html_escape(c)));
    }
    h.push_str("</tr>");
    for row in &table.rows {
        h.push_str("<tr>");
        for c in row {
            let s = match c {
                Cell::Num(x) => format!("{}", (x * 1e4).round() / 1e4),
                Cell::Text(t) => t.clone(),
                Cell::Empty => "–".into(),
            };
            h.push_str(&format!("<td>{}</td>", html_escape(&s)));
        }
        h.push_str("</tr>");
    }
    h.push_str("</table></body></html>\n");
    let p = out.join("report.html");
    write_atomically(&p, |tmp| std::fs::write(tmp, h.as_bytes()))
        .map_err(|e| CliError::output(&p, e))
}
