//! The one-evaluation integrators (`pec`, `symplectic_pec`): the predictor takes the rates of the
//! step before's evaluation, so a step evaluates the neighbour passes once, not twice.

mod common;
use common::max_abs_diff;
use pairsum::backend::cpu::CpuBackend;
use pairsum::engine::setup::build_store;
use pairsum::engine::Engine;
use pairsum::schedule::Action;
use std::path::Path;

fn case(name: &str) -> String {
    format!("{}/cases/{name}.toml", env!("CARGO_MANIFEST_DIR"))
}

/// The bundled dam break (CI resolution, DBC walls) with `integrator` set, after `steps` steps:
/// the engine, and the neighbour evaluations its plan makes per step.
fn dam_break(integrator: &str, steps: usize) -> (Engine<CpuBackend<f64>>, usize) {
    let opts = pairsum::scene::Options { set: vec![("integrator".into(), integrator.into())], ..Default::default() };
    let (scene, plan) = pairsum::runner::prepare(Path::new(&case("dam_break_2d")), &opts).expect("case");
    let evaluations = plan.actions.iter().filter(|a| matches!(a, Action::Evaluate)).count();
    let store = build_store::<f64>(&plan, &scene.particles, &scene.materials).expect("store");
    let backend = CpuBackend::new(plan, store, scene.mirrors.clone()).expect("backend");
    let mut engine = Engine::new(backend, scene.config.clone());
    engine.initialise().expect("initialise");
    for k in 0..steps {
        engine.step().unwrap_or_else(|e| panic!("{integrator}: step {k}: {e}"));
    }
    (engine, evaluations)
}

/// 1,000 steps (56 ms, the column half collapsed): `symplectic_pec` evaluates once per step where
/// `symplectic` evaluates twice, reaches the same time to 1e-4 (its steps follow the same limits
/// from rates half a step older), and puts every particle within 0.2 % of Δx of where the
/// two-evaluation scheme puts it.
#[test]
fn symplectic_pec_evaluates_once_per_step_and_keeps_the_dam_break_within_a_fraction_of_a_spacing() {
    let (two, twice) = dam_break("symplectic", 1000);
    let (one, once) = dam_break("symplectic_pec", 1000);
    assert_eq!((twice, once), (2, 1));
    assert!((two.time - one.time).abs() <= 1e-4 * two.time, "clocks {} and {}", two.time, one.time);
    let x = |e: &Engine<CpuBackend<f64>>| {
        let f = e.backend.plan.model.field_id("x").expect("x");
        pairsum::backend::Backend::read(&e.backend, f).expect("read").expect("stored").1
    };
    let (a, b) = (x(&two), x(&one));
    assert_eq!(a.len(), b.len());
    let dx = 2.8575e-3;
    let worst = max_abs_diff("positions, symplectic against symplectic_pec", &a, &b);
    eprintln!("largest difference of a position: {worst:e} m ({:.2e} of the spacing)", worst / dx);
    assert!(worst <= 2e-3 * dx, "a particle moved {worst:e} m from the two-evaluation scheme's position");
}
