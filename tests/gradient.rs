//! The corrected kernel gradient (stdlib correction/kernel_gradient.sph) reproduces the gradient
//! of a linear field to round-off in f64, inside a body and at its free surface, in 2D and 3D.

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
