//! The study table: one row per point in spec order, the parameters (labels, and values when
//! numeric) then the metrics; written as CSV and JSON (atomically).
use super::spec::Study;
use crate::error::CliError;
use camsim_core::exr_io::write_atomically;
use serde_json::{json, Value};
use std::path::Path;

/// A cell.
#[derive(Debug, Clone, PartialEq)]
pub enum Cell {
    /// A number (metric or numeric parameter).
    Num(f64),
    /// Text (a label).
    Text(String),
    /// Missing (point not finished, or metric not measurable).
    Empty,
}

/// The table.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// Column names: `point`, `folder`, the parameters, the metrics.
    pub columns: Vec<String>,
    /// Number of leading non-metric columns.
    pub n_key_columns: usize,
    /// One row per point, spec order.
    pub rows: Vec<Vec<Cell>>,
}

impl Table {
    /// Index of a column.
    pub fn col(&self, name: &str) -> Option<usize> {
        self.columns.iter().position(|c| c == name)
    }
    /// The metric columns.
    pub fn metric_columns(&self) -> &[String] {
        &self.columns[self.n_key_columns..]
    }
}

/// Build the table from the points' results (`None` = unfinished).
pub fn build(study: &Study, results: &[Option<Value>]) -> Table {
    let mut columns = vec!["point".to_string(), "folder".to_string()];
    for p in &study.parameters {
        columns.push(p.name.clone());
    }
    let n_key = columns.len();
    let mut metrics: Vec<String> = Vec::new();
    for r in results.iter().flatten() {
        for m in r["metric_order"].as_array().into_iter().flatten() {
            if let Some(m) = m.as_str() {
                if !metrics.iter().any(|x| x == m) {
                    metrics.push(m.to_string());
                }
            }
        }
    }
    columns.extend(metrics.iter().cloned());
    let rows = study
        .points
        .iter()
        .zip(results)
        .map(|(p, r)| {
            let mut row = vec![Cell::Num(p.index as f64), Cell::Text(p.folder())];
            for (q, &i) in study.parameters.iter().zip(&p.coords) {
                row.push(match q.values[i].as_f64() {
                    Some(x) if q.numeric => Cell::Num(x),
                    _ => Cell::Text(q.labels[i].clone()),
                });
            }
            for m in &metrics {
                row.push(
                    r.as_ref()
                        .and_then(|r| r["metrics"][m.as_str()].as_f64())
                        .map_or(Cell::Empty, Cell::Num),
                );
            }
            row
        })
        .collect();
    Table {
        columns,
        n_key_columns: n_key,
        rows,
    }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// The CSV text (numbers in Rust's shortest round-trip form, empty cells for missing values).
pub fn to_csv(t: &Table) -> String {
    let mut s = t
        .columns
        .iter()
        .map(|c| csv_field(c))
        .collect::<Vec<_>>()
        .join(",");
    s.push('\n');
    for row in &t.rows {
        let line: Vec<String> = row
            .iter()
            .map(|c| match c {
                Cell::Num(x) => format!("{x}"),
                Cell::Text(x) => csv_field(x),
                Cell::Empty => String::new(),
            })
            .collect();
        s.push_str(&line.join(","));
        s.push('\n');
    }
    s
}

/// The JSON form: `{"columns": [...], "rows": [{column: value}]}`.
pub fn to_json(t: &Table) -> Value {
    let rows: Vec<Value> = t
        .rows
        .iter()
        .map(|row| {
            let mut m = serde_json::Map::new();
            for (c, v) in t.columns.iter().zip(row) {
                m.insert(
                    c.clone(),
                    match v {
                        Cell::Num(x) => json!(x),
                        Cell::Text(x) => json!(x),
                        Cell::Empty => Value::Null,
                    },
                );
            }
            Value::Object(m)
        })
        .collect();
    json!({"columns": t.columns, "rows": rows})
}

/// Write `table.csv` and `table.json` into `out`.
pub fn write(out: &Path, t: &Table) -> Result<(), CliError> {
    let csv = to_csv(t);
    let p = out.join("table.csv");
    write_atomically(&p, |tmp| std::fs::write(tmp, csv.as_bytes()))
        .map_err(|e| CliError::output(&p, e))?;
    let js = serde_json::to_string_pretty(&to_json(t)).expect("json");
    let p = out.join("table.json");
    write_atomically(&p, |tmp| std::fs::write(tmp, js.as_bytes()))
        .map_err(|e| CliError::output(&p, e))?;
    Ok(())
}
