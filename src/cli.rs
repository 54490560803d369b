//! The `pairsum` command line.

use crate::check::{self, Stdlib};
use crate::diag::{render, Sources};
use clap::{Parser, Subcommand};
use std::path::{Path, PathBuf};

#[derive(Parser)]
#[command(name = "pairsum", version, about = "Compile and run SPH models written in the pair-sum language")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Check model files (or every .sph file under a directory); each file is checked with what it uses.
    Check {
        /// Files or directories
        #[arg(required = true)]
        paths: Vec<PathBuf>,
        /// Treat warnings as errors
        #[arg(long)]
        deny_warnings: bool,
    },
}

/// Runs the CLI; returns the process exit code (0 ok, 1 errors in the input, 2 usage).
pub fn main() -> i32 {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() { 2 } else { 0 };
        }
    };
    match cli.command {
        Command::Check { paths, deny_warnings } => run_check(&paths, deny_warnings),
    }
}

/// Every .sph file under the given paths, sorted.
pub fn sph_files(paths: &[PathBuf]) -> Vec<PathBuf> {
    fn walk(p: &Path, out: &mut Vec<PathBuf>) {
        if p.is_dir() {
            let mut entries: Vec<PathBuf> =
                std::fs::read_dir(p).map(|d| d.flatten().map(|e| e.path()).collect()).unwrap_or_default();
            entries.sort();
            for e in entries {
                if e.is_dir() || e.extension().is_some_and(|x| x == "sph") {
                    walk(&e, out);
                }
            }
        } else {
            out.push(p.to_path_buf());
        }
    }
    let mut out = vec![];
    for p in paths {
        walk(p, &mut out);
    }
    out
}

fn run_check(paths: &[PathBuf], deny_warnings: bool) -> i32 {
    let files = sph_files(paths);
    let mut errors = 0;
    let mut warnings = 0;
    for f in &files {
        let mut sources = Sources::new();
        let checked = check::check_paths(&mut sources, &[f.as_path()], Stdlib::locate());
        if !checked.diags.is_empty() {
            eprint!("{}", render(&sources, &checked.diags));
        }
        errors += checked.diags.iter().filter(|d| d.is_error()).count();
        warnings += checked.diags.iter().filter(|d| !d.is_error()).count();
    }
    let n = files.len();
    if errors > 0 {
        eprintln!("checked {n} file(s): {errors} error(s), {warnings} warning(s)");
        1
    } else if deny_warnings && warnings > 0 {
        eprintln!("checked {n} file(s): {warnings} warning(s), denied");
        1
    } else {
        eprintln!("checked {n} file(s): ok ({warnings} warning(s))");
        0
    }
}
