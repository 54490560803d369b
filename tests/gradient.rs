//! The corrected kernel gradient (stdlib correction/kernel_gradient.sph) reproduces the gradient
//! of a linear field to round-off in f64, inside a body and at its free surface, in 2D and 3D; and
//! the kernels that follow the deformation (stdlib solid/shaped_kernel.sph) follow a homogeneous
//! squeeze exactly, with that gradient still exact, floored or bounded in aspect; their hourglass stiffness
//! (solid/shaped_hourglass.sph) pulls a zig-zag back as its formula says and leaves a homogeneous
//! stretch alone; and their hourglass viscosity damps a zig-zag velocity as its formula says and
//! leaves a linear velocity field alone.

mod common;
use common::*;
use pairsum::backend::Backend;
use pairsum::schedule::IntegratorKind;

const MODEL: &str = "
use kernels
use correction::kernel_gradient
group all
kernel = wendland_c2
param slope: vec [1/m]
state phi: scalar [-] = dot(slope, x)
pairsum phi_gradient -> grad_phi: vec [1/m] {
    acc g: vec [1/m]
    g += m[j] / rho[j] * (phi[j] - phi[i]) * gradW_ij
    finally { grad_phi = L_inv * g }
}
integrate { }
";

#[test]
fn corrected_gradient_of_a_linear_field_is_exact_to_round_off() {
    let m = model(MODEL);
    for dim in [2usize, 3] {
        let n = if dim == 2 { 16 } else { 9 };
        let dx = 0.01;
        // A slightly irregular lattice, so that L is not the identity anywhere.
        let mut x = lattice(dim, n, dx);
        let mut seed = 12345u64;
        for p in &mut x {
            for c in p.iter_mut().take(dim) {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                *c += dx * 0.2 * ((seed % 1000) as f64 / 1000.0 - 0.5);
            }
        }
        let slope = [3.0, -1.5, 0.75];
        // det_min is lowered from its default (0.1, which leaves the L of 3D corners uncorrected)
        // so that every particle, corners included, is corrected.
        let mat = material(
            &m,
            &[
                ("rho0", vec![1000.0]),
                ("h_ratio", vec![1.3]),
                ("slope", slope[..dim].to_vec()),
                ("det_min", vec![1e-3]),
            ],
        );
        let mut b = backend::<f64>(
            &m,
            &scene(&m, dim, &["grad_phi"], IntegratorKind::Euler),
            &input(dim, x, dx),
            &[mat],
            vec![],
        );
        b.evaluate(Default::default()).expect("evaluate");
        let (comps, grad) = field_by_id(&b, "grad_phi");
        let exact: Vec<f64> = (0..grad.len()).map(|k| slope[k % comps]).collect();
        let worst = max_abs_diff(&format!("{dim}D corrected gradient against the slope"), &grad, &exact) / 3.0;
        // Corner particles (a quarter or an eighth of a support) included.
        assert!(worst < 1e-6, "{dim}D: worst relative error of the corrected gradient {worst:e}");
    }
}

/// Case text for probes of the body `block` (`common::block_case`): (name, expression, reduction).
fn block_probes(probes: &[(&str, &str, &str)]) -> String {
    probes
        .iter()
        .map(|(name, e, r)| {
            format!("[[probes]]\nname = \"{name}\"\nbody = \"block\"\nexpression = \"{e}\"\nreduce = \"{r}\"\n\n")
        })
        .collect()
}

/// A homogeneous squeeze for the kernels that follow the deformation (solid/shaped_kernel.sph):
/// the velocity v = G x with G = diag(−r, r) kept linear (v̇ = G v), so the motion is
/// x(t) = exp(G t) x(0) and the kernel's shape must be A(t) = exp(G t).
const SQUEEZE_MODEL: &str = "
use kernels
use solid::shaped_kernel
use eos::linear
group metal
kernel = wendland_c2
param C_cfl: scalar [-] = 0.3      // solid/shaped_kernel.sph's step takes it; it gives no default
param rate: scalar [1/s]
particle squeeze -> a: vec [m/s^2] {
    a = rate * vec(-dot(v, vec(1, 0)), dot(v, vec(0, 1)))
}
integrate { x' = v  v' = a  kernel_shape' = dkernel_shape }
";

/// `common::block_case`'s 6 × 6 block squeezed along x and stretched along y for 24 ms at 100 1/s,
/// with `material` further keys of its material: each probe below at the end of the run.
fn squeezed_block(tag: &str, material: &str) -> impl Fn(&str) -> f64 {
    let dir = Scratch::new(&format!("gradient-squeeze-{tag}"));
    std::fs::write(dir.join("squeeze.sph"), SQUEEZE_MODEL).unwrap();
    let probes = block_probes(&[
        ("axx", "kernel_shape.xx", "min"),
        ("axx_max", "kernel_shape.xx", "max"),
        ("ayy", "kernel_shape.yy", "min"),
        ("ayy_max", "kernel_shape.yy", "max"),
        ("axy", "abs(kernel_shape.xy) + abs(kernel_shape.yx)", "max"),
        ("exx", "edot.xx", "min"),
        ("exx_max", "edot.xx", "max"),
        ("eyy", "edot.yy", "min"),
        ("eyy_max", "edot.yy", "max"),
        ("h_max", "h", "max"),
        ("h_short_min", "h_short", "min"),
        ("h_short_max", "h_short", "max"),
        // With the aspect bound r = 4: how far h_short / h misses the bound's ratio (`bound_miss`).
        ("bound_miss_max", &bound_miss(), "max"),
        ("bound_miss_min", &bound_miss(), "min"),
    ]);
    // The prescribed squeeze feeds energy in; the watchdog would stop it as a blow-up.
    let probes = probes + "[watchdog]\nspeed_factor = inf\nenergy_factor = inf\n";
    let top = "integrator = \"predictor_corrector\"\nend_time = \"24 ms\"";
    let body = "initial = { v = \"100 [1/s] * vec(-dot(x, vec(1, 0)), dot(x, vec(0, 1)))\" }";
    let case = common::block_case("squeeze.sph", top, body, &probes).replace(
        "rho0 = \"1000 kg/m^3\"",
        &format!(
            "rho0 = \"1000 kg/m^3\"\nc0 = \"10 m/s\"\nbulk = \"1e5 Pa\"\nrate = \"100 1/s\"\nh_ratio = 1.3\n{material}"
        ),
    );
    let outcome = common::run_case_text_on_cpu(&dir, &case);
    let t = outcome.histories[0].1.last().expect("a point").0;
    assert!((t - 0.024).abs() < 1e-9, "the run ended at t = {t}");
    move |probe: &str| -> f64 {
        let points = &outcome.histories.iter().find(|(n, _)| n == probe).expect("probe").1;
        assert!(points.iter().all(|(_, v)| v.is_finite()), "{probe}: {points:?}");
        points.last().expect("a point").1
    }
}

/// The squeeze with the default bounds: every particle's kernel shape is exp(G t) =
/// diag(e^−2.4, e^2.4) (0.0907 and 11.0) to the integrator's error; its corrected velocity
/// gradient is G to round-off on a lattice squeezed elevenfold (corners and edges included); its
/// time step's length is held at the squeeze floor, 0.2 h0, and its search length is
/// h0 √(e^4.8 + 0.2² − e^−4.8), B's largest axis once the floor has lifted its smallest.
#[test]
fn shaped_kernels_follow_a_squeeze_keep_the_velocity_gradient_exact_and_stop_at_the_floor() {
    let last = squeezed_block("floor", "");
    let (squeezed, stretched) = ((-2.4f64).exp(), 2.4f64.exp());
    for (probe, exact) in [("axx", squeezed), ("axx_max", squeezed), ("ayy", stretched), ("ayy_max", stretched)] {
        let rel = (last(probe) / exact - 1.0).abs();
        assert!(rel < 1e-4, "{probe} = {} against exp(±2.4) = {exact}: {rel:e} apart", last(probe));
    }
    assert!(last("axy") < 1e-9, "the kernel shape turned: |A_xy| + |A_yx| = {}", last("axy"));
    for (probe, exact) in [("exx", -100.0), ("exx_max", -100.0), ("eyy", 100.0), ("eyy_max", 100.0)] {
        let rel = (last(probe) / exact - 1.0).abs();
        assert!(rel < 1e-9, "{probe} = {} against {exact} 1/s", last(probe));
    }
    let h0 = 1.3 * 0.01;
    let longest = h0 * (stretched * stretched + 0.04 - squeezed * squeezed).sqrt();
    assert!((last("h_max") / longest - 1.0).abs() < 1e-4, "h = {} against {longest}", last("h_max"));
    assert!((last("h_short_min") / (h0 * 0.2) - 1.0).abs() < 1e-12, "h_short = {}", last("h_short_min"));
}

/// h_short / h − (√λ₊ / 4) / √(λ₊ (1 + 1/16) − λ₋) at a particle, with λ± the eigenvalues of
/// A Aᵀ of its shape A (from its trace and determinant, 2D): how far the ratio of its shortest
/// axis to its search length misses the aspect bound r = 4's, B = A Aᵀ + (λ₊/16 − λ₋) I.
fn bound_miss() -> String {
    let trace = "(kernel_shape.xx^2 + kernel_shape.xy^2 + kernel_shape.yx^2 + kernel_shape.yy^2)";
    let det = "(kernel_shape.xx * kernel_shape.yy - kernel_shape.xy * kernel_shape.yx)";
    let root = format!("sqrt({trace}^2 - 4 * {det}^2)");
    let (lmax, lmin) = (format!("(({trace} + {root}) / 2)"), format!("(({trace} - {root}) / 2)"));
    format!("h_short / h - sqrt({lmax}) / 4 / sqrt({lmax} * 17 / 16 - {lmin})")
}

/// The squeeze with the aspect bound r = 4 (`shape_aspect`): every kernel's shortest axis is held
/// at a quarter of its shape's longest stretch, h_short = h0 √λ₊ / 4, while its search length is
/// B's largest axis once the bound has lifted its smallest: their ratio at each particle, from its
/// own shape A, within 1e-9 (`bound_miss`). (That shape is not exp(G t) here: a kernel a quarter
/// as wide as it is long overhangs the squeezed block, six particles thinner than its short axis,
/// and where its L falls below det_min the gradient is left uncorrected; the bound still acts,
/// A_yy / A_xx above 6.)
#[test]
fn shaped_kernels_aspect_bound_holds_the_short_axis_at_a_quarter_of_the_longest_stretch() {
    let last = squeezed_block("aspect", "shape_aspect = 4");
    let (axx, ayy) = (last("axx_max"), last("ayy"));
    assert!(ayy / axx > 6.0, "the shape {axx} × {ayy} is not long enough for the bound to act");
    for probe in ["bound_miss_max", "bound_miss_min"] {
        assert!(last(probe).abs() < 1e-9, "{probe}: h_short / h misses the bound's ratio by {}", last(probe));
    }
}

/// The hourglass stiffness of the shaped kernels (solid/shaped_hourglass.sph), at rest.
const HOURGLASS_MODEL: &str = "
use kernels
use solid::shaped_kernel
use solid::shaped_hourglass
use eos::linear
group metal
kernel = wendland_c2
param C_cfl: scalar [-] = 0.3
integrate { x' = v  u' = v  v' = dv_hourglass  kernel_shape' = dkernel_shape }
";

/// `common::block_case`'s 6 × 6 block run one step of 1 ns with the model `model`, `initial` its
/// particles' initial values and `material` further keys of its material (ρ0 1000 kg/m³, c0 10 m/s,
/// h_ratio 1.3 already): each of `probes` (name, expression, reduction) at the end.
fn one_step_of_the_block<const N: usize>(
    tag: &str,
    model: &str,
    initial: &str,
    material: &str,
    probes: [(&str, &str, &str); N],
) -> [f64; N] {
    let dir = Scratch::new(&format!("gradient-{tag}"));
    std::fs::write(dir.join("model.sph"), model).unwrap();
    let top = "integrator = \"predictor_corrector\"\nend_time = \"1 ns\"";
    let case = common::block_case("model.sph", top, &format!("initial = {{ {initial} }}"), &block_probes(&probes))
        .replace(
            "rho0 = \"1000 kg/m^3\"",
            &format!("rho0 = \"1000 kg/m^3\"\nc0 = \"10 m/s\"\nh_ratio = 1.3\n{material}"),
        );
    let outcome = common::run_case_text_on_cpu(&dir, &case);
    probes.map(|(probe, ..)| {
        let points = &outcome.histories.iter().find(|(n, _)| n == probe).expect("probe").1;
        points.last().expect("a point").1
    })
}

/// The block's particles at step 0: the 6 × 6 lattice at 5, 15, …, 55 mm.
fn block_lattice() -> Vec<[f64; 2]> {
    let dx = 0.01;
    (0..36).map(|k| [(k % 6) as f64 * dx + dx / 2.0, (k / 6) as f64 * dx + dx / 2.0]).collect()
}

/// The block at rest with `initial` its particles' initial values: the largest |a| of the
/// hourglass stiffness, the largest and the smallest a · u, each at the end.
fn hourglass_pull(tag: &str, initial: &str) -> [f64; 3] {
    hourglass_pull_of(tag, initial, "")
}

/// As `hourglass_pull`, with `material` further keys of the block's material.
fn hourglass_pull_of(tag: &str, initial: &str, material: &str) -> [f64; 3] {
    let probes = [
        ("pull", "norm(dv_hourglass)", "max"),
        ("against_u_max", "dot(dv_hourglass, u)", "max"),
        ("against_u_min", "dot(dv_hourglass, u)", "min"),
    ];
    let material = format!("bulk = \"2e5 Pa\"\nG = \"1e5 Pa\"\n{material}");
    one_step_of_the_block(&format!("hourglass-{tag}"), HOURGLASS_MODEL, initial, &material, probes)
}

/// A zig-zag along x of 1 mm (a tenth of the spacing) from a reference the kernels' shape (I)
/// maps to the lattice: every particle is pulled back against its displacement (a · u < 0 at
/// each), and the largest pull is the one computed here from the module's formula,
/// α V0 W(|X_ij|, h0) E / (ρ0 |X_ij|²) (ε_ij · x̂_ij) x̂_ij summed over the lattice, within 1e-6.
/// A homogeneous stretch (shape 1.2 I, reference x / 1.2) is pulled by less than 1e-9 of that.
#[test]
fn the_shaped_hourglass_stiffness_pulls_a_zig_zag_back_as_its_formula_says_and_leaves_a_homogeneous_deformation_alone()
{
    let [pull, against_max, against_min] =
        hourglass_pull("zigzag", "u = \"vec(0.001 [m] * sin(pi * x.x / 0.01 [m]), 0 [m])\"");
    // The formula, on the lattice at 5, 15, …, 55 mm.
    let (dx, h0, alpha) = (0.01, 0.013, 0.01);
    let (bulk, g, rho0) = (2e5, 1e5, 1000.0);
    let e = 9.0 * bulk * g / (3.0 * bulk + g);
    let x = block_lattice();
    let u = |p: [f64; 2]| [1e-3 * (std::f64::consts::PI * p[0] / dx).sin(), 0.0];
    let pulls: Vec<f64> = x
        .iter()
        .map(|xi| {
            let mut a = [0.0f64; 2];
            for xj in &x {
                let xij = [xi[0] - xj[0], xi[1] - xj[1]];
                let r = xij[0].hypot(xij[1]);
                if r == 0.0 || r >= 2.0 * h0 {
                    continue;
                }
                let uij = [u(*xi)[0] - u(*xj)[0], u(*xi)[1] - u(*xj)[1]];
                let big_x = [xij[0] - uij[0], xij[1] - uij[1]];
                let r0 = big_x[0].hypot(big_x[1]);
                let unit = [xij[0] / r, xij[1] / r];
                let miss = (big_x[0] - xij[0]) * unit[0] + (big_x[1] - xij[1]) * unit[1];
                let k = alpha * dx * dx * wendland_c2_2d(r0, h0) * e / (rho0 * r0 * r0);
                a = [a[0] + k * miss * unit[0], a[1] + k * miss * unit[1]];
            }
            a[0].hypot(a[1])
        })
        .collect();
    let expected = largest("the formula's pull", &pulls);
    assert!(expected > 0.0);
    assert!((pull / expected - 1.0).abs() < 1e-6, "the largest pull {pull:e} against the formula's {expected:e}");
    assert!(against_max < 0.0, "a particle not pulled back: largest a · u = {against_max:e}");
    assert!(against_min < 0.0 && against_min.is_finite(), "a · u = {against_min:e}");
    let homogeneous = "kernel_shape = \"1.2 * I\", u = \"x - x / 1.2\"";
    let [still, ..] = hourglass_pull("homogeneous", homogeneous);
    assert!(still.is_finite() && still < 1e-9 * expected, "a homogeneous deformation pulled by {still:e}");
}

/// Weakened by the damage (`hourglass_damage = 1`, solid/shaped_hourglass.sph), the zig-zag's
/// largest pull with D = 0.4 at every particle and the material's damage_coupling c = 0.5 is
/// (1 − c D) = 0.8 of the undamaged block's, within 1e-9; with the switch off (the default) the
/// damaged block is pulled as the undamaged one, within 1e-12.
#[test]
fn the_hourglass_pull_weakened_by_the_damage_is_one_less_c_d_of_the_full_pull_and_full_with_the_switch_off() {
    let zigzag = "u = \"vec(0.001 [m] * sin(pi * x.x / 0.01 [m]), 0 [m])\"";
    let damaged = format!("{zigzag}, D = \"0.4\"");
    let [full, ..] = hourglass_pull("undamaged", zigzag);
    let [weakened, against_max, _] =
        hourglass_pull_of("weakened", &damaged, "damage_coupling = 0.5\nhourglass_damage = 1");
    let [unweakened, ..] = hourglass_pull_of("switch-off", &damaged, "damage_coupling = 0.5");
    assert!(full > 0.0 && full.is_finite(), "the undamaged pull {full:e}");
    assert!((weakened / full - 0.8).abs() < 1e-9, "weakened {weakened:e} against 0.8 × {full:e}");
    assert!(against_max < 0.0, "a damaged particle not pulled back: largest a · u = {against_max:e}");
    assert!((unweakened / full - 1.0).abs() < 1e-12, "switch off: {unweakened:e} against {full:e}");
}

/// The hourglass viscosity of the shaped kernels (solid/shaped_kernel.sph's `hourglass_visc` β in
/// `shaped_viscosity`), alone: Monaghan's terms off, the block's velocity held, its acceleration
/// as momentum/shaped.sph applies Π_ij.
const HOURGLASS_VISC_MODEL: &str = "
use kernels
use solid::shaped_kernel
use eos::linear
group metal
kernel = wendland_c2
param C_cfl: scalar [-] = 0.3
pairsum hourglass_damping -> a_hourglass: vec [m/s^2] {
    if body[i] == body[j] {
        a_hourglass -= m[j] * shaped_viscosity() * (L_inv[i] * gradW_shaped())
    }
}
integrate { x' = v  kernel_shape' = dkernel_shape }
";

/// The block with β = 0.5 and the velocity `v`: the largest |a| of the hourglass viscosity, the
/// largest a · v and the power Σ m a · v, at the end.
fn hourglass_damping(tag: &str, v: &str) -> [f64; 3] {
    let probes = [
        ("damping", "norm(a_hourglass)", "max"),
        ("along_v_max", "dot(a_hourglass, v)", "max"),
        ("power", "m * dot(a_hourglass, v)", "sum"),
    ];
    let material = "bulk = \"2e5 Pa\"\nvisc_a = 0\nvisc_b = 0\nhourglass_visc = 0.5";
    one_step_of_the_block(
        &format!("hourglass-visc-{tag}"),
        HOURGLASS_VISC_MODEL,
        &format!("v = \"{v}\""),
        material,
        probes,
    )
}

/// The module's hourglass acceleration on the lattice at 5, 15, …, 55 mm with the velocity `v`,
/// computed here: kernels round (A = I), L_i = −Σ_j V_j ∇W_ij ⊗ x_ij, ∇v_i = [Σ_j V_j (v_j − v_i)
/// ⊗ ∇W_ij] L_i⁻ᵀ, δv_ij = v_ij − ½ (∇v_i + ∇v_j) x_ij and a_i = Σ_j m_j β c h0 (δv_ij · x_ij) /
/// (ρ (r² + (0.1 h0)²)) L_i⁻¹ ∇W_ij, with c = √(K / ρ).
fn hourglass_damping_formula(v: impl Fn([f64; 2]) -> [f64; 2]) -> Vec<[f64; 2]> {
    let (dx, h0, beta, rho) = (0.01, 0.013, 0.5, 1000.0);
    let (c, volume) = ((2e5f64 / rho).sqrt(), dx * dx);
    let x = block_lattice();
    let grad_w = |xij: [f64; 2]| {
        let r = xij[0].hypot(xij[1]);
        let q = r / h0;
        let slope = -5.0 * q * 7.0 / (4.0 * std::f64::consts::PI * h0 * h0) * (1.0 - q / 2.0).powi(3) / h0;
        [slope * xij[0] / r, slope * xij[1] / r]
    };
    let neighbours: Vec<Vec<(usize, [f64; 2])>> = (0..36)
        .map(|i| {
            let near = (0..36).map(|j| (j, [x[i][0] - x[j][0], x[i][1] - x[j][1]]));
            near.filter(|&(j, xij)| j != i && xij[0].hypot(xij[1]) < 2.0 * h0).collect()
        })
        .collect();
    let pairs = |i: usize| neighbours[i].iter().copied();
    let inverse = |m: [[f64; 2]; 2]| {
        let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
        assert!(det.abs() > 0.1, "det L = {det}");
        [[m[1][1] / det, -m[0][1] / det], [-m[1][0] / det, m[0][0] / det]]
    };
    let l_inv: Vec<[[f64; 2]; 2]> = (0..36)
        .map(|i| {
            let mut l = [[0.0; 2]; 2];
            for (_, xij) in pairs(i) {
                let g = grad_w(xij);
                (0..4).for_each(|k| l[k / 2][k % 2] -= volume * g[k / 2] * xij[k % 2]);
            }
            inverse(l)
        })
        .collect();
    let grad_v: Vec<[[f64; 2]; 2]> = (0..36)
        .map(|i| {
            let mut sum = [[0.0; 2]; 2];
            for (j, xij) in pairs(i) {
                let (g, vji) = (grad_w(xij), [v(x[j])[0] - v(x[i])[0], v(x[j])[1] - v(x[i])[1]]);
                (0..4).for_each(|k| sum[k / 2][k % 2] += volume * vji[k / 2] * g[k % 2]);
            }
            let li = l_inv[i];
            let mut out = [[0.0; 2]; 2];
            (0..4).for_each(|k| out[k / 2][k % 2] = sum[k / 2][0] * li[k % 2][0] + sum[k / 2][1] * li[k % 2][1]);
            out
        })
        .collect();
    (0..36)
        .map(|i| {
            let mut a = [0.0; 2];
            for (j, xij) in pairs(i) {
                let g = grad_w(xij);
                let gi = [l_inv[i][0][0] * g[0] + l_inv[i][0][1] * g[1], l_inv[i][1][0] * g[0] + l_inv[i][1][1] * g[1]];
                let linear = |k: usize| {
                    (grad_v[i][k][0] + grad_v[j][k][0]) / 2.0 * xij[0]
                        + (grad_v[i][k][1] + grad_v[j][k][1]) / 2.0 * xij[1]
                };
                let beyond: f64 = (0..2).map(|k| (v(x[i])[k] - v(x[j])[k] - linear(k)) * xij[k]).sum();
                let coefficient = rho * volume * beta * c * h0 * beyond
                    / (rho * (xij[0] * xij[0] + xij[1] * xij[1] + (0.1 * h0).powi(2)));
                a = [a[0] + coefficient * gi[0], a[1] + coefficient * gi[1]];
            }
            a
        })
        .collect()
}

/// A zig-zag velocity along x (±1 m/s column by column, the mode the corrected gradient maps to
/// almost no strain rate) is damped: the largest |a| is the formula's (computed here), within
/// 1e-6; a · v < 0 at every particle. A linear velocity field (a stretch, a shear and a turn) gets
/// less than 1e-9 of that.
#[test]
fn the_shaped_hourglass_viscosity_damps_a_zig_zag_velocity_as_its_formula_says_and_leaves_a_linear_field_alone() {
    let [damping, along_max, power] = hourglass_damping("zigzag", "vec(1 [m/s] * sin(pi * x.x / 0.01 [m]), 0 [m/s])");
    let zigzag = |p: [f64; 2]| [(std::f64::consts::PI * p[0] / 0.01).sin(), 0.0];
    let norms: Vec<f64> = hourglass_damping_formula(zigzag).iter().map(|a| a[0].hypot(a[1])).collect();
    let expected = largest("the formula's damping", &norms);
    assert!(expected > 0.0);
    assert!(
        (damping / expected - 1.0).abs() < 1e-6,
        "the largest damping {damping:e} against the formula's {expected:e}"
    );
    assert!(along_max < 0.0, "a particle not damped: largest a · v = {along_max:e}");
    assert!(power < 0.0, "the damping's power {power:e}");
    let linear = "1 [1/s] * vec(0.3 * x.x + 0.1 * x.y, -0.2 * x.x + 0.5 * x.y)";
    let [still, ..] = hourglass_damping("linear", linear);
    assert!(still.is_finite() && still < 1e-9 * expected, "a linear velocity field damped by {still:e}");
}
