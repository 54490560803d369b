//! Axisymmetric cases (`axisymmetric = true`, solid/hoop.sph): the hoop terms of the rates against
//! the cylindrical equations' closed forms, the scene's rules, and a planar case that pays nothing
//! for them.

mod common;
use pairsum::backend::cpu::CpuBackend;
use pairsum::engine::{setup, Engine};
use pairsum::runner::prepare;
use std::path::PathBuf;

fn case(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("cases").join(format!("{name}.toml"))
}

fn scratch(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("pairsum-axisymmetric-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch folder");
    dir
}

/// The axisymmetric Børvik case with the projectile expanding radially, v = (a r, 0), and holding
/// a uniform hoop stress s_θθ, initialised (every pass evaluated once at t = 0) on the CPU in f64.
fn expanding_projectile(a: f64, s_hoop: f64) -> Engine<CpuBackend<f64>> {
    let text = std::fs::read_to_string(case("borvik_axisymmetric")).expect("case");
    let moving = r#"velocity = [0, "-${v_impact} m/s"]"#;
    assert!(text.contains(moving), "the case's projectile velocity line");
    let initial = format!(r#"initial = {{ v = "vec({a} [1/s] * x.x, 0 [m/s])", s_hoop = "{s_hoop} [Pa]" }}"#);
    initialised(&text.replace(moving, &initial), "expanding")
}

/// The case `text` initialised (every pass evaluated once at t = 0) on the CPU in f64.
fn initialised(text: &str, tag: &str) -> Engine<CpuBackend<f64>> {
    let dir = scratch(tag);
    let path = dir.join("case.toml");
    std::fs::write(&path, text).expect("case.toml");
    let (scene, plan) = prepare(&path, &Default::default()).unwrap_or_else(|e| panic!("{e}"));
    let store = setup::build_store::<f64>(&plan, &scene.particles, &scene.materials).expect("store");
    let b = CpuBackend::new(plan, store, scene.mirrors.clone()).expect("backend");
    let mut e = Engine::new(b, scene.config.clone());
    e.initialise().expect("initialise");
    let _ = std::fs::remove_dir_all(&dir);
    e
}

/// In a radially expanding cylinder, v = (a r, 0), the strain rates are ε̇_rr = ε̇_θθ = a and
/// ε̇_zz = 0, so ρ̇ = −2 a ρ, ṡ_rr = ṡ_θθ = ⅔ G a and ṡ_zz = −(4/3) G a; a uniform hoop stress
/// s_θθ with no in-plane stress pulls each ring in, v̇_r = −s_θθ / (ρ r), and works at
/// ė = s_θθ ε̇_θθ / ρ. The corrected gradients are exact in a linear field, so the projectile's
/// particles a kernel away from its surface (the axis is a mirror, not a surface) get these to
/// rounding.
#[test]
fn a_radially_expanding_cylinder_gets_the_hoop_terms_of_continuity_jaumann_momentum_and_energy() {
    let (a, s_hoop) = (1000.0, 1e8);
    let e = expanding_projectile(a, s_hoop);
    let b = &e.backend;
    let (rho0, g) = (7850.0, 77.07e9);
    let x = common::field_by_id(b, "x").1;
    let body = common::field_by_id(b, "body").1;
    let field = |name: &str| common::field_by_id(b, name);
    let (ds, ds_hoop, drho, dv, de) = (field("ds"), field("ds_hoop"), field("drho"), field("dv"), field("de"));
    // The projectile: r ≤ 10 mm, z from 1.5 to 81.5 mm; its kernels reach 2 × 1.3 × 1 mm.
    let inner: Vec<usize> = (0..body.len())
        .filter(|k| body[*k] == 0.0 && x[2 * k] < 7e-3 && x[2 * k + 1] > 5e-3 && x[2 * k + 1] < 78e-3)
        .collect();
    assert!(inner.len() > 300, "{} inner particles", inner.len());
    let mut worst = 0.0f64;
    for &k in &inner {
        let r = x[2 * k];
        // symtensor components in 2D: xx, xy, yy.
        let checks = [
            (drho.1[k], -2.0 * a * rho0, "drho"),
            (ds.1[3 * k], 2.0 / 3.0 * g * a, "ds_rr"),
            (ds.1[3 * k + 1], 0.0, "ds_rz"),
            (ds.1[3 * k + 2], -4.0 / 3.0 * g * a, "ds_zz"),
            (ds_hoop.1[k], 2.0 / 3.0 * g * a, "ds_hoop"),
            (dv.1[2 * k], -s_hoop / (rho0 * r), "dv_r"),
            (dv.1[2 * k + 1], 0.0, "dv_z"),
            (de.1[k], s_hoop * a / rho0, "de"),
        ];
        for (got, want, what) in checks {
            let scale = match what {
                "ds_rz" => g * a,
                "dv_z" => s_hoop / (rho0 * 10e-3),
                _ => want.abs(),
            };
            let error = (got - want).abs() / scale;
            assert!(error.is_finite() && error < 1e-6, "{what} at r = {r}: {got} against {want}");
            worst = worst.max(error);
        }
    }
    println!("{} particles, worst relative error {worst:.2e}", inner.len());
}

/// A ring's mass 2π r m is what is conserved, so the particle's mass per metre of the slab falls as
/// the ring moves out: ṁ = −m v_r / r, over one step of the expanding cylinder m (1 − a Δt).
#[test]
fn an_expanding_rings_particle_mass_falls_as_its_radius_grows() {
    let a = 1000.0;
    let mut e = expanding_projectile(a, 0.0);
    let m0 = common::field_by_id(&e.backend, "m").1;
    e.step().expect("a step");
    let dt = e.time;
    let m1 = common::field_by_id(&e.backend, "m").1;
    let x = common::field_by_id(&e.backend, "x").1;
    let body = common::field_by_id(&e.backend, "body").1;
    let mut n = 0;
    for k in (0..body.len()).filter(|k| body[*k] == 0.0 && x[2 * k + 1] > 5e-3 && x[2 * k + 1] < 78e-3) {
        let rate = (m1[k] / m0[k] - 1.0) / (-a * dt);
        assert!((rate - 1.0).abs() < 1e-3, "particle {k} at r = {}: m fell by {rate} a Δt", x[2 * k]);
        n += 1;
    }
    assert!(n > 500, "{n} particles");
}

/// `axisymmetric = true` needs a 2D case and a model that carries the hoop stress wherever it
/// moves particles (C0053), and a material may not set it (C0007).
#[test]
fn axisymmetric_is_c0053_in_3d_or_with_a_model_without_hoop_stress_and_c0007_on_a_material() {
    let text = std::fs::read_to_string(case("borvik_axisymmetric")).expect("case");
    let dir = scratch("errors");
    for (from, to, code) in [
        ("dim = 2", "dim = 3", "C0053"),
        (r#"model = "models::ftlr19_perforation_shaped""#, r#"model = "models::ftlr19_perforation""#, "C0053"),
        ("[materials.weldox]\n", "[materials.weldox]\naxisymmetric = 1\n", "C0007"),
    ] {
        assert!(text.contains(from), "{from}");
        let path = dir.join("bad.toml");
        std::fs::write(&path, text.replacen(from, to, 1)).expect("bad.toml");
        let err = prepare(&path, &Default::default()).err().map(|e| e.to_string()).expect("an error");
        assert!(err.contains(code), "{to}: {err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A planar case of the same model neither stores nor computes the hoop stress: its terms settle
/// to 0, the rate of s_hoop is dropped and s_hoop is folded (schedule/settle.rs).
#[test]
fn a_planar_case_of_a_model_with_hoop_terms_stores_no_hoop_stress() {
    let set = pairsum::scene::Options {
        set: vec![("model".into(), "models::ftlr19_perforation_shaped".into())],
        ..Default::default()
    };
    let (_, plan) = prepare(&case("borvik_perforation"), &set).unwrap_or_else(|e| panic!("{e}"));
    let stored: Vec<&str> = plan.layout.iter().map(|l| plan.model.field(l.field).name.as_str()).collect();
    assert!(stored.contains(&"s") && stored.contains(&"eps_p"), "{stored:?}");
    assert!(!stored.contains(&"s_hoop") && !stored.contains(&"ds_hoop"), "{stored:?}");
    let (_, plan) = prepare(&case("borvik_axisymmetric"), &Default::default()).unwrap_or_else(|e| panic!("{e}"));
    let stored: Vec<&str> = plan.layout.iter().map(|l| plan.model.field(l.field).name.as_str()).collect();
    assert!(stored.contains(&"s_hoop") && stored.contains(&"ds_hoop"), "{stored:?}");
}

/// The watchdog weighs each particle of an axisymmetric case as its ring (`m 2π r`), whose energy
/// is the one conserved: at t = 0 the Børvik rings' energy is the 3D projectile's ½ ρ π R² L v²
/// (ρ 7850 kg/m³, R 10 mm, L 80 mm, v 399.6 m/s) within 1 %, where the particles' planar masses
/// alone give a number of other units.
#[test]
fn the_watchdogs_energy_of_an_axisymmetric_case_is_its_rings() {
    let e = initialised(&std::fs::read_to_string(case("borvik_axisymmetric")).expect("case"), "watchdog");
    let plan = pairsum::backend::Backend::plan(&e.backend);
    let motion = pairsum::engine::watchdog::Motion::read(&e.backend).expect("read").expect("motion");
    let g = pairsum::engine::watchdog::gravity(plan, 2);
    let watched = motion.watch_values(&g);
    // The same sum from the fields, weighed here.
    let (m, x, v) = (
        common::field_by_id(&e.backend, "m").1,
        common::field_by_id(&e.backend, "x").1,
        common::field_by_id(&e.backend, "v").1,
    );
    let rings: f64 = (0..m.len())
        .map(|k| 2.0 * std::f64::consts::PI * x[2 * k] * m[k] * 0.5 * (v[2 * k].powi(2) + v[2 * k + 1].powi(2)))
        .sum();
    let projectile = 0.5 * 7850.0 * std::f64::consts::PI * 0.01f64.powi(2) * 0.08 * 399.6f64.powi(2);
    assert!((watched.kinetic / rings - 1.0).abs() < 1e-12, "watchdog {} J, the rings {rings} J", watched.kinetic);
    assert!((watched.energy / projectile - 1.0).abs() < 0.01, "watchdog {} J, ½ m v² {projectile} J", watched.energy);
}

/// A disc's lattice holds the disc's exact area, not the ball's volume its rings sweep: in an
/// axisymmetric case its particles' volumes are scaled so that Σ V 2π r is the ball's 4/3 π R³
/// (the hypervelocity sphere, R = 5 mm, at 1 mm: +1.3 % before), or the torus's 2π² c R² for a
/// disc off the axis (its centre at c = 10 mm, R = 3 mm). The plate, a box of whole spacings,
/// sweeps its cylinder's π R² t unscaled.
#[test]
fn a_disc_about_the_axis_sweeps_the_exact_volume_of_its_ball_or_torus() {
    let text = std::fs::read_to_string(case("hypervelocity_impact_axisymmetric")).expect("case");
    let disc = r#"shape = { disc = { center = [0, "6 mm"], radius = "5 mm" } }"#;
    assert!(text.contains(disc), "the case's sphere");
    let torus = text.replace(disc, r#"shape = { disc = { center = ["10 mm", "6 mm"], radius = "3 mm" } }"#);
    let pi = std::f64::consts::PI;
    let ball = 4.0 / 3.0 * pi * 0.005f64.powi(3);
    let ring = 2.0 * pi * pi * 0.01 * 0.003f64.powi(2);
    let plate = pi * 0.05f64.powi(2) * 0.004;
    for (text, tag, expected) in [(text.clone(), "ball", ball), (torus, "torus", ring)] {
        let dir = scratch(tag);
        let path = dir.join("case.toml");
        std::fs::write(&path, &text).expect("case.toml");
        let model = "hypervelocity_impact_axisymmetric.sph";
        std::fs::copy(case("hypervelocity_impact_axisymmetric").with_file_name(model), dir.join(model)).expect("model");
        let (scene, _) = prepare(&path, &Default::default()).unwrap_or_else(|e| panic!("{e}"));
        let _ = std::fs::remove_dir_all(&dir);
        let p = &scene.particles;
        let swept = |b: u32| -> f64 {
            (0..p.x.len()).filter(|k| p.body[*k] == b).map(|k| p.vol[k] * 2.0 * pi * p.x[k][0]).sum()
        };
        assert!(
            (swept(0) / expected - 1.0).abs() < 1e-12,
            "{tag}: the rings sweep {} m³, exactly {expected}",
            swept(0)
        );
        assert!((swept(1) / plate - 1.0).abs() < 1e-12, "the plate's rings sweep {} m³, exactly {plate}", swept(1));
    }
}

/// `round_failed` (damage/round_failed_kernels.sph): with 1, the 3D models' default, a failed
/// particle's kernel turns round; with 0, the axisymmetric Børvik case's default, it keeps its
/// shape. The plate starts failed (D = 1) with its kernels stretched 1.2×; after
/// one step its kernels' xx component is 1 with 1, and within 1e-3 of 1.2 with 0.
#[test]
fn a_failed_particles_kernel_turns_round_with_round_failed_1_and_keeps_its_shape_with_0() {
    let text = std::fs::read_to_string(case("borvik_axisymmetric")).expect("case");
    let plate = "name = \"plate\"\n";
    let default = "\nround_failed = 0 ";
    assert!(text.contains(plate) && text.contains(default), "the case's plate and its round_failed default");
    let initial = r#"initial = { D = "1", kernel_shape = "1.2 * I" }"#;
    let failed = text.replacen(plate, &format!("{plate}{initial}\n"), 1);
    for (round, expected) in [(1, 1.0), (0, 1.2)] {
        let mut e =
            initialised(&failed.replacen(default, &format!("\nround_failed = {round} "), 1), &format!("round{round}"));
        e.step().expect("a step");
        let (comps, shape) = common::field_by_id(&e.backend, "kernel_shape");
        let body = common::field_by_id(&e.backend, "body").1;
        let plate: Vec<usize> = (0..body.len()).filter(|k| body[*k] == 1.0).collect();
        assert!(plate.len() > 400, "{} plate particles", plate.len());
        for k in plate {
            let xx = shape[k * comps];
            assert!(
                (xx - expected).abs() <= 1e-3,
                "round_failed = {round}: particle {k}'s kernel xx {xx}, not {expected}"
            );
        }
    }
}

/// Σ 2π r m a_y over every particle of the acceleration fields `terms` (added), each on the bodies
/// it names (a field one body does not store reads NaN there), and the sum of the sizes of each
/// particle's share.
fn rings_axial_force(e: &Engine<CpuBackend<f64>>, terms: &[(&str, &[f64])]) -> (f64, f64) {
    let field = |name: &str| common::field_by_id(&e.backend, name).1;
    let (m, x, body) = (field("m"), field("x"), field("body"));
    let fields: Vec<(Vec<f64>, &[f64])> = terms.iter().map(|(t, bodies)| (field(t), *bodies)).collect();
    let ring = |k: usize| -> f64 {
        let a: f64 = fields.iter().filter(|(_, bodies)| bodies.contains(&body[k])).map(|(a, _)| a[2 * k + 1]).sum();
        2.0 * std::f64::consts::PI * x[2 * k] * m[k] * a
    };
    ((0..m.len()).map(ring).sum(), (0..m.len()).map(|k| ring(k).abs()).sum())
}

/// `conservative = 1` (momentum/corrected_pair.sph, solid/hoop.sph): each pair's forces, weighed
/// by the rings, are equal and opposite. Two tubes meet (the Børvik plate and a projectile 16 mm
/// in radius, both with an 8 mm bore, so that no pair reaches across the axis); after 100 steps,
/// the rates evaluated at the state reached, Σ 2π r m a_y over both bodies of the stresses,
/// viscosity, hourglass pull and contact is 0 to round-off (1e-12 of the sum of its sizes), where
/// with `conservative = 0` (L_i⁻¹ on both stresses, the plane's pair weights) it is more than 1 %.
#[test]
fn two_tubes_that_meet_feel_ring_forces_that_sum_to_round_off_with_conservative_pairs_only() {
    let text = std::fs::read_to_string(case("borvik_axisymmetric")).expect("case");
    let (axis, bore) = (r#"min = ["0 mm", "#, r#"min = ["8 mm", "#);
    let default = "\nconservative = 1 ";
    assert!(
        text.matches(axis).count() == 3 && text.contains(default),
        "the case's bodies from the axis and its default"
    );
    let tubes = text.replace(axis, bore).replacen("\ngap = 1.5\n", "\ngap = 0.2\n", 1).replacen(
        "\nprojectile_radius = 10\n",
        "\nprojectile_radius = 16\n",
        1,
    );
    for conservative in [1, 0] {
        let text = tubes.replacen(default, &format!("\nconservative = {conservative} "), 1);
        let mut e = initialised(&text, &format!("tubes{conservative}"));
        for _ in 0..100 {
            e.step().expect("a step");
        }
        let at = pairsum::backend::Globals { time: e.time, dt: e.dt };
        pairsum::backend::Backend::evaluate(&mut e.backend, at).expect("the rates at the state reached");
        // No pair reaches across the axis: a particle and a mirror image are the two radii
        // apart, and a kernel reaches 2 h, so each particle stays more than 2 h from the axis.
        let (x, h) = (common::field_by_id(&e.backend, "x").1, common::field_by_id(&e.backend, "h").1);
        for k in 0..h.len() {
            assert!(
                x[2 * k] > 2.0 * h[k],
                "particle {k} at r = {} m, its kernel's reach 2 h = {} m",
                x[2 * k],
                2.0 * h[k]
            );
        }
        let both: &[f64] = &[0.0, 1.0];
        let (contact, _) = rings_axial_force(&e, &[("a_contact", &[0.0])]);
        let (total, size) = rings_axial_force(&e, &[("dv", both), ("a_contact", both), ("dv_hourglass", &[1.0])]);
        println!("conservative = {conservative}: Σ 2π r m a_y = {total} N of {size} N, the contact's on the projectile {contact} N at {} s", e.time);
        assert!(
            contact.abs() > 0.01 * size,
            "conservative = {conservative}: the contact's force {contact} N: the tubes barely met"
        );
        if conservative == 1 {
            assert!(total.abs() < 1e-12 * size, "conservative = 1: the rings' forces sum to {total} N of {size} N");
        } else {
            assert!(total.abs() > 0.01 * size, "conservative = 0: the rings' forces sum to {total} N of {size} N only");
        }
    }
}
