//! Neighbour lists kept across evaluations: the Verlet lists never miss a pair under their
//! conservative bound (checked against brute force while particles move, smoothing lengths grow,
//! mirrors reflect and the store is reordered), a case gives the cell search's result with them,
//! and the F-ANS adaptive search rebuilds what its threshold says.

mod common;

use common::{max_abs, max_abs_diff, rnd};
use pairsum::backend::cpu::lists::{beyond_reach, transformed, BuildInput, Lists, INDEX_MASK, TRANSFORM_SHIFT};
use pairsum::backend::cpu::CpuBackend;
use pairsum::backend::{Backend, Mirror};
use pairsum::engine::{setup, Engine};
use pairsum::ir::FieldId;
use pairsum::runner::prepare;
use pairsum::schedule::Search;
use std::collections::HashSet;
use std::path::PathBuf;

const SUPPORT: f64 = 2.0;

/// Every (i, j, transform) within the cut-off support · (h_i + h_j)/2, by brute force.
fn pairs_within(x: &[f64], h: &[f64], dim: usize, mirrors: &[Mirror]) -> Vec<(usize, u32)> {
    let n = h.len();
    let mut out = vec![];
    for i in 0..n {
        let mut xi = [0.0; 3];
        xi[..dim].copy_from_slice(&x[i * dim..(i + 1) * dim]);
        for t in 0..1u32 << mirrors.len() {
            // Both sides of a periodic axis move i nowhere: no transform (at any distance).
            if beyond_reach(xi, t, mirrors, f64::INFINITY) {
                continue;
            }
            let (yi, _) = transformed(xi, t, mirrors);
            for j in 0..n {
                if t == 0 && j == i {
                    continue;
                }
                let r2: f64 = (0..dim).map(|c| (yi[c] - x[j * dim + c]).powi(2)).sum();
                let rc = SUPPORT * 0.5 * (h[i] + h[j]);
                if r2 < rc * rc && r2 != 0.0 {
                    out.push((i, j as u32 | t << TRANSFORM_SHIFT));
                }
            }
        }
    }
    out
}

fn missed(lists: &Lists<f64>, x: &[f64], h: &[f64], dim: usize, mirrors: &[Mirror]) -> usize {
    let sets: Vec<HashSet<u32>> = lists.of.iter().map(|l| l.iter().copied().collect()).collect();
    pairs_within(x, h, dim, mirrors).into_iter().filter(|(i, e)| !sets[*i].contains(e)).count()
}

#[test]
fn verlet_lists_never_miss_a_pair_under_the_conservative_bound() {
    verlet_lists_never_miss(|dim| (0..dim.min(2)).map(|axis| Mirror::symmetry(axis, 0.0)).collect(), 30);
}

/// The same across periodic sides: the last axis periodic over [0, 1), beside a symmetry plane
/// on x in 2D and 3D; particles that leave the domain come back at the other side. Each such jump
/// rebuilds every list, so the lists are kept over fewer steps here (in 3D 31 builds in 60).
#[test]
fn verlet_lists_never_miss_a_pair_across_periodic_sides() {
    let planes = |dim| {
        let mut planes: Vec<Mirror> = if dim > 1 { vec![Mirror::symmetry(0, 0.0)] } else { vec![] };
        planes.extend(Mirror::periodic(dim - 1, 0.0, 1.0));
        planes
    };
    verlet_lists_never_miss(planes, 45);
}

/// Lists kept over 60 steps of a moving, growing, reordered cloud miss no pair a brute-force
/// search over every image finds; they are rebuilt more than twice and fewer than `max_builds`
/// times, so they were kept across steps.
fn verlet_lists_never_miss(planes: impl Fn(usize) -> Vec<Mirror>, max_builds: u64) {
    for dim in 1..=3 {
        let mirrors = planes(dim);
        let n = [60, 200, 400][dim - 1];
        let mut seed = 7 + dim as u64;
        // A cloud on the positive side of the mirrors, 1 unit across, h ≈ 0.1–0.15.
        let mut x: Vec<f64> = (0..n * dim).map(|_| rnd(&mut seed)).collect();
        let mut h: Vec<f64> = (0..n).map(|_| 0.1 + 0.05 * rnd(&mut seed)).collect();
        let mut v: Vec<f64> = (0..n * dim).map(|_| 0.005 * (rnd(&mut seed) - 0.5)).collect();
        let search = Search::Verlet { skin: 0.1 };
        let mut lists = Lists::default();
        let no_field = |_: FieldId| -> Vec<f64> { unreachable!("Verlet lists read no field") };
        let steps = 60u64;
        for step in 0..steps {
            let h_max = max_abs("h", &h);
            let inp = BuildInput { x: &x, h: &h, dim, support: SUPPORT, h_max, mirrors: &mirrors, sources: None };
            lists.prepare(&search, &inp, no_field);
            assert_eq!(missed(&lists, &x, &h, dim, &mirrors), 0, "{dim}D, step {step}: a pair is missing");
            // Move, grow some smoothing lengths, and reorder the store now and then.
            for (k, (p, u)) in x.iter_mut().zip(v.iter_mut()).enumerate() {
                *p += *u;
                // As the engine does: a particle that crosses a mirror comes back, reflected; one
                // that leaves a periodic domain comes back at its other side.
                let axis = k % dim;
                if let Some(m) = mirrors.iter().find(|m| m.axis == axis && m.shift > 0.0) {
                    if *p >= m.offset + m.shift {
                        *p -= m.shift;
                    } else if *p < m.offset {
                        *p += m.shift;
                    }
                } else if mirrors.iter().any(|m| m.axis == axis) && *p < 0.0 {
                    (*p, *u) = (-*p, -*u);
                }
            }
            for (k, hk) in h.iter_mut().enumerate() {
                if k as u64 % 7 == step % 7 {
                    *hk *= 1.004;
                }
            }
            if step % 13 == 12 {
                let mut perm: Vec<u32> = (0..n as u32).collect();
                for k in (1..n).rev() {
                    perm.swap(k, (rnd(&mut seed) * (k + 1) as f64) as usize % (k + 1));
                }
                x = perm.iter().flat_map(|p| x[*p as usize * dim..(*p as usize + 1) * dim].to_vec()).collect();
                h = perm.iter().map(|p| h[*p as usize]).collect();
                v = perm.iter().flat_map(|p| v[*p as usize * dim..(*p as usize + 1) * dim].to_vec()).collect();
                lists.permute(&perm);
            }
        }
        let s = lists.stats;
        assert_eq!(s.evaluations, steps);
        // The test means something only if lists were kept across steps and rebuilt too.
        assert!(
            s.full_builds > 2 && s.full_builds < max_builds,
            "{dim}D: {} full builds in {steps} steps",
            s.full_builds
        );
        // Entries name particles of the store, and the lists are not empty.
        let listed: usize = lists.of.iter().map(|l| l.len()).sum();
        assert!(lists.of.iter().flatten().all(|e| (e & INDEX_MASK) < n as u32));
        assert!(listed > 0);
    }
}

/// Lists hold only the groups some pass reads neighbours from on a particle's group: in a cloud of
/// three groups, where group 0 reads 0 and 1, group 1 reads 0 only (a wall that takes from the
/// fluid) and group 2 nothing, every pair brute force finds within those groups is listed and no
/// other.
#[test]
fn lists_hold_every_neighbour_of_the_groups_a_pass_reads_from_and_no_other() {
    let (dim, n) = (2, 300);
    let mut seed = 11;
    let x: Vec<f64> = (0..n * dim).map(|_| rnd(&mut seed)).collect();
    let h: Vec<f64> = (0..n).map(|_| 0.1 + 0.05 * rnd(&mut seed)).collect();
    let group: Vec<u32> = (0..n as u32).map(|i| i % 3).collect();
    let sources = [0b011u64, 0b001, 0b000];
    let mut lists = Lists::default();
    let inp = BuildInput {
        x: &x,
        h: &h,
        dim,
        support: SUPPORT,
        h_max: max_abs("h", &h),
        mirrors: &[],
        sources: Some((&group, &sources)),
    };
    lists.prepare(&Search::Verlet { skin: 0.1 }, &inp, |_| unreachable!("Verlet lists read no field"));
    let wanted = |i: usize, e: u32| sources[group[i] as usize] >> group[(e & INDEX_MASK) as usize] & 1 == 1;
    let sets: Vec<HashSet<u32>> = lists.of.iter().map(|l| l.iter().copied().collect()).collect();
    let within = pairs_within(&x, &h, dim, &[]);
    let missed = within.iter().filter(|(i, e)| wanted(*i, *e) && !sets[*i].contains(e)).count();
    assert_eq!(missed, 0, "pairs of the groups read from that no list holds");
    let unwanted: Vec<(usize, u32)> = lists
        .of
        .iter()
        .enumerate()
        .flat_map(|(i, l)| l.iter().map(move |e| (i, *e)))
        .filter(|(i, e)| !wanted(*i, *e))
        .collect();
    assert!(unwanted.is_empty(), "entries of groups no pass reads from: {:?}", &unwanted[..unwanted.len().min(5)]);
    // Group 1's lists hold group 0's neighbours: the filter keeps what it must.
    assert!((0..n).filter(|i| group[*i] == 1).all(|i| !lists.of[i].is_empty()));
}

fn case(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("cases").join(format!("{name}.toml"))
}

fn bullet(search: Search) -> Engine<CpuBackend<f64>> {
    let (scene, mut plan) = prepare(&case("fans_bullet"), &Default::default()).unwrap_or_else(|e| panic!("{e}"));
    plan.search = search;
    let store = setup::build_store::<f64>(&plan, &scene.particles, &scene.materials).expect("store");
    let b = CpuBackend::new(plan, store, scene.mirrors.clone()).expect("backend");
    let mut e = Engine::new(b, scene.config.clone());
    e.initialise().expect("initialise");
    e
}

fn eps_p(e: &Engine<CpuBackend<f64>>) -> FieldId {
    e.backend.plan().model.field_id("eps_p").expect("eps_p")
}

#[test]
fn verlet_lists_give_the_cell_search_result_on_the_bullet_case() {
    // 150 steps of the bullet entering the plate (six Morton reorders on the way): the same pairs
    // in a different order, so the states agree to rounding.
    let mut cells = bullet(Search::Cells);
    let mut verlet = bullet(Search::Verlet { skin: 0.1 });
    for _ in 0..150 {
        cells.step().expect("cells step");
        verlet.step().expect("verlet step");
    }
    assert!((cells.time - verlet.time).abs() <= 1e-9 * cells.time, "{} vs {}", cells.time, verlet.time);
    let (a, b) = (cells.backend.snapshot().expect("snapshot"), verlet.backend.snapshot().expect("snapshot"));
    assert_eq!(a.id, b.id, "the same particle order");
    let model = &cells.backend.plan().model;
    for name in ["x", "v", "rho", "s", "eps_p"] {
        let f = model.field_id(name).expect("field").index();
        let (p, q) = (a.columns[f].as_ref().expect("stored"), b.columns[f].as_ref().expect("stored"));
        let scale = max_abs(&format!("{name} with the cell search"), p);
        let diff = max_abs_diff(&format!("{name}, cell search against Verlet lists"), p, q);
        assert!(diff <= 1e-9 * scale, "{name}: differs by {diff:e} (scale {scale:e})");
    }
    let stats = verlet.backend.search_stats();
    // Two a step, and one before the first step (every field valid at t = 0).
    assert_eq!(stats.evaluations, 301);
    assert!(stats.full_builds > 1 && stats.full_builds < 150, "{} full builds", stats.full_builds);
    // The plastic zone formed: the comparison covers plastic flow, not only elastic waves.
    let (_, plastic) = verlet.backend.read(eps_p(&verlet)).expect("read").expect("stored");
    assert!(plastic.iter().any(|e| *e > 0.01));
}

#[test]
fn the_adaptive_search_rebuilds_the_lists_its_threshold_picks() {
    let (_, plan) = prepare(&case("fans_bullet"), &Default::default()).unwrap_or_else(|e| panic!("{e}"));
    let field = plan.model.field_id("eps_p").expect("eps_p");
    let run = |threshold: f64| {
        let mut e = bullet(Search::Adaptive { field, field_name: "eps_p".into(), threshold, skin: 0.0 });
        for _ in 0..100 {
            e.step().expect("step");
        }
        let (_, plastic) = e.backend.read(field).expect("read").expect("stored");
        (e.backend.search_stats(), plastic.iter().filter(|p| **p > 1e-3).count())
    };
    // Step 0 only: one build, nothing after.
    let (never, _) = run(f64::INFINITY);
    assert_eq!((never.full_builds, never.particle_rebuilds, never.evaluations), (1, 0, 201));
    // A tiny threshold rebuilds the plastic particles, over and over; a large one fewer times.
    let (often, plastic) = run(1e-6);
    let (rarely, _) = run(1e-2);
    assert_eq!(often.full_builds, 1);
    assert!(plastic > 0);
    assert!(often.particle_rebuilds >= plastic as u64, "{} rebuilds, {plastic} plastic", often.particle_rebuilds);
    assert!(rarely.particle_rebuilds < often.particle_rebuilds / 2);
}
