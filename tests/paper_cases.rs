//! The paper cases at their CI resolution on the CPU (f64), end to end through `run_file`: every
//! result lies within its pinned band of what the case computed when it was pinned
//! (`tests/data/ci_values.toml`: a regression test), the results with a reference lie within the
//! tolerance their case file states (its measured gap to the paper, with why: wide where the gap
//! is wide, so it is the pin that catches a change), and the runs stay physical: no particle
//! faster than the impact allows, residual velocities below the impact speed. The figures at finer resolutions are in
//! docs/results/; the GPU runs of the same cases are compared with the CPU in tests/gpu.rs.

mod common;
use pairsum::runner::{run_file, BackendChoice, Precision, RunOptions, RunOutcome};
use std::path::{Path, PathBuf};

fn case(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("cases").join(format!("{name}.toml"))
}

/// Runs a case or study at CI resolution on the CPU and checks every result that has a reference
/// against the tolerance the case file gives it.
fn run_ci(name: &str) -> RunOutcome {
    run_ci_with(name, &[])
}

/// `run_ci` with case parameters set (`--set`), pinned under them.
fn run_ci_with(name: &str, set: &[(&str, &str)]) -> RunOutcome {
    let out = std::env::temp_dir().join(format!("pairsum-paper-{name}-{}-{}", set.len(), std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let mut opts = RunOptions {
        backend: BackendChoice::Cpu,
        precision: Precision::F64,
        out: out.clone(),
        vtk: false,
        ..RunOptions::default()
    };
    opts.scene.set = set.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
    let outcome = run_file(&case(name), &opts).unwrap_or_else(|e| panic!("{name}: {e}"));
    let _ = std::fs::remove_dir_all(&out);
    let results: Vec<(String, f64)> = outcome.report.results.iter().map(|r| (r.quantity.clone(), r.value)).collect();
    common::assert_pinned(name, set, false, &results);
    outcome
}

fn value(o: &RunOutcome, quantity: &str) -> f64 {
    let row = o.report.results.iter().find(|r| r.quantity == quantity);
    let v = row.unwrap_or_else(|| panic!("no result `{quantity}`")).value;
    assert!(v.is_finite(), "`{quantity}` = {v}");
    v
}

/// `quantity` within `tol` (relative) of its reference.
fn within(o: &RunOutcome, quantity: &str, tol: f64) {
    let row = o.report.results.iter().find(|r| r.quantity == quantity).unwrap_or_else(|| panic!("no `{quantity}`"));
    let err = row.rel_error.unwrap_or_else(|| panic!("`{quantity}` has no reference"));
    assert!(
        err.abs() <= tol,
        "{quantity} = {} vs {:?}: error {:+.1} % beyond ±{:.0} %",
        row.value,
        row.reference,
        100.0 * err,
        100.0 * tol
    );
}

#[test]
fn hypervelocity_impact_crater_and_debris_cloud() {
    let o = run_ci("hypervelocity_impact");
    // The tolerances of the case file (its gap to the experiment, with why).
    within(&o, "intact_crater_diameter", 0.15);
    within(&o, "crater_diameter", 0.30);
    within(&o, "debris_length_to_width", 0.05);
    // A crater at least the projectile's diameter; the intact plate's hole holds the failed rim
    // too, so it is at least as wide; and no particle faster than the impact by more than the
    // shock's particle velocity allows.
    assert!(value(&o, "crater_diameter") > 0.010);
    assert!(value(&o, "intact_crater_diameter") >= value(&o, "crater_diameter"));
    assert!(value(&o, "max_speed") <= 1.25 * 6180.0, "max speed {}", value(&o, "max_speed"));
}

/// The same crater with the damage driven by a plastic strain averaged over 2 mm of each body
/// (`damage_length`, damage/nonlocal_strain.sph): within the bounds of the local damage's, its
/// results held to their pins. Before stop 57 the Laplacian's weights took the sign of EK18's
/// quartic kernel's slope, which turns positive past 1.8 h; the average then amplified instead
/// of smoothing, and the damage swept the plate from 10 µs on (the intact crater 142 mm wide).
#[test]
fn hypervelocity_impact_with_damage_over_a_length_keeps_the_crater_within_the_local_damages_bounds() {
    let o = run_ci_with("hypervelocity_impact", &[("damage_length", "2")]);
    within(&o, "intact_crater_diameter", 0.15);
    within(&o, "crater_diameter", 0.30);
    within(&o, "debris_length_to_width", 0.05);
    assert!(value(&o, "intact_crater_diameter") >= value(&o, "crater_diameter"));
    assert!(value(&o, "max_speed") <= 1.25 * 6180.0, "max speed {}", value(&o, "max_speed"));
}

/// The hypervelocity impact about its axis (CI: 1 mm, 240 particles, its own model: that is,
/// models::ek18_solid_failure with the failed density floored, the damage over ℓ = 2 mm) against the 3D
/// quarter model at the same spacing and ℓ, an independent computation of the same crater: the
/// crater with the failed rim within 3 % of the 3D one's and the intact crater within 5 % (24.96
/// against 25.09 mm and 29.76 against 30.30 mm when pinned: at 1 mm the plate is four particles
/// thick, on rings about the axis in one and on a cubic lattice in the other). The debris cloud is
/// held to the experiment only: the 3D model does not floor the failed debris's density (1.332
/// against its 1.406). And the sphere's rings start with its kinetic energy ½ (4/3 π R³ ρ) v² (the
/// peak: it only falls) to rounding, their volumes scaled to the ball's.
#[test]
fn hypervelocity_impact_about_its_axis_makes_the_3d_models_craters_within_5_percent() {
    let axi = run_ci("hypervelocity_impact_axisymmetric");
    within(&axi, "intact_crater_diameter", 0.15);
    within(&axi, "crater_diameter", 0.30);
    within(&axi, "debris_length_to_width", 0.05);
    let quarter = run_ci_with("hypervelocity_impact", &[("damage_length", "2")]);
    for (quantity, tol) in [("crater_diameter", 0.03), ("intact_crater_diameter", 0.05)] {
        let (a, q) = (value(&axi, quantity), value(&quarter, quantity));
        assert!((a - q).abs() <= tol * q, "{quantity}: {a} about the axis, {q} in 3D");
    }
    let ke0 = 0.5 * 2710.0 * 4.0 / 3.0 * std::f64::consts::PI * 0.005f64.powi(3) * 6180.0f64.powi(2);
    let first = value(&axi, "peak_kinetic_energy");
    assert!((first / ke0 - 1.0).abs() <= 1e-9, "the rings' kinetic energy at impact {first} J, the sphere's {ke0} J");
    assert!(value(&axi, "max_speed") <= 1.25 * 6180.0, "max speed {}", value(&axi, "max_speed"));
}

/// A Børvik run at `v_i` (its results named `prefix` + quantity) perforated the plate: the
/// projectile left slower than it came, the plug slower than 1.5 times that, and the kinetic
/// energy never exceeded the projectile's at impact (197 g, a quarter model).
fn perforated_without_gaining_energy(o: &RunOutcome, prefix: &str, v_i: f64) {
    let proj = value(o, &format!("{prefix}projectile_residual_velocity"));
    assert!(proj > 0.0 && proj < v_i, "{v_i} m/s: projectile residual {proj}");
    let ke0 = 0.5 * 0.197 / 4.0 * v_i * v_i;
    let peak = value(o, &format!("{prefix}peak_kinetic_energy"));
    assert!(peak <= 1.02 * ke0, "{v_i} m/s: kinetic energy rose to {peak} J from {ke0} J");
    let plug = value(o, &format!("{prefix}plug_residual_velocity"));
    assert!((0.0..1.5 * v_i).contains(&plug), "{v_i} m/s: plug {plug}");
}

/// The Taylor bar about its axis (CI: 0.8 mm, 4 rings across the radius): its final length and
/// foot against the 3D finite elements (the 3D quarter model: +0.20 %, −10.4 % at 0.8 mm).
/// Measured with pair forces that conserve the rings' momentum (stop 118): −0.05 % and −7.87 %;
/// −0.32 % and +0.04 % at 0.2 mm (docs/results/taylor_bar_axisymmetric/); with the plane's pair
/// forces the foot was −14.67 % here.
#[test]
fn taylor_bar_about_its_axis_keeps_its_length_within_1_percent_and_its_foot_within_9() {
    let o = run_ci("taylor_bar_axisymmetric");
    within(&o, "final_length", 0.01);
    within(&o, "foot_diameter", 0.09);
}

/// The 12 mm Børvik plate about its axis at 399.6 m/s (CI: 1 mm near the axis, 150 µs): the
/// projectile leaves slower than it came, and the kinetic energy, summed over the rings, starts at
/// the 3D projectile's ½ m v² (m = ρ π R² L = 0.1973 kg) and never rises above it. The energy the
/// two energy equations count, Σ m (e + ½ |v|²), falls by about 4.6 % (727 J at CI); with the work
/// of the hourglass pull and of the contact booked (probes with `integrate = true`) it is the
/// impact's within 1 % at every sample (at most 0.38 % at CI), and the pull's work is negative:
/// a damper.
#[test]
fn borvik_plate_about_its_axis_is_perforated_and_balances_its_energy_within_1_percent_with_the_pull_and_contact_booked()
{
    let o = run_ci("borvik_axisymmetric");
    let v_i = 399.6;
    let proj = value(&o, "projectile_residual_velocity");
    assert!(proj > 0.0 && proj < v_i, "projectile residual {proj}");
    let ke0 = 0.5 * 7850.0 * std::f64::consts::PI * 0.01f64.powi(2) * 0.08 * v_i * v_i;
    let peak = value(&o, "peak_kinetic_energy");
    assert!(
        (peak - ke0).abs() <= 0.01 * ke0,
        "the rings' kinetic energy peaks at {peak} J, the projectile's is {ke0} J"
    );
    let history = |name: &str| common::history(&o.histories, name);
    let (total, pull, contact) = (history("total_energy"), history("hourglass_work"), history("contact_work"));
    let at = |h: &[(f64, f64)], t: f64| h.iter().find(|p| p.0 == t).map(|p| p.1);
    let mut sampled = 0;
    for &(t, energy) in total {
        let (Some(w_pull), Some(w_contact)) = (at(pull, t), at(contact, t)) else { continue };
        sampled += 1;
        let off = energy - w_pull - w_contact - ke0;
        assert!(off.abs() <= 0.01 * ke0, "at {t} s the energy {energy} J less the pull's {w_pull} J and the contact's {w_contact} J is {off} J off the impact's {ke0} J");
    }
    assert!(sampled > 50, "the balance was checked at {sampled} times");
    let pull_end = pull.last().expect("the pull's work").1;
    assert!(pull_end < -0.01 * ke0, "the hourglass pull's work at the end is {pull_end} J");
}

#[test]
fn borvik_8mm_plate_is_perforated_without_gaining_energy() {
    let o = run_ci("borvik_8mm");
    // The CI runs: 298, 250.8, 190.7 m/s, all above the ballistic limit (152.5 m/s).
    for v in ["298", "250.8", "190.7"] {
        let v_i: f64 = v.parse().unwrap();
        perforated_without_gaining_energy(&o, &format!("{v}: "), v_i);
        // No particle is thrown off at more than 2.5 times the impact speed. (It was 1.14 times
        // before failed particles were floored at ρ0: the floor re-pressurises a failed particle
        // at once when it is compressed again, and throws single debris particles at up to 2.02
        // times here, 2.5 times in the fine 12 mm study: a known artefact, docs/results/.)
        let fastest = value(&o, &format!("{v}: max_speed"));
        assert!(fastest < 2.5 * v_i, "{v} m/s: a particle thrown at {fastest} m/s");
    }
    // The ballistic limit from Recht and Ipson's plugging curve (p = 2, a = m_p / (m_p + m_plug)
    // = 0.909) through these three runs, on a plate of 40 mm radius with four particles through
    // the thickness: +2.4 %; +3.7 / +2.4 / −0.4 % at 2.667 / 2 / 1.6 mm, no order
    // (docs/results/borvik_8mm_convergence/, pair forces that conserve momentum; FTLR19's
    // one-sided form gave −3.7 % here). The free fit (a and p fitted too) has three
    // unknowns for three runs and swings (−46 % here); the full plate's runs are the figures to
    // quote (docs/results/README.md, Børvik).
    within(&o, "ballistic_limit_plugging", 0.15);
    // The fit's rms, recomputed from the runs and the fitted limit on the plugging curve.
    let v_bl = value(&o, "ballistic_limit_plugging");
    let misses: Vec<f64> = ["298", "250.8", "190.7"]
        .iter()
        .map(|v| {
            let v_i: f64 = v.parse().unwrap();
            value(&o, &format!("{v}: projectile_residual_velocity")) - 0.909 * (v_i * v_i - v_bl * v_bl).sqrt()
        })
        .collect();
    let rms = (misses.iter().map(|m| m * m).sum::<f64>() / 3.0).sqrt();
    let reported = value(&o, "ballistic_limit_plugging, fit rms");
    assert!((reported - rms).abs() <= 1e-9 * rms.max(1.0), "fit rms {reported}, recomputed {rms}");
}

/// The 8 mm plate at 298 m/s (CI: 2 mm, a 40 mm plate, 100 µs) with its damage driven by the
/// nonlocal plastic strain over 2 mm (`damage_length`, damage/johnson_cook.sph): perforated, the
/// projectile slower than it came, no energy gained, and its residuals held to their pins.
#[test]
fn borvik_8mm_plate_with_nonlocal_damage_is_perforated_without_gaining_energy() {
    let o = run_ci_with("borvik_perforation", &[("damage_length", "2")]);
    perforated_without_gaining_energy(&o, "", 298.0);
}

// The bar does not neck where the FEM's does at CI: its peak plastic strain lies at 30.7 mm, past
// the neck's end (25 mm is its middle); at 0.5 mm at 34.3 mm (README.md, docs/results/). So the
// test holds the position to its pin and claims no neck.
#[test]
fn tensile_test_reaches_the_grips_elongation_and_clumps_without_artificial_stress() {
    let o = run_ci("tensile_artificial_stress");
    for run in ["artificial_stress", "no_artificial_stress"] {
        // The grip's prescribed motion reaches the bar's end: 7.5 mm of elongation.
        within(&o, &format!("{run}: elongation"), 0.02);
    }
    // With artificial stress: -32 % of the FEM's 0.281 at CI (four particles across the neck's
    // radius; the paper's geometry is not available).
    within(&o, "artificial_stress: max_effective_plastic_strain", 0.40);
    // Without it the tensile instability pulls particles into clumps (F-ANS §3): the least
    // distance between two particles falls well below the one with artificial stress.
    let with = value(&o, "artificial_stress: min_pair_distance_over_dx");
    let without = value(&o, "no_artificial_stress: min_pair_distance_over_dx");
    assert!(without < 0.85 * with, "least pair distance: {without} Δx without, {with} Δx with artificial stress");
    let eps = value(&o, "no_artificial_stress: max_effective_plastic_strain");
    assert!(eps > 0.05 && eps < 1.0, "without artificial stress: max plastic strain {eps}");
}

// EK18 Fig 2 is not reproduced (README.md): here the plain cubes keep the wider gap. Both keep
// more than a tenth of a spacing between them; the plain ones let no particle within half a
// spacing of the other body, the CSPM ones two.
#[test]
fn cube_on_cube_keeps_a_tenth_of_a_spacing_between_the_bodies_and_at_most_two_particles_interpenetrate() {
    let o = run_ci("cube_on_cube_cspm");
    for (run, most_interpenetrated) in [("plain", 0.0), ("cspm", 2.0)] {
        let d = value(&o, &format!("{run}: least interbody distance / Δx"));
        assert!(d > 0.1, "{run}: least distance between the cubes {d} Δx");
        let n = value(&o, &format!("{run}: most interpenetrated particles"));
        assert!(n <= most_interpenetrated, "{run}: {n} particles within Δx/2 of the other cube");
        assert!(value(&o, &format!("{run}: max_speed")) < 1.5 * 500.0);
    }
}

#[test]
fn graded_plate_keeps_the_sphere_and_the_flow_stress_of_the_uniform_one() {
    let o = run_ci("sphere_plate_graded_study");
    // EK18 Table 4: "almost identical". With the plate at its mesh nodes, as EK18's (three layers
    // through the 10 mm at 5 mm, two where graded to 10 mm), the graded plate deflects as the
    // uniform one (+1.7 % at CI), slows the sphere a little less (+8.2 %) and flows alike (−0.6 %).
    let dv = value(&o, "sphere residual velocity, graded vs uniform");
    let dd = value(&o, "plate deflection, graded vs uniform");
    let ds = value(&o, "peak flow stress, graded vs uniform");
    assert!(dv.abs() < 0.15, "sphere residual velocity differs by {:+.1} %", 100.0 * dv);
    assert!(dd.abs() < 0.10, "plate deflection differs by {:+.1} %", 100.0 * dd);
    assert!(ds.abs() < 0.05, "peak flow stress differs by {:+.1} %", 100.0 * ds);
    // At the cell centres the graded plate is one layer where coarse and deflects a third less
    // (−32 % at CI): the node-centred fill is what makes the two plates alike.
    let cells = value(&o, "cells: plate deflection, graded vs uniform");
    assert!(dd.abs() < cells.abs() / 3.0, "deflection: {dd:+.3} at the nodes, {cells:+.3} at the cell centres");
    let cells_ds = value(&o, "cells: peak flow stress, graded vs uniform");
    assert!(cells_ds.abs() < 0.05, "cells: peak flow stress differs by {:+.1} %", 100.0 * cells_ds);
    for run in ["uniform", "cells_uniform"] {
        let v = value(&o, &format!("{run}: sphere_residual_velocity"));
        assert!(v > 0.0 && v < 1000.0, "{run}: the sphere perforates and slows: {v}");
    }
}

#[test]
fn bullet_study_perforates_with_every_search_and_verlet_lists_and_thresholds_give_the_full_searchs_velocity() {
    // F-ANS Table 1's study at CI resolution (7.5 mm, a 120 mm plate): the bullet goes through
    // with every search, the Verlet lists (no pair missed) give the cell search's residual
    // velocity to rounding, and F-ANS's thresholds stay within a few per cent of it, as in the
    // paper for 1e-5 and 1e-6. A search at step 0 only is not alike (+302 % at 5 mm, README.md):
    // it is held only to perforate. Speed-ups are timings: in the study's report, not here.
    let o = run_ci("fans_bullet_study");
    let every = value(&o, "every step: residual velocity");
    assert!(every > 0.0 && every < 400.0, "residual velocity {every}: the bullet must perforate and slow down");
    let verlet = value(&o, "verlet: residual velocity, against every step");
    assert!(verlet.abs() < 1e-3, "Verlet lists change the residual velocity by {:+.3} %", 100.0 * verlet);
    for t in ["1e-4", "1e-5", "1e-6"] {
        let v = value(&o, &format!("{t}: residual velocity"));
        assert!((v - every).abs() <= 0.03 * every, "threshold {t}: {v} m/s against {every} m/s with a full search");
    }
    let once = value(&o, "step 0 only: residual velocity");
    assert!(once > 0.0 && once < 400.0, "search at step 0 only: {once}");
}
