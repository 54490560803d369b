//! What the generated-input tests (`tests/fuzz.rs`) found, each input minimised and kept here:
//! every failure of an input must be a diagnostic with a code and a location, never a panic, a
//! hang, a stack overflow or an allocation without bound.

use pairsum::check::{check_text, Stdlib};
use pairsum::diag::{render, Diagnostic, Sources};
use pairsum::scene::build::{load_text, Limits};
use pairsum::scene::Options;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn stdlib() -> Stdlib {
    Stdlib::Dir(root().join("stdlib"))
}

/// A small case (one steel box) with `extra` lines inserted after its body's `shape`, and `top`
/// lines before its tables.
fn case(top: &str, extra: &str) -> String {
    format!(
        r#"name = "block"
model = "models::elastic_solid"
dim = 2
end_time = "10 us"
{top}
[resolutions]
ci = "1 mm"

[materials.steel]
rho0 = "7850 kg/m^3"
E = "200 GPa"
nu = 0.3

[[bodies]]
name = "block"
group = "solid"
material = "steel"
shape = {{ box = {{ min = [0, 0], max = ["10 mm", "10 mm"] }} }}
{extra}
"#
    )
}

/// Loads a case text as if it were `cases/fuzz.toml`; returns the diagnostics (empty when it
/// loads) and the source map they point into.
fn load(text: &str, opts: &Options) -> (Vec<Diagnostic>, Sources) {
    let mut sources = Sources::new();
    let path = root().join("cases/fuzz.toml");
    let diags = match load_text(text, &path, &mut sources, opts, Limits::default()) {
        Ok(_) => vec![],
        Err(d) => d,
    };
    (diags, sources)
}

/// The first error, which must have a code and a location on the characters of its file.
fn first_error<'a>(diags: &'a [Diagnostic], sources: &Sources) -> &'a Diagnostic {
    let d = diags.iter().find(|d| d.is_error()).unwrap_or_else(|| panic!("no error: {diags:?}"));
    let (span, _) = d.primary.as_ref().unwrap_or_else(|| panic!("[{}] has no location: {}", d.code, d.message));
    let text = sources.text(span.file);
    let (a, b) = (span.start as usize, span.end as usize);
    assert!(b <= text.len() && text.is_char_boundary(a) && text.is_char_boundary(b), "[{}] span {a}..{b}", d.code);
    let _ = render(sources, diags);
    d
}

fn snippet(d: &Diagnostic, sources: &Sources) -> String {
    sources.snippet(d.primary.as_ref().expect("located").0).to_string()
}

/// Found by the case-file fuzzer: an initial value's diagnostics were placed as if the TOML
/// string had no escapes, so after a `\t` they pointed one byte early, into the middle of `é`.
#[test]
fn an_initial_value_with_escapes_is_pointed_at_where_the_file_has_it() {
    for (expr, at) in [(r#""\té""#, "é"), (r#""\u00e9 + x""#, "\\u"), (r#""1 [m] + \t\t é""#, "é"), ("'x +'", "")] {
        let (diags, sources) = load(&case("", &format!("initial = {{ v = {expr} }}")), &Options::default());
        let d = first_error(&diags, &sources);
        assert_eq!(d.code, "E0001", "{expr}: {}", render(&sources, &diags));
        assert_eq!(snippet(d, &sources), at, "{expr}: {}", render(&sources, &diags));
    }
}

/// The known limit of `fuzz/README.md`: a few thousand levels of nesting overflowed the stack of
/// the parser and the checker. Now E0004 (the text) and E0217 (with helpers and constants).
#[test]
fn deep_nesting_is_a_diagnostic_not_a_stack_overflow() {
    let n = 100_000;
    let sources_of = |text: &str| {
        let mut sources = Sources::new();
        let checked = check_text(&mut sources, "deep.sph", text, stdlib());
        let code = first_error(&checked.diags, &sources).code;
        code
    };
    assert_eq!(sources_of(&format!("const a = {}1{}", "(".repeat(n), ")".repeat(n))), "E0004");
    assert_eq!(sources_of(&format!("const a = 1{}", " + 1".repeat(n))), "E0004");
    assert_eq!(sources_of(&format!("const a = {}1", "-".repeat(n))), "E0004");
    assert_eq!(sources_of(&format!("const a = 1 [m{}]", " * m".repeat(n))), "E0004");
    let chain = " else if true { q = 1 }".repeat(n);
    let eq = format!("group g\nfield q: scalar\nparticle e -> q {{ if true {{ q = 1 }}{chain} }}");
    assert_eq!(sources_of(&eq), "E0004");
    // Just inside the parser's limit, the checker's recursion is fine.
    let mut sources = Sources::new();
    let ok =
        check_text(&mut sources, "deep.sph", &format!("const a = {}1{}", "(".repeat(127), ")".repeat(127)), stdlib());
    assert!(!ok.has_errors(), "{}", render(&sources, &ok.diags));
    // Helpers inlined into helpers: deep, or doubling at each level.
    let mut helpers = String::from("fn f0(x) { x + 1 }\n");
    for k in 1..2000 {
        helpers.push_str(&format!("fn f{k}(x) {{ f{}(x) + 1 }}\n", k - 1));
    }
    assert_eq!(sources_of(&(helpers + "const a = f1999(1)\n")), "E0217");
    let mut lets = String::from("fn g(x) {\n");
    for k in 0..5000 {
        lets.push_str(&format!("let y{k} = x\n"));
    }
    assert_eq!(sources_of(&(lets + "x }\nconst a = g(1)\n")), "E0217");
    let t = Instant::now();
    let mut doubling = String::from("fn d0(x) { x + 1 }\n");
    for k in 1..60 {
        doubling.push_str(&format!("fn d{k}(x) {{ d{}(x) + d{}(x) }}\n", k - 1, k - 1));
    }
    assert_eq!(sources_of(&(doubling + "const a = d59(1)\n")), "E0217");
    assert!(t.elapsed() < Duration::from_secs(10), "{:?}", t.elapsed());
}

/// Equations that all write one field were reported pair by pair: n equations made n²/2 errors
/// (20,000 of them 200 million, which never finished). Now one error per equation, against the
/// first that writes the field; and locating the equations no longer scans the file for each.
#[test]
fn many_writers_of_one_field_are_reported_once_each() {
    let n = 20_000;
    let mut text = String::from("group g\nfield q: scalar\n");
    for k in 0..n {
        text.push_str(&format!("particle e{k} -> q {{ q = 1 }}\n"));
    }
    let t = Instant::now();
    let mut sources = Sources::new();
    let checked = check_text(&mut sources, "many.sph", &text, stdlib());
    assert_eq!(first_error(&checked.diags, &sources).code, "E0305");
    assert_eq!(checked.diags.iter().filter(|d| d.code == "E0305").count(), n - 1);
    assert!(checked.diags[0].message.contains("`e0` and `e1`"), "{}", checked.diags[0].message);
    assert!(t.elapsed() < Duration::from_secs(30), "{:?}", t.elapsed());
}

/// `use "/dev/zero"` read the device forever (into a string that grew to the memory's size).
#[test]
fn a_module_that_is_a_device_is_not_read() {
    let t = Instant::now();
    let mut sources = Sources::new();
    let checked = check_text(&mut sources, "m.sph", "use \"/dev/zero\"\n", stdlib());
    assert_eq!(first_error(&checked.diags, &sources).code, "E0003");
    assert!(t.elapsed() < Duration::from_secs(5));
}

/// A node file, a case or a study's case that is a device is refused, not read forever.
#[test]
fn a_file_that_is_a_device_is_not_read() {
    let t = Instant::now();
    let (diags, sources) = load(
        &case("", "")
            .replace("box = { min = [0, 0], max = [\"10 mm\", \"10 mm\"] }", "nodes = { file = \"/dev/zero\" }"),
        &Options::default(),
    );
    assert_eq!(first_error(&diags, &sources).code, "C0021");
    let mut sources = Sources::new();
    let e = pairsum::scene::load(Path::new("/dev/zero"), &mut sources, &Options::default()).err().expect("refused");
    assert_eq!(e[0].code, "C0001");
    let study = "name = \"s\"\ncase = \"/dev/zero\"\n[[runs]]\nname = \"a\"\n";
    let mut sources = Sources::new();
    let e = pairsum::scene::study::load_text(study, &root().join("cases/s.toml"), &mut sources).err().expect("refused");
    assert_eq!(first_error(&e, &sources).code, "C0001");
    assert!(t.elapsed() < Duration::from_secs(5));
}

/// A spacing far too fine for its domain is refused before anything is allocated (the default
/// limit, 50 million particles in the scene), and `max_particles` moves the limit.
#[test]
fn too_many_particles_are_refused_before_they_are_placed() {
    let t = Instant::now();
    for (top, res) in [("", "ci = \"1e-9 m\""), ("", "ci = \"1 mm\""), ("max_particles = 50", "ci = \"1 mm\"")] {
        let mut text = case(top, "").replace("ci = \"1 mm\"", res);
        if res.ends_with("\"1 mm\"") && top.is_empty() {
            // A box of a million metres.
            text = text.replace("max = [\"10 mm\", \"10 mm\"]", "max = [\"1e6 m\", \"1e6 m\"]");
        }
        let (diags, sources) = load(&text, &Options::default());
        let d = first_error(&diags, &sources);
        assert_eq!(d.code, "C0039", "{}", render(&sources, &diags));
        assert!(snippet(d, &sources).contains("box"), "{}", render(&sources, &diags));
    }
    assert!(t.elapsed() < Duration::from_secs(5), "{:?}", t.elapsed());
    // The limit is the scene's: two bodies of 100 particles under a limit of 150.
    let second = "[[bodies]]\nname = \"other\"\ngroup = \"solid\"\nmaterial = \"steel\"\nshape = { box = { min = [0, \"20 mm\"], max = [\"10 mm\", \"30 mm\"] } }";
    let (diags, sources) = load(&case("max_particles = 150", second), &Options::default());
    let d = first_error(&diags, &sources);
    assert!(
        d.code == "C0039" && d.message.contains("`other`") && d.message.contains("50 the scene's limit of 150"),
        "{}",
        d.message
    );
    let (diags, sources) = load(&case("max_particles = 200", second), &Options::default());
    assert!(diags.iter().all(|d| !d.is_error()), "{}", render(&sources, &diags));
    // And a caller's limit holds whatever the case says.
    let mut sources = Sources::new();
    let text = case("max_particles = 1000000", "");
    let r = load_text(
        &text,
        &root().join("cases/fuzz.toml"),
        &mut sources,
        &Options::default(),
        Limits { max_particles: Some(10) },
    );
    assert_eq!(first_error(&r.err().expect("refused"), &sources).code, "C0039");
}

/// Values that would stop the clock or never end a run are refused when the case loads.
#[test]
fn times_that_would_never_end_a_run_are_refused() {
    let texts = [
        case("", "").replace("end_time = \"10 us\"", "end_time = \"inf s\""),
        case("", "").replace("end_time = \"10 us\"", "end_time = -1"),
        case("dt_max = 0", ""),
        case("dt_max = \"-1 s\"", ""),
        case("", "[output]\ninterval = 0"),
        case("", "").replace("ci = \"1 mm\"", "ci = { dx = \"1 mm\", time_scale = 0 }"),
        case("", "").replace("ci = \"1 mm\"", "ci = \"-1 mm\""),
    ];
    for text in texts {
        let (diags, sources) = load(&text, &Options::default());
        assert_eq!(first_error(&diags, &sources).code, "C0002", "{}", render(&sources, &diags));
    }
}

/// Found by the case-file fuzzer: errors in the options (`--resolution`, `--verlet`, `--set`,
/// `--end-time`) had no location. They point into the command line now.
#[test]
fn errors_in_the_options_point_at_the_command_line() {
    let text = case("[parameters]\nv = 1", "");
    let options = [
        Options { resolution: Some("inf".into()), ..Options::default() },
        Options { resolution: Some("@".into()), ..Options::default() },
        Options { verlet: Some(2.0), ..Options::default() },
        Options { set: vec![("nope".into(), "1".into())], ..Options::default() },
        Options { end_time: Some(f64::INFINITY), ..Options::default() },
    ];
    for o in options {
        let (diags, sources) = load(&text, &o);
        let d = first_error(&diags, &sources);
        let span = d.primary.as_ref().expect("located").0;
        assert_eq!(sources.name(span.file), "<command line>", "{o:?}: {}", render(&sources, &diags));
    }
}

/// Found by the case-file fuzzer: an unknown `kernel` was P0001 of the plan, without a location.
#[test]
fn an_unknown_kernel_is_an_error_at_its_key() {
    let (diags, sources) = load(&case("kernel = \"abc\"", ""), &Options::default());
    let d = first_error(&diags, &sources);
    assert_eq!((d.code, snippet(d, &sources).as_str()), ("C0040", "\"abc\""));
}

/// The case's own resolution errors are located in it: an unknown `default_resolution`, no `ci`
/// without one, a resolution's `set` naming no parameter, a body-less case.
#[test]
fn resolution_errors_of_the_case_file_are_located() {
    let unknown = case("default_resolution = \"nope\"", "");
    let no_ci = case("", "").replace("ci = \"1 mm\"", "fine = \"1 mm\"");
    let bad_set = case("[parameters]\nv = 1", "").replace("ci = \"1 mm\"", "ci = { dx = \"1 mm\", set = { w = 2 } }");
    for (text, code) in [(unknown, "C0006"), (no_ci, "C0006"), (bad_set, "C0026")] {
        let (diags, sources) = load(&text, &Options::default());
        assert_eq!(first_error(&diags, &sources).code, code, "{}", render(&sources, &diags));
    }
    let empty = case("bodies = []", "").split("[[bodies]]").next().expect("head").to_string();
    let (diags, sources) = load(&empty, &Options::default());
    assert_eq!(first_error(&diags, &sources).code, "C0011", "{}", render(&sources, &diags));
}

/// Found by the case-file fuzzer's counts: a text that is not TOML was C0001 without placeholders
/// and C0026 (a parameter's error) with them. Both are C0001 now, where the TOML breaks.
#[test]
fn a_case_that_is_not_toml_is_c0001_with_or_without_placeholders() {
    for top in ["x = [1,", "[parameters]\nv = 1\nx = \"${v}\"\ny = [1,"] {
        let (diags, sources) = load(&case(top, ""), &Options::default());
        let d = first_error(&diags, &sources);
        assert_eq!(d.code, "C0001", "{}", render(&sources, &diags));
    }
}

/// A study's `plots` and `ci_runs` that name nothing were errors without a location.
#[test]
fn study_errors_are_located() {
    let study =
        "name = \"s\"\ncase = \"cantilever.toml\"\nplots = [\"nope\"]\nci_runs = [\"b\"]\n[[runs]]\nname = \"a\"\n";
    let mut sources = Sources::new();
    let path: PathBuf = root().join("cases/s.toml");
    let st = pairsum::scene::study::load_text(study, &path, &mut sources).expect("loads");
    let problems = pairsum::scene::study::validate(&st, &[], &["tip_deflection".into()]);
    assert_eq!(problems.len(), 2);
    for p in &problems {
        let d = first_error(std::slice::from_ref(p), &sources);
        assert!(["\"nope\"", "\"b\""].contains(&snippet(d, &sources).as_str()), "{}", render(&sources, &problems));
    }
}
