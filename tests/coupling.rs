//! The fluid–solid coupling (stdlib/coupling/fluid_solid.sph): water at rest on a plate that bends
//! feels the plate's pressure, not its bending stress. EK18's Eq 31 as printed (every pair with
//! the total stresses, kept in tests/data/ek18_eq31_coupling.sph) pushes the water along the plate
//! where the plate's stress varies along it, which made water at rest on a clamped plate slide
//! over it and blow up (issue 38, docs/results/README.md). Fourtakas' density diffusion, which
//! takes only water neighbours, diffuses nothing in hydrostatic water beside the plate.

mod common;
use common::*;
use pairsum::backend::{Backend, Globals};
use pairsum::schedule::IntegratorKind;

/// `models::ek18_fsi` with its coupling module replaced by `coupling`.
fn ek18_fsi_with(coupling: &str) -> pairsum::ir::Model {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/stdlib/models/ek18_fsi.sph")).unwrap();
    model(&text.replace("use coupling::fluid_solid\n", &format!("{coupling}\n")))
}

const DX: f64 = 0.01;
/// The plate's bending stress: s_xx = S0 x / 0.3 m, from −10 to 10 MPa across the plate.
const S0: f64 = 1e7;
/// The water's pressure, uniform (its density set to match).
const P0: f64 = 1e5;
const BULK: f64 = 2.2e9;

/// Water 0.4 × 0.1 m at rest on a plate 0.6 × 0.04 m (2D, 10 mm): the CPU backend, the particles'
/// positions and groups, and the groups of fluid and solid.
struct WaterOnPlate {
    b: pairsum::backend::cpu::CpuBackend<f64>,
    x: Vec<[f64; 3]>,
    group: Vec<u32>,
    fluid: u32,
    solid: u32,
}

fn water_on_plate(m: &pairsum::ir::Model, gravity: Option<Vec<f64>>) -> WaterOnPlate {
    let fluid = m.groups.iter().position(|g| g.name == "fluid").unwrap() as u32;
    let solid = m.groups.iter().position(|g| g.name == "solid").unwrap() as u32;
    let mut x = vec![];
    let mut group = vec![];
    let cells = |n: usize, x0: f64, y0: f64, ny: usize| {
        (0..ny).flat_map(move |j| (0..n).map(move |i| [x0 + (i as f64 + 0.5) * DX, y0 + (j as f64 + 0.5) * DX, 0.0]))
    };
    for p in cells(40, -0.2, 0.0, 10) {
        x.push(p);
        group.push(fluid);
    }
    for p in cells(60, -0.3, -0.04, 4) {
        x.push(p);
        group.push(solid);
    }
    let mut inp = input(2, x.clone(), DX);
    inp.body = group.iter().map(|g| u32::from(*g == solid)).collect();
    inp.material = inp.body.clone();
    inp.group = group.clone();
    let water = material(
        m,
        &[
            ("rho0", vec![1000.0]),
            ("bulk", vec![BULK]),
            ("c0", vec![1483.24]),
            ("S_s", vec![1.0]),
            ("h_ratio", vec![1.3]),
        ],
    );
    let al = material(
        m,
        &[
            ("rho0", vec![2710.0]),
            ("c0", vec![6320.0]),
            ("S_s", vec![1.337]),
            ("gamma0", vec![2.1]),
            ("G", vec![26e9]),
            ("jc_A", vec![2.65e8]),
            ("jc_B", vec![4.26e8]),
            ("jc_C", vec![0.015]),
            ("jc_m", vec![1.0]),
            ("jc_n", vec![0.34]),
            ("T_melt", vec![925.0]),
            ("C_v", vec![896.0]),
            ("h_ratio", vec![1.3]),
        ],
    );
    let outputs = ["dv", "drho"];
    let spec = pairsum::schedule::SceneSpec { gravity, ..scene(m, 2, &outputs, IntegratorKind::PredictorCorrector) };
    let b = backend::<f64>(m, &spec, &inp, &[water, al], vec![]);
    WaterOnPlate { b, x, group, fluid, solid }
}

/// The water of [`water_on_plate`] at a uniform pressure P0, the plate carrying a bending stress
/// that varies along it; the acceleration of every particle after one evaluation, and the
/// particles' positions and groups.
fn accelerations(m: &pairsum::ir::Model) -> (Vec<[f64; 3]>, Vec<u32>, Vec<f64>) {
    let WaterOnPlate { mut b, x, group, fluid, solid } = water_on_plate(m, None);
    // The water at a uniform pressure P0, the plate bending.
    let mut state = b.snapshot().unwrap();
    let ids = b.ids().unwrap();
    let (rho, s) = (m.field_id("rho").unwrap(), m.field_id("s").unwrap());
    let rho_col = state.columns[rho.index()].as_mut().unwrap();
    for (k, id) in ids.iter().enumerate() {
        if group[*id as usize] == fluid {
            rho_col[k] = 1000.0 * (1.0 + P0 / BULK);
        }
    }
    // The total stress σ = s − p I is updated with the state (after each stage), so it is set
    // with s (p = 0 at ρ0 and e = 0).
    for field in [s, m.field_id("sigma").unwrap()] {
        let col = state.columns[field.index()].as_mut().unwrap();
        let comps = col.len() / ids.len();
        for (k, id) in ids.iter().enumerate() {
            if group[*id as usize] == solid {
                col[k * comps] = S0 * x[*id as usize][0] / 0.3;
            }
        }
    }
    b.restore(&state).unwrap();
    b.evaluate(Globals { time: 0.0, dt: 1e-7 }).unwrap();
    (x, group, field_by_id(&b, "dv").1)
}

/// The largest |dv_x| of the water's two rows on the plate, away from the water's sides.
fn largest_along_the_plate(x: &[[f64; 3]], group: &[u32], fluid: u32, dv: &[f64]) -> f64 {
    let mut largest = 0.0_f64;
    for (k, p) in x.iter().enumerate() {
        if group[k] == fluid && p[1] < 2.0 * DX && p[0].abs() < 0.1 {
            assert!(dv[2 * k].is_finite(), "dv of particle {k} is {}", dv[2 * k]);
            largest = largest.max(dv[2 * k].abs());
        }
    }
    largest
}

#[test]
fn water_at_rest_on_a_bending_plate_is_not_pushed_along_it_where_eq_31_pushes_it() {
    let pressure_only = ek18_fsi_with("use coupling::fluid_solid");
    let eq31 = ek18_fsi_with(&format!("use \"{}/tests/data/ek18_eq31_coupling.sph\"", env!("CARGO_MANIFEST_DIR")));
    let fluid = pressure_only.groups.iter().position(|g| g.name == "fluid").unwrap() as u32;
    let (x, group, dv) = accelerations(&pressure_only);
    let ours = largest_along_the_plate(&x, &group, fluid, &dv);
    let (x31, group31, dv31) = accelerations(&eq31);
    let theirs = largest_along_the_plate(&x31, &group31, fluid, &dv31);
    // The scale of the push: the stress's change along the plate over the water's density,
    // (20 MPa / 0.6 m) / 1000 kg/m³ = 3.3e4 m/s².
    let scale = 2.0 * S0 / 0.6 / 1000.0;
    assert!(theirs > 0.05 * scale, "Eq 31 pushes the water along the plate by {theirs} m/s² (scale {scale})");
    assert!(
        ours < 1e-9 * scale,
        "the water is pushed along the plate by {ours} m/s²: {:.3e} of Eq 31's",
        ours / theirs
    );
}

/// `models::ek18_fsi` with Fourtakas' density diffusion on the water (`continuity::fourtakas on
/// fluid`, δ = 0.1, γ = 7): its diffusion acts between water particles only, so beside the plate
/// the water's kernel support is cut off by a body it does not diffuse over.
fn ek18_fsi_with_fourtakas() -> pairsum::ir::Model {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/stdlib/models/ek18_fsi.sph")).unwrap();
    model(&text.replace("use continuity::plain on fluid\n", "use continuity::fourtakas on fluid\n"))
}

/// The largest |Dρ/Dt| of the water's two rows on the plate, away from its sides, after one
/// evaluation of water at rest whose density is hydrostatic (Tait, γ = 7, c0 = 1483.24 m/s, 0.1 m
/// deep), with the scene's gravity `gravity`.
fn diffusion_on_the_plate(gravity: Option<Vec<f64>>) -> f64 {
    let m = ek18_fsi_with_fourtakas();
    let WaterOnPlate { mut b, x, group, fluid, .. } = water_on_plate(&m, gravity);
    let mut state = b.snapshot().unwrap();
    let ids = b.ids().unwrap();
    let rho_col = state.columns[m.field_id("rho").unwrap().index()].as_mut().unwrap();
    let (gamma, c0, depth) = (7.0, 1483.24_f64, 0.1);
    for (k, id) in ids.iter().enumerate() {
        if group[*id as usize] == fluid {
            let y = x[*id as usize][1];
            rho_col[k] = 1000.0 * (1.0 + gamma * 9.81 * (depth - y) / (c0 * c0)).powf(1.0 / gamma);
        }
    }
    b.restore(&state).unwrap();
    b.evaluate(Globals { time: 0.0, dt: 1e-7 }).unwrap();
    let drho = field_by_id(&b, "drho").1;
    let mut largest = 0.0_f64;
    for (k, p) in x.iter().enumerate() {
        if group[k] == fluid && p[1] < 2.0 * DX && p[0].abs() < 0.1 {
            assert!(drho[k].is_finite(), "drho of particle {k} is {}", drho[k]);
            largest = largest.max(drho[k].abs());
        }
    }
    largest
}

#[test]
fn fourtakas_diffusion_beside_a_plate_it_does_not_diffuse_over_leaves_hydrostatic_water_unchanged() {
    // With gravity, ρ^H takes the hydrostatic difference out of every pair, so the cut-off support
    // beside the plate diffuses nothing; without it (Molteni–Colagrossi's term, ρ^H = 0) the same
    // water on the same plate diffuses its hydrostatic gradient: that is the scale.
    let plain = diffusion_on_the_plate(None);
    let corrected = diffusion_on_the_plate(Some(vec![0.0, -9.81]));
    // δ h c0 · (ρ0 g / c0²) / h · O(1) = 0.1 · 1483 m/s · 4.5e-3 kg/m⁴ ≈ 0.66 kg/m³/s (0.76
    // measured); with the correction 1.7e-6 kg/m³/s is left, the second order of Tait's ρ^H.
    assert!(plain > 0.1, "without the hydrostatic correction the water on the plate diffuses {plain} kg/m³/s");
    assert!(
        corrected < 1e-4 * plain,
        "hydrostatic water on the plate diffuses {corrected} kg/m³/s ({:.2e} of the uncorrected term)",
        corrected / plain
    );
}
