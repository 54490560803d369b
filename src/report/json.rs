//! The run report's data and its JSON form (`report.json`).
//!
//! The top level always has the keys `case`, `backend`, `precision`, `particles`, `steps`,
//! `wall_s`, `particle_steps_per_s` and `results` (a list of `{quantity, unit, value, reference,
//! rel_error, source}`), plus `bytes_per_particle`, `histories`, `notes`, `resolution`, `dx`,
//! `end_time` and `tables`.
//!
//! JSON has no NaN or infinity: non-finite numbers are written as `null` (serde_json's
//! behaviour) and read back as NaN, so a report of a diverged run still parses.

use std::io;
use std::path::Path;

use serde::{Deserialize, Deserializer, Serialize};

/// Everything a run reports.
#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct RunReport {
    pub case: String,
    /// `"cpu"` or `"gpu (adapter name)"`.
    pub backend: String,
    /// `"f32"` or `"f64"`.
    pub precision: String,
    pub particles: usize,
    pub steps: u64,
    #[serde(deserialize_with = "f64_or_nan")]
    pub wall_s: f64,
    #[serde(deserialize_with = "f64_or_nan")]
    pub particle_steps_per_s: f64,
    pub results: Vec<ResultRow>,
    /// Particle state bytes per particle, per group.
    #[serde(default)]
    pub bytes_per_particle: Vec<GroupBytes>,
    /// Time series for plots.
    #[serde(default)]
    pub histories: Vec<History>,
    /// Free text, e.g. how a figure was measured.
    #[serde(default)]
    pub notes: Vec<String>,
    #[serde(default)]
    pub resolution: String,
    /// The resolution's particle spacing [m] (0 in reports written before it was recorded).
    #[serde(default)]
    pub dx: f64,
    #[serde(default, deserialize_with = "f64_or_nan")]
    pub end_time: f64,
    /// Tables beyond the results, e.g. a convergence study's value at each resolution.
    #[serde(default)]
    pub tables: Vec<Table>,
}

/// A titled table of text cells, rendered as is into `report.md`.
#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct Table {
    pub title: String,
    pub header: Vec<String>,
    pub rows: Vec<Vec<String>>,
}

/// One measured quantity, with an optional reference value to compare against.
#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct ResultRow {
    pub quantity: String,
    pub unit: String,
    #[serde(deserialize_with = "f64_or_nan")]
    pub value: f64,
    pub reference: Option<f64>,
    /// `(value − reference) / |reference|`.
    pub rel_error: Option<f64>,
    /// Where the reference comes from (a paper, an analytic solution).
    #[serde(default)]
    pub source: Option<String>,
    /// The standard error of a value that is a mean over runs (a study's `mean`): the sample
    /// standard deviation of the runs' values over √n.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub standard_error: Option<f64>,
}

impl ResultRow {
    /// A row; `rel_error` is `(value − reference) / |reference|` when a reference is given and is
    /// finite and non-zero, otherwise `None`.
    pub fn new(quantity: impl Into<String>, unit: impl Into<String>, value: f64, reference: Option<f64>) -> Self {
        let rel_error = reference.filter(|r| *r != 0.0 && r.is_finite()).map(|r| (value - r) / r.abs());
        ResultRow {
            quantity: quantity.into(),
            unit: unit.into(),
            value,
            reference,
            rel_error,
            source: None,
            standard_error: None,
        }
    }

    /// Sets where the reference value comes from.
    pub fn with_source(mut self, source: impl Into<String>) -> Self {
        self.source = Some(source.into());
        self
    }
}

/// Particle state bytes per particle of one particle group.
#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct GroupBytes {
    pub group: String,
    pub bytes: usize,
}

/// A plot: one or more curves against a common x axis, and an optional horizontal reference line.
#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct History {
    pub name: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Curve>,
    /// An optional horizontal reference line at this y.
    #[serde(default)]
    pub reference: Option<f64>,
    /// Both axes logarithmic (points with a coordinate ≤ 0 are left out).
    #[serde(default)]
    pub log_log: bool,
}

/// One named curve of a [`History`]: `(x, y)` points in order.
#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct Curve {
    pub name: String,
    #[serde(deserialize_with = "points_or_nan")]
    pub points: Vec<(f64, f64)>,
}

impl Curve {
    pub fn new(name: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Curve { name: name.into(), points }
    }
}

fn f64_or_nan<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

fn points_or_nan<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<(f64, f64)>, D::Error> {
    let raw = Vec::<(Option<f64>, Option<f64>)>::deserialize(d)?;
    Ok(raw.into_iter().map(|(x, y)| (x.unwrap_or(f64::NAN), y.unwrap_or(f64::NAN))).collect())
}

/// The report as pretty-printed JSON, each array of numbers (and of such arrays: a curve's
/// points) on one line: a history's thousands of samples would otherwise take a line each, and
/// the reports kept in docs/results/ 2.3 times the bytes.
pub fn to_json(report: &RunReport) -> String {
    let mut text = serde_json::to_string_pretty(report).expect("a RunReport always serializes");
    loop {
        let joined = number_arrays_on_one_line(&text);
        if joined.len() == text.len() {
            return text;
        }
        text = joined;
    }
}

/// `text` (pretty-printed JSON) with every array whose items, one per line, are all numbers,
/// nulls or arrays of them on one line, joined onto the line that opens it.
fn number_arrays_on_one_line(text: &str) -> String {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = String::with_capacity(text.len());
    let mut k = 0;
    while k < lines.len() {
        let line = lines[k];
        if line.ends_with('[') {
            let items: Vec<&str> = lines[k + 1..].iter().map(|l| l.trim()).take_while(|l| is_number_item(l)).collect();
            let close = lines.get(k + 1 + items.len()).map(|l| l.trim_start());
            if let Some(close) = close.filter(|c| !items.is_empty() && c.starts_with(']')) {
                let joined: Vec<&str> = items.iter().map(|item| item.trim_end_matches(',')).collect();
                out.push_str(line);
                out.push_str(&joined.join(","));
                out.push_str(close);
                out.push('\n');
                k += items.len() + 2;
                continue;
            }
        }
        out.push_str(line);
        out.push('\n');
        k += 1;
    }
    out.pop();
    out
}

/// Whether a line of pretty-printed JSON, trimmed, is one item of an array that is a number, null
/// or an array of them on one line.
fn is_number_item(line: &str) -> bool {
    let item = line.trim_end_matches(',');
    let flat_array = item.starts_with('[') && item.ends_with(']') && !item.contains(['"', '{']);
    item == "null" || flat_array || item.parse::<f64>().is_ok()
}

/// Parses a report written by [`to_json`].
pub fn from_json(text: &str) -> serde_json::Result<RunReport> {
    serde_json::from_str(text)
}

/// Writes the report as JSON to `path` (through a temporary file and a rename).
pub fn write_json(path: &Path, report: &RunReport) -> io::Result<()> {
    let mut text = to_json(report);
    text.push('\n');
    crate::output_dir::write_atomic(path, text.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arrays_of_numbers_go_on_one_line_and_read_back_the_same() {
        let value =
            serde_json::json!({"t": [0.0, 1e-5, -2.5], "names": ["a", "b"], "empty": [], "v": [[1, 2], [3, null]]});
        let mut text = serde_json::to_string_pretty(&value).unwrap();
        for _ in 0..3 {
            text = number_arrays_on_one_line(&text);
        }
        assert!(text.contains("\"t\": [0.0,0.00001,-2.5]"), "{text}");
        assert!(text.contains("\"names\": [\n"), "{text}");
        assert!(text.contains("\"v\": [[1,2],[3,null]]"), "{text}");
        assert_eq!(serde_json::from_str::<serde_json::Value>(&text).unwrap(), value);
    }

    #[test]
    fn rel_error() {
        let r = ResultRow::new("rho", "kg/m^3", 1010.0, Some(1000.0));
        assert!((r.rel_error.unwrap() - 0.01).abs() < 1e-15);
        let r = ResultRow::new("x", "m", -1.1, Some(-1.0));
        assert!((r.rel_error.unwrap() + 0.1).abs() < 1e-12, "{:?}", r.rel_error);
        assert_eq!(ResultRow::new("x", "m", 1.0, Some(0.0)).rel_error, None);
        assert_eq!(ResultRow::new("x", "m", 1.0, None).rel_error, None);
        assert_eq!(ResultRow::new("x", "m", 1.0, None).with_source("paper").source.as_deref(), Some("paper"));
    }

    #[test]
    fn non_finite_numbers_round_trip_as_nan() {
        let report = RunReport {
            case: "diverged".into(),
            wall_s: f64::INFINITY,
            particle_steps_per_s: f64::NAN,
            results: vec![ResultRow::new("e", "J", f64::NAN, Some(1.0))],
            histories: vec![History {
                name: "e".into(),
                series: vec![Curve::new("e", vec![(0.0, 1.0), (1.0, f64::NAN)])],
                ..Default::default()
            }],
            ..Default::default()
        };
        let text = to_json(&report);
        let back = from_json(&text).unwrap();
        assert!(back.wall_s.is_nan() && back.particle_steps_per_s.is_nan());
        assert!(back.results[0].value.is_nan());
        assert_eq!(back.results[0].rel_error, None);
        assert_eq!(back.histories[0].series[0].points[0], (0.0, 1.0));
        assert!(back.histories[0].series[0].points[1].1.is_nan());
    }
}
