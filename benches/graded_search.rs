//! The cell search on a graded scene: the Børvik 12 mm plate at 1 mm near the axis, 4 mm beyond
//! (a quarter: projectile ∅20 × 80 mm and plate r = 256 mm, 1 mm within 24 mm of the axis),
//! about the 21,800 particles of `docs/results/borvik_12mm_refined_1mm/` (dropped in stop 104:
//! `git show e77815e5:docs/results/borvik_12mm_refined_1mm/303.5/report.md`).
//!
//! Each variant walks every particle's candidates and keeps the pairs within
//! `support · (h_i + h_j)/2`, as the CPU backend's cell walk does, and must find the same pairs:
//! - `whole-scene bound`: every particle searches `support · (h_i + h_max)/2` (before stop 30);
//! - `nearby bound`: it searches `support · (h_i + h_near_i)/2`, `h_near` from
//!   [`Grid::nearby_max`], its cost included (stop 30);
//! - `size levels`: a grid per particle size, each of cells of half its largest cut-off over its
//!   own particles' box ([`SizeLevels`]), searched only where the nearby bound reaches it: what
//!   the CPU backend does since stop 31.
//!
//! It prints the time per sweep, the ratios to the first, measured in this run, and the
//! candidates visited per pair found. The sweep only counts pairs; what the backend's whole step
//! gains on the case itself is in `docs/ARCHITECTURE.md` ("The CPU cell list").
//!
//! `cargo bench --bench graded_search`

use criterion::{criterion_group, criterion_main, Criterion};
use pairsum::grid::{Grid, Level, SizeLevels};
use std::hint::black_box;
use std::time::{Duration, Instant};

const SUPPORT: f64 = 2.0;
const H_OVER_DX: f64 = 1.3;

/// Lattice nodes of spacing `dx` in the quarter cylinder `r < r_max` (and `r >= r_min`), with z
/// in `[z0, z0 + length)`.
fn quarter_cylinder(dx: f64, r_min: f64, r_max: f64, z0: f64, length: f64, x: &mut Vec<f64>, h: &mut Vec<f64>) {
    let n_r = (r_max / dx).ceil() as usize;
    let n_z = (length / dx).round() as usize;
    for k in 0..n_z {
        for j in 0..n_r {
            for i in 0..n_r {
                let p = [(i as f64 + 0.5) * dx, (j as f64 + 0.5) * dx, z0 + (k as f64 + 0.5) * dx];
                let r = p[0].hypot(p[1]);
                if r < r_max && r >= r_min {
                    x.extend_from_slice(&p);
                    h.push(H_OVER_DX * dx);
                }
            }
        }
    }
}

/// The graded quarter scene: positions (x, y, z interleaved) and smoothing lengths.
fn borvik_12mm_1mm() -> (Vec<f64>, Vec<f64>) {
    let (mut x, mut h) = (vec![], vec![]);
    let (fine, coarse, t) = (1e-3, 4e-3, 12e-3);
    quarter_cylinder(fine, 0.0, 10e-3, 3e-3, 80e-3, &mut x, &mut h); // projectile, 3 mm above
    quarter_cylinder(fine, 0.0, 24e-3, -t, t, &mut x, &mut h); // plate near the axis
    quarter_cylinder(coarse, 24e-3, 256e-3, -t, t, &mut x, &mut h); // plate beyond
    (x, h)
}

/// Whether candidate j is a neighbour of particle i, at `p`.
fn is_pair(x: &[f64], h: &[f64], i: usize, p: [f64; 3], j: usize) -> bool {
    let d2 = (0..3).map(|c| (x[3 * j + c] - p[c]).powi(2)).sum::<f64>();
    let cut = SUPPORT * 0.5 * (h[i] + h[j]);
    j != i && d2 < cut * cut
}

/// Of the candidates in `ranges` of `order`: (pairs with i, candidates).
fn count_pairs(x: &[f64], h: &[f64], i: usize, p: [f64; 3], order: &[u32], ranges: &[(u32, u32)]) -> (usize, usize) {
    let (mut pairs, mut candidates) = (0, 0);
    for &(s, e) in ranges {
        for &j in &order[s as usize..e as usize] {
            candidates += 1;
            pairs += is_pair(x, h, i, p, j as usize) as usize;
        }
    }
    (pairs, candidates)
}

/// One sweep over every particle of one grid; returns (pairs found, candidates visited).
fn sweep(x: &[f64], h: &[f64], grid: &Grid, reach_h: &dyn Fn(usize) -> f64) -> (usize, usize) {
    let (mut pairs, mut candidates) = (0, 0);
    let mut ranges = Vec::new();
    for i in 0..h.len() {
        let p = [x[3 * i], x[3 * i + 1], x[3 * i + 2]];
        grid.cell_ranges_within(p, SUPPORT * 0.5 * (h[i] + reach_h(i)), &mut ranges);
        let (found, seen) = count_pairs(x, h, i, p, grid.order(), &ranges);
        pairs += found;
        candidates += seen;
    }
    (pairs, candidates)
}

/// Before stop 30: cells of half the largest cut-off, every particle searching as far as the
/// coarsest particle's cut-off needs.
fn whole_scene_bound(x: &[f64], h: &[f64], h_max: f64) -> (usize, usize) {
    let grid = Grid::build(x, 3, 0.5 * SUPPORT * h_max);
    sweep(x, h, &grid, &|_| h_max)
}

/// Stop 30: the same cells, each particle searching only as far as the largest h near it needs.
fn nearby_bound(x: &[f64], h: &[f64], h_max: f64) -> (usize, usize) {
    let grid = Grid::build(x, 3, 0.5 * SUPPORT * h_max);
    let h_near = Grid::nearby_max(x, 3, h, SUPPORT * h_max);
    sweep(x, h, &grid, &|i| h_near[i])
}

/// The backend now: a grid per particle size ([`SizeLevels`]), each searched as far as its
/// largest h and the nearby bound need.
fn size_levels(x: &[f64], h: &[f64], h_max: f64) -> (usize, usize) {
    let levels = SizeLevels::build(x, 3, h, SUPPORT, 0.0);
    let h_near = Grid::nearby_max(x, 3, h, SUPPORT * h_max);
    let (mut pairs, mut candidates) = (0, 0);
    let mut ranges = Vec::new();
    for i in 0..h.len() {
        let p = [x[3 * i], x[3 * i + 1], x[3 * i + 2]];
        let reach = |level: &Level| level.reach(SUPPORT, h[i], h_near[i], 0.0);
        levels.for_each_candidate(p, reach, &mut ranges, |j| {
            candidates += 1;
            pairs += is_pair(x, h, i, p, j as usize) as usize;
        });
    }
    (pairs, candidates)
}

/// Mean seconds per call over `runs` calls.
fn seconds_per_call(runs: usize, mut f: impl FnMut() -> (usize, usize)) -> f64 {
    let start = Instant::now();
    for _ in 0..runs {
        black_box(f());
    }
    start.elapsed().as_secs_f64() / runs as f64
}

type Search = fn(&[f64], &[f64], f64) -> (usize, usize);

fn bench(c: &mut Criterion) {
    let (x, h) = borvik_12mm_1mm();
    let h_max = h.iter().cloned().fold(0.0, f64::max);
    let searches: [(&str, Search); 3] =
        [("whole_scene_bound", whole_scene_bound), ("nearby_bound", nearby_bound), ("size_levels", size_levels)];

    // Plain figures first, from this run, independent of criterion's report.
    let runs = 5;
    let (pairs, _) = whole_scene_bound(&x, &h, h_max);
    println!("graded scene, {} particles, {pairs} pairs (one thread, mean of {runs} sweeps):", h.len());
    let mut first = None;
    for (name, search) in searches {
        let (found, candidates) = search(&x, &h, h_max);
        assert_eq!(found, pairs, "{name} must find every pair");
        let t = seconds_per_call(runs, || search(&x, &h, h_max));
        let base = *first.get_or_insert(t);
        println!(
            "  {name:<18} {:6.1} ms  {:5.1} candidates per pair  {:.2}x the whole-scene bound's speed",
            t * 1e3,
            candidates as f64 / pairs as f64,
            base / t
        );
    }

    let mut group = c.benchmark_group("graded_search");
    group.sample_size(10).warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3));
    for (name, search) in searches {
        group.bench_function(name, |b| b.iter(|| search(black_box(&x), &h, h_max)));
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
