//! Helpers for tests that run models on the CPU backend without a case file.
#![allow(dead_code)]

use pairsum::backend::cpu::CpuBackend;
use pairsum::backend::{Backend, Mirror};
use pairsum::check::{check_text, Stdlib};
use pairsum::diag::{render, Sources};
use pairsum::engine::setup::{build_store, MaterialInput, ParticleInput};
use pairsum::ir::Model;
use pairsum::particles::Real;
use pairsum::schedule::{IntegratorKind, Plan, SceneSpec};
use std::path::Path;

pub fn stdlib() -> Stdlib {
    Stdlib::Dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("stdlib"))
}

pub fn model(text: &str) -> Model {
    let mut sources = Sources::new();
    let checked = check_text(&mut sources, "test.sph", text, stdlib());
    assert!(!checked.has_errors(), "{}", render(&sources, &checked.diags));
    checked.model
}

/// A regular lattice of `n` particles per axis, spacing `dx`, starting at `dx/2`.
pub fn lattice(dim: usize, n: usize, dx: f64) -> Vec<[f64; 3]> {
    let mut out = vec![];
    let ny = if dim > 1 { n } else { 1 };
    let nz = if dim > 2 { n } else { 1 };
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..n {
                let c = |m: usize| (m as f64 + 0.5) * dx;
                out.push([c(i), if dim > 1 { c(j) } else { 0.0 }, if dim > 2 { c(k) } else { 0.0 }]);
            }
        }
    }
    out
}

pub fn input(dim: usize, x: Vec<[f64; 3]>, dx: f64) -> ParticleInput {
    let n = x.len();
    ParticleInput {
        v: vec![[0.0; 3]; n],
        vol: vec![dx.powi(dim as i32); n],
        dx: vec![dx; n],
        body: vec![0; n],
        part: vec![-1; n],
        group: vec![0; n],
        material: vec![0; n],
        initial: vec![],
        x,
    }
}

/// A material binding parameters by name.
pub fn material(model: &Model, values: &[(&str, Vec<f64>)]) -> MaterialInput {
    let mut m = MaterialInput { name: "test".into(), ..Default::default() };
    for (name, v) in values {
        let p = model.param_id(name).unwrap_or_else(|| panic!("no parameter {name}"));
        m.values.insert(p, v.clone());
    }
    m
}

pub fn scene(model: &Model, dim: usize, outputs: &[&str], integrator: IntegratorKind) -> SceneSpec {
    SceneSpec {
        dim,
        groups: model.all_groups(),
        outputs: outputs.iter().map(|n| model.field_id(n).unwrap_or_else(|| panic!("no field {n}"))).collect(),
        integrator,
        gravity: None,
        loads: vec![],
        constraints: vec![],
        symmetry: vec![],
        search: Default::default(),
    }
}

pub fn backend<T: Real>(
    model: &Model,
    scene: &SceneSpec,
    input: &ParticleInput,
    materials: &[MaterialInput],
    mirrors: Vec<Mirror>,
) -> CpuBackend<T> {
    let plan = Plan::build(model, scene, None).expect("plan");
    let store = build_store::<T>(&plan, input, materials).expect("store");
    let mut b = CpuBackend::new(plan, store, mirrors).expect("backend");
    b.initialise().expect("initialise");
    b
}

/// A field of every particle in the scene's original order.
pub fn field_by_id<B: Backend>(b: &B, name: &str) -> (usize, Vec<f64>) {
    let f = b.plan().model.field_id(name).expect("field");
    let (comps, data) = b.read(f).expect("read").expect("stored");
    let ids = b.ids().expect("ids");
    let mut out = vec![0.0; data.len()];
    for (k, id) in ids.iter().enumerate() {
        out[*id as usize * comps..(*id as usize + 1) * comps].copy_from_slice(&data[k * comps..(k + 1) * comps]);
    }
    (comps, out)
}

/// A model whose one equation is `tensile_part` (stdlib/solid/principal.sph) of the state `s`.
pub const TENSILE_PART_MODEL: &str = "use kernels\nuse solid::principal\ngroup all\nkernel = cubic_spline\n\
     state s: symtensor [Pa]\nparticle tension -> pulled: symtensor [Pa] { pulled = tensile_part(s) }\nintegrate { }\n";

/// A xorshift pseudo-random number in [0, 1), advancing `seed`.
pub fn rnd(seed: &mut u64) -> f64 {
    *seed ^= *seed << 13;
    *seed ^= *seed >> 7;
    *seed ^= *seed << 17;
    (*seed % 1_000_000) as f64 / 1_000_000.0
}
