//! pairsum: a compiler and runner for SPH interaction equations written in a pair-sum language.
//!
//! The pipeline, one module per stage (see docs/ARCHITECTURE.md):
//! `syntax` (parse) → `check` (names, shapes, units, i/j) → `ir` (typed model) → …

pub mod backend;
pub mod bench;
pub mod check;
pub mod cli;
pub mod compare;
pub mod config;
pub mod diag;
pub mod engine;
pub mod grid;
pub mod host_eval;
pub mod ir;
pub mod output_dir;
pub mod particles;
pub mod report;
pub mod runner;
pub mod scene;
pub mod schedule;
pub mod syntax;
pub mod units;
