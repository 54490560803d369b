//! The generated WGSL: `shaders_gen/` holds the kernels of every stdlib model and bundled case
//! and must be current; the stdlib models' neighbour-pass kernels are snapshotted (review any
//! change as a code change). Every module was validated by naga when generated.

use pairsum::cli::{plan_of, shader_sources};
use std::collections::BTreeMap;
use std::path::Path;

fn committed(dir: &Path) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            let p = e.path();
            if p.extension().is_some_and(|x| x == "wgsl") {
                out.insert(
                    p.file_name().unwrap().to_string_lossy().into_owned(),
                    std::fs::read_to_string(&p).unwrap_or_default(),
                );
            }
        }
    }
    out
}

#[test]
fn shaders_gen_is_current() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    std::env::set_current_dir(root).expect("cd to the repository");
    let sources = shader_sources(Path::new("."));
    assert!(sources.len() >= 5, "{sources:?}");
    let mut stale = vec![];
    for (sub, src) in sources {
        let plan = plan_of(&src, 3).unwrap_or_else(|e| panic!("{}: {e}", src.display()));
        let fresh: BTreeMap<String, String> =
            pairsum::backend::wgsl::files(&plan).expect("generate").into_iter().collect();
        let dir = root.join("shaders_gen").join(&sub);
        if fresh != committed(&dir) {
            stale.push(dir.display().to_string());
        }
    }
    assert!(stale.is_empty(), "generated WGSL differs from the committed files in {stale:?}: run `cargo run -- emit --all` and review the diff");
}

#[test]
fn stdlib_model_pass_kernels_are_snapshotted() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    std::env::set_current_dir(root).expect("cd to the repository");
    for (sub, src) in shader_sources(Path::new(".")).into_iter().filter(|(s, _)| s.starts_with("models")) {
        let plan = plan_of(&src, 3).expect("plan");
        for (name, text) in pairsum::backend::wgsl::files(&plan).expect("generate") {
            if name.starts_with("pass") {
                let model = sub.file_name().unwrap().to_string_lossy().into_owned();
                insta::assert_snapshot!(format!("{model}__{}", name.trim_end_matches(".wgsl")), text);
            }
        }
    }
}
