//! The stdlib is written in the language and must check clean, file by file, through the library
//! and through `pairsum check stdlib` (exit 0).

use pairsum::check::{check_paths, Stdlib};
use pairsum::diag::{render, Sources};
use std::path::Path;
use std::process::Command;

mod common;
use common::field_by_id;

fn stdlib_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("stdlib")
}

#[test]
fn every_stdlib_file_checks_without_errors() {
    let files = pairsum::cli::sph_files(&[stdlib_dir()]);
    assert!(files.len() >= 30, "only {} stdlib files", files.len());
    for f in &files {
        let mut sources = Sources::new();
        let checked = check_paths(&mut sources, &[f.as_path()], Stdlib::Dir(stdlib_dir()));
        assert!(!checked.has_errors(), "{}:\n{}", f.display(), render(&sources, &checked.diags));
    }
}

#[test]
fn stdlib_models_check_without_warnings() {
    for f in pairsum::cli::sph_files(&[stdlib_dir().join("models")]) {
        let mut sources = Sources::new();
        let checked = check_paths(&mut sources, &[f.as_path()], Stdlib::Dir(stdlib_dir()));
        assert!(checked.is_model, "{} should be a complete model", f.display());
        assert!(checked.diags.is_empty(), "{}:\n{}", f.display(), render(&sources, &checked.diags));
    }
}

#[test]
fn pairsum_check_accepts_the_whole_stdlib() {
    let out = Command::new(env!("CARGO_BIN_EXE_pairsum")).arg("check").arg(stdlib_dir()).output().expect("runs");
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn pairsum_check_exits_1_on_errors_and_never_panics() {
    let dir = std::env::temp_dir().join(format!("pairsum-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let bad = dir.join("bad.sph");
    std::fs::write(&bad, "pairsum p -> a: scalar [m] { a += rho[j] }\n").expect("write");
    let out = Command::new(env!("CARGO_BIN_EXE_pairsum")).arg("check").arg(&bad).output().expect("runs");
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("bad.sph:1:"), "{stderr}");
    assert!(stderr.contains("unit mismatch"), "{stderr}");
    let missing =
        Command::new(env!("CARGO_BIN_EXE_pairsum")).arg("check").arg(dir.join("nope.sph")).output().expect("runs");
    assert_eq!(missing.status.code(), Some(1));
    let _ = std::fs::remove_dir_all(&dir);
}

/// `use m on G from S` restricts m's equations, and the modules m uses unless another path reaches
/// them unrestricted: the damage model on `target` pulls the radial return onto `target` only, while
/// the Jaumann rate it also uses stays on every group because the model uses it directly.
#[test]
fn use_on_restricts_a_module_and_what_it_pulls_in() {
    let text = "use kernels\ngroup projectile, target\nkernel = wendland_c2\n\
                use solid::strain_rate\nuse solid::jaumann\nuse eos::linear\n\
                use momentum::total_stress on target from target\n\
                use damage::simplified on target\n\
                param E: scalar [Pa]\nparam nu: scalar [-]\nparam bulk: scalar [Pa] = E / (3 * (1 - 2 * nu))\n\
                integrate { x' = v  s' = ds  rho' = 0 [kg/m^3/s] }\nintegrate on target { v' = dv }\n";
    let mut sources = Sources::new();
    let checked = pairsum::check::check_text(&mut sources, "m.sph", text, Stdlib::Dir(stdlib_dir()));
    assert!(!checked.has_errors(), "{}", render(&sources, &checked.diags));
    let m = &checked.model;
    let eq = |name: &str| m.equations.iter().find(|e| e.name == name).unwrap_or_else(|| panic!("no `{name}`"));
    let groups = |set| m.group_names(set);
    assert_eq!(groups(eq("radial_return").dest), "target");
    assert_eq!(groups(eq("damage").dest), "target");
    assert_eq!(groups(eq("jaumann").dest), "projectile|target");
    assert_eq!(groups(eq("momentum").dest), "target");
    let pairsum::ir::EquationKind::PairSum { sources: from, .. } = &eq("momentum").kind else { panic!("a pair sum") };
    assert_eq!(groups(*from), "target");
}

/// `from own body` holds for a module only when every `use` that reaches it says so: a model that
/// asks for the corrected gradient's sums `from own body` while a module it uses (the corrected
/// velocity gradient) uses the same module without gets warning W0503 at both `use` lines (before
/// stop 120 `models::elastic_solid_corrected` was in that state, its correction summed over the
/// other bar of `colliding_bars_1d`); with both uses restricted, none.
#[test]
fn a_from_own_body_that_another_plain_use_undoes_is_warning_w0503_at_both_uses() {
    let check = |strain_rate_use: &str| {
        let text = format!("use correction::kernel_gradient from own body\n{strain_rate_use}\n");
        let mut sources = Sources::new();
        let checked = pairsum::check::check_text(&mut sources, "m.sph", &text, Stdlib::Dir(stdlib_dir()));
        let undone: Vec<_> = checked.diags.iter().filter(|d| d.code == "W0503").collect();
        (undone.len(), render(&sources, &checked.diags))
    };
    let (count, text) = check("use solid::strain_rate_corrected");
    assert_eq!(count, 1, "{text}");
    for part in ["this `from own body` does not hold", "m.sph:1:1", "strain_rate_corrected.sph", "used here without it"]
    {
        assert!(text.contains(part), "{part} not in:\n{text}");
    }
    let (count, text) = check("use solid::strain_rate_corrected from own body");
    assert_eq!(count, 0, "{text}");
}

/// Two modules may give one parameter a default when it is the same constant (the corrected
/// gradient's and the shaped kernel's `det_min = 0.1`): the model keeps it. Different defaults
/// stay error E0107 (tests/ui/parameter_with_two_defaults.sph).
#[test]
fn two_modules_that_default_a_parameter_to_the_same_constant_compose() {
    let text = "use kernels\ngroup round, shaped\nkernel = wendland_c2\n\
                use correction::kernel_gradient on round\nuse solid::shaped_kernel on shaped\n";
    let mut sources = Sources::new();
    let checked = pairsum::check::check_text(&mut sources, "m.sph", text, Stdlib::Dir(stdlib_dir()));
    assert!(!checked.has_errors(), "{}", render(&sources, &checked.diags));
    let m = &checked.model;
    let det_min = m.param_id("det_min").expect("det_min");
    let default = m.params[det_min.index()].default.as_ref().expect("a default");
    assert_eq!(pairsum::host_eval::constant(default), Some(0.1));
}

/// Every plasticity module with every thermal module (and none) and every equation of state, in a
/// solid model with the energy equation: each combination whose physics makes sense checks clean
/// and schedules, with the radial return before the heating it causes.
#[test]
fn every_plasticity_thermal_and_eos_module_compose() {
    // thermal::plastic_work heats by σ_y Δε_p of the Johnson–Cook return (FTLR19 Eq 3.14): it is
    // written for that return and uses it itself.
    let pairs = [
        ("radial_return_jc", ""),
        ("radial_return_jc", "thermal::from_energy"),
        ("radial_return_jc", "thermal::plastic_work"),
        ("radial_return_linear", ""),
        ("radial_return_linear", "thermal::from_energy"),
    ];
    let mut checked_models = 0;
    for (plasticity, thermal) in pairs {
        for eos in ["linear", "linear_free_surface", "mie_gruneisen", "tait"] {
            let thermal_use = if thermal.is_empty() { String::new() } else { format!("use {thermal}\n") };
            let text = format!(
                "use kernels\nuse continuity::plain\nuse solid::strain_rate\nuse solid::jaumann\nuse eos::{eos}\n\
                 use energy::solid\nuse momentum::total_stress\nuse plasticity::{plasticity}\n{thermal_use}\
                 use timestep::acoustic\ngroup solid\nkernel = wendland_c2\n\
                 integrate {{ x' = v  v' = dv  rho' = drho  s' = ds  e' = de }}\n"
            );
            let what = format!(
                "plasticity::{plasticity} + {} + eos::{eos}",
                if thermal.is_empty() { "no thermal" } else { thermal }
            );
            let mut sources = Sources::new();
            let checked = pairsum::check::check_text(&mut sources, "pairing.sph", &text, Stdlib::Dir(stdlib_dir()));
            let errors: Vec<_> = checked.diags.iter().filter(|d| d.is_error()).cloned().collect();
            assert!(errors.is_empty(), "{what}:\n{}", render(&sources, &errors));
            let m = checked.model;
            let scene = pairsum::schedule::SceneSpec {
                dim: 3,
                groups: m.all_groups(),
                outputs: vec![],
                integrator: pairsum::schedule::IntegratorKind::PredictorCorrector,
                gravity: None,
                loads: vec![],
                constraints: vec![],
                planes: vec![],
                search: Default::default(),
                damping: None,
                settled: vec![],
                initialised: vec![],
                axisymmetric: false,
            };
            let plan = pairsum::schedule::Plan::build(&m, &scene, None).unwrap_or_else(|e| panic!("{what}: {e}"));
            let order: Vec<&str> =
                plan.stages[0].corrections.iter().map(|e| m.equations[e.index()].name.as_str()).collect();
            if thermal == "thermal::plastic_work" {
                assert_eq!(order, ["radial_return", "plastic_heating"], "{what}");
            }
            checked_models += 1;
        }
    }
    assert_eq!(checked_models, 20);
}

/// Modules whose equations share a name combine across groups (issue 41): a fluid's
/// `continuity::fourtakas`, `eos::tait` and `momentum::fluid` beside a solid's `continuity::plain`,
/// `eos::linear` and `momentum::inviscid_stress` give one `continuity`, `eos` and `momentum` on
/// each group, from its own module.
#[test]
fn modules_whose_equations_share_names_combine_across_groups() {
    let text = "use kernels\n\
        use continuity::fourtakas on fluid from fluid\nuse continuity::plain on solid from solid\n\
        use eos::tait on fluid\nuse eos::linear on solid\n\
        use momentum::pressure_term on fluid\nuse momentum::fluid on fluid from fluid\n\
        use momentum::inviscid_stress on solid from solid\nuse timestep::acoustic\n\
        group fluid, solid\nkernel = wendland_c2\nintegrate { x' = v  v' = dv  rho' = drho }\n";
    let mut sources = Sources::new();
    let checked = pairsum::check::check_text(&mut sources, "mixed.sph", text, Stdlib::Dir(stdlib_dir()));
    assert!(!checked.has_errors(), "{}", render(&sources, &checked.diags));
    let model = &checked.model;
    let (fluid, solid) = (model.group_id("fluid").unwrap(), model.group_id("solid").unwrap());
    for name in ["continuity", "eos", "momentum"] {
        let eqs: Vec<_> = model.equations.iter().filter(|e| e.name == name).collect();
        assert_eq!(eqs.len(), 2, "`{name}`: {} equations", eqs.len());
        assert!(eqs[0].span.file != eqs[1].span.file, "`{name}` twice from one file");
        let on: Vec<(bool, bool)> = eqs.iter().map(|e| (e.dest.contains(fluid), e.dest.contains(solid))).collect();
        assert!(on.contains(&(true, false)) && on.contains(&(false, true)), "`{name}` runs on {on:?}");
    }
}

/// Mie–Grüneisen (eos/mie_gruneisen.sph) on the CPU backend over a block whose density rises
/// from ρ0 to 4 ρ0 across it (e = 0), steel's constants (S = 1.5, Γ = 2): up to the papers' peak
/// η* the pressure is the papers' (1 − ½ Γ η) P_H to 1e-12, computed here in Rust; `eos_eta_peak`
/// is that peak, found by the test on a grid of 1e-6 in η; and the pressure rises with the
/// density at every particle, where the papers' form falls past η* and is tension past η = 1.
#[test]
fn mie_gruneisen_is_the_papers_up_to_its_peak_and_rises_with_the_density_beyond() {
    use pairsum::backend::cpu::CpuBackend;
    use pairsum::engine::setup::build_store;
    let dir = std::env::temp_dir().join(format!("pairsum-mie-gruneisen-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let model = "use kernels\nuse eos::mie_gruneisen\ngroup metal\nkernel = wendland_c2\n\
                 integrate { x' = v  v' = 0 }\n";
    let case = r#"name = "eos"
model = "model.sph"
dim = 2
end_time = "1 us"

[materials.metal]
rho0 = "7850 kg/m^3"
c0 = "5110.25 m/s"
S_s = 1.5
gamma0 = 2.0

[[bodies]]
name = "block"
group = "metal"
material = "metal"
shape = { box = { min = [0, 0], max = ["300 mm", "10 mm"] } }
initial = { rho = "7850 [kg/m^3] * (1 + x.x / 0.1 [m])" }

[resolutions]
ci = "1 mm"

[output]
interval = "1 us"
fields = ["p"]
"#;
    std::fs::write(dir.join("model.sph"), model).unwrap();
    std::fs::write(dir.join("case.toml"), case).unwrap();
    let (scene, plan) =
        pairsum::runner::prepare(&dir.join("case.toml"), &Default::default()).unwrap_or_else(|e| panic!("{e}"));
    let values = pairsum::runner::material_values(&scene, &plan);
    let store = build_store::<f64>(&plan, &scene.particles, &scene.materials).unwrap_or_else(|e| panic!("{e}"));
    let mut b = CpuBackend::new(plan, store, vec![]).expect("backend");
    pairsum::backend::Backend::initialise(&mut b).expect("initialise");
    let (_, x) = field_by_id(&b, "x");
    let (_, p) = field_by_id(&b, "p");
    let (a0, s, gamma) = (7850.0 * 5110.25f64.powi(2), 1.5, 2.0);
    let papers = |eta: f64| {
        let (b0, c0) = (a0 * (1.0 + 2.0 * (s - 1.0)), a0 * (2.0 * (s - 1.0) + 3.0 * (s - 1.0f64).powi(2)));
        let p_h = if eta > 0.0 { a0 * eta + b0 * eta * eta + c0 * eta.powi(3) } else { a0 * eta };
        (1.0 - 0.5 * gamma * eta) * p_h
    };
    let peak = (0..1_000_000).map(|k| k as f64 * 1e-6).fold((0.0, f64::NEG_INFINITY), |best, eta| {
        let v = papers(eta);
        assert!(v.is_finite(), "the papers' pressure at η = {eta} is {v}");
        if v > best.1 {
            (eta, v)
        } else {
            best
        }
    });
    let held: f64 = values
        .lines()
        .find_map(|l| l.trim().strip_prefix("eos_eta_peak = "))
        .and_then(|v| v.split_whitespace().next()?.parse().ok())
        .unwrap_or_else(|| panic!("no eos_eta_peak among the material's values:\n{values}"));
    assert!((held - peak.0).abs() < 2e-6, "eos_eta_peak {held}, the papers' peak at η = {}", peak.0);
    // One row of particles, one density each.
    let mut by_density: Vec<(f64, f64)> =
        (0..p.len()).filter(|&k| x[2 * k + 1] < 1e-3).map(|k| (x[2 * k] / 0.1, p[k])).collect();
    by_density.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (mut same, mut beyond) = (0, 0);
    for (eta, p) in &by_density {
        if *eta <= peak.0 - 1e-5 {
            let expected = papers(*eta);
            assert!((p - expected).abs() <= 1e-12 * expected.abs(), "η = {eta}: p = {p} Pa, the papers' {expected} Pa");
            same += 1;
        } else {
            beyond += 1;
        }
    }
    for w in by_density.windows(2) {
        assert!(
            w[1].1 > w[0].1,
            "the pressure falls from {} Pa at η = {} to {} Pa at η = {}",
            w[0].1,
            w[0].0,
            w[1].1,
            w[1].0
        );
    }
    assert!(papers(2.5) < 0.0, "the papers' form is tension at η = 2.5: {}", papers(2.5));
    assert!(same >= 60 && beyond >= 200 && same + beyond == 300, "{same} particles below the peak, {beyond} beyond");
    let _ = std::fs::remove_dir_all(&dir);
}
