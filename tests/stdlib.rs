//! The stdlib is written in the language and must check clean, file by file, through the library
//! and through `pairsum check stdlib` (exit 0).

use pairsum::check::{check_paths, Stdlib};
use pairsum::diag::{render, Sources};
use std::path::Path;
use std::process::Command;

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
