//! Check time of the whole stdlib: every module checked as its own unit (with what it uses and the
//! prelude), as `pairsum check stdlib/` does. The target is under 50 ms for the lot.
//!
//! `cargo bench --bench check_stdlib`

use criterion::{criterion_group, criterion_main, Criterion};
use pairsum::check::{check_paths, Stdlib};
use pairsum::cli::sph_files;
use pairsum::diag::Sources;
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

fn stdlib_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("stdlib")
}

/// Checks every module once; returns how many errors were found (so nothing is optimised away).
fn check_all(files: &[PathBuf], dir: &Path) -> usize {
    let mut errors = 0;
    for f in files {
        let mut sources = Sources::new();
        let checked = check_paths(&mut sources, &[f.as_path()], Stdlib::Dir(dir.to_path_buf()));
        errors += checked.diags.iter().filter(|d| d.is_error()).count();
    }
    errors
}

fn bench(c: &mut Criterion) {
    let dir = stdlib_dir();
    let files = sph_files(std::slice::from_ref(&dir));
    let errors = check_all(&files, &dir);

    // A plain figure first, independent of criterion's report.
    let runs = 20;
    let start = Instant::now();
    for _ in 0..runs {
        black_box(check_all(black_box(&files), &dir));
    }
    let per_check = start.elapsed().as_secs_f64() * 1e3 / runs as f64;
    println!(
        "checking the whole stdlib: {per_check:.2} ms (target < 50 ms) [{} modules, {errors} errors, mean of {runs} runs]",
        files.len()
    );

    let mut group = c.benchmark_group("check");
    group.sample_size(10).warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(2));
    group.bench_function("whole_stdlib", |b| b.iter(|| check_all(black_box(&files), &dir)));
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
