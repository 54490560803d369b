//! Embeds the stdlib (`stdlib/**/*.sph`) into the binary, so `pairsum` works from any directory.
use std::path::Path;

fn collect(dir: &Path, root: &Path, out: &mut Vec<(String, String)>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<_> = entries.flatten().map(|e| e.path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            collect(&p, root, out);
        } else if p.extension().is_some_and(|e| e == "sph") {
            let rel = p.strip_prefix(root).expect("inside root").to_string_lossy().replace('\\', "/");
            out.push((rel, p.canonicalize().expect("readable").to_string_lossy().into_owned()));
        }
    }
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("stdlib");
    println!("cargo:rerun-if-changed=stdlib");
    println!("cargo:rerun-if-changed=grammar");
    let mut files = vec![];
    collect(&root, &root, &mut files);
    let mut code = String::from("pub static STDLIB_FILES: &[(&str, &str)] = &[\n");
    for (rel, abs) in &files {
        code.push_str(&format!("    ({rel:?}, include_str!({abs:?})),\n"));
    }
    code.push_str("];\n");
    let out = Path::new(&std::env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("stdlib_files.rs");
    std::fs::write(out, code).expect("write stdlib table");
}
