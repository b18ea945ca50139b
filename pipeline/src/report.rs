//! HTML reports: a self-contained page that shows the figures (PNG files beside it) and the
//! numbers of summary.json.
use serde_json::Value;

/// Escapes text for HTML element content and attribute values (`&`, `<`, `>`, `"`): the one
/// escaping function of every report page.
pub fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn num(v: &Value, key: &str) -> String {
    v.get(key)
        .and_then(Value::as_f64)
        .map(|x| format!("{x:.4}"))
        .unwrap_or_else(|| "–".into())
}

/// The report of `camsim run`.
pub fn run_report_html(summary: &Value, figures: &[(&str, &str)]) -> String {
    let mut h = String::new();
    h.push_str("<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>camsim run report</title>");
    h.push_str("<style>body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}figure{display:inline-block;margin:8px;vertical-align:top}figure img{max-width:520px;border:1px solid #ccc;image-rendering:pixelated}table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}th{background:#f3f3f3}</style></head><body>");
    h.push_str("<h1>camsim run</h1>");
    h.push_str("<p>Scene → optics → sensor → processor → display, after Farrell, Catrysse &amp; Wandell, <i>Digital camera simulation</i>, Applied Optics 2012 (§3).</p>");
    h.push_str("<h2>Settings</h2><table>");
    let rows = [
        (
            "camera",
            summary["camera"].as_str().unwrap_or("").to_string(),
        ),
        (
            "configuration",
            summary["config"].as_str().unwrap_or("").to_string(),
        ),
        (
            "scene mean luminance (cd/m²)",
            num(summary, "scene_mean_luminance_cd_m2"),
        ),
        ("exposure (s)", num(summary, "exposure_s")),
        ("raw mean (DN)", num(summary, "raw_mean_dn")),
        (
            "demosaic",
            summary["processor"]["demosaic"]
                .as_str()
                .unwrap_or("")
                .to_string(),
        ),
        (
            "white balance",
            summary["processor"]["white_balance"]
                .as_str()
                .unwrap_or("")
                .to_string(),
        ),
        (
            "colour correction fitted on",
            summary["processor"]["ccm_fitted_on"]
                .as_str()
                .unwrap_or("")
                .to_string(),
        ),
        (
            "display",
            summary["display"]["name"]
                .as_str()
                .unwrap_or("")
                .to_string(),
        ),
    ];
    for (k, v) in rows {
        h.push_str(&format!(
            "<tr><th style=\"text-align:left\">{}</th><td style=\"text-align:left\">{}</td></tr>",
            html_escape(k),
            html_escape(&v)
        ));
    }
    h.push_str("</table>");
    if summary.get("delta_e_2000").is_some() {
        h.push_str("<h2>Colour accuracy</h2><table><tr><th></th><th>mean</th><th>median</th><th>95th pct</th><th>max</th></tr>");
        for (name, key) in [("ΔE2000", "delta_e_2000"), ("ΔE*ab (1976)", "delta_e_76")] {
            let d = &summary[key];
            h.push_str(&format!(
                "<tr><th>{name}</th><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                num(d, "mean"),
                num(d, "median"),
                num(d, "p95"),
                num(d, "max")
            ));
        }
        if let Some(f) = summary.get("delta_e_2000_fitted") {
            h.push_str(&format!(
                "<tr><th>ΔE2000 fitted (calibration capture)</th><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                num(f, "mean"),
                num(f, "median"),
                num(f, "p95"),
                num(f, "max")
            ));
        }
        h.push_str("</table>");
        if let Some(w) = summary.get("delta_e_scored_on").and_then(|v| v.as_str()) {
            h.push_str(&format!("<p>ΔE scored on {}.</p>", html_escape(w)));
        }
        if let Some(rows) = summary
            .get("white_balance_comparison")
            .and_then(|v| v.as_array())
        {
            h.push_str("<h3>White balance (matrix fitted on the calibration capture, scored on this scene)</h3><table><tr><th>white balance</th><th>fitted mean ΔE2000</th><th>held-out mean ΔE2000</th><th>held-out max ΔE2000</th></tr>");
            for r in rows {
                h.push_str(&format!(
                    "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                    html_escape(r["white_balance"].as_str().unwrap_or("")),
                    num(r, "fitted_delta_e_2000_mean"),
                    num(r, "held_out_delta_e_2000_mean"),
                    num(r, "held_out_delta_e_2000_max")
                ));
            }
            h.push_str("</table>");
        }
    }
    h.push_str("<h2>Figures</h2>");
    for (file, caption) in figures {
        h.push_str(&format!(
            "<figure><img src=\"{}\" alt=\"{}\"><figcaption>{}</figcaption></figure>",
            html_escape(file),
            html_escape(caption),
            html_escape(caption)
        ));
    }
    if let Some(snr) = summary.get("patch_snr") {
        h.push_str("<h2>Per-patch SNR (dB, raw)</h2><table><tr><th>patch</th><th>R</th><th>G</th><th>B</th></tr>");
        for i in 0..24 {
            let cell = |c: &str| {
                snr[c][i]["snr_db"]
                    .as_f64()
                    .map(|x| format!("{x:.1}"))
                    .unwrap_or_default()
            };
            h.push_str(&format!(
                "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                i + 1,
                cell("r"),
                cell("g"),
                cell("b")
            ));
        }
        h.push_str("</table>");
    }
    h.push_str("<h2>Files</h2><ul>");
    for f in summary["files"].as_array().into_iter().flatten() {
        let f = f.as_str().unwrap_or("");
        h.push_str(&format!("<li><a href=\"{0}\">{0}</a></li>", html_escape(f)));
    }
    h.push_str("</ul></body></html>\n");
    h
}
