//! Every model the checker accepts can be generated: names in the WGSL come from one naming helper
//! (`backend::wgsl::names`), whatever the model's fields, parameters and locals are called. The
//! stdlib models are extended with a state, a parameter, a particle equation and a pair sum whose
//! names are drawn from what is likely to collide (saved copies `x@0`, accessors `ld_x`, WGSL
//! keywords, the kernels' own variables and helper functions); each program the checker accepts
//! must generate WGSL that naga validates.

mod common;
use common::*;
use pairsum::backend::wgsl::{files, names};
use pairsum::check::check_text;
use pairsum::diag::{render, Sources};
use pairsum::schedule::{IntegratorKind, Plan};

const MODELS: &[&str] = &[
    "elastic_solid",
    "elastic_solid_corrected",
    "ek18_solid",
    "ek18_solid_cspm",
    "ek18_solid_variable_h",
    "ek18_solid_failure",
    "fans_solid",
    "fans_solid_plain",
    "ftlr19_perforation",
    "wcsph_fluid",
    "wcsph_dbc",
    "wcsph_adami",
    "lsm_solid",
    "wcsph_lsm",
    "ek18_fsi",
];

/// Names likely to collide with something in the generated code.
const NAMES: &[&str] = &[
    "x_0",
    "v_0",
    "rho_0",
    "s_0",
    "e_0",
    "x_0_2",
    "ld_x",
    "ldj_v",
    "st_rho",
    "prm_E",
    "ld_x_0",
    "filter",
    "target",
    "smooth",
    "loop",
    "struct",
    "var",
    "fn",
    "array",
    "sampler",
    "x_ij",
    "W_ij",
    "sgn",
    "first",
    "count",
    "k",
    "wg",
    "li",
    "G",
    "xi",
    "hi",
    "tr",
    "skip",
    "axis",
    "data",
    "ints",
    "params",
    "info",
    "globals",
    "cells",
    "grid",
    "R",
    "sym",
    "inv",
    "trace",
    "outer",
    "eye",
    "diag",
    "kernel_w",
    "pinf",
    "nan",
    "main",
    "h_of",
    "pos3",
    "in_groups",
    "cl_add",
    "ClF64",
    "_a",
    "a__b",
    "best",
    "remaining",
    "mirrors",
    "h_max",
    "r2",
    "rc",
    "dxv",
    "cell",
    "base",
    "b",
];

/// xorshift: a deterministic choice of names.
fn next(seed: &mut u64) -> usize {
    *seed ^= *seed << 13;
    *seed ^= *seed >> 7;
    *seed ^= *seed << 17;
    (*seed >> 11) as usize
}

fn program(model: &str, n: [&str; 6]) -> String {
    let [state, param, local, out, acc, sum] = n;
    format!(
        "use models::{model}\n\
         state {state}: vec [m]\n\
         param {param}: scalar [-] = 2\n\
         pairsum fuzz_sum -> {sum}: scalar [1/m^3] {{\n    acc {acc}: scalar [1/m^3]\n    {acc} += W_ij\n    finally {{\n        {sum} = {acc}\n    }}\n}}\n\
         particle fuzz_drift -> {out}: vec [m/s] {{\n    let {local} = {param} * v\n    {out} = {local} * {sum} * 1 [m^3]\n}}\n\
         integrate {{ {state}' = {out} }}\n"
    )
}

#[test]
fn every_accepted_model_generates_whatever_its_names() {
    let mut seed = 0x5eed_u64;
    let (mut accepted, mut tried) = (0, 0);
    let mut failures = vec![];
    for model in MODELS {
        for _ in 0..40 {
            // Six different names (a name declared twice is rightly an error).
            let mut n: Vec<&str> = vec![];
            while n.len() < 6 {
                let name = NAMES[next(&mut seed) % NAMES.len()];
                if !n.contains(&name) {
                    n.push(name);
                }
            }
            let n = [n[0], n[1], n[2], n[3], n[4], n[5]];
            let text = program(model, n);
            tried += 1;
            let mut sources = Sources::new();
            let checked = check_text(&mut sources, "fuzz.sph", &text, stdlib());
            if checked.has_errors() {
                continue;
            }
            accepted += 1;
            let m = checked.model;
            let plan = match Plan::build(&m, &scene(&m, 3, &[], IntegratorKind::PredictorCorrector), None) {
                Ok(p) => p,
                Err(e) => {
                    failures.push(format!("{text}\nplan: {e}"));
                    continue;
                }
            };
            if let Err(e) = files(&plan) {
                failures.push(format!("{text}\n{}", e.lines().take(6).collect::<Vec<_>>().join("\n")));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {accepted} accepted programs do not generate:\n{}",
        failures.len(),
        failures.join("\n---\n")
    );
    // The test is only as good as the programs it generates: most must pass the checker.
    assert!(accepted * 5 > tried * 2, "only {accepted} of {tried} programs passed the checker");
}

/// The program of the issue that found the defect: a state named like the integrator's saved copy.
#[test]
fn a_state_named_like_a_saved_copy_generates() {
    let text = "use models::elastic_solid\nstate x_0: vec [m]\nintegrate { x_0' = v }\n";
    let mut sources = Sources::new();
    let checked = check_text(&mut sources, "x0.sph", text, stdlib());
    assert!(!checked.has_errors(), "{}", render(&sources, &checked.diags));
    let m = checked.model;
    let plan = Plan::build(&m, &scene(&m, 3, &[], IntegratorKind::PredictorCorrector), None).expect("plan");
    let kernels = files(&plan).unwrap_or_else(|e| panic!("{e}"));
    let update = &kernels.iter().find(|(n, _)| n.starts_with("update2")).expect("stage 2").1;
    assert!(update.contains("fn ld_x_0(") && update.contains("fn ld_x_0_2("), "both x_0 and x@0 are read:\n{update}");
}

/// `names::HELPERS` is the list of what stands at module scope besides the accessors; a helper
/// added to the generated code without it would be a name a local could take.
#[test]
fn every_module_scope_name_of_the_stdlib_kernels_is_known_to_the_namer() {
    for model in MODELS {
        let m = common::model(&format!("use models::{model}\n"));
        let plan = Plan::build(&m, &scene(&m, 3, &[], IntegratorKind::PredictorCorrector), None).expect("plan");
        for (file, text) in files(&plan).expect("generate") {
            for line in text.lines() {
                let decl = line
                    .strip_prefix("fn ")
                    .or_else(|| line.strip_prefix("const "))
                    .or_else(|| line.strip_prefix("struct "))
                    .or_else(|| line.split_once("> ").filter(|_| line.starts_with("@group")).map(|(_, r)| r));
                let Some(rest) = decl else { continue };
                let name: String = rest.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
                let accessor = ["ld_", "ldj_", "st_", "prm_"].iter().any(|p| name.starts_with(p));
                assert!(
                    accessor || names::HELPERS.contains(&name.as_str()),
                    "{model}/{file}: `{name}` is not in names::HELPERS"
                );
            }
        }
    }
}
