//! The outputs of a run, independent of how the run was computed: everything here takes plain
//! `f64` data.
//!
//! - [`vtk`]: particle snapshots as VTK XML unstructured grids (`.vtu`) and a `.pvd` time series
//!   that ParaView opens.
//! - [`json`]: the machine-readable run report (`report.json`) and its types.
//! - [`markdown`]: the human-readable run report (`report.md`) with embedded plots.
//! - [`plot`]: SVG line plots of time histories.
//! - [`convergence`]: a case run at several resolutions: error at each, observed order, Richardson.
//! - [`uncertainty`]: the numerical uncertainty of a study's finest value, from least-squares fits through
//!   four or more levels.
//! - [`csv`]: the time histories as `histories.csv`, one column per probe.
//!
//! [`write`] writes a whole report directory: `report.json`, `report.md`, `histories.csv` and one
//! SVG per history.

pub mod convergence;
pub mod csv;
pub mod json;
pub mod markdown;
pub mod plot;
pub mod uncertainty;
pub mod vtk;

use std::io;
use std::path::Path;

pub use json::{Curve, GroupBytes, History, ResultRow, RunReport};
pub use vtk::{pvtu_pieces, read_pvtu, read_vtu, write_vtu, PointField, Series, VtuData};

/// Writes `dir/report.json`, `dir/report.md`, `dir/histories.csv` (when there are time
/// histories) and, for every history, `dir/<name>.svg` (see
/// [`markdown::plot_file_name`]). Creates `dir` if needed. A plot that cannot be drawn does not
/// fail the report: `report.md` says why in its place. Errors are I/O errors only.
/// Writes `histories.csv` into `dir` (atomically: a reader sees the old file or the new), when
/// any of `histories` is a time history.
pub fn write_histories_csv(dir: &Path, histories: &[History]) -> io::Result<()> {
    match csv::histories_csv(histories) {
        Some(text) => crate::output_dir::write_atomic(&dir.join("histories.csv"), text.as_bytes()),
        None => Ok(()),
    }
}

pub fn write(dir: &Path, report: &RunReport) -> io::Result<()> {
    std::fs::create_dir_all(dir)?;
    json::write_json(&dir.join("report.json"), report)?;
    write_histories_csv(dir, &report.histories)?;
    markdown::write_markdown(dir, report)
}
