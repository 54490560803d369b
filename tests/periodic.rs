//! Periodic boundaries (issue 40): a lattice under pressure stays at rest where an open one moves;
//! a lattice that crosses the periodic sides keeps its speed and momentum, with the cell list and
//! with kept (Verlet and adaptive) lists alike; a case's periodic mistakes are errors with a place.
//! The GPU runs of the same are compared with the CPU in tests/gpu.rs, the Poiseuille channel in
//! tests/cases.rs.

mod common;
use common::{lattice_case, BOTH_AXES};
use pairsum::runner::{prepare, run_case, BackendChoice, RunOptions};
use std::path::{Path, PathBuf};

fn fresh_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pairsum-periodic-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

/// Each probe's name and its (t, value) points.
type Histories = Vec<(String, Vec<(f64, f64)>)>;

/// Runs `case` on the CPU; each probe's history.
fn run(dir: &Path, case: &str) -> Result<Histories, String> {
    std::fs::write(dir.join("case.toml"), case).unwrap();
    let opts = RunOptions { backend: BackendChoice::Cpu, out: dir.join("out"), vtk: false, ..Default::default() };
    run_case(&dir.join("case.toml"), &opts).map(|o| o.histories).map_err(|e| e.to_string())
}

fn last(histories: &[(String, Vec<(f64, f64)>)], probe: &str) -> f64 {
    let points = &histories.iter().find(|(n, _)| n == probe).expect("probe").1;
    points.iter().for_each(|(t, v)| assert!(v.is_finite(), "{probe} = {v} at t = {t}"));
    points.last().expect("a point").1
}

#[test]
fn a_periodic_lattice_under_pressure_stays_at_rest_where_an_open_one_moves() {
    let dir = fresh_dir("rest");
    let periodic = run(&dir, &lattice_case("0 m/s", "0.02 s", BOTH_AXES, "")).expect("the periodic lattice runs");
    let speed = last(&periodic, "max_speed");
    assert!(speed < 1e-12, "the periodic lattice moves at {speed} m/s");
    // Open, the same water spreads from its free surface (the watchdog stops it as it speeds up).
    let open = run(&dir, &lattice_case("0 m/s", "0.002 s", "", "[watchdog]\nspeed_factor = inf\nenergy_factor = inf"))
        .expect("the open lattice runs");
    let speed = last(&open, "max_speed");
    assert!(speed > 0.01, "the open lattice moves at only {speed} m/s");
    let _ = std::fs::remove_dir_all(&dir);
}

/// 1 m/s for 0.25 s: every particle crosses the side at x = 0.2 m once or twice.
#[test]
fn a_lattice_crossing_the_periodic_sides_keeps_its_speed_and_momentum_with_cells_and_kept_lists() {
    let dir = fresh_dir("crossing");
    let searches = [
        ("cells", String::new()),
        ("verlet", "[neighbours]\nsearch = \"verlet\"\nskin = 0.3".to_string()),
        ("adaptive", "[neighbours]\nsearch = \"adaptive\"\nfield = \"rho\"\nthreshold = inf\nskin = 0.3".to_string()),
    ];
    for (search, table) in searches {
        let h =
            run(&dir, &lattice_case("1 m/s", "0.25 s", BOTH_AXES, &table)).unwrap_or_else(|e| panic!("{search}: {e}"));
        let (speed, momentum) = (last(&h, "max_speed"), last(&h, "momentum"));
        // 400 particles of ρ0 Δx² = 0.1 kg at 1 m/s.
        assert!((speed - 1.0).abs() < 1e-9, "{search}: the fastest particle at {speed} m/s");
        assert!((momentum - 40.0).abs() < 1e-9, "{search}: momentum {momentum} kg m/s");
        let (lo, hi) = (last(&h, "x_min"), last(&h, "x_max"));
        assert!(lo >= 0.0 && hi < 0.2, "{search}: particles at x in [{lo}, {hi}], outside [0, 0.2)");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A case's periodic mistakes: a body outside the domain, an axis with a symmetry plane too, an
/// axis the case does not have. Each is C0047 at its place in the case file.
#[test]
fn periodic_mistakes_are_errors_at_their_place() {
    let dir = fresh_dir("mistakes");
    for (periodic, says) in [
        ("[periodic]\nx = [0, \"0.1 m\"]", "body `water` has a particle at"),
        ("[periodic]\nx = [0, \"0.2 m\"]\n\n[[symmetry]]\naxis = \"x\"", "an axis is periodic or has one, not both"),
        ("[periodic]\nz = [0, \"0.2 m\"]", "a 2D case has no axis z"),
        ("[periodic]\nx = [\"0.2 m\", 0]", "two lengths with min < max"),
    ] {
        std::fs::write(dir.join("case.toml"), lattice_case("0 m/s", "0.01 s", periodic, "")).unwrap();
        let err = match prepare(&dir.join("case.toml"), &Default::default()) {
            Ok(_) => panic!("{periodic}: loaded"),
            Err(e) => e.to_string(),
        };
        assert!(err.contains("error[C0047]") && err.contains(says) && err.contains("case.toml:"), "{periodic}: {err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A periodic axis beside a symmetry plane on another: the lattice, periodic along x and held by a
/// symmetry plane at y = 0, spreads upward from its free top, and every row moves as one (the flow
/// is the same at every x): no velocity along x anywhere, while the top rises.
#[test]
fn a_periodic_axis_beside_a_symmetry_plane_keeps_the_flow_uniform_along_it() {
    let dir = fresh_dir("beside");
    let planes = "[periodic]\nx = [0, \"0.2 m\"]\n\n[[symmetry]]\naxis = \"y\"";
    let probes = "[[probes]]\nname = \"vx_abs_max\"\nfield = \"v\"\ncomponent = \"x\"\nreduce = \"abs_max\"\n\n\
                  [[probes]]\nname = \"vy_max\"\nfield = \"v\"\ncomponent = \"y\"\nreduce = \"max\"\n\n\
                  [watchdog]\nspeed_factor = inf\nenergy_factor = inf";
    let h = run(&dir, &lattice_case("0 m/s", "0.005 s", planes, probes)).expect("runs");
    let (vx, vy) = (last(&h, "vx_abs_max"), last(&h, "vy_max"));
    assert!(vy > 0.01, "the free top rises at only {vy} m/s");
    assert!(vx < 1e-12 * vy.max(1.0), "a velocity of {vx} m/s along the periodic axis");
    let _ = std::fs::remove_dir_all(&dir);
}
