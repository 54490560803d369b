//! `compensated` pair sums (Kahan) keep f32 sums close to the f64 ones where plain f32 sums
//! drift: a Shepard sum over ~2,000 neighbours per particle.

mod common;
use common::*;
use pairsum::backend::{Backend, Globals};
use pairsum::schedule::IntegratorKind;

pub const MODEL: &str = "
use kernels
group all
kernel = wendland_c2
pairsum plain -> sum_plain: scalar [-] {
    sum_plain += vol[j] * W_ij
}
pairsum kahan -> sum_kahan: scalar [-] compensated {
    sum_kahan += vol[j] * W_ij
}
integrate { }
";

fn worst_error(values: &[f64], exact: &[f64]) -> f64 {
    max_abs_diff("f32 sum against the f64 one", values, exact)
}

#[test]
fn compensated_f32_sums_stay_close_to_f64() {
    let m = model(MODEL);
    let dim = 3;
    let inp = input(dim, lattice(dim, 18, 0.01), 0.01);
    let mat = material(&m, &[("rho0", vec![1000.0]), ("h_ratio", vec![3.9])]);
    let sc = scene(&m, dim, &["sum_plain", "sum_kahan"], IntegratorKind::Euler);
    let mut f64b = backend::<f64>(&m, &sc, &inp, std::slice::from_ref(&mat), vec![]);
    let mut f32b = backend::<f32>(&m, &sc, &inp, &[mat], vec![]);
    f64b.evaluate(Globals::default()).expect("f64");
    f32b.evaluate(Globals::default()).expect("f32");
    let (_, exact) = field_by_id(&f64b, "sum_plain");
    let (_, plain) = field_by_id(&f32b, "sum_plain");
    let (_, kahan) = field_by_id(&f32b, "sum_kahan");
    let (e_plain, e_kahan) = (worst_error(&plain, &exact), worst_error(&kahan, &exact));
    // Within 2 ulp of f32 at the sum's value (about 1): the compensated sum of the f32 terms is
    // exact to about one, and the terms' own rounding (each W_ij in f32) adds about another.
    let ulp = f32::EPSILON as f64;
    assert!(e_kahan < 2.0 * ulp, "compensated f32 error {e_kahan:e} ({:.2} ulp)", e_kahan / ulp);
    // The CPU folds each batch of at most 64 neighbours in interleaved partial sums (the vector
    // width of its native code), which already keeps plain f32 sums within 3 ulp here (summed
    // one lane after another they were off by more than five times the compensated sum);
    // compensation must still not be worse. On the GPU, which sums one
    // neighbour after another, it is what keeps f32 close (tests/gpu.rs).
    assert!(e_kahan <= e_plain, "compensation should not hurt: plain {e_plain:e}, compensated {e_kahan:e}");
}

/// A compensated sum of a vec: its three components come back from the native pair program in
/// neighbouring registers of the frame.
pub const VEC_MODEL: &str = "
use kernels
group all
kernel = wendland_c2
pairsum plain -> v_plain: vec [-] {
    v_plain += vol[j] * W_ij * vec(1, 2, 3)
}
pairsum kahan -> v_kahan: vec [-] compensated {
    v_kahan += vol[j] * W_ij * vec(1, 2, 3)
}
integrate { }
";

/// In f64 a compensated sum and a plain one differ by rounding alone. The native code writes a
/// compensated sum's terms lane by lane for Rust to fold, in whole vectors: before this was
/// fixed, the last vector of a full batch spilled past the register into the first lane of the
/// next, another particle's term, and each batch's first term of the next component was lost
/// (1e-2 relative off here).
#[test]
fn a_compensated_vec_sum_in_native_code_equals_the_plain_sum_to_rounding() {
    let m = model(VEC_MODEL);
    let dim = 3;
    let inp = input(dim, lattice(dim, 12, 0.01), 0.01);
    let mat = material(&m, &[("rho0", vec![1000.0]), ("h_ratio", vec![2.1])]);
    let sc = scene(&m, dim, &["v_plain", "v_kahan"], IntegratorKind::Euler);
    // Native code from each generator: C where a C compiler answers, and Cranelift.
    let c = backend::<f64>(&m, &sc, &inp, std::slice::from_ref(&mat), vec![]);
    let cranelift = pairsum::backend::cpu::ccode::without_c(|| backend::<f64>(&m, &sc, &inp, &[mat], vec![]));
    for (label, mut b) in [("C or Cranelift", c), ("Cranelift", cranelift)] {
        assert!(b.native_passes().0 >= 1, "the pair sums did not run as native code ({label})");
        b.evaluate(Globals::default()).expect("evaluate");
        let (_, plain) = field_by_id(&b, "v_plain");
        let (_, kahan) = field_by_id(&b, "v_kahan");
        let d = max_rel_diff("compensated against plain", &kahan, &plain);
        assert!(d < 1e-14, "{label}: a compensated vec sum differs from the plain one by {d:e} (relative)");
    }
}
