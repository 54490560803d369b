//! Coverage-guided fuzzing of the front end: any UTF-8 text through parse + check (+ render).
//! Must never panic. Run with `cargo +nightly fuzz run check` from the repository root.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pairsum::check::{check_text, Stdlib};
use pairsum::diag::{render, Sources};
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let stdlib = Stdlib::Dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("../stdlib"));
    let mut sources = Sources::new();
    let checked = check_text(&mut sources, "fuzz.sph", text, stdlib);
    // Rendering walks every span, so a span outside its file shows up too.
    let _ = render(&sources, &checked.diags);
});
