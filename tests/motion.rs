//! Prescribed rigid motion (`[[constraints]]` with `velocity` and `rotation`): the moved bodies
//! follow the exact motion, computed here independently of the integrator's Rodrigues formula
//! (as the matrix exponential of the rotation's generator, summed as a power series), and push
//! the water they meet.

mod common;
use common::*;
use pairsum::backend::cpu::CpuBackend;
use pairsum::engine::setup::build_store;
use pairsum::engine::Engine;
use pairsum::runner::prepare;
use std::path::{Path, PathBuf};

/// A case written into a fresh folder, removed when the test passes.
fn case_file(tag: &str, text: &str) -> (Scratch, PathBuf) {
    let dir = Scratch::new(&format!("motion-{tag}"));
    let path = dir.join(format!("{tag}.toml"));
    std::fs::write(&path, text).expect("write case");
    (dir, path)
}

/// Runs a case on the CPU in f64 for `steps` steps; returns the engine and the initial positions.
fn run(path: &Path, steps: usize) -> (Engine<CpuBackend<f64>>, Vec<[f64; 3]>, Vec<u32>) {
    let (scene, plan) = prepare(path, &Default::default()).unwrap_or_else(|e| panic!("{e}"));
    let store = build_store::<f64>(&plan, &scene.particles, &scene.materials).expect("store");
    let cpu = CpuBackend::new(plan, store, scene.mirrors.clone()).expect("cpu");
    let mut engine = Engine::new(cpu, scene.config.clone());
    engine.initialise().expect("init");
    for k in 0..steps {
        engine.step().unwrap_or_else(|e| panic!("step {k}: {e}"));
    }
    (engine, scene.particles.x.clone(), scene.particles.body.clone())
}

type V3 = [f64; 3];

fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn scale(s: f64, a: V3) -> V3 {
    [s * a[0], s * a[1], s * a[2]]
}
fn cross(a: V3, b: V3) -> V3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
fn dist(a: V3, b: V3) -> f64 {
    let d = sub(a, b);
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

/// exp(θ [â]ₓ) u: the power series Σ (θ [â]ₓ)ⁿ u / n!, each term the cross product of the last.
fn rotate(axis: V3, theta: f64, u: V3) -> V3 {
    let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    let a = scale(1.0 / n, axis);
    let (mut sum, mut term) = (u, u);
    for k in 1..60 {
        term = scale(theta / k as f64, cross(a, term));
        sum = add(sum, term);
    }
    sum
}

/// The rotated angle of a speed ramped over `ramp`: ω ∫₀ᵗ min(τ/ramp, 1) dτ.
fn ramped(omega: f64, ramp: f64, t: f64) -> f64 {
    omega * if t < ramp { t * t / (2.0 * ramp) } else { t - ramp / 2.0 }
}

/// A 2D tank of water with a paddle above it turning about its middle (`tests/data/paddle_2d.toml`).
fn paddle_case() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/paddle_2d.toml")
}

#[test]
fn a_paddle_turns_rigidly_about_its_centre_and_pushes_the_water_aside() {
    let (engine, x0, body) = run(&paddle_case(), 5000);
    let t = engine.time;
    let (omega, c, z) = (3.0, [0.1, 0.09, 0.0], [0.0, 0.0, 1.0]);
    let theta = ramped(omega, 0.05, t);
    assert!(theta > 1.8, "the paddle has turned only {theta} rad by t = {t}");
    let (_, x) = field_by_id(&engine.backend, "x");
    let (_, v) = field_by_id(&engine.backend, "v");
    let (mut paddle, mut water) = (vec![], vec![]);
    for (k, x0) in x0.iter().enumerate() {
        let at = [x[2 * k], x[2 * k + 1], 0.0];
        let vel = [v[2 * k], v[2 * k + 1], 0.0];
        match body[k] {
            2 => {
                let exact = add(c, rotate(z, theta, sub(*x0, c)));
                assert!(dist(at, exact) < 1e-12, "paddle particle {k} at {at:?}, exact {exact:?}");
                let exact_v = scale(omega, cross(z, sub(exact, c)));
                assert!(dist(vel, exact_v) < 1e-12, "paddle particle {k}: v {vel:?}, exact {exact_v:?}");
                paddle.push(at);
            }
            0 => water.push(at),
            _ => {}
        }
    }
    // The paddle pushes the water rather than passing through it: no water particle comes within
    // half a spacing of it, though its left half has swept through the water.
    let distances: Vec<f64> = water.iter().flat_map(|w| paddle.iter().map(move |p| dist(*w, *p))).collect();
    let gap = least("water–paddle distance", &distances);
    let deepest = least("paddle's y", &paddle.iter().map(|p| p[1]).collect::<Vec<_>>());
    assert!(deepest < 0.05, "the paddle reaches down to y = {deepest} only");
    assert!(gap > 0.5 * 0.005, "a water particle is {gap} m from the paddle");
}

#[test]
fn a_cube_turning_about_a_tilted_axis_while_its_centre_moves_follows_rodrigues_exactly() {
    let text = r#"
name = "cube"
model = "models::wcsph_dbc"
dim = 3
integrator = "predictor_corrector"
end_time = "1 s"

[resolutions]
ci = "10 mm"

[materials.solid]
rho0 = "1000 kg/m^3"
c0 = "10 m/s"
gamma = 7
h_ratio = 1.5
visc_a = 0.1
visc_b = 0
nu0 = "1e-6 m^2/s"
delta = 0.1

[[bodies]]
name = "cube"
group = "wall"
material = "solid"
shape = { box = { min = [0, 0, 0], max = ["60 mm", "60 mm", "60 mm"] } }

[[constraints]]
body = "cube"
velocity = ["0.5 m/s", 0, "-0.2 m/s"]
rotation = { center = ["30 mm", "30 mm", "30 mm"], omega = "-4 rad/s", axis = [1, 2, 2] }
ramp = "20 ms"
"#;
    let (_dir, path) = case_file("cube", text);
    let (engine, x0, _) = run(&path, 400);
    let t = engine.time;
    let (omega, ramp, axis) = (-4.0, 0.02, [1.0, 2.0, 2.0]);
    let theta = ramped(omega, ramp, t);
    let speed = [0.5, 0.0, -0.2];
    let c0 = [0.03, 0.03, 0.03];
    let c = add(c0, scale(ramped(1.0, ramp, t), speed));
    let (_, x) = field_by_id(&engine.backend, "x");
    let (_, v) = field_by_id(&engine.backend, "v");
    assert!(t > 0.05, "only {t} s simulated");
    for (k, x0) in x0.iter().enumerate() {
        let at = [x[3 * k], x[3 * k + 1], x[3 * k + 2]];
        let exact = add(c, rotate(axis, theta, sub(*x0, c0)));
        assert!(dist(at, exact) < 1e-12, "particle {k} at {at:?}, exact {exact:?}");
        let vel = [v[3 * k], v[3 * k + 1], v[3 * k + 2]];
        let exact_v = add(speed, scale(omega / 3.0, cross(axis, sub(exact, c))));
        assert!(dist(vel, exact_v) < 1e-12, "particle {k}: v {vel:?}, exact {exact_v:?}");
    }
}

/// A block falling under gravity with the case's `damping` c: every particle's velocity follows
/// the explicit Euler recurrence v ← v + Δt (g − c v), v_n = −(g/c) (1 − (1 − c Δt)ⁿ), and tends to
/// the terminal speed g/c.
#[test]
fn a_damped_falling_block_reaches_the_terminal_speed_g_over_c_as_euler_steps_it() {
    let (_dir, path) = case_file(
        "damped",
        &common::block_case(
            "falling.sph",
            "integrator = \"euler\"\nend_time = \"1 s\"\ngravity = [0, \"-9.81 m/s^2\"]\ndamping = \"10 1/s\"",
            "",
            "",
        ),
    );
    let model = "use kernels\ngroup metal\nkernel = wendland_c2\nintegrate { x' = v  v' = 0 }\n";
    std::fs::write(path.with_file_name("falling.sph"), model).expect("write model");
    let (engine, _, _) = run(&path, 1000);
    let (_, v) = field_by_id(&engine.backend, "v");
    let (g, c, dt) = (9.81, 10.0, 1e-3_f64);
    let expected = -(g / c) * (1.0 - (1.0 - c * dt).powi(1000));
    for (k, vy) in v.iter().skip(1).step_by(2).enumerate() {
        assert!((vy - expected).abs() <= 1e-12 * expected.abs(), "particle {k}: v_y = {vy}, expected {expected}");
    }
    assert!((expected + g / c).abs() < 1e-4 * g / c, "not yet at the terminal speed: {expected}");
}
