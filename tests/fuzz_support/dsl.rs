//! The language's inputs: mutations of every stdlib module and of the diagnostics corpus (tokens
//! deleted, duplicated, swapped, replaced by tokens of the same file or of the language;
//! characters inserted and deleted; lines shuffled; pieces of other files spliced in), purely
//! random token sequences built from the language's vocabulary, and random programs that follow
//! the grammar's shape; each parsed and checked by `pairsum::check::check_text`.

use super::text::{mutate_text, mutate_tokens, tokenize};
use super::{check_diagnostics, code_of, Kind, Outcome, Rng};
use pairsum::check::{check_text, Stdlib};
use pairsum::diag::Sources;
use std::path::{Path, PathBuf};

/// The language's vocabulary, for random programs and for tokens dropped into mutated files.
pub const VOCABULARY: &[&str] = &[
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
    "\"/dev/zero\"",
    "\"/\"",
    "\"\"",
];

/// A program of random tokens of the language.
pub fn random_program(rng: &mut Rng) -> String {
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
pub fn random_items(rng: &mut Rng) -> String {
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
        let item = match rng.below(9) {
            8 => format!(
                "use {}",
                rng.word(&[
                    "\"/dev/zero\"",
                    "\"/dev/urandom\"",
                    "\"/\"",
                    "\"\"",
                    "\"../x.sph\"",
                    "\"../stdlib/prelude.sph\"",
                    "solid::jaumann",
                    "models::nope",
                    "prelude",
                    "kernels"
                ])
            ),
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
pub fn sph_files(dir: &Path, out: &mut Vec<PathBuf>) {
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
pub const MODEL_SEED: &str = r#"
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

/// A program nested deep, around the parser's and the checker's depth limits or far past them:
/// brackets, operators, calls, units, `else if` chains, blocks, helpers calling helpers,
/// constants defined through constants, helpers that double at each level.
pub fn nested(rng: &mut Rng) -> String {
    let n = match rng.below(4) {
        0 => 100 + rng.below(60),
        1 => 200 + rng.below(100),
        2 => rng.below(1000),
        _ => rng.below(20_000),
    };
    let eq = |body: &str| format!("group g\nfield q: scalar\nparticle e -> q {{\n{body}\n}}\n");
    match rng.below(11) {
        0 => format!("const a = {}1{}", "(".repeat(n), ")".repeat(n)),
        1 => format!("const a = {}1", "- ".repeat(n)),
        2 => format!("const a = 1{}", " + 1".repeat(n)),
        3 => format!("const a = 2{}", " ^ 1".repeat(n)),
        4 => format!("const a = {}1{}", "max(1, ".repeat(n), ")".repeat(n)),
        5 => format!("const a = 1 [m{}]", " * m".repeat(n)),
        6 => eq(&format!("if true {{ q = 1 }}{} else {{ q = 2 }}", " else if true { q = 1 }".repeat(n))),
        7 => eq(&format!("{}q = 1{}", "if true { ".repeat(n), " }".repeat(n))),
        8 => {
            let mut t = String::from("fn f0(x) { x + 1 }\n");
            for k in 1..=n.min(3000) {
                t.push_str(&format!("fn f{k}(x) {{ f{}(x) * 2 }}\n", k - 1));
            }
            t + &eq(&format!("q = f{}(1)", n.min(3000)))
        }
        9 => {
            let mut t = String::from("const c0 = 1\n");
            for k in 1..=n.min(3000) {
                t.push_str(&format!("const c{k} = c{} + 1\n", k - 1));
            }
            t
        }
        10 if rng.chance(20) => {
            let levels = 10 + rng.below(30);
            let mut t = String::from("fn d0(x) { x + 1 }\n");
            for k in 1..=levels {
                t.push_str(&format!("fn d{k}(x) {{ d{}(x) + d{}(x) }}\n", k - 1, k - 1));
            }
            t + &eq(&format!("q = d{levels}(1)"))
        }
        _ => format!("const a = 1{}", " * 1".repeat(n)),
    }
}

/// DSL source text.
pub struct Dsl {
    seeds: Vec<String>,
    tokens: Vec<Vec<String>>,
    stdlib: PathBuf,
}

impl Dsl {
    pub fn new() -> Dsl {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut paths = vec![];
        sph_files(&root.join("stdlib"), &mut paths);
        sph_files(&root.join("tests/ui"), &mut paths);
        let mut seeds: Vec<String> = paths.iter().filter_map(|p| std::fs::read_to_string(p).ok()).collect();
        seeds.push(MODEL_SEED.to_string());
        let tokens = seeds.iter().map(|s| tokenize(s).into_iter().map(str::to_string).collect()).collect();
        Dsl { seeds, tokens, stdlib: root.join("stdlib") }
    }
}

impl Kind for Dsl {
    fn name(&self) -> &'static str {
        "dsl"
    }
    fn extension(&self) -> &'static str {
        "sph"
    }
    fn generate(&mut self, index: u64, rng: &mut Rng) -> Vec<u8> {
        if let Some(s) = self.seeds.get(index as usize) {
            return s.clone().into_bytes();
        }
        let text = match rng.below(10) {
            0 if rng.chance(20) => nested(rng),
            0 => random_program(rng),
            1 => random_items(rng),
            2 | 3 => {
                let mut text = rng.pick(&self.seeds).clone();
                let other = rng.pick(&self.seeds).clone();
                for _ in 0..1 + rng.below(3) {
                    mutate_text(rng, &mut text, &other);
                }
                text
            }
            _ => {
                let s = rng.below(self.seeds.len());
                let o = rng.below(self.seeds.len());
                let mut toks = self.tokens[s].clone();
                for _ in 0..1 + rng.below(4) {
                    mutate_tokens(rng, &mut toks, &self.tokens[s], &self.tokens[o], VOCABULARY);
                }
                toks.concat()
            }
        };
        text.into_bytes()
    }
    fn run(&mut self, input: &[u8]) -> Outcome {
        let text = String::from_utf8_lossy(input);
        let mut sources = Sources::new();
        let checked = check_text(&mut sources, "fuzz.sph", &text, Stdlib::Dir(self.stdlib.clone()));
        // Rendering walks every span: a span outside its file would show up here.
        match check_diagnostics(&sources, &checked.diags) {
            Ok(()) if checked.has_errors() => Outcome::Refused(code_of(&checked.diags)),
            Ok(()) => Outcome::Accepted("checked".into()),
            Err(e) => Outcome::Bad(e),
        }
    }
}
