//! The corrected kernel gradient (stdlib correction/kernel_gradient.sph) reproduces the gradient
//! of a linear field to round-off in f64, inside a body and at its free surface, in 2D and 3D; and
//! the kernels that follow the deformation (stdlib solid/shaped_kernel.sph) follow a homogeneous
//! squeeze exactly, with that gradient still exact.

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

/// A homogeneous squeeze for the kernels that follow the deformation (solid/shaped_kernel.sph):
/// the velocity v = G x with G = diag(−r, r) kept linear (v̇ = G v), so the motion is
/// x(t) = exp(G t) x(0) and the kernel's shape must be A(t) = exp(G t).
const SQUEEZE_MODEL: &str = "
use kernels
use solid::shaped_kernel
use eos::linear
group metal
kernel = wendland_c2
param rate: scalar [1/s]
particle squeeze -> a: vec [m/s^2] {
    a = rate * vec(-dot(v, vec(1, 0)), dot(v, vec(0, 1)))
}
integrate { x' = v  v' = a  kernel_shape' = dkernel_shape }
";

/// `common::block_case`'s 6 × 6 block squeezed along x and stretched along y for 24 ms at 100 1/s:
/// every particle's kernel shape is exp(G t) = diag(e^−2.4, e^2.4) (0.0907 and 11.0) to the
/// integrator's error; its corrected velocity gradient is G to round-off on a lattice squeezed
/// elevenfold (corners and edges included); its time step's length is held at the squeeze floor,
/// 0.2 h0, and its search length is h0 √(e^4.8 + 0.2² − e^−4.8), B's largest axis once the floor
/// has lifted its smallest.
#[test]
fn shaped_kernels_follow_a_squeeze_keep_the_velocity_gradient_exact_and_stop_at_the_floor() {
    let dir = std::env::temp_dir().join(format!("pairsum-gradient-squeeze-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    std::fs::write(dir.join("squeeze.sph"), SQUEEZE_MODEL).unwrap();
    let probes: String = [
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
    ]
    .iter()
    .map(|(name, e, r)| {
        format!("[[probes]]\nname = \"{name}\"\nbody = \"block\"\nexpression = \"{e}\"\nreduce = \"{r}\"\n\n")
    })
    .collect();
    // The prescribed squeeze feeds energy in; the watchdog would stop it as a blow-up.
    let probes = probes + "[watchdog]\nspeed_factor = inf\nenergy_factor = inf\n";
    let top = "integrator = \"predictor_corrector\"\nend_time = \"24 ms\"";
    let body = "initial = { v = \"100 [1/s] * vec(-dot(x, vec(1, 0)), dot(x, vec(0, 1)))\" }";
    let case = common::block_case("squeeze.sph", top, body, &probes).replace(
        "rho0 = \"1000 kg/m^3\"",
        "rho0 = \"1000 kg/m^3\"\nc0 = \"10 m/s\"\nbulk = \"1e5 Pa\"\nrate = \"100 1/s\"\nh_ratio = 1.3",
    );
    let outcome = common::run_case_text_on_cpu(&dir, &case);
    let last = |probe: &str| -> f64 {
        let points = &outcome.histories.iter().find(|(n, _)| n == probe).expect("probe").1;
        assert!(points.iter().all(|(_, v)| v.is_finite()), "{probe}: {points:?}");
        points.last().expect("a point").1
    };
    let t = outcome.histories[0].1.last().expect("a point").0;
    assert!((t - 0.024).abs() < 1e-9, "the run ended at t = {t}");
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
    let _ = std::fs::remove_dir_all(&dir);
}
