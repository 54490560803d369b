//! The CPU backend's native pair programs against its closures, from both generators: C over
//! 256-bit vectors (`backend/cpu/ccode.rs`, where a C compiler answers) and Cranelift over
//! 128-bit ones (`backend/cpu/jit.rs`). The same operations in the same order and the same fold
//! of the sums, so every stored field must agree bit for bit after several steps of every bundled
//! case, in f64 and in f32. Also checks that the native code is actually used (a program that
//! fell back to closures would make the comparison empty), and what a run without a C compiler
//! does.

mod common;
use common::*;
use pairsum::backend::cpu::ccode;
use pairsum::backend::cpu::jit::NativeKind;
use pairsum::backend::cpu::CpuBackend;
use pairsum::backend::Backend;
use pairsum::engine::setup::build_store;
use pairsum::engine::Engine;
use pairsum::particles::Real;
use pairsum::runner::prepare;
use std::path::Path;

fn case(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("cases").join(format!("{name}.toml"))
}

/// The backend with native pair programs from each generator: the machine's C compiler (256-bit
/// vectors, `backend/cpu/ccode.rs`) where it answers, and Cranelift (128-bit, `jit.rs`).
fn natives<T: Real>(
    plan: &pairsum::schedule::Plan,
    store: &pairsum::particles::Store<T>,
    mirrors: &[pairsum::backend::Mirror],
) -> Vec<(&'static str, CpuBackend<T>)> {
    let build = || CpuBackend::new(plan.clone(), store.clone(), mirrors.to_vec()).expect("cpu");
    let cranelift = ccode::without_c(build);
    assert_eq!(cranelift.passes_made_by(NativeKind::C), 0, "a C program with the C path off");
    let mut out = vec![];
    if ccode::enabled() {
        let c = build();
        // Every program Cranelift runs, C runs (they share the graph and the unsupported list; C
        // also runs the elementary functions, which no bundled pair sum calls).
        assert_eq!(c.passes_made_by(NativeKind::C), cranelift.native_passes().0, "C compiles what Cranelift does");
        out.push(("C", c));
    }
    out.push(("Cranelift", cranelift));
    out
}

/// `steps` steps of the case at its CI resolution with native pair programs from each generator
/// and with closures; returns how many pass variants ran natively, of how many.
fn native_equals_closures<T: Real>(name: &str, steps: usize) -> (usize, usize) {
    let opts = pairsum::scene::Options { resolution: Some("ci".into()), ..Default::default() };
    let (scene, plan) = prepare(&case(name), &opts).unwrap_or_else(|e| panic!("{name}: {e}"));
    let store = build_store::<T>(&plan, &scene.particles, &scene.materials).expect("store");
    let natives = natives(&plan, &store, &scene.mirrors);
    let counts = natives[0].1.native_passes();
    let closures = CpuBackend::new(plan.clone(), store, scene.mirrors.clone()).expect("cpu").without_jit();
    assert_eq!(closures.native_passes().0, 0);
    let mut b = Engine::new(closures, scene.config.clone());
    b.initialise().expect("init");
    for k in 0..steps {
        b.step().unwrap_or_else(|e| panic!("{name}: closure step {k}: {e}"));
    }
    for (label, native) in natives {
        let mut a = Engine::new(native, scene.config.clone());
        a.initialise().expect("init");
        for k in 0..steps {
            a.step().unwrap_or_else(|e| panic!("{name}: {label} step {k}: {e}"));
        }
        assert_eq!(a.time.to_bits(), b.time.to_bits(), "{name}: the clocks differ ({label})");
        assert_same_bits(&a.backend, &b.backend, &format!("{name} ({}, {label})", T::NAME));
    }
    counts
}

/// Every watched field of `a` equals `b`'s bit for bit, over the particles that store it, and is
/// finite there (a run that blew up alike on both sides proves nothing).
fn assert_same_bits<B: Backend>(a: &B, b: &B, what: &str) {
    for f in a.plan().watched_fields() {
        let field = &a.plan().model.field(f).name;
        let (_, x) = stored_field(a, field);
        let (_, y) = stored_field(b, field);
        if let Err(e) = pairsum::compare::max_abs_diff(&x, &y) {
            panic!("{what}: `{field}`: {e}");
        }
        let differ = x.iter().zip(&y).filter(|(p, q)| p.to_bits() != q.to_bits()).count();
        assert_eq!(differ, 0, "{what}: `{field}` differs in {differ} of {} values", x.len());
    }
}

/// Every bundled case: each `cases/*.toml` that is not a study (a study runs one of these).
fn bundled_cases() -> Vec<String> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("cases");
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .expect("cases/")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .filter(|p| !pairsum::scene::study::is_study(&std::fs::read_to_string(p).expect("case file")))
        .map(|p| p.file_stem().expect("name").to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// The bundled cases with pair programs the JIT does not emit yet, how many of their pass variants
/// run natively all the same, and why the others do not: those run as closures (`PAIRSUM_DEBUG=1`
/// prints the reason). `pow` with a varying exponent (Fourtakas' hydrostatic term) and `ln` run
/// natively since they share the closures' recipes (`backend::cpu::math`). Each case is still
/// compared bit for bit below (for the closure passes, closures against closures: the run is
/// deterministic).
const CLOSURE_CASES: [(&str, usize, &str); 1] = [("body_in_water_2d", 1, "a gathered column with no single base")];

#[test]
fn native_pair_programs_equal_the_closures_bit_for_bit_on_every_bundled_case_and_run_natively_but_one() {
    let cases = bundled_cases();
    assert!(cases.len() >= 17, "{cases:?}");
    let mut wrong = vec![];
    for name in &cases {
        let (native, all) = native_equals_closures::<f64>(name, 4);
        // When the JIT learns their programs, this fails: update the list.
        let (expected, why) = CLOSURE_CASES.iter().find(|c| c.0 == name).map_or((all, "none"), |c| (c.1, c.2));
        if native != expected {
            wrong.push(format!(
                "{name}: {native} of {all} pass variants ran as native code, not {expected} (what kept the others closures: {why})"
            ));
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

/// The native backend walks the neighbours in C (`backend/cpu/cwalk.rs`), the closures' backend
/// one candidate at a time; the runs above compare them on every bundled case for 4 steps. Here
/// over 40 steps, in f64 and f32: the dam break (kept lists, walls that take from the fluid
/// only), the F-ANS bullet (kept lists across two symmetry planes: images with flipped signs)
/// and the hypervelocity impact (the cell list, across symmetry planes).
#[test]
fn the_walk_in_c_gives_the_scalar_walks_fields_bit_for_bit_over_40_steps_with_lists_cells_and_mirrors() {
    assert!(ccode::enabled(), "no C compiler answers `cc --version`: install one (Debian: gcc)");
    for name in ["dam_break_2d", "fans_bullet", "hypervelocity_impact"] {
        let opts = pairsum::scene::Options { resolution: Some("ci".into()), ..Default::default() };
        let (scene, plan) = prepare(&case(name), &opts).unwrap_or_else(|e| panic!("{name}: {e}"));
        let store = build_store::<f64>(&plan, &scene.particles, &scene.materials).expect("store");
        let native = CpuBackend::new(plan.clone(), store, scene.mirrors.clone()).expect("cpu");
        assert!(native.walks_in_c(), "{name}: its neighbours are not walked in C");
        assert!(!native.without_jit().walks_in_c(), "{name}: the closures' backend walks in C");
        native_equals_closures::<f64>(name, 40);
        native_equals_closures::<f32>(name, 40);
    }
}

#[test]
fn native_pair_programs_equal_the_closures_bit_for_bit_in_f32() {
    // The dam break's fluid pass takes Fourtakas' pow: the f32 recipes of ln and exp.
    for name in ["hypervelocity_impact", "rings_2d", "borvik_perforation", "pysph_impact3d", "dam_break_2d"] {
        let (n, a) = native_equals_closures::<f32>(name, 4);
        assert_eq!(n, a, "{name}: {n} of {a} pass variants ran as native code");
    }
}

/// One evaluation of every pass of the stdlib solid and fluid models on a jittered cloud with
/// varying smoothing lengths (so `h` is not a constant of the run), natively and by closures.
#[test]
fn native_pair_programs_equal_the_closures_on_jittered_clouds_with_variable_h() {
    use pairsum::backend::Globals;
    use pairsum::schedule::{IntegratorKind, Plan};
    let steel = |m: &pairsum::ir::Model| {
        material(m, &[("rho0", vec![7850.0]), ("E", vec![200e9]), ("nu", vec![0.3]), ("h_ratio", vec![1.3])])
    };
    let water =
        |m: &pairsum::ir::Model| material(m, &[("rho0", vec![1000.0]), ("c0", vec![30.0]), ("h_ratio", vec![1.3])]);
    type Mat = fn(&pairsum::ir::Model) -> pairsum::engine::setup::MaterialInput;
    let models: [(&str, Mat); 3] =
        [("models::elastic_solid", steel), ("models::elastic_solid_corrected", steel), ("models::wcsph_fluid", water)];
    for (name, mat) in models {
        let m = model(&format!("use {name}\n"));
        for dim in [2, 3] {
            let dx = 0.01;
            let mut seed = 11 + dim as u64;
            let mut x = lattice(dim, if dim == 2 { 14 } else { 7 }, dx);
            for p in &mut x {
                for c in p.iter_mut().take(dim) {
                    *c += 0.3 * dx * (rnd(&mut seed) - 0.5);
                }
            }
            let mut inp = input(dim, x, dx);
            for k in 0..inp.len() {
                for c in 0..dim {
                    inp.v[k][c] = 5.0 * (rnd(&mut seed) - 0.5);
                }
                inp.dx[k] = dx * (0.7 + 0.6 * rnd(&mut seed));
            }
            let plan = Plan::build(&m, &scene(&m, dim, &[], IntegratorKind::Euler), None).expect("plan");
            let store = build_store::<f64>(&plan, &inp, &[mat(&m)]).expect("store");
            let mut b = CpuBackend::new(plan.clone(), store.clone(), vec![]).expect("cpu").without_jit();
            b.initialise().expect("init");
            let g = Globals { time: 0.0, dt: 1e-7 };
            b.evaluate(g).expect("closures");
            for (label, mut a) in natives(&plan, &store, &[]) {
                assert_eq!(a.native_passes().0, a.native_passes().1, "{name}: every pass native");
                a.initialise().expect("init");
                a.evaluate(g).expect("native");
                assert_same_bits(&a, &b, &format!("{name} {dim}D, {label} code against closures"));
            }
        }
    }
}

/// Every function of the language's table of elementary functions (`ir::ELEMENTARY`) in one pair
/// sum, of a direction cosine in [−1, 1] on a jittered cloud: the C code calls libm's function on
/// each lane as the closures call it, so one evaluation agrees with the closures bit for bit, in
/// f64 and in f32; Cranelift's code has none of them and leaves the pass to the closures.
#[test]
fn a_pair_sum_of_every_elementary_function_runs_as_c_code_bit_for_bit_with_the_closures_in_f64_and_f32() {
    fn check<T: Real>() {
        use pairsum::backend::Globals;
        use pairsum::schedule::{IntegratorKind, Plan};
        let calls: Vec<String> = pairsum::ir::ELEMENTARY.iter().map(|e| format!("y += {}(q)", e.name)).collect();
        let m = model(&format!(
            "use kernels\ngroup metal\nkernel = wendland_c2\n\
             pairsum elementary -> y: scalar [-] {{\n    let q = x_ij.x / max(r_ij, 1e-12 [m])\n    {}\n}}\n\
             integrate {{ x' = v  v' = 0 }}\n",
            calls.join("\n    ")
        ));
        let dx = 0.01;
        let mut seed = 5;
        let mut x = lattice(2, 8, dx);
        for p in &mut x {
            for c in p.iter_mut().take(2) {
                *c += 0.3 * dx * (rnd(&mut seed) - 0.5);
            }
        }
        let inp = input(2, x, dx);
        let mats = [material(&m, &[("rho0", vec![1000.0]), ("h_ratio", vec![1.3])])];
        let plan = Plan::build(&m, &scene(&m, 2, &["y"], IntegratorKind::Euler), None).expect("plan");
        let store = build_store::<T>(&plan, &inp, &mats).expect("store");
        let g = Globals { time: 0.0, dt: 1e-3 };
        let mut closures = CpuBackend::new(plan.clone(), store.clone(), vec![]).expect("cpu").without_jit();
        closures.initialise().expect("init");
        closures.evaluate(g).expect("closures");
        let (_, want) = stored_field(&closures, "y");
        let cranelift = ccode::without_c(|| CpuBackend::new(plan.clone(), store.clone(), vec![]).expect("cpu"));
        assert_eq!(cranelift.native_passes(), (0, 1), "Cranelift leaves the pass to the closures ({})", T::NAME);
        assert!(ccode::enabled(), "a C compiler answers on every machine that builds pairsum");
        let mut c = CpuBackend::new(plan.clone(), store, vec![]).expect("cpu");
        assert_eq!(c.passes_made_by(NativeKind::C), 1, "the pass runs as C code ({})", T::NAME);
        c.initialise().expect("init");
        c.evaluate(g).expect("C");
        let (_, got) = stored_field(&c, "y");
        let differ = got.iter().zip(&want).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
        assert_eq!(differ, 0, "{}: y differs in {differ} of {} particles", T::NAME, got.len());
        assert!(want.iter().all(|v| v.is_finite()) && want.iter().any(|v| *v != 0.0), "{}: y = {want:?}", T::NAME);
    }
    check::<f64>();
    check::<f32>();
}

/// A field that only some of a pass's source groups store: FTLR19's plate gathers its damage `D`
/// at j, which the elastic projectile does not store. On a jittered cloud with the two groups
/// mixed at random (about half the pairs cross the groups) and `D` set anywhere from 0 to failed,
/// every pass must run natively and one evaluation must agree bit for bit with the closures, so
/// the plate's rows are gathered from their own base. A neighbour of the other group reads a zero
/// row (`jit::PairSpec::partial`) that the bundled sums never use (they take `D` from their own
/// group only: with that row set to NaN this test still passes), so the row guards the read
/// rather than the value.
#[test]
fn native_pair_programs_gather_a_field_that_one_of_two_mixed_groups_stores() {
    use pairsum::backend::Globals;
    let opts = pairsum::scene::Options { resolution: Some("ci".into()), ..Default::default() };
    let (scene, plan) = prepare(&case("borvik_perforation"), &opts).expect("borvik_perforation");
    let d = plan.model.field_id("D").expect("D");
    assert_eq!(plan.model.all_groups().0.count_ones(), 2, "projectile and target");
    // Each group's material as the case binds it.
    let material_of = |g: u32| {
        let k = scene.particles.group.iter().position(|&q| q == g).expect("a particle of the group");
        scene.particles.material[k]
    };
    let dx = 0.002;
    let mut seed = 7;
    let mut x = lattice(3, 9, dx);
    for p in &mut x {
        for c in p.iter_mut() {
            *c += 0.3 * dx * (rnd(&mut seed) - 0.5);
        }
    }
    let mut inp = input(3, x, dx);
    for k in 0..inp.len() {
        let g = u32::from(rnd(&mut seed) < 0.5);
        inp.group[k] = g;
        inp.material[k] = material_of(g);
        inp.body[k] = g;
        for c in 0..3 {
            inp.v[k][c] = 50.0 * (rnd(&mut seed) - 0.5);
        }
    }
    let store = build_store::<f64>(&plan, &inp, &scene.materials).expect("store");
    let mut b = CpuBackend::new(plan.clone(), store.clone(), vec![]).expect("cpu").without_jit();
    b.initialise().expect("init");
    // Damage from none to failed (a fifth of the particles), so that a row read from the wrong
    // base shows.
    let mut snap = b.snapshot().expect("snapshot");
    let damage = snap.columns[d.index()].as_mut().expect("D is stored on the target");
    for v in damage.iter_mut() {
        let r = rnd(&mut seed);
        *v = if r < 0.2 { 1.0 } else { r };
    }
    b.restore(&snap).expect("restore");
    let g = Globals { time: 0.0, dt: 1e-8 };
    b.evaluate(g).expect("closures");
    assert!(!plan.watched_fields().is_empty());
    let mut natives = natives(&plan, &store, &[]);
    for (label, a) in &mut natives {
        assert_eq!(a.native_passes().0, a.native_passes().1, "every pass native ({label})");
        a.initialise().expect("init");
        a.restore(&snap).expect("restore");
        a.evaluate(g).expect("native");
        assert_same_bits(a, &b, &format!("mixed groups, {label} against closures"));
    }
    let a = &natives[0].1;
    // The damage reached the sums: some watched field differs from a cloud without it.
    let mut c =
        CpuBackend::new(plan.clone(), build_store::<f64>(&plan, &inp, &scene.materials).expect("store"), vec![])
            .expect("cpu");
    c.initialise().expect("init");
    c.evaluate(g).expect("undamaged");
    let changed = plan.watched_fields().into_iter().any(|f| {
        let field = &plan.model.field(f).name;
        // Compared as bits over the particles that store the field: a NaN (`field_by_id`'s value
        // for a particle that does not) would make any two vectors unequal.
        let bits = |b: &CpuBackend<f64>| stored_field(b, field).1.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        bits(a) != bits(&c)
    });
    assert!(changed, "the damage changes none of the sums");
}

/// The C path is on wherever the C compiler answers (`$CC`, else `cc`), so that the comparisons
/// above cover it on every machine that builds pairsum; without a compiler they cover Cranelift.
#[test]
fn pair_programs_are_compiled_as_c_wherever_a_c_compiler_answers() {
    let cc = std::env::var("CC").ok().filter(|v| !v.is_empty()).unwrap_or_else(|| "cc".into());
    let answers = std::process::Command::new(&cc).arg("--version").output().is_ok_and(|o| o.status.success());
    let off =
        std::env::var("PAIRSUM_NATIVE").is_ok_and(|v| v == "cranelift") || std::env::var("PAIRSUM_NO_JIT").is_ok();
    assert_eq!(ccode::enabled(), answers && !off, "`{cc} --version` answers: {answers}");
    assert!(!ccode::without_c(ccode::enabled), "the C path off on this thread");
}

/// Where the C compiler is missing, or answers but fails, a run keeps Cranelift's code and its
/// results: the histories of `rings_2d` after 40 steps are byte for byte those of the C path, the
/// summary line says which code ran, a failing compiler is warned of, and a fresh cache says what
/// compiling cost.
#[test]
fn a_run_without_a_working_c_compiler_keeps_cranelifts_code_and_the_same_histories() {
    let dir = std::env::temp_dir().join(format!("pairsum-jit-fallback-{}", std::process::id()));
    let run = |cc: &str, out: &str| {
        let out = dir.join(out);
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_pairsum"))
            .args(["run", "rings_2d", "--resolution", "ci", "--max-steps", "40", "--backend", "cpu", "--out"])
            .arg(&out)
            .env("CC", cc)
            .env("PAIRSUM_CACHE", dir.join("cache"))
            .output()
            .expect("pairsum runs");
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(o.status.success(), "{err}");
        (err, std::fs::read(out.join("histories.csv")).expect("histories.csv"))
    };
    let (c_log, c) = run("cc", "c");
    let (k_log, k) = run("/nonexistent/cc", "cranelift");
    // A compiler that answers `--version` but fails to compile: Cranelift again, with a warning.
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let broken = dir.join("broken-cc");
    std::fs::write(&broken, "#!/bin/sh\n[ \"$1\" = --version ] && { echo broken 1.0; exit 0; }\necho no >&2; exit 1\n")
        .expect("write the broken compiler");
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&broken, std::fs::Permissions::from_mode(0o755)).expect("chmod");
    let (b_log, b) = run(broken.to_str().expect("path"), "broken");
    assert!(b_log.contains("warning: the C compiler failed on a pair program"), "{b_log}");
    assert!(b_log.contains("Cranelift pair code)"), "{b_log}");
    assert!(b == k, "the histories differ between a failed C compile and Cranelift");
    if ccode::enabled() {
        assert!(c_log.contains("C pair code)"), "{c_log}");
        assert!(c_log.contains("1 pair program and the neighbour walk compiled by the C compiler in"), "{c_log}");
    }
    assert!(k_log.contains("Cranelift pair code)"), "{k_log}");
    assert!(!k_log.contains("compiled by the C compiler"), "{k_log}");
    assert!(c.len() > 100, "histories of 40 steps");
    assert!(c == k, "the histories differ between C and Cranelift code");
    let _ = std::fs::remove_dir_all(&dir);
}
