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

#[test]
fn an_initial_value_the_host_cannot_evaluate_names_what_it_calls() {
    let dir = fresh_dir("tensor");
    let velocity = "vec(det(I) * 1 [m/s], 0 [m/s])";
    let (scene, plan) = prepare(&block_case(&dir, velocity), &Default::default()).unwrap_or_else(|e| panic!("{e}"));
    let err = match build_store::<f64>(&plan, &scene.particles, &scene.materials) {
        Ok(_) => panic!("det(I) was evaluated on the host"),
        Err(e) => e.0,
    };
    assert!(
        err.contains(
            "cannot compute the case's initial value of `v`: it calls `det`, which is not evaluated before the run"
        ),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
