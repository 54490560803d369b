//! The watchdog stops a run that blows up at finite values, on either backend: energy that grows
//! without a source (two elastic bars that collide through sums that mix their bodies), a
//! particle faster than the case can explain, and never a run that only converts energy (a block
//! falling freely for a second). A stopped run exits 1, names the step, particle, group and
//! field, keeps its last good state and reports no figures.

mod common;
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

/// Runs the bars on `backend`, with `[watchdog]` keys `watchdog`, and checks what every stopped
/// run must show: exit 1 within the impact (2L/c ≈ 20 µs, long before the 0.1 ms asked for), the
/// particle and group named, a report without figures and a finite last good state. Returns
/// stderr.
fn colliding_bars_stopped(tag: &str, backend: &str, watchdog: &str) -> String {
    let dir = fresh_dir(&format!("bars-{tag}-{backend}"));
    let case = format!("{BARS_CASE}\n[watchdog]\n{watchdog}\n");
    let o = run(&dir, &[("mixing.sph", MIXING_MODEL), ("case.toml", &case)], backend);
    let stderr = String::from_utf8_lossy(&o.stderr).to_string();
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("(group solid)"), "{stderr}");
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
    stderr
}

/// The number after `after` in `text`, up to the next space.
fn number_after(text: &str, after: &str) -> f64 {
    text.split(after).nth(1).and_then(|s| s.split(' ').next()).unwrap().parse().unwrap()
}

/// The bars meet at ±10 m/s: a particle past 30 m/s stops the run (at step 230, t = 19.4 µs, on
/// either backend), before the energy bound does (step 260).
fn colliding_bars_stop_on_three_times_their_initial_speed(backend: &str) {
    let stderr = colliding_bars_stopped("speed", backend, "");
    assert!(stderr.contains("faster than the watchdog's bound 3.000e1 m/s (3.000 × the case's speed scale, 1.000e1 m/s, from the fastest initial speed; where such a speed is real, a fragment thrown off, `[watchdog] speed_factor` raises the bound)"), "{stderr}");
    assert!(number_after(&stderr, "moves at `v` = ") > 30.0, "{stderr}");
}

#[test]
fn colliding_bars_that_gain_energy_stop_on_three_times_their_initial_speed_on_the_cpu() {
    colliding_bars_stop_on_three_times_their_initial_speed("cpu");
}

#[test]
fn colliding_bars_that_gain_energy_stop_on_three_times_their_initial_speed_on_the_gpu() {
    colliding_bars_stop_on_three_times_their_initial_speed("gpu");
}

#[test]
fn colliding_bars_that_gain_energy_stop_on_the_energy_bound_without_the_speed_bound() {
    let stderr = colliding_bars_stopped("energy", "cpu", "speed_factor = inf");
    assert!(stderr.contains("the energy (kinetic, internal and gravity's potential) grew by "), "{stderr}");
    assert!(stderr.contains("in a case without loads or moving constraints; the fastest particle, "), "{stderr}");
    assert!(stderr.contains("(group solid), has `v` = "), "{stderr}");
    // The bound is the energy at t = 0: ½ · 2 · 7850 kg/m³ · (50 × 10 mm²) · 1 m · (10 m/s)² = 392.5 J.
    let bound = number_after(&stderr, "the watchdog's bound ");
    assert!((bound - 392.5).abs() < 0.01 * 392.5, "bound {bound} J: {stderr}");
}

/// For one 1 ms step from t = 10.5 ms, the particles at x > 25 mm accelerate at `kick`: they move
/// at `kick` × 1 ms from then on.
fn kicked_model(kick: &str) -> String {
    format!(
        "use kernels\ngroup metal\nkernel = wendland_c2\n\
         particle kick -> dv: vec [m/s^2] {{ dv = select(t > 0.0105 [s] && t < 0.0115 [s] && x.x > 0.025 [m], vec({kick}, 0 [m/s^2]), 0) }}\n\
         integrate {{ x' = v  v' = dv }}\n"
    )
}

/// The block of `common::block_case` with the model `model`, the top-level keys `top` and its
/// largest speed probed, the result `result` on that probe.
fn block_case(model: &str, top: &str, result: &str) -> String {
    let probe = format!(
        "[[probes]]\nname = \"speed\"\nbody = \"block\"\nfield = \"v\"\ncomponent = \"norm\"\nreduce = \"max\"\n\
         unit = \"m/s\"\n\n[[results]]\nprobe = \"speed\"\nat = \"end\"\n{result}"
    );
    common::block_case(model, top, "", &probe)
}

/// Runs the kicked block with the top-level keys `top` and checks that the kick, seen at the
/// first check after it (step 20), stops the run, naming a kicked particle. Returns stderr.
fn kicked_block_stopped(tag: &str, kick: &str, top: &str) -> String {
    let dir = fresh_dir(tag);
    let case = block_case(
        "kicked.sph",
        &format!("integrator = \"euler\"\nend_time = \"50 ms\"\n{top}"),
        "quantity = \"largest_speed\"",
    );
    let o = run(&dir, &[("kicked.sph", &kicked_model(kick)), ("case.toml", &case)], "cpu");
    let stderr = String::from_utf8_lossy(&o.stderr).to_string();
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("went unstable at step 20 "), "{stderr}");
    assert!(stderr.contains("(group metal) moves at `v` = "), "{stderr}");
    let particle: usize = stderr.split("particle ").nth(1).and_then(|s| s.split(' ').next()).unwrap().parse().unwrap();
    // Filled row by row from the corner: 6 × 6 at 10 mm, x = 5 … 55 mm.
    assert!(particle % 6 >= 3, "particle {particle} lies at x < 25 mm and was never kicked");
    assert_eq!(report(&dir)["results"].as_array().map(Vec::len), Some(0));
    let _ = std::fs::remove_dir_all(&dir);
    stderr
}

#[test]
fn a_particle_kicked_past_three_times_the_signal_speed_in_a_scene_nothing_drives_stops_the_run_naming_it() {
    // At rest, without gravity, loads or drivers, the scale is the signal speed
    // min h / Δt₀ = 1.2 · 10 mm / 1 ms = 12 m/s; the kick gives 100 m/s.
    let stderr = kicked_block_stopped("kicked-signal", "1e5 [m/s^2]", "");
    let expected = "faster than the watchdog's bound 3.600e1 m/s (3.000 × the case's speed scale, 1.200e1 m/s, \
                    from nothing drives the motion: the signal speed min h / Δt₀; where such a speed is real";
    assert!(stderr.contains(expected), "{stderr}");
}

#[test]
fn a_particle_kicked_below_the_signal_speed_in_a_falling_block_is_stopped_by_three_times_the_fall_speed() {
    // Under gravity the scale is the fall through the block's 50 mm, √(2 g · 50 mm) = 0.9905 m/s,
    // not the signal speed (12 m/s): the 10 m/s kick, under 3 × 12 m/s, stops the run.
    let stderr = kicked_block_stopped("kicked-falling", "1e4 [m/s^2]", "gravity = [0, \"-9.81 m/s^2\"]");
    let expected = "faster than the watchdog's bound 2.971e0 m/s (3.000 × the case's speed scale, 9.905e-1 m/s, \
                    from a fall through the scene; where such a speed is real";
    assert!(stderr.contains(expected), "{stderr}");
    assert!((number_after(&stderr, "moves at `v` = ") - 10.0).abs() < 0.1, "{stderr}");
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
