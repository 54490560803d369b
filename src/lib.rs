//! pairsum: a compiler and runner for SPH interaction equations written in a pair-sum language.
//!
//! The pipeline, one module per stage (see docs/ARCHITECTURE.md):
//! `syntax` (parse) → `check` (names, shapes, units, i/j) → `ir` (typed model) → …

pub mod check;
pub mod cli;
pub mod diag;
pub mod ir;
pub mod syntax;
pub mod units;
