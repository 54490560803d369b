//! `pairsum bench`: the closure backend against a hand-written native Rust implementation of the
//! same fused step — continuity (EK18 Eq 2), velocity gradient (Eq 7, 9), momentum with
//! Monaghan–Gingold viscosity (Eq 10–11), Jaumann (Eq 5), Wendland C2 — on the same data layout
//! (the particle store's columns), the same cell list and the same parallel chunks, on a 3D
//! elastic block. Ratios are measured in one run.

use crate::backend::cpu::CpuBackend;
use crate::backend::{Backend, Globals};
use crate::check::{check_stdlib_modules, Stdlib};
use crate::diag::Sources;
use crate::engine::setup::{build_store, MaterialInput, ParticleInput};
use crate::grid::Grid;
use crate::ir::FieldId;
use crate::particles::Store;
use crate::schedule::{IntegratorKind, Plan, SceneSpec};
use rayon::prelude::*;
use std::time::Instant;

/// The elastic model and a cubic block of about `n` particles with non-trivial velocity and stress.
pub fn elastic_block(n: usize) -> Result<CpuBackend<f64>, String> {
    let (plan, store) = elastic_store::<f64>(n)?;
    let mut b = CpuBackend::new(plan, store, vec![]).map_err(|e| e.0)?;
    b.initialise().map_err(|e| e.0)?;
    b.reorder().map_err(|e| e.0)?;
    Ok(b)
}

/// The same block on the GPU (f32), if an adapter is found.
pub fn elastic_block_gpu(n: usize) -> Result<crate::backend::gpu::GpuBackend, String> {
    let gpu = crate::backend::gpu::device::Gpu::new().map_err(|e| e.to_string())?;
    let (plan, store) = elastic_store::<f32>(n)?;
    let mut b = crate::backend::gpu::GpuBackend::new(gpu, plan, store, &[]).map_err(|e| e.0)?;
    b.initialise().map_err(|e| e.0)?;
    b.reorder().map_err(|e| e.0)?;
    Ok(b)
}

fn elastic_store<T: crate::particles::Real>(n: usize) -> Result<(Plan, Store<T>), String> {
    let mut sources = Sources::new();
    let checked = check_stdlib_modules(&mut sources, &["models/elastic_solid.sph"], Stdlib::locate());
    if checked.has_errors() {
        return Err(crate::diag::render(&sources, &checked.diags));
    }
    let model = checked.model;
    let side = (n as f64).cbrt().round().max(2.0) as usize;
    let dx = 0.01;
    let mut input = ParticleInput::default();
    let mut seed = 0x9e3779b97f4a7c15u64;
    let mut rnd = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed % 1_000_000) as f64 / 1_000_000.0 - 0.5
    };
    for k in 0..side {
        for j in 0..side {
            for i in 0..side {
                let p = [(i as f64 + 0.5) * dx, (j as f64 + 0.5) * dx, (k as f64 + 0.5) * dx];
                input.x.push([p[0] + 0.05 * dx * rnd(), p[1] + 0.05 * dx * rnd(), p[2] + 0.05 * dx * rnd()]);
                input.v.push([rnd(), rnd(), rnd() + 2.0 * p[0]]);
                input.vol.push(dx * dx * dx);
                input.dx.push(dx);
                input.body.push(0);
                input.part.push(-1);
                input.group.push(0);
                input.material.push(0);
            }
        }
    }
    let p = |name: &str| model.param_id(name).expect("elastic_solid parameter");
    let mut mat = MaterialInput { name: "steel".into(), ..Default::default() };
    for (name, v) in [("rho0", 7850.0), ("E", 200e9), ("nu", 0.3), ("h_ratio", 1.3)] {
        mat.values.insert(p(name), vec![v]);
    }
    let scene = SceneSpec {
        dim: 3,
        groups: model.all_groups(),
        outputs: vec![],
        integrator: IntegratorKind::Euler,
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
    let plan = Plan::build(&model, &scene, None).map_err(|e| e.to_string())?;
    let mut store: Store<T> = build_store(&plan, &input, &[mat]).map_err(|e| e.to_string())?;
    // A non-trivial stress state.
    let s = plan.model.field_id("s").expect("s");
    if let Some(col) = store.column_mut(s) {
        for (k, v) in col.data.iter_mut().enumerate() {
            *v = T::from_f64(1e6 * ((k * 7919 % 1000) as f64 / 1000.0 - 0.5));
        }
    }
    Ok((plan, store))
}

/// Outputs of the native step, per particle (same layouts as the store).
pub struct NativeOut {
    pub drho: Vec<f64>,
    pub edot: Vec<f64>,
    pub spin: Vec<f64>,
    pub dv: Vec<f64>,
    pub ds: Vec<f64>,
}

fn col<'a>(b: &'a CpuBackend<f64>, name: &str) -> &'a [f64] {
    let f: FieldId = b.plan.model.field_id(name).expect("field");
    &b.store.column(f).expect("stored").data
}

fn param(b: &CpuBackend<f64>, name: &str) -> f64 {
    let p = b.plan.model.param_id(name).expect("param");
    b.store.params.get(0, p, 0)
}

/// The fused step written by hand: one neighbour loop per particle, everything in registers.
pub fn native_step(b: &CpuBackend<f64>, grid: &Grid) -> NativeOut {
    let (x, v, m, rho, h) = (col(b, "x"), col(b, "v"), col(b, "m"), col(b, "rho"), col(b, "h"));
    let (s, p, c) = (col(b, "s"), col(b, "p"), col(b, "c"));
    let g_mod = param(b, "G");
    let (va, vb, eta_ratio) = (param(b, "visc_a"), param(b, "visc_b"), param(b, "eta_ratio"));
    let n = m.len();
    let norm = 21.0 / (16.0 * std::f64::consts::PI);
    let support = 2.0;
    let mut out = NativeOut {
        drho: vec![0.0; n],
        edot: vec![0.0; 6 * n],
        spin: vec![0.0; 3 * n],
        dv: vec![0.0; 3 * n],
        ds: vec![0.0; 6 * n],
    };
    let order = grid.order();
    let chunks: Vec<(usize, usize)> = (0..n).step_by(64).map(|s| (s, (s + 64).min(n))).collect();
    let results: Vec<Vec<[f64; 19]>> = chunks
        .par_iter()
        .map(|&(a, z)| {
            let mut ranges = vec![];
            (a..z)
                .map(|i| {
                    let xi = [x[3 * i], x[3 * i + 1], x[3 * i + 2]];
                    let vi = [v[3 * i], v[3 * i + 1], v[3 * i + 2]];
                    let si = sym(&s[6 * i..6 * i + 6]);
                    let (rhoi, pi, ci, hi) = (rho[i], p[i], c[i], h[i]);
                    let ai = add_diag(scale(si, 1.0 / (rhoi * rhoi)), -pi / (rhoi * rhoi));
                    let mut div_v = 0.0;
                    let mut grad_v = [[0.0; 3]; 3];
                    let mut acc = [0.0; 3];
                    grid.cell_ranges_around(xi, &mut ranges);
                    for &(lo, hi_r) in &ranges {
                        for &jj in &order[lo as usize..hi_r as usize] {
                            let j = jj as usize;
                            if j == i {
                                continue;
                            }
                            let d = [xi[0] - x[3 * j], xi[1] - x[3 * j + 1], xi[2] - x[3 * j + 2]];
                            let r2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
                            let hij = 0.5 * (hi + h[j]);
                            let rc = support * hij;
                            if r2 >= rc * rc || r2 == 0.0 {
                                continue;
                            }
                            let r = r2.sqrt();
                            let big_r = r / hij;
                            let t = 1.0 - 0.5 * big_r;
                            let dw = -5.0 * big_r * t * t * t;
                            let f = norm / (hij * hij * hij * hij) * dw / r;
                            let gw = [f * d[0], f * d[1], f * d[2]];
                            let vol_j = m[j] / rho[j];
                            let vij = [vi[0] - v[3 * j], vi[1] - v[3 * j + 1], vi[2] - v[3 * j + 2]];
                            div_v += vol_j * (vij[0] * gw[0] + vij[1] * gw[1] + vij[2] * gw[2]);
                            for a in 0..3 {
                                for bb in 0..3 {
                                    grad_v[a][bb] -= vol_j * vij[a] * gw[bb];
                                }
                            }
                            // Monaghan–Gingold viscosity
                            let vr = vij[0] * d[0] + vij[1] * d[1] + vij[2] * d[2];
                            let eta = eta_ratio * hij;
                            let phi = hij * vr / (r2 + eta * eta);
                            let visc = if vr < 0.0 {
                                (-va * 0.5 * (ci + c[j]) * phi + vb * phi * phi) / (0.5 * (rhoi + rho[j]))
                            } else {
                                0.0
                            };
                            // (σ_i/ρ_i² + σ_j/ρ_j² − Π I) ∇W, with σ = s − p I, written out
                            let sj = &s[6 * j..6 * j + 6];
                            let rj2 = 1.0 / (rho[j] * rho[j]);
                            let diag = -p[j] * rj2 - visc;
                            let b00 = ai[0][0] + sj[0] * rj2 + diag;
                            let b01 = ai[0][1] + sj[1] * rj2;
                            let b02 = ai[0][2] + sj[2] * rj2;
                            let b11 = ai[1][1] + sj[3] * rj2 + diag;
                            let b12 = ai[1][2] + sj[4] * rj2;
                            let b22 = ai[2][2] + sj[5] * rj2 + diag;
                            let mj = m[j];
                            acc[0] += mj * (b00 * gw[0] + b01 * gw[1] + b02 * gw[2]);
                            acc[1] += mj * (b01 * gw[0] + b11 * gw[1] + b12 * gw[2]);
                            acc[2] += mj * (b02 * gw[0] + b12 * gw[1] + b22 * gw[2]);
                        }
                    }
                    // finally: continuity; tail: Jaumann
                    let e = symm(&grad_v);
                    let w = skew(&grad_v);
                    let tr = (e[0][0] + e[1][1] + e[2][2]) / 3.0;
                    let mut rot = [[0.0; 3]; 3];
                    for a in 0..3 {
                        for bb in 0..3 {
                            for k in 0..3 {
                                // s ωᵀ + ω s
                                rot[a][bb] += si[a][k] * w[bb][k] + w[a][k] * si[k][bb];
                            }
                        }
                    }
                    let rot = symm(&rot);
                    let mut ds = [[0.0; 3]; 3];
                    for a in 0..3 {
                        for bb in 0..3 {
                            ds[a][bb] = 2.0 * g_mod * (e[a][bb] - if a == bb { tr } else { 0.0 }) + rot[a][bb];
                        }
                    }
                    let mut o = [0.0; 19];
                    o[0] = rhoi * div_v;
                    o[1..7].copy_from_slice(&upper(&e));
                    o[7..10].copy_from_slice(&[w[0][1], w[0][2], w[1][2]]);
                    o[10..13].copy_from_slice(&acc);
                    o[13..19].copy_from_slice(&upper(&ds));
                    o
                })
                .collect()
        })
        .collect();
    for (k, o) in results.into_iter().flatten().enumerate() {
        out.drho[k] = o[0];
        out.edot[6 * k..6 * k + 6].copy_from_slice(&o[1..7]);
        out.spin[3 * k..3 * k + 3].copy_from_slice(&o[7..10]);
        out.dv[3 * k..3 * k + 3].copy_from_slice(&o[10..13]);
        out.ds[6 * k..6 * k + 6].copy_from_slice(&o[13..19]);
    }
    out
}

type M3 = [[f64; 3]; 3];

fn sym(s: &[f64]) -> M3 {
    [[s[0], s[1], s[2]], [s[1], s[3], s[4]], [s[2], s[4], s[5]]]
}
fn upper(m: &M3) -> [f64; 6] {
    [m[0][0], m[0][1], m[0][2], m[1][1], m[1][2], m[2][2]]
}
fn scale(m: M3, f: f64) -> M3 {
    m.map(|r| r.map(|x| x * f))
}
fn add_diag(mut a: M3, d: f64) -> M3 {
    for (k, row) in a.iter_mut().enumerate() {
        row[k] += d;
    }
    a
}
fn symm(a: &M3) -> M3 {
    let mut o = [[0.0; 3]; 3];
    for r in 0..3 {
        for c in 0..3 {
            o[r][c] = 0.5 * (a[r][c] + a[c][r]);
        }
    }
    o
}
fn skew(a: &M3) -> M3 {
    let mut o = [[0.0; 3]; 3];
    for r in 0..3 {
        for c in 0..3 {
            o[r][c] = 0.5 * (a[r][c] - a[c][r]);
        }
    }
    o
}

/// Largest relative difference between the closure backend's fields and the native ones (each
/// over the larger magnitude of the two); an error naming the field where a value is not finite
/// or the lengths differ.
pub fn compare(b: &CpuBackend<f64>, native: &NativeOut) -> Result<f64, String> {
    let mut worst: f64 = 0.0;
    for (name, ours) in
        [("drho", &native.drho), ("edot", &native.edot), ("spin", &native.spin), ("dv", &native.dv), ("ds", &native.ds)]
    {
        let d = crate::compare::max_rel_diff(ours, col(b, name)).map_err(|e| format!("`{name}`: {e}"))?;
        worst = worst.max(d);
    }
    Ok(worst)
}

fn time<R>(f: impl FnMut() -> R, reps: usize) -> f64 {
    let mut f = f;
    let mut best = f64::INFINITY;
    for _ in 0..reps {
        let t = Instant::now();
        std::hint::black_box(f());
        best = best.min(t.elapsed().as_secs_f64());
    }
    best
}

/// Runs the comparison at the given sizes and returns the printed table.
pub fn run(sizes: &[usize], reps: usize) -> Result<String, String> {
    let mut out = String::new();
    out.push_str(&format!(
        "pairsum bench: fused continuity + velocity gradient + momentum (MG viscosity) + Jaumann, 3D, f64, {} threads, {} lanes{}\n",
        rayon::current_num_threads(),
        crate::backend::cpu::BATCH_LANES,
        if crate::backend::cpu::program::wide_simd() { ", AVX2 lane loops" } else { "" }
    ));
    out.push_str(
        "particles   generated [ms]  closures [ms]  hand-written [ms]  generated/hand-written  closures/hand-written  steps/s (generated)  max rel diff  steps/s (gpu, f32)\n",
    );
    for &n in sizes {
        let mut b = elastic_block(n)?;
        let mut closures = elastic_block(n)?.without_jit();
        let h_max = crate::compare::max_abs(col(&b, "h")).map_err(|e| format!("h: {e}"))?;
        let cell = b.support * h_max;
        // Interleaved, best of `reps` each: the machine's load drifts between measurements.
        let (mut t_grid, mut t_native, mut t_closure) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
        let mut t_lanes = f64::INFINITY;
        for _ in 0..reps {
            t_grid = t_grid.min(time(|| Grid::build(col(&b, "x"), 3, cell), 1));
            let grid = Grid::build(col(&b, "x"), 3, cell);
            t_native = t_native.min(time(|| native_step(&b, &grid), 1));
            t_closure = t_closure.min(time(|| b.evaluate(Globals::default()), 1));
            t_lanes = t_lanes.min(time(|| closures.evaluate(Globals::default()), 1));
        }
        let grid = Grid::build(col(&b, "x"), 3, cell);
        let native = native_step(&b, &grid);
        b.evaluate(Globals::default()).map_err(|e| e.0)?;
        let diff =
            compare(&b, &native).map_err(|e| format!("{n} particles, generated code against hand-written: {e}"))?;
        let gpu = match elastic_block_gpu(n) {
            Ok(mut g) => {
                let mut best = f64::INFINITY;
                for _ in 0..reps {
                    let t = Instant::now();
                    g.evaluate(Globals::default()).map_err(|e| e.0)?;
                    g.gpu().wait().map_err(|e| e.to_string())?;
                    best = best.min(t.elapsed().as_secs_f64());
                }
                format!("{:.1} ({})", 1.0 / best, g.describe())
            }
            Err(e) => format!("- ({})", e.lines().next().unwrap_or_default()),
        };
        let hand = t_native + t_grid;
        out.push_str(&format!(
            "{:>9}   {:>14.2}  {:>13.2}  {:>17.2}  {:>22.2}  {:>21.2}  {:>19.1}  {:>12.1e}  {gpu}\n",
            b.particles(),
            1e3 * t_closure,
            1e3 * t_lanes,
            1e3 * hand,
            t_closure / hand,
            t_lanes / hand,
            1.0 / t_closure,
            diff
        ));
    }
    out.push_str(
        "(generated: native pair programs (C, or Cranelift without a C compiler); closures: the same programs as closures; both include their cell-list build, \
         and the hand-written step adds the same build; one evaluation per step)\n",
    );
    Ok(out)
}
