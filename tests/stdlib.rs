//! The stdlib is written in the language and must check clean, file by file, through the library
//! and through `pairsum check stdlib` (exit 0).

use pairsum::check::{check_paths, Stdlib};
use pairsum::diag::{render, Sources};
use std::path::Path;
use std::process::Command;

fn stdlib_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("stdlib")
}

#[test]
fn every_stdlib_file_checks_without_errors() {
    let files = pairsum::cli::sph_files(&[stdlib_dir()]);
    assert!(files.len() >= 30, "only {} stdlib files", files.len());
    for f in &files {
        let mut sources = Sources::new();
        let checked = check_paths(&mut sources, &[f.as_path()], Stdlib::Dir(stdlib_dir()));
        assert!(!checked.has_errors(), "{}:\n{}", f.display(), render(&sources, &checked.diags));
    }
}

#[test]
fn stdlib_models_check_without_warnings() {
    for f in pairsum::cli::sph_files(&[stdlib_dir().join("models")]) {
        let mut sources = Sources::new();
        let checked = check_paths(&mut sources, &[f.as_path()], Stdlib::Dir(stdlib_dir()));
        assert!(checked.is_model, "{} should be a complete model", f.display());
        assert!(checked.diags.is_empty(), "{}:\n{}", f.display(), render(&sources, &checked.diags));
    }
}

#[test]
fn pairsum_check_accepts_the_whole_stdlib() {
    let out = Command::new(env!("CARGO_BIN_EXE_pairsum")).arg("check").arg(stdlib_dir()).output().expect("runs");
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn pairsum_check_exits_1_on_errors_and_never_panics() {
    let dir = std::env::temp_dir().join(format!("pairsum-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let bad = dir.join("bad.sph");
    std::fs::write(&bad, "pairsum p -> a: scalar [m] { a += rho[j] }\n").expect("write");
    let out = Command::new(env!("CARGO_BIN_EXE_pairsum")).arg("check").arg(&bad).output().expect("runs");
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("bad.sph:1:"), "{stderr}");
    assert!(stderr.contains("unit mismatch"), "{stderr}");
    let missing =
        Command::new(env!("CARGO_BIN_EXE_pairsum")).arg("check").arg(dir.join("nope.sph")).output().expect("runs");
    assert_eq!(missing.status.code(), Some(1));
    let _ = std::fs::remove_dir_all(&dir);
}
