//! Case files and study files: the bundled cases and studies (`cases/`, `tests/data/`) and the
//! node-list cases of `fuzz/seeds/`, mutated by [`super::toml_mut`], sometimes loaded with
//! command-line options (`--resolution`, `--set`, `--verlet`, `--end-time`) of their own. A case
//! goes as far as `pairsum run` takes it before running: loaded (`scene::build::load_text`),
//! planned, and its particle store built; a study as far as `pairsum check` takes it: loaded, its
//! first runs' cases loaded with the runs' parameters, its results validated against the case.
//!
//! An input's first line is a TOML comment naming the file it stands for (its folder places the
//! model and node files it names) and the options: `# fuzz {"path": …, "resolution": …, …}`.

use super::text::NUMBERS;
use super::toml_mut::{mutate, VALUES};
use super::{check_diagnostics, code_of, Kind, Outcome, Rng};
use pairsum::diag::{Diagnostic, Sources};
use pairsum::scene::build::{load_text, read_text, Limits};
use pairsum::scene::{study, Options};
use pairsum::schedule::Plan;
use std::path::{Path, PathBuf};

/// The most particles a fuzzed scene may hold (the bundled cases hold up to 37,029 at their
/// default resolution): a mutated spacing is refused quickly rather than filled for seconds.
pub const MAX_PARTICLES: u64 = 100_000;

/// Particle stores are built only for scenes up to this size (a store costs a few ms per 10,000).
const STORE_PARTICLES: usize = 20_000;

/// A study loads at most this many of its runs' cases.
const STUDY_RUNS: usize = 3;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Every `.toml` file of the seed folders, with its text; studies or cases.
fn seeds(studies: bool) -> Vec<(PathBuf, String)> {
    let mut out = vec![];
    for dir in ["cases", "tests/data", "fuzz/seeds"] {
        let Ok(entries) = std::fs::read_dir(root().join(dir)) else { continue };
        let mut files: Vec<PathBuf> =
            entries.flatten().map(|e| e.path()).filter(|p| p.extension().is_some_and(|e| e == "toml")).collect();
        files.sort();
        for f in files {
            let Ok(text) = std::fs::read_to_string(&f) else { continue };
            if study::is_study(&text) == studies {
                out.push((f, text));
            }
        }
    }
    assert!(!out.is_empty(), "no seed files");
    out
}

/// The first line of an input: which file it stands for, and the options.
#[derive(serde::Serialize, serde::Deserialize, Default)]
struct Header {
    path: String,
    #[serde(default)]
    resolution: Option<String>,
    #[serde(default)]
    set: Vec<(String, String)>,
    #[serde(default)]
    verlet: Option<f64>,
    #[serde(default)]
    end_time: Option<f64>,
}

fn with_header(h: &Header, text: &str) -> Vec<u8> {
    format!("# fuzz {}\n{text}", serde_json::to_string(h).expect("a header")).into_bytes()
}

fn header(text: &str) -> (Header, PathBuf) {
    let h: Header = text
        .lines()
        .next()
        .and_then(|l| l.strip_prefix("# fuzz "))
        .and_then(|j| serde_json::from_str(j).ok())
        .unwrap_or_default();
    let path = root().join(&h.path);
    (h, path)
}

fn relative(p: &Path) -> String {
    p.strip_prefix(root()).unwrap_or(p).to_string_lossy().into_owned()
}

/// Expressions for a body's `initial` values, written as TOML strings: escapes, other string
/// forms, placeholders, text that is no expression, nesting.
const EXPRESSIONS: &[&str] = &[
    r#""4 [1/s] * x * (1 [m] - x.x) / 1 [m]""#,
    r#""rho0 * (1 + 1e-4 [1/m] * x.y)""#,
    r#""\té""#,
    r#""\t\t é +""#,
    r#""\u00e9 + x""#,
    r#""x \"""#,
    r#""\\ x""#,
    r#""1 [m/s] * x.x / 1 [m] + \t é""#,
    r#""\U0001F600""#,
    r#""\x41""#,
    "\"\"\"\nx.x *\n  1 [1/s]\"\"\"",
    "\"\"\"x \\\n      + 1\"\"\"",
    "'x.x * 1 [1/s]'",
    "'''x.x +'''",
    r#""${v} * x""#,
    r#""x.z""#,
    r#""v[j]""#,
    r#""min_over(x.x)""#,
    r#""W_at(x.x, 1 [m])""#,
    r#""sqrt(-1) / 0""#,
    r#""1e308 * 1e308""#,
    r#""((((((((((((((((((((((((((((((((((((((((((((((((((x))))))))))))))))))))))))))))))))))))))))))))))))))""#,
    r#""""#,
    r#""é""#,
    r#""1 +""#,
];

/// An `initial` table added to a body (a second one is a duplicate key, which is fine).
fn initial(rng: &mut Rng, text: &mut String) {
    let bodies: Vec<usize> = text.match_indices("[[bodies]]").map(|(k, _)| k + "[[bodies]]".len()).collect();
    if bodies.is_empty() {
        return;
    }
    let at = *rng.pick(&bodies);
    let field = rng.word(&["v", "rho", "p", "s", "e", "T", "x", "nope", "D", "eps_p"]);
    let line = format!("\ninitial = {{ {field} = {} }}", rng.word(EXPRESSIONS));
    text.insert_str(at, &line);
}

/// Options as the command line would give them, now and then.
fn options(rng: &mut Rng, text: &str, h: &mut Header) {
    if rng.chance(85) {
        return;
    }
    let table = pairsum::scene::template::skeleton(text).ok();
    let names: Vec<String> = table
        .as_ref()
        .and_then(|t| t.get("resolutions"))
        .and_then(|r| r.as_table())
        .map(|r| r.keys().cloned().collect())
        .unwrap_or_default();
    let params: Vec<String> = table
        .as_ref()
        .and_then(|t| t.get("parameters"))
        .and_then(|r| r.as_table())
        .map(|r| r.keys().cloned().collect())
        .unwrap_or_default();
    match rng.below(4) {
        0 => {
            h.resolution = Some(match rng.below(3) {
                0 if !names.is_empty() => format!("{}@{} mm", rng.pick(&names), rng.word(NUMBERS)),
                0 | 1 if !names.is_empty() => rng.pick(&names).clone(),
                _ => rng
                    .word(&[
                        "ci@2mm", "0.001", "5 mm", "1e-9", "paper@", "@", "ci@nan", "abc", "ci@-1 mm", "1e300", "",
                        "inf", "2 s",
                    ])
                    .to_string(),
            })
        }
        1 => {
            for _ in 0..1 + rng.below(2) {
                let name =
                    if params.is_empty() || rng.chance(20) { "nope".to_string() } else { rng.pick(&params).clone() };
                let value = if rng.chance(50) {
                    rng.word(NUMBERS).to_string()
                } else {
                    rng.word(VALUES).trim_matches('"').to_string()
                };
                h.set.push((name, value));
            }
        }
        2 => h.verlet = Some(*rng.pick(&[0.1, 0.0, -1.0, 1.0, 2.0, f64::NAN, f64::INFINITY, 1e-300])),
        _ => h.end_time = Some(*rng.pick(&[0.0, -1.0, 1e-12, f64::NAN, f64::INFINITY, 1e300])),
    }
}

fn opts(h: &Header) -> Options {
    Options { resolution: h.resolution.clone(), end_time: h.end_time, set: h.set.clone(), verlet: h.verlet }
}

/// A case as far as `pairsum run` takes it before the first step: loaded, planned, its store
/// built.
fn prepare(text: &str, path: &Path, o: &Options) -> Outcome {
    let mut sources = Sources::new();
    let scene = match load_text(text, path, &mut sources, o, Limits { max_particles: Some(MAX_PARTICLES) }) {
        Ok(s) => s,
        Err(diags) => return refused(&sources, &diags),
    };
    if scene.particles.len() as u64 > MAX_PARTICLES {
        return Outcome::Bad(format!("{} particles, more than the limit of {MAX_PARTICLES}", scene.particles.len()));
    }
    let plan = match Plan::build(&scene.model, &scene.spec, scene.kernel.as_deref()) {
        Ok(p) => p,
        Err(e) => return refused(&sources, &[*e.0]),
    };
    if scene.particles.len() > STORE_PARTICLES {
        return Outcome::Accepted("planned".into());
    }
    match pairsum::engine::setup::build_store::<f64>(&plan, &scene.particles, &scene.materials) {
        Ok(_) => Outcome::Accepted("stored".into()),
        Err(e) => Outcome::Refused(format!("setup: {}", super::label(&e.to_string()))),
    }
}

/// Diagnostics that refused an input: they must hold an error, each with a code and a location.
fn refused(sources: &Sources, diags: &[Diagnostic]) -> Outcome {
    if let Err(e) = check_diagnostics(sources, diags) {
        return Outcome::Bad(e);
    }
    if !diags.iter().any(Diagnostic::is_error) {
        return Outcome::Bad("refused without an error".into());
    }
    Outcome::Refused(code_of(diags))
}

/// Case files.
pub struct Cases {
    seeds: Vec<(PathBuf, String)>,
    texts: Vec<String>,
}

impl Cases {
    pub fn new() -> Cases {
        let seeds = seeds(false);
        let texts = seeds.iter().map(|s| s.1.clone()).collect();
        Cases { seeds, texts }
    }
}

impl Kind for Cases {
    fn name(&self) -> &'static str {
        "cases"
    }
    fn extension(&self) -> &'static str {
        "toml"
    }
    fn generate(&mut self, index: u64, rng: &mut Rng) -> Vec<u8> {
        let (path, seed) = match self.seeds.get(index as usize) {
            Some(s) => s.clone(),
            None => rng.pick(&self.seeds).clone(),
        };
        let mut text = seed;
        let mut h = Header { path: relative(&path), ..Header::default() };
        if index as usize >= self.seeds.len() {
            if rng.chance(10) {
                initial(rng, &mut text);
            }
            for _ in 0..1 + rng.below(2) {
                mutate(rng, &mut text, &self.texts);
            }
            options(rng, &text, &mut h);
        }
        with_header(&h, &text)
    }
    fn run(&mut self, input: &[u8]) -> Outcome {
        let text = String::from_utf8_lossy(input);
        let (h, path) = header(&text);
        prepare(&text, &path, &opts(&h))
    }
}

/// Study files; each run's case is read from disk (the bundled cases).
pub struct Studies {
    seeds: Vec<(PathBuf, String)>,
    texts: Vec<String>,
}

impl Studies {
    pub fn new() -> Studies {
        let seeds = seeds(true);
        let texts = seeds.iter().map(|s| s.1.clone()).collect();
        Studies { seeds, texts }
    }
}

impl Kind for Studies {
    fn name(&self) -> &'static str {
        "studies"
    }
    fn extension(&self) -> &'static str {
        "toml"
    }
    fn generate(&mut self, index: u64, rng: &mut Rng) -> Vec<u8> {
        let (path, seed) = match self.seeds.get(index as usize) {
            Some(s) => s.clone(),
            None => rng.pick(&self.seeds).clone(),
        };
        let mut text = seed;
        if index as usize >= self.seeds.len() {
            for _ in 0..1 + rng.below(3) {
                mutate(rng, &mut text, &self.texts);
            }
        }
        with_header(&Header { path: relative(&path), ..Header::default() }, &text)
    }
    fn run(&mut self, input: &[u8]) -> Outcome {
        let text = String::from_utf8_lossy(input);
        let (_, path) = header(&text);
        study_run(&text, &path)
    }
}

/// A study as `pairsum check` takes it (`runner::prepare_study`): loaded; its first runs' cases
/// loaded and planned with the runs' parameters; its results validated against the case's.
fn study_run(text: &str, path: &Path) -> Outcome {
    let mut sources = Sources::new();
    let st = match study::load_text(text, path, &mut sources) {
        Ok(s) => s,
        Err(diags) => return refused(&sources, &diags),
    };
    let case_text = match read_text(&st.case_path) {
        Ok(t) => t,
        Err(d) => return Outcome::Bad(format!("the study loaded, but its case cannot be read: {}", d.message)),
    };
    let runs = st.file.runs.iter().filter(|r| st.file.ci_runs.as_ref().is_none_or(|c| c.contains(&r.name)));
    let mut case = None;
    for r in runs.take(STUDY_RUNS) {
        let o =
            Options { set: r.set.iter().map(|(k, v)| (k.clone(), study::text_of(v))).collect(), ..Options::default() };
        let mut cs = Sources::new();
        match load_text(&case_text, &st.case_path, &mut cs, &o, Limits { max_particles: Some(MAX_PARTICLES) }) {
            Ok(scene) => {
                if let Err(e) = Plan::build(&scene.model, &scene.spec, scene.kernel.as_deref()) {
                    return refused(&cs, &[*e.0]);
                }
                case.get_or_insert(scene);
            }
            Err(diags) => return refused(&cs, &diags),
        }
    }
    let Some(case) = case else { return Outcome::Refused("no runs".into()) };
    let results: Vec<String> = case.results.iter().map(|r| r.quantity.clone()).collect();
    let probes: Vec<String> = case.probes.iter().map(|p| p.name.clone()).collect();
    let problems = study::validate(&st, &results, &probes);
    if problems.is_empty() {
        return Outcome::Accepted("validated".into());
    }
    refused(&sources, &problems)
}
