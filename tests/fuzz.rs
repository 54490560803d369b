//! Robustness: whatever a user feeds pairsum — DSL source, a case or study file (with `--set`,
//! `--resolution` and the like), a CSV or LS-DYNA node file, a checkpoint — fails with a
//! diagnostic or an error, never with a panic, a hang, a stack overflow or an allocation without
//! bound. A deterministic property test (no fuzzing engine needed): each kind's seeds (the stdlib,
//! `tests/ui/`, `cases/`, `tests/data/`, `fuzz/seeds/`, a checkpoint of a bundled case) mutated by
//! structure-aware and byte-level edits (`tests/fuzz_support/`). Diagnostics must carry a code and a
//! location inside a file the source map holds.
//!
//! Each kind runs in child processes (this binary), which report each input before running it,
//! so a crash or a hang (an input past `PAIRSUM_FUZZ_TIMEOUT_MS`, 10 s) is pinned to its input;
//! one allocating more than `PAIRSUM_FUZZ_ALLOC_MB` (1024) fails too. A failing input is printed
//! and saved under `target/fuzz-failures/`; the run is seeded, so a failure reproduces
//! (`PAIRSUM_FUZZ_REPLAY=<input>`). `PAIRSUM_FUZZ_SEED=n` and `PAIRSUM_FUZZ_INPUTS=n` (inputs per
//! kind) explore further. The million-input run is the ignored test `million_inputs`:
//! `cargo test --test fuzz -- --ignored --nocapture million_inputs` (`fuzz/README.md`).
//! For coverage-guided fuzzing of the language see `fuzz/` (cargo fuzz).

mod fuzz_support;

use fuzz_support::cases::{Cases, Studies};
use fuzz_support::checkpoint::Checkpoints;
use fuzz_support::dsl::Dsl;
use fuzz_support::nodes::NodeFiles;
use fuzz_support::{conclude, inputs, run_kind, Kind, Report};

#[global_allocator]
static ALLOC: fuzz_support::alloc::Counting = fuzz_support::alloc::Counting;

/// Every kind, by name, for a child process.
fn kind(name: &str) -> Box<dyn Kind> {
    match name {
        "dsl" => Box::new(Dsl::new()),
        "cases" => Box::new(Cases::new()),
        "studies" => Box::new(Studies::new()),
        "nodes_csv" => Box::new(NodeFiles::csv()),
        "nodes_lsdyna" => Box::new(NodeFiles::lsdyna()),
        "checkpoints" => Box::new(Checkpoints::new()),
        other => panic!("no input kind `{other}`"),
    }
}

/// What a child process runs (`PAIRSUM_FUZZ_CHILD`); nothing in a plain test run.
#[test]
fn fuzz_child() {
    if let Ok(spec) = std::env::var("PAIRSUM_FUZZ_CHILD") {
        let name = spec.split_whitespace().next().unwrap_or("").to_string();
        fuzz_support::child_main(&mut [kind(&name)]);
    }
}

/// One kind's inputs through children, one child at a time (the suite runs tests side by side).
fn suite(name: &str, default: u64) {
    let report = run_kind(kind(name).as_mut(), inputs(default), 1, "fuzz_child");
    conclude(&report);
}

#[test]
fn dsl_sources_never_panic() {
    suite("dsl", 60_000);
}

#[test]
fn case_files_never_panic() {
    suite("cases", 10_000);
}

#[test]
fn study_files_never_panic() {
    suite("studies", 1_000);
}

#[test]
fn csv_node_files_never_panic() {
    suite("nodes_csv", 20_000);
}

#[test]
fn lsdyna_node_files_never_panic() {
    suite("nodes_lsdyna", 20_000);
}

#[test]
fn checkpoints_never_panic() {
    suite("checkpoints", 20_000);
}

/// The million-input run (not in the suite): every kind, `PAIRSUM_FUZZ_TOTAL` inputs in all
/// (1,000,000 by default) shared as below, `PAIRSUM_FUZZ_JOBS` children at a time (the cores).
/// Writes `target/fuzz-summary.json`; fails if any input failed.
#[test]
#[ignore = "about 10 minutes on 2 cores: cargo test --test fuzz -- --ignored --nocapture million_inputs"]
fn million_inputs() {
    let total: u64 = std::env::var("PAIRSUM_FUZZ_TOTAL").ok().and_then(|s| s.parse().ok()).unwrap_or(1_000_000);
    let jobs: usize = std::env::var("PAIRSUM_FUZZ_JOBS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(2, |n| n.get()));
    // Shares of the total, in thousandths.
    let shares: [(&str, u64); 6] =
        [("dsl", 400), ("cases", 200), ("studies", 20), ("nodes_csv", 150), ("nodes_lsdyna", 150), ("checkpoints", 80)];
    let seed = fuzz_support::Settings::from_env().seed;
    let start = std::time::Instant::now();
    let mut reports: Vec<Report> = vec![];
    for (name, share) in shares {
        let n = total * share / 1000;
        let report = run_kind(kind(name).as_mut(), n, jobs, "fuzz_child");
        println!(
            "{name}: {} inputs, {} refused, {:.1} s, {} failures",
            report.inputs,
            report.refused,
            report.wall.as_secs_f64(),
            report.failures.len()
        );
        reports.push(report);
    }
    let wall = start.elapsed().as_secs_f64();
    let kinds: Vec<serde_json::Value> = reports
        .iter()
        .map(|r| {
            serde_json::json!({
                "kind": r.kind,
                "inputs": r.inputs,
                "refused": r.refused,
                "accepted": r.inputs - r.refused - r.failures.len().min(r.inputs as usize) as u64,
                "wall_s": (r.wall.as_secs_f64() * 10.0).round() / 10.0,
                "slowest_ms": (r.slowest.0 * 10.0).round() / 10.0,
                "slowest_input": r.slowest.1,
                "most_allocated_mib": (r.most_allocated as f64 / 1048576.0 * 10.0).round() / 10.0,
                "outcomes": r.outcomes,
                "failures": r.failures.iter().map(|f| serde_json::json!({"input": f.index, "what": f.what, "message": f.message})).collect::<Vec<_>>(),
            })
        })
        .collect();
    let summary = serde_json::json!({
        "seed": seed,
        "jobs": jobs,
        "inputs": reports.iter().map(|r| r.inputs).sum::<u64>(),
        "wall_s": (wall * 10.0).round() / 10.0,
        "failures": reports.iter().map(|r| r.failures.len()).sum::<usize>(),
        "kinds": kinds,
    });
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("target/fuzz-summary.json");
    let text = serde_json::to_string_pretty(&summary).expect("json");
    std::fs::write(&path, &text).expect("write the summary");
    println!("{text}\nwritten to {}", path.display());
    for r in &reports {
        conclude(r);
    }
}
