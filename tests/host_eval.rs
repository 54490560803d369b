//! The host evaluator (src/host_eval.rs): a case's initial values with `select`, comparisons and
//! the hyperbolic functions (a mode shape's), against the same formulas in Rust; and the one
//! error of what it does not evaluate.

mod common;
use common::*;
use pairsum::backend::cpu::CpuBackend;
use pairsum::engine::setup::build_store;
use pairsum::runner::prepare;
use std::path::PathBuf;

const MODEL: &str = "use kernels\ngroup metal\nkernel = wendland_c2\nintegrate { x' = v  v' = 0 }\n";

/// The block of `common::block_case` with its initial velocity `velocity`, written with the model
/// into `dir`; the case's path.
fn block_case(dir: &PathBuf, velocity: &str) -> PathBuf {
    let case =
        common::block_case("model.sph", "end_time = \"1 ms\"", &format!("initial = {{ v = \"{velocity}\" }}"), "");
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("model.sph"), MODEL).unwrap();
    std::fs::write(dir.join("case.toml"), case).unwrap();
    dir.join("case.toml")
}

fn fresh_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pairsum-host-eval-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

#[test]
fn an_initial_velocity_with_select_a_comparison_cosh_sinh_and_tanh_equals_the_formula() {
    let dir = fresh_dir("select");
    let velocity = "select(x.x > 0.03 [m] && !(x.y > 0.05 [m]), vec(cosh(x.x / 0.02 [m]) * 1 [m/s], sinh(x.y / 0.02 [m]) * 1 [m/s]), vec(0, tanh(x.x / 0.02 [m]) * 1 [m/s]))";
    let (scene, plan) = prepare(&block_case(&dir, velocity), &Default::default()).unwrap_or_else(|e| panic!("{e}"));
    let store = build_store::<f64>(&plan, &scene.particles, &scene.materials).unwrap_or_else(|e| panic!("{e}"));
    let b = CpuBackend::new(plan, store, vec![]).expect("backend");
    let (_, x) = field_by_id(&b, "x");
    let (_, v) = field_by_id(&b, "v");
    assert_eq!(x.len(), 72);
    let (mut picked, mut other) = (0, 0);
    for k in 0..36 {
        let (px, py) = (x[2 * k], x[2 * k + 1]);
        let expected = if px > 0.03 && py <= 0.05 {
            picked += 1;
            [(px / 0.02).cosh(), (py / 0.02).sinh()]
        } else {
            other += 1;
            [0.0, (px / 0.02).tanh()]
        };
        for c in 0..2 {
            let d = (v[2 * k + c] - expected[c]).abs();
            assert!(
                d <= 1e-12 * expected[c].abs().max(1.0),
                "particle {k} at ({px}, {py}): v = {:?}, expected {expected:?}",
                &v[2 * k..2 * k + 2]
            );
        }
    }
    // Both branches are taken: 3 columns × 5 rows, and the rest.
    assert_eq!((picked, other), (15, 21));
    let _ = std::fs::remove_dir_all(&dir);
}

/// An initial value the host cannot compute is a load error with its code and place in the case
/// file (issue 40), in every branch of a `select` whether or not a particle takes it: a call the
/// host does not evaluate, a field computed during the step, the time.
#[test]
fn an_initial_value_the_host_cannot_evaluate_is_a_load_error_at_its_place_naming_the_cause() {
    let dir = fresh_dir("tensor");
    for (velocity, says) in [
        ("vec(det(I) * 1 [m/s], 0 [m/s])", "it calls `det`, which is not evaluated before the run"),
        ("select(x.x > 1 [m], vec(det(I) * 1 [m/s], 0 [m/s]), 0)", "it calls `det`"),
        ("vec(t * 1 [m/s^2], 0 [m/s])", "it reads `t`, which has no value before the run"),
    ] {
        let err = match prepare(&block_case(&dir, velocity), &Default::default()) {
            Ok(_) => panic!("{velocity}: loaded"),
            Err(e) => e.to_string(),
        };
        assert!(
            err.contains("error[C0045]: the initial value of `v` cannot be computed before the run: ")
                && err.contains(says)
                && err.contains("case.toml:15:17"),
            "{velocity}: {err}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A probe of an expression (issue 40) is the same evaluator over the run's fields: the kinetic
/// energy written as `0.5 * m * dot(v, v)` summed over the block is the `kinetic_energy` measure,
/// and the mean of a tensor expression's component (`s - p * I`, `xx`) is the mean of `s.xx` less
/// the mean of `p`, at every recorded step.
#[test]
fn a_probe_of_an_expression_equals_the_measure_and_the_fields_it_is_written_from() {
    let dir = fresh_dir("probe-expression");
    std::fs::create_dir_all(&dir).unwrap();
    let probes = r#"
[[probes]]
name = "by_expression"
expression = "0.5 * m * dot(v, v)"
reduce = "sum"

[[probes]]
name = "measured"
measure = "kinetic_energy"

[[probes]]
name = "total_xx"
expression = "s - p * I"
component = "xx"

[[probes]]
name = "s_xx"
field = "s"
component = "xx"

[[probes]]
name = "p"
field = "p"
"#;
    // A block squeezed along x by its initial velocity: stress and pressure build up.
    let case = common::block_case(
        "models::elastic_solid",
        "end_time = \"0.2 ms\"",
        "initial = { v = \"vec(-2 [1/s] * (x.x - 0.03 [m]), 0 [m/s])\" }",
        probes,
    )
    .replace("rho0 = \"1000 kg/m^3\"", "rho0 = \"1000 kg/m^3\"\nE = \"1 GPa\"\nnu = 0.3")
    .replace("group = \"metal\"", "group = \"solid\"");
    let outcome = common::run_case_text_on_cpu(&dir, &case);
    let history = |name: &str| outcome.histories.iter().find(|(n, _)| n == name).expect("probe").1.clone();
    let (by_expression, measured) = (history("by_expression"), history("measured"));
    assert!(by_expression.len() > 10 && by_expression.len() == measured.len());
    for ((t, a), (_, b)) in by_expression.iter().zip(&measured) {
        assert!(*b > 0.0 && (a - b).abs() <= 1e-12 * b, "t = {t}: ½ m v·v summed {a} J, kinetic energy {b} J");
    }
    let (total, s_xx, p) = (history("total_xx"), history("s_xx"), history("p"));
    assert!(p.iter().any(|(_, v)| *v > 1e4), "the block was not squeezed: p = {p:?} Pa");
    for k in 0..total.len() {
        let expected = s_xx[k].1 - p[k].1;
        let scale = s_xx[k].1.abs() + p[k].1.abs();
        assert!(
            (total[k].1 - expected).abs() <= 1e-12 * scale,
            "t = {}: mean(s.xx − p) {} Pa, mean s.xx − mean p {expected} Pa",
            total[k].0,
            total[k].1
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
