//! Robustness: parse + check must never panic, whatever the input. A deterministic property test
//! (no fuzzing engine needed): mutations of every stdlib module and of the diagnostics corpus
//! (tokens deleted, duplicated, swapped, replaced by tokens of the same file or of the language;
//! characters inserted and deleted; lines shuffled; pieces of other files spliced in), plus purely
//! random token sequences built from the language's vocabulary.
//!
//! A panicking input is printed and saved under `target/fuzz-failures/`. The run is seeded, so a
//! failure reproduces; `PAIRSUM_FUZZ_SEED=n` and `PAIRSUM_FUZZ_INPUTS=n` explore further, e.g.
//! `PAIRSUM_FUZZ_INPUTS=2000000 cargo test --release --test fuzz -- --nocapture`.
//! For coverage-guided fuzzing see `fuzz/` (cargo fuzz).

use pairsum::check::{check_text, Stdlib};
use pairsum::diag::{render, Sources};
use std::panic::{self, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// How many inputs a plain `cargo test` feeds through the checker.
const DEFAULT_INPUTS: usize = 60_000;

/// xorshift64*: small, fast, deterministic.
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Rng {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    fn next(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in `0..n` (n > 0).
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
    fn chance(&mut self, percent: usize) -> bool {
        self.below(100) < percent
    }
    fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.below(items.len())]
    }
    fn word(&mut self, words: &[&'static str]) -> &'static str {
        words[self.below(words.len())]
    }
}

/// The language's vocabulary, for random programs and for tokens dropped into mutated files.
const VOCABULARY: &[&str] = &[
    // items and statement keywords
    "use",
    "group",
    "field",
    "state",
    "param",
    "const",
    "kernel",
    "fn",
    "pairsum",
    "particle",
    "integrate",
    "timestep",
    "on",
    "from",
    "let",
    "if",
    "else",
    "init",
    "finally",
    "in",
    "acc",
    "true",
    "false",
    "i",
    "j",
    // shapes
    "scalar",
    "vec",
    "symtensor",
    "skewtensor",
    "tensor",
    "bool",
    // punctuation and operators
    "{",
    "}",
    "(",
    ")",
    "[",
    "]",
    ",",
    ":",
    "::",
    ";",
    "->",
    "'",
    "=",
    "+=",
    "-=",
    "min=",
    "max=",
    "==",
    "!=",
    "<",
    "<=",
    ">",
    ">=",
    "+",
    "-",
    "*",
    "/",
    "^",
    "!",
    "&&",
    "||",
    "|",
    ".",
    "\"",
    "//",
    "/*",
    "*/",
    // names the prelude, the stdlib and the language know
    "x",
    "v",
    "m",
    "rho",
    "rho0",
    "h",
    "p",
    "s",
    "c0",
    "G",
    "dv",
    "drho",
    "ds",
    "dx",
    "vol",
    "solid",
    "fluid",
    "wall",
    "t",
    "dt",
    "dim",
    "pi",
    "inf",
    "I",
    "R",
    "x_ij",
    "r_ij",
    "v_ij",
    "h_ij",
    "W_ij",
    "gradW_ij",
    "dot",
    "outer",
    "ddot",
    "sym",
    "skew",
    "dev",
    "trace",
    "transpose",
    "norm",
    "inv",
    "det",
    "sqrt",
    "exp",
    "ln",
    "pow",
    "abs",
    "min",
    "max",
    "select",
    "avg",
    "W_at",
    "min_over",
    "max_over",
    "sum_over",
    "support",
    "norm1",
    "norm2",
    "norm3",
    "w",
    "dw",
    "xy",
    "kernels",
    "prelude",
    // numbers, including awkward ones
    "0",
    "1",
    "2",
    "0.5",
    "1.5e-3",
    "7",
    "1e308",
    "1e400",
    "4294967296",
    "99999999999999999999",
    "0.0",
    "2147483647",
    "2147483648",
    // units
    "[kg/m^3]",
    "[Pa]",
    "[m/s]",
    "[1/s]",
    "[-]",
    "[1]",
    "[m^(1/2)]",
    "[Pa*s]",
    "[m^(-3)]",
    "[kg.m]",
    "[m^(1/0)]",
    "[m^2147483647]",
    "[m^(-2147483648/3)]",
    "[s^(1/12)]",
    "[K^99999]",
    "[MPa]",
    "[J/kg]",
    "\"kernels.sph\"",
    "\"../x.sph\"",
];

/// Splits text into tokens that concatenate back to it: runs of word characters, runs of
/// whitespace, and single other characters.
fn tokenize(text: &str) -> Vec<&str> {
    #[derive(PartialEq, Clone, Copy)]
    enum Class {
        Word,
        Space,
        Other,
    }
    let class = |c: char| {
        if c.is_alphanumeric() || c == '_' {
            Class::Word
        } else if c.is_whitespace() {
            Class::Space
        } else {
            Class::Other
        }
    };
    let mut out = vec![];
    let mut start = 0;
    let mut prev: Option<Class> = None;
    for (k, c) in text.char_indices() {
        let cl = class(c);
        if let Some(p) = prev {
            if p != cl || cl == Class::Other {
                out.push(&text[start..k]);
                start = k;
            }
        }
        prev = Some(cl);
    }
    if start < text.len() {
        out.push(&text[start..]);
    }
    out
}

/// One random edit of a token list; `pool` holds tokens of the same file, `other` another seed.
fn mutate_tokens(rng: &mut Rng, toks: &mut Vec<String>, pool: &[String], other: &[String]) {
    if toks.is_empty() {
        toks.push(rng.word(VOCABULARY).to_string());
        return;
    }
    let n = toks.len();
    let k = rng.below(n);
    match rng.below(7) {
        0 => {
            let len = 1 + rng.below(3.min(n - k));
            toks.drain(k..k + len);
        }
        1 => {
            let t = toks[k].clone();
            toks.insert(k, t);
        }
        2 => toks.swap(k, rng.below(n)),
        3 => toks[k] = rng.pick(pool).clone(),
        4 => toks[k] = rng.word(VOCABULARY).to_string(),
        5 => toks.insert(k, format!(" {} ", rng.word(VOCABULARY))),
        _ => {
            // Splice a run of another file's tokens.
            if !other.is_empty() {
                let a = rng.below(other.len());
                let b = (a + 1 + rng.below(40)).min(other.len());
                let piece: Vec<String> = other[a..b].to_vec();
                toks.splice(k..k, piece);
            }
        }
    }
}

/// One random edit at the level of characters or lines.
fn mutate_text(rng: &mut Rng, text: &mut String) {
    let boundaries: Vec<usize> = text.char_indices().map(|(k, _)| k).chain([text.len()]).collect();
    let at = *rng.pick(&boundaries);
    match rng.below(4) {
        0 => {
            const CHARS: &[char] =
                &['{', '}', '(', ')', '[', ']', '\'', '"', '/', '*', '^', '-', '\n', ' ', '0', 'é', '∇', '\u{0}', '#'];
            text.insert(at, *rng.pick(CHARS));
        }
        1 => {
            if at < text.len() {
                text.remove(at);
            }
        }
        2 => {
            // Swap two lines.
            let mut lines: Vec<&str> = text.split('\n').collect();
            let (a, b) = (rng.below(lines.len()), rng.below(lines.len()));
            lines.swap(a, b);
            *text = lines.join("\n");
        }
        _ => {
            // Shuffle a run of lines.
            let mut lines: Vec<&str> = text.split('\n').collect();
            let a = rng.below(lines.len());
            let b = (a + 2 + rng.below(8)).min(lines.len());
            for k in (a + 1..b).rev() {
                let r = a + rng.below(k - a + 1);
                lines.swap(k, r);
            }
            *text = lines.join("\n");
        }
    }
}

/// A program of random tokens of the language.
fn random_program(rng: &mut Rng) -> String {
    let n = 1 + rng.below(60);
    let mut out = String::new();
    for _ in 0..n {
        out.push_str(rng.word(VOCABULARY));
        out.push(if rng.chance(10) { '\n' } else { ' ' });
    }
    out
}

/// A random program that follows the shape of the grammar (items with plausible insides), so
/// that the checker, not only the parser, sees it.
fn random_items(rng: &mut Rng) -> String {
    const NAMES: &[&str] = &["rho", "p", "v", "x", "s", "h", "m", "c0", "G", "drho", "dv", "q", "f", "solid"];
    const SHAPES: &[&str] = &["scalar", "vec", "symtensor", "skewtensor", "tensor", "bool"];
    const UNITS: &[&str] = &["", "[kg/m^3]", "[Pa]", "[m/s]", "[1/s]", "[-]", "[m^(1/2)]", "[kg/m^3/s]", "[m/s^2]"];
    let expr = |rng: &mut Rng| {
        let mut e = String::new();
        for k in 0..1 + rng.below(6) {
            if k > 0 {
                e.push_str(rng.word(&[" + ", " - ", " * ", " / ", " ^ ", " < ", " == ", " && "]));
            }
            match rng.below(6) {
                0 => e.push_str(rng.word(&["0", "1", "2.5", "1e308", "0.5 [m]", "3 [Pa]", "true"])),
                1 => e.push_str(&format!("{}[{}]", rng.word(NAMES), rng.word(&["i", "j"]))),
                2 => e.push_str(&format!(
                    "{}({}, {})",
                    rng.word(&["dot", "outer", "min", "max", "pow", "ddot", "W_at"]),
                    rng.word(NAMES),
                    rng.word(&["gradW_ij", "x_ij", "v_ij", "r_ij", "h", "2"])
                )),
                3 => e.push_str(&format!(
                    "{}({})",
                    rng.word(&["sqrt", "exp", "norm", "dev", "sym", "trace", "abs", "avg", "min_over", "inv"]),
                    rng.word(NAMES)
                )),
                4 => e.push_str(rng.word(&["W_ij", "gradW_ij", "x_ij", "r_ij", "v_ij", "h_ij", "dt", "I", "pi"])),
                _ => e.push_str(rng.word(NAMES)),
            }
        }
        e
    };
    let mut out = String::from("group solid, fluid\n");
    for _ in 0..1 + rng.below(5) {
        let name = rng.word(NAMES);
        let ty = format!("{} {}", rng.word(SHAPES), rng.word(UNITS));
        let item = match rng.below(8) {
            0 => format!("field {name}: {ty}"),
            1 => format!("state {name}: {ty} = {}", expr(rng)),
            2 => format!("param {name}: {ty}"),
            3 => format!("const {name} = {}", expr(rng)),
            4 => format!(
                "pairsum e{} on solid from fluid -> {name}: {ty} {{\n  acc a: {ty}\n  a += {}\n  {name} {} {}\n  finally {{ {name} = a }}\n}}",
                rng.below(3),
                expr(rng),
                rng.word(&["+=", "=", "max=", "-="]),
                expr(rng)
            ),
            5 => format!("particle e{} -> {name}: {ty} {{ let z = {}\n {name} = z }}", rng.below(3), expr(rng)),
            6 => format!("integrate {{ {name}' = {} }}", expr(rng)),
            _ => format!("fn f{}(a: {ty}, b) -> {ty} {{ {} }}", rng.below(2), expr(rng)),
        };
        out.push_str(&item);
        out.push('\n');
    }
    out
}

/// Every `.sph` file under `dir`, sorted.
fn sph_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    let mut entries: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            sph_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "sph") {
            out.push(p);
        }
    }
}

/// A small complete model that reaches every stage of the checker, model checks included.
const MODEL_SEED: &str = r#"
group solid, fluid
state s: symtensor [Pa]
field p: scalar [Pa]
param c0: scalar [m/s]
param G: scalar [Pa] = 1e9 [Pa]
const eps = 0.1
kernel cubic {
    support = 2  norm1 = 2 / 3  norm2 = 10 / (7 * pi)  norm3 = 1 / pi
    w(R) = select(R < 1, 1 - 1.5 * R^2 + 0.75 * R^3, 0.25 * max(2 - R, 0)^3)
    dw(R) = select(R < 1, -3 * R + 2.25 * R^2, -0.75 * max(2 - R, 0)^2)
}
kernel = cubic
fn tait(r: scalar [kg/m^3], r0: scalar [kg/m^3], c) -> scalar [Pa] { let k = r / r0
    r0 * c^2 / 7 * (k^7 - 1) }
particle eos on fluid -> p { p = tait(rho, rho0, c0) }
particle eos_solid on solid -> p { p = -trace(s) / 3 }
pairsum continuity from solid | fluid -> drho: scalar [kg/m^3/s] {
    acc div_v: scalar [1/s]
    init { drho = 0 }
    div_v += m[j] / rho[j] * dot(v_ij, gradW_ij)
    if j in fluid && r_ij > 0 [m] { div_v += 0 } else { div_v -= 0 }
    finally { drho = rho[i] * div_v }
}
pairsum momentum -> dv: vec [m/s^2], gradv: tensor [1/s] {
    dv += m[j] * ((s[i] - p[i] * I) / rho[i]^2 + (s[j] - p[j] * I) / rho[j]^2) * gradW_ij
    gradv += -m[j] / rho[j] * outer(v_ij, gradW_ij)
}
particle jaumann on solid -> ds: symtensor [Pa/s] {
    let edot = sym(gradv)
    let spin = skew(gradv)
    ds = 2 * G * dev(edot) + sym(s * transpose(spin) + spin * s)
}
integrate { x' = v   v' = dv   rho' = drho }
integrate on solid { s' = ds }
timestep cfl = min_over(0.3 * h / (c0 + norm(v)))
timestep visc = eps * 1 [s] * W_at(1 [m], 1 [m]) * 1 [m^3]
"#;

/// What a panic said, caught by the hook installed for the run.
fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        s.to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "(non-string panic payload)".to_string()
    }
}

#[test]
fn parse_and_check_never_panic() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let stdlib_dir = root.join("stdlib");
    let budget: usize =
        std::env::var("PAIRSUM_FUZZ_INPUTS").ok().and_then(|s| s.parse().ok()).unwrap_or(DEFAULT_INPUTS);
    let seed: u64 = std::env::var("PAIRSUM_FUZZ_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(0x5eed_5eed);

    let mut paths = vec![];
    sph_files(&stdlib_dir, &mut paths);
    sph_files(&root.join("tests/ui"), &mut paths);
    let mut seeds: Vec<String> = paths.iter().filter_map(|p| std::fs::read_to_string(p).ok()).collect();
    seeds.push(MODEL_SEED.to_string());
    let seed_tokens: Vec<Vec<String>> =
        seeds.iter().map(|s| tokenize(s).into_iter().map(str::to_string).collect()).collect();

    let failures_dir = root.join("target/fuzz-failures");
    let mut rng = Rng::new(seed);
    let mut failures: Vec<(String, String)> = vec![];
    let mut slowest = (Duration::ZERO, String::new());
    let mut with_errors = 0usize;
    let mut parsed = 0usize;

    // Silence the default hook's report of each caught panic; the test prints its own.
    let hook = panic::take_hook();
    panic::set_hook(Box::new(|_| {}));
    let start = Instant::now();
    for n in 0..budget {
        let input = match n % 10 {
            // The seeds themselves first, unchanged.
            _ if n < seeds.len() => seeds[n].clone(),
            0 => random_program(&mut rng),
            1 => random_items(&mut rng),
            2 | 3 => {
                let mut text = rng.pick(&seeds).clone();
                for _ in 0..1 + rng.below(3) {
                    mutate_text(&mut rng, &mut text);
                }
                text
            }
            _ => {
                let s = rng.below(seeds.len());
                let o = rng.below(seeds.len());
                let mut toks = seed_tokens[s].clone();
                for _ in 0..1 + rng.below(4) {
                    mutate_tokens(&mut rng, &mut toks, &seed_tokens[s], &seed_tokens[o]);
                }
                toks.concat()
            }
        };
        let t0 = Instant::now();
        let result = panic::catch_unwind(AssertUnwindSafe(|| {
            let mut sources = Sources::new();
            let checked = check_text(&mut sources, "fuzz.sph", &input, Stdlib::Dir(stdlib_dir.clone()));
            // Rendering walks every span: a span outside its file would show up here.
            let _ = render(&sources, &checked.diags);
            (checked.has_errors(), checked.diags.iter().any(|d| d.code == "E0001"))
        }));
        let took = t0.elapsed();
        if took > slowest.0 {
            slowest = (took, input.clone());
        }
        match result {
            Ok((err, syntax)) => {
                with_errors += usize::from(err);
                parsed += usize::from(!syntax);
            }
            Err(payload) => failures.push((input, panic_message(payload.as_ref()))),
        }
    }
    let elapsed = start.elapsed();
    panic::set_hook(hook);

    println!(
        "fuzz: {budget} inputs ({} seeds) in {:.2} s ({:.1} µs each); {parsed} parsed, {with_errors} with errors; \
         slowest {:.1} ms",
        seeds.len(),
        elapsed.as_secs_f64(),
        elapsed.as_secs_f64() * 1e6 / budget.max(1) as f64,
        slowest.0.as_secs_f64() * 1e3
    );
    if failures.is_empty() {
        return;
    }
    std::fs::create_dir_all(&failures_dir).expect("create target/fuzz-failures");
    for (k, (input, msg)) in failures.iter().enumerate().take(20) {
        let path = failures_dir.join(format!("panic-{seed}-{k}.sph"));
        std::fs::write(&path, input).expect("write failure");
        println!("---- panic: {msg}\n     saved to {}\n{input}\n----", path.display());
    }
    panic!("{} of {budget} inputs panicked; see target/fuzz-failures/", failures.len());
}
