//! Case files and geometry: from a case file to particles, materials, loads, symmetry planes,
//! outputs and the probes a run records.

pub mod build;
pub mod case;
pub mod geometry;
pub mod measure;
pub mod quantity;
pub mod spec;
pub mod study;
pub mod template;

pub use build::load;

/// The largest of `start` and `values`, NaN if any of them is NaN (`f64::max` would drop it).
pub(crate) fn max_keeping_nan(start: f64, values: impl IntoIterator<Item = f64>) -> f64 {
    values.into_iter().fold(start, |m, x| if m.is_nan() || x.is_nan() { f64::NAN } else { m.max(x) })
}

/// The least of `start` and `values`, NaN if any of them is NaN (`f64::min` would drop it).
pub(crate) fn min_keeping_nan(start: f64, values: impl IntoIterator<Item = f64>) -> f64 {
    -max_keeping_nan(-start, values.into_iter().map(|x| -x))
}
pub use spec::{split_resolution, Options, Scene};
