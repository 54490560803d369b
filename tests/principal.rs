//! `tensile_part` (stdlib/solid/principal.sph), which the artificial stress takes in principal
//! axes, against an eigen-decomposition by nalgebra: Σ max(σ_k, 0) n_k ⊗ n_k, in 1D, 2D and 3D, on
//! random stresses and on stresses with equal principal values (isotropic, uniaxial, two equal),
//! where a closed form is most likely to divide by a small difference.

mod common;
use common::*;
use nalgebra::{DMatrix, SymmetricEigen};
use pairsum::backend::cpu::CpuBackend;
use pairsum::backend::Backend;
use pairsum::engine::setup::build_store;
use pairsum::ir::{component_indices, components, Shape};
use pairsum::schedule::{IntegratorKind, Plan};

/// A random rotation (Gram–Schmidt of a random matrix).
fn rotation(dim: usize, seed: &mut u64) -> DMatrix<f64> {
    let m = DMatrix::from_fn(dim, dim, |_, _| rnd(seed) - 0.5);
    m.qr().q()
}

/// R diag(values) Rᵀ.
fn with_principal_values(values: &[f64], seed: &mut u64) -> DMatrix<f64> {
    let r = rotation(values.len(), seed);
    &r * DMatrix::from_diagonal(&nalgebra::DVector::from_row_slice(values)) * r.transpose()
}

fn expected(s: &DMatrix<f64>) -> DMatrix<f64> {
    let e = SymmetricEigen::new(s.clone());
    let mut t = DMatrix::zeros(s.nrows(), s.ncols());
    for k in 0..s.nrows() {
        let n = e.eigenvectors.column(k);
        t += e.eigenvalues[k].max(0.0) * n * n.transpose();
    }
    t
}

/// The stresses of the test in `dim` dimensions: random ones and ones with repeated values.
fn stresses(dim: usize) -> Vec<DMatrix<f64>> {
    let mut seed = 17 + dim as u64;
    let mut out = vec![DMatrix::zeros(dim, dim)];
    for _ in 0..200 {
        let a = DMatrix::from_fn(dim, dim, |_, _| 2e8 * (rnd(&mut seed) - 0.5));
        out.push((&a + a.transpose()) / 2.0);
    }
    let repeated: &[&[f64]] = match dim {
        1 => &[&[3e8], &[-3e8], &[0.0]],
        2 => &[&[1e8, 1e8], &[-1e8, -1e8], &[2e8, 0.0], &[0.0, -2e8], &[1e8, -1e8]],
        _ => &[
            &[1e8, 1e8, 1e8],
            &[-1e8, -1e8, -1e8],
            &[2e8, 0.0, 0.0],
            &[0.0, 0.0, -2e8],
            &[1e8, 1e8, -3e8],
            &[3e8, -1e8, -1e8],
            &[1e8, 1e8, 0.0],
            &[5e7, -5e7, -5e7],
            &[1e8, 1e8 * (1.0 + 1e-9), -2e8],
            &[2e8, 1e-3, -1e-3],
        ],
    };
    for values in repeated {
        for _ in 0..5 {
            out.push(with_principal_values(values, &mut seed));
        }
    }
    out
}

#[test]
fn tensile_part_is_the_positive_part_of_the_eigen_decomposition() {
    let m = model(TENSILE_PART_MODEL);
    for dim in 1..=3 {
        let stresses = stresses(dim);
        let n = stresses.len();
        let inp = input(dim, lattice(dim, 1, 1.0).into_iter().cycle().take(n).collect(), 1.0);
        let scene = scene(&m, dim, &["pulled"], IntegratorKind::Euler);
        let plan = Plan::build(&m, &scene, None).expect("plan");
        let mut store = build_store::<f64>(&plan, &inp, &[material(&m, &[("rho0", vec![1.0])])]).expect("store");
        let s = plan.model.field_id("s").expect("s");
        let pairs = component_indices(Shape::SymTensor, dim);
        let comps = components(Shape::SymTensor, dim);
        let column = store.column_mut(s).expect("s is stored");
        for (k, sigma) in stresses.iter().enumerate() {
            for (c, (a, b)) in pairs.iter().enumerate() {
                column.data[k * comps + c] = sigma[(*a, *b)];
            }
        }
        let mut b = CpuBackend::<f64>::new(plan, store, vec![]).expect("backend");
        b.initialise().expect("initialise");
        b.evaluate(Default::default()).expect("evaluate");
        let (_, t) = field_by_id(&b, "pulled");
        for (k, sigma) in stresses.iter().enumerate() {
            let want = expected(sigma);
            let scale = sigma.norm().max(1.0);
            for (c, (a, bb)) in pairs.iter().enumerate() {
                let got = t[k * comps + c];
                assert!(
                    (got - want[(*a, *bb)]).abs() <= 1e-7 * scale,
                    "{dim}D, stress {k} {sigma}: component ({a}, {bb}) is {got:e}, the eigen-decomposition gives {:e}",
                    want[(*a, *bb)]
                );
            }
        }
    }
}
