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
pub use spec::{split_resolution, Options, Scene};
