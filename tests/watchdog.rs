//! The watchdog stops a run that blows up at finite values, on either backend: energy that grows
//! without a source (two elastic bars that collide through sums that mix their bodies), a
//! particle faster than the case can explain, and never a run that only converts energy (a block
//! falling freely for a second). A stopped run exits 1, names the step, particle, group and
//! field, keeps its last good state and reports no figures.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn fresh_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pairsum-watchdog-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

/// Writes the files and runs `pairsum run` on the case `case.toml`, into `dir/out`.
fn run(dir: &Path, files: &[(&str, &str)], backend: &str) -> Output {
    for (name, text) in files {
        std::fs::write(dir.join(name), text).unwrap();
    }
    Command::new(env!("CARGO_BIN_EXE_pairsum"))
        .args(["run", "--quiet", "--backend", backend, "--out"])
        .arg(dir.join("out"))
        .arg(dir.join("case.toml"))
        .output()
        .expect("pairsum runs")
}

fn report(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("out/report.json")).expect("report.json");
    serde_json::from_str(&text).expect("json")
}

/// The stdlib's corrected elastic solid as it was when issue 38 was filed: its momentum sum
/// skips the other body, its continuity, velocity-gradient and correction sums do not, so two
/// bodies that meet feel each other's velocity but not each other's stress.
const MIXING_MODEL: &str = "use kernels\nuse continuity::plain\nuse correction::kernel_gradient\n\
    use solid::strain_rate_corrected\nuse solid::jaumann\nuse eos::linear\nuse momentum::corrected\n\
    use timestep::acoustic\ngroup solid\nkernel = wendland_c2\nparam E: scalar [Pa]\nparam nu: scalar [-]\n\
    param G: scalar [Pa] = E / (2 * (1 + nu))\nparam bulk: scalar [Pa] = E / (3 * (1 - 2 * nu))\n\
    integrate { x' = v  v' = dv  rho' = drho  s' = ds }\n";

/// Two steel bars, 50 × 10 mm at 1 mm, 1 mm apart, meeting at ±10 m/s. With the mixing model the
/// run took 68,896 steps instead of about 450 and ended at a mean speed of 22 km/s.
const BARS_CASE: &str = r#"name = "bars"
model = "mixing.sph"
dim = 2
integrator = "predictor_corrector"
end_time = "0.1 ms"

[resolutions]
ci = "1 mm"

[materials.steel]
rho0 = "7850 kg/m^3"
E = "200 GPa"
nu = 0.3
h_ratio = 1.3

[[bodies]]
name = "left"
group = "solid"
material = "steel"
shape = { box = { min = ["-50.5 mm", "-5 mm"], max = ["-0.5 mm", "5 mm"] } }
velocity = ["10 m/s", 0]

[[bodies]]
name = "right"
group = "solid"
material = "steel"
shape = { box = { min = ["0.5 mm", "-5 mm"], max = ["50.5 mm", "5 mm"] } }
velocity = ["-10 m/s", 0]

[output]
fields = ["v"]

[[probes]]
name = "kinetic_energy"
measure = "kinetic_energy"
unit = "J"

[[results]]
quantity = "kinetic_energy_at_the_end"
probe = "kinetic_energy"
at = "end"
"#;

fn colliding_bars_that_gain_energy_are_stopped(backend: &str) {
    let dir = fresh_dir(&format!("bars-{backend}"));
    let o = run(&dir, &[("mixing.sph", MIXING_MODEL), ("case.toml", BARS_CASE)], backend);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("the energy (kinetic, internal and gravity's potential) grew by "), "{stderr}");
    assert!(stderr.contains("in a case without loads or moving constraints; the fastest particle, "), "{stderr}");
    assert!(stderr.contains("(group solid), has `v` = "), "{stderr}");
    // The bound is the energy at t = 0: ½ · 2 · 7850 kg/m³ · (50 × 10 mm²) · 1 m · (10 m/s)² = 392.5 J.
    let bound: f64 =
        stderr.split("the watchdog's bound ").nth(1).and_then(|s| s.split(' ').next()).unwrap().parse().unwrap();
    assert!((bound - 392.5).abs() < 0.01 * 392.5, "bound {bound} J: {stderr}");
    // Stopped within the impact (2L/c ≈ 20 µs), long before the 0.1 ms it was asked to run.
    let t: f64 = stderr.split("(t = ").nth(1).and_then(|s| s.split(' ').next()).unwrap().parse().unwrap();
    assert!(t < 5e-5, "stopped at t = {t} s: {stderr}");
    let report = report(&dir);
    assert!(report["notes"].to_string().contains("the run did not complete"), "{}", report["notes"]);
    assert_eq!(report["results"].as_array().map(Vec::len), Some(0), "{}", report["results"]);
    let kept = pairsum::report::vtk::read_vtu(&dir.join("out/last_good.vtu")).expect("last_good.vtu");
    assert_eq!(kept.positions.len(), 1000);
    let v = &kept.fields.iter().find(|f| f.name == "v").expect("v kept").data;
    assert!(v.iter().all(|x| x.is_finite()), "the last good state holds a non-finite velocity");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn colliding_bars_that_gain_energy_stop_on_the_energy_bound_on_the_cpu() {
    colliding_bars_that_gain_energy_are_stopped("cpu");
}

#[test]
fn colliding_bars_that_gain_energy_stop_on_the_energy_bound_on_the_gpu() {
    colliding_bars_that_gain_energy_are_stopped("gpu");
}

/// From t = 10.5 ms the particles at x > 25 mm accelerate at 10⁵ m/s²: 100 m/s after one 1 ms step.
const KICKED_MODEL: &str = "use kernels\ngroup metal\nkernel = wendland_c2\n\
    particle kick -> dv: vec [m/s^2] { dv = select(t > 0.0105 [s] && x.x > 0.025 [m], vec(1e5 [m/s^2], 0 [m/s^2]), 0) }\n\
    integrate { x' = v  v' = dv }\n";

/// A case of one block of 6 × 6 particles at 10 mm, its largest speed probed, with the model
/// `model`, the top-level keys `top` and the result `result` on the probe `speed`.
fn block_case(model: &str, top: &str, result: &str) -> String {
    format!(
        r#"name = "block"
model = "{model}"
dim = 2
{top}
dt_max = "1 ms"

[materials.metal]
rho0 = "1000 kg/m^3"

[[bodies]]
name = "block"
group = "metal"
material = "metal"
shape = {{ box = {{ min = [0, 0], max = ["60 mm", "60 mm"] }} }}

[resolutions]
ci = "10 mm"

[[probes]]
name = "speed"
body = "block"
field = "v"
component = "norm"
reduce = "max"
unit = "m/s"

[[results]]
probe = "speed"
at = "end"
{result}
"#
    )
}

/// The kicked block, with a load (of a micronewton) that makes the energy bound step aside, so
/// that the speed bound must catch the kick.
fn kicked_case() -> String {
    let case = block_case("kicked.sph", "integrator = \"euler\"\nend_time = \"50 ms\"", "quantity = \"largest_speed\"");
    format!("{case}\n[[loads]]\nbody = \"block\"\nforce = [0, \"1e-6 N\"]\n")
}

#[test]
fn a_particle_faster_than_three_times_the_signal_speed_stops_the_run_naming_it() {
    let dir = fresh_dir("kicked");
    let o = run(&dir, &[("kicked.sph", KICKED_MODEL), ("case.toml", &kicked_case())], "cpu");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    // Checked every 10 steps: the kick at step 11 is seen at step 20. The speed scale is the
    // signal speed min h / Δt₀ = 1.2 · 10 mm / 1 ms = 12 m/s; the bound three times that.
    assert!(stderr.contains("went unstable at step 20 "), "{stderr}");
    assert!(stderr.contains("(group metal) moves at `v` = "), "{stderr}");
    assert!(
        stderr.contains("faster than the watchdog's bound 3.600e1 m/s (3.000 × the case's speed scale, 1.200e1 m/s"),
        "{stderr}"
    );
    let particle: usize = stderr.split("particle ").nth(1).and_then(|s| s.split(' ').next()).unwrap().parse().unwrap();
    // Filled row by row from the corner: 6 × 6 at 10 mm, x = 5 … 55 mm.
    assert!(particle % 6 >= 3, "particle {particle} lies at x < 25 mm and was never kicked");
    assert_eq!(report(&dir)["results"].as_array().map(Vec::len), Some(0));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A block that falls freely for 1 s gains 4.9 m of fall's energy from gravity: no bound trips.
fn falling_case() -> String {
    block_case(
        "falling.sph",
        "integrator = \"symplectic\"\nend_time = \"1 s\"\ngravity = [0, \"-9.81 m/s^2\"]",
        "quantity = \"speed_at_the_end\"\nreference = \"9.81 m/s\"",
    )
}

const FALLING_MODEL: &str = "use kernels\ngroup metal\nkernel = wendland_c2\nintegrate { x' = v  v' = 0 }\n";

#[test]
fn a_block_falling_freely_for_a_second_is_not_stopped_and_reaches_g_times_t() {
    let dir = fresh_dir("falling");
    let o = run(&dir, &[("falling.sph", FALLING_MODEL), ("case.toml", &falling_case())], "cpu");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let speed = report(&dir)["results"][0]["value"].as_f64().expect("a figure");
    assert!((speed - 9.81).abs() < 1e-6 * 9.81, "speed {speed} m/s after 1 s of free fall");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_watchdog_factor_that_is_not_positive_is_an_error_at_its_line() {
    let dir = fresh_dir("factor");
    let case = format!("{}\n[watchdog]\nenergy_factor = 0\n", falling_case());
    let o = run(&dir, &[("falling.sph", FALLING_MODEL), ("case.toml", &case)], "cpu");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("C0041") && stderr.contains("`watchdog.energy_factor` must be positive"), "{stderr}");
    let line = case.lines().position(|l| l.starts_with("energy_factor")).unwrap() + 1;
    assert!(stderr.contains(&format!("case.toml:{line}:")), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}
