//! The CPU neighbour grid against brute force: random clouds (uniform and variable h), lattices
//! on cell boundaries, far debris and NaNs, Morton reordering, and the range API.

use pairsum::grid::{
    apply_permutation, max_cells, morton_code, morton_codes, morton_permutation, point_of, Coord, Grid, Level,
    SizeLevels,
};

/// Kernel support in units of h: a pair interacts when `r < SUPPORT * (h_i + h_j) / 2`.
const SUPPORT: f64 = 2.0;

struct XorShift(u64);

impl XorShift {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
}

fn cloud(rng: &mut XorShift, n: usize, dim: usize, side: f64) -> Vec<f64> {
    (0..n * dim).map(|_| rng.range(-0.5 * side, 0.5 * side)).collect()
}

fn interacts<T: Coord>(x: &[T], dim: usize, h: &[f64], i: usize, j: usize) -> bool {
    let (a, b) = (point_of(x, dim, i), point_of(x, dim, j));
    let r2: f64 = (0..dim).map(|k| (a[k] - b[k]).powi(2)).sum();
    r2.sqrt() < SUPPORT * (h[i] + h[j]) / 2.0
}

fn brute_force<T: Coord>(x: &[T], dim: usize, h: &[f64]) -> Vec<(u32, u32)> {
    let n = h.len();
    let mut pairs = Vec::new();
    for i in 0..n {
        for j in 0..n {
            if i != j && interacts(x, dim, h, i, j) {
                pairs.push((i as u32, j as u32));
            }
        }
    }
    pairs
}

fn h_max(h: &[f64]) -> f64 {
    pairsum::compare::max_abs(h).expect("finite smoothing lengths")
}

/// Pairs found through `for_each_candidate`, sorted; panics if a candidate comes twice.
fn via_grid<T: Coord>(grid: &Grid, x: &[T], dim: usize, h: &[f64]) -> Vec<(u32, u32)> {
    let mut pairs = Vec::new();
    let mut seen = vec![false; h.len()];
    for i in 0..h.len() {
        let mut cands = Vec::new();
        grid.for_each_candidate(point_of(x, dim, i), |j| {
            assert!(!seen[j as usize], "candidate {j} visited twice for {i}");
            seen[j as usize] = true;
            cands.push(j);
        });
        for &j in &cands {
            seen[j as usize] = false;
            if j as usize != i && interacts(x, dim, h, i, j as usize) {
                pairs.push((i as u32, j));
            }
        }
    }
    pairs.sort_unstable();
    pairs
}

fn check_invariants(grid: &Grid) {
    let (order, start) = (grid.order(), grid.cell_start());
    assert_eq!(start.len(), grid.num_cells() + 1);
    assert_eq!(grid.num_cells(), grid.cells_per_axis().iter().product::<usize>());
    assert_eq!(start[0], 0);
    assert_eq!(*start.last().unwrap() as usize, order.len());
    assert!(start.windows(2).all(|w| w[0] <= w[1]));
    let mut sorted = order.to_vec();
    sorted.sort_unstable();
    assert!(sorted.iter().enumerate().all(|(k, &i)| k == i as usize), "order is not a permutation");
    for c in 0..grid.num_cells() {
        let cell = &order[start[c] as usize..start[c + 1] as usize];
        assert!(cell.windows(2).all(|w| w[0] < w[1]), "cell {c} is not stable");
    }
}

/// Builds at `SUPPORT * h_max` and compares with brute force.
fn check_against_brute_force<T: Coord>(x: &[T], dim: usize, h: &[f64]) -> Grid {
    let grid = Grid::build(x, dim, SUPPORT * h_max(h));
    check_invariants(&grid);
    let found = via_grid(&grid, x, dim, h);
    let expected = brute_force(x, dim, h);
    assert_eq!(found.len(), expected.len(), "dim {dim}: pair counts differ");
    assert_eq!(found, expected, "dim {dim}: pair sets differ");
    grid
}

#[test]
fn random_clouds_match_brute_force() {
    let mut rng = XorShift(0x9E37_79B9_7F4A_7C15);
    for dim in 1..=3 {
        for variable in [false, true] {
            let n = 1200;
            let x = cloud(&mut rng, n, dim, 10.0);
            // Spacing ~ side / n^(1/dim); h0 = 1.3 spacing.
            let h0 = 1.3 * 10.0 / (n as f64).powf(1.0 / dim as f64);
            let h: Vec<f64> = (0..n).map(|_| if variable { h0 * rng.range(0.5, 1.5) } else { h0 }).collect();
            let grid = check_against_brute_force(&x, dim, &h);
            assert!(grid.num_cells() > 1, "dim {dim}: the test should exercise several cells");
        }
    }
}

#[test]
fn f32_positions_match_brute_force() {
    let mut rng = XorShift(12345);
    for dim in 1..=3 {
        let n = 800;
        let x: Vec<f32> = cloud(&mut rng, n, dim, 3.0).into_iter().map(|v| v as f32).collect();
        let h0 = 1.3 * 3.0 / (n as f64).powf(1.0 / dim as f64);
        let h: Vec<f64> = (0..n).map(|_| h0 * rng.range(0.5, 1.5)).collect();
        check_against_brute_force(&x, dim, &h);
    }
}

/// A lattice of `m` points per axis with spacing `s`, starting at `start`.
fn lattice(dim: usize, m: usize, s: f64, start: f64) -> Vec<f64> {
    let n = m.pow(dim as u32);
    let mut x = Vec::with_capacity(n * dim);
    for i in 0..n {
        let mut rest = i;
        for _ in 0..dim {
            x.push(start + (rest % m) as f64 * s);
            rest /= m;
        }
    }
    x
}

fn neighbours_of(grid: &Grid, x: &[f64], dim: usize, h: &[f64], i: usize) -> usize {
    let mut count = 0;
    grid.for_each_candidate(point_of(x, dim, i), |j| {
        count += (j as usize != i && interacts(x, dim, h, i, j as usize)) as usize
    });
    count
}

#[test]
fn lattice_on_cell_boundaries() {
    // Powers of two: every lattice coordinate and distance is exact, so pairs exactly at the
    // support radius exist, and they must be excluded (r < support).
    let c0 = 0.25;
    for dim in 1..=3 {
        let m: usize = [40, 12, 7][dim - 1];
        let centre = (m / 2) * (1 + m + m * m) % m.pow(dim as u32);
        // Spacing = cell size, support exactly the spacing: no pairs at all.
        let x = lattice(dim, m, c0, -1.0);
        let h = vec![c0 / 2.0; x.len() / dim];
        check_against_brute_force(&x, dim, &h);
        assert!(brute_force(&x, dim, &h).is_empty());
        // Support just above the spacing: the face neighbours only.
        let h = vec![c0 / 2.0 * (1.0 + 1e-9); x.len() / dim];
        let grid = check_against_brute_force(&x, dim, &h);
        assert_eq!(neighbours_of(&grid, &x, dim, &h, centre), 2 * dim);
        // Spacing = half the cell size: all 3^dim - 1 around, the next ones (at exactly c0) out.
        let x = lattice(dim, m, c0 / 2.0, 0.0);
        let h = vec![c0 / 2.0; x.len() / dim];
        let grid = check_against_brute_force(&x, dim, &h);
        assert_eq!(neighbours_of(&grid, &x, dim, &h, centre), 3usize.pow(dim as u32) - 1);
        // Spacing = half the cell size the grid actually uses: every other point on a boundary.
        let spacing = grid.cell_size() / 2.0;
        let x = lattice(dim, m, spacing, 3.0);
        check_against_brute_force(&x, dim, &h);
    }
}

#[test]
fn far_debris_is_capped_and_complete() {
    let mut rng = XorShift(777);
    for dim in 1..=3 {
        let n = 900;
        let mut x = cloud(&mut rng, n, dim, 5.0);
        x[dim * 17] = 1e9;
        x[dim * 400 + dim - 1] = -3e8;
        let h0 = 1.3 * 5.0 / (n as f64).powf(1.0 / dim as f64);
        let h: Vec<f64> = (0..n).map(|_| h0 * rng.range(0.5, 1.5)).collect();
        let grid = check_against_brute_force(&x, dim, &h);
        assert!(grid.num_cells() <= max_cells(n), "dim {dim}: {} cells", grid.num_cells());
        assert!(grid.cell_size() >= SUPPORT * h_max(&h));
    }
}

#[test]
fn huge_extent_and_bad_cell_sizes_fall_back_to_one_cell() {
    let x = [-1e308, 0.0, 1e308, 5.0, 5.0 + 1e-3];
    let h = vec![1e-3; x.len()];
    let grid = check_against_brute_force(&x, 1, &h);
    assert_eq!(grid.num_cells(), 1);
    for cell in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let grid = Grid::build(&x, 1, cell);
        check_invariants(&grid);
        assert_eq!(grid.num_cells(), 1);
    }
}

#[test]
fn non_finite_positions_do_not_panic() {
    let mut rng = XorShift(4242);
    for dim in 1..=3 {
        let n = 300;
        let mut x = cloud(&mut rng, n, dim, 3.0);
        x[0] = f64::NAN;
        x[dim * 5 + dim - 1] = f64::INFINITY;
        x[dim * 9] = f64::NEG_INFINITY;
        x[dim * 11..dim * 12].fill(f64::NAN);
        let h = vec![0.2; n];
        check_against_brute_force(&x, dim, &h);
        let grid = Grid::build(&x, dim, 0.4);
        grid.for_each_candidate([f64::NAN; 3], |_| {});
        grid.for_each_candidate([f64::INFINITY, f64::NEG_INFINITY, f64::NAN], |_| {});
        let all_nan = vec![f64::NAN; n * dim];
        let grid = Grid::build(&all_nan, dim, 0.4);
        check_invariants(&grid);
        let mut count = 0;
        grid.for_each_candidate([0.0; 3], |_| count += 1);
        assert_eq!(count, n, "all NaN particles share cell 0");
        let perm = morton_permutation(&all_nan, dim, 0.4);
        assert_eq!(perm, (0..n as u32).collect::<Vec<_>>());
    }
}

#[test]
fn empty_and_single_particle() {
    for dim in 1..=3 {
        let grid = Grid::build::<f64>(&[], dim, 1.0);
        check_invariants(&grid);
        assert_eq!(grid.num_particles(), 0);
        grid.for_each_candidate([0.0; 3], |_| panic!("no particles"));
        let mut ranges = vec![(7, 9)];
        grid.cell_ranges_around([1e30; 3], &mut ranges);
        assert!(ranges.is_empty());
        assert!(morton_permutation::<f32>(&[], dim, 1.0).is_empty());

        let one = vec![2.5f32; dim];
        let grid = Grid::build(&one, dim, 1.0);
        check_invariants(&grid);
        let mut found = Vec::new();
        grid.for_each_candidate([-1e6; 3], |j| found.push(j));
        assert_eq!(found, [0], "a far query point is clamped to the grid");
    }
}

/// Reference bit interleaving: bit b of axis k to bit b * dim + k.
fn naive_morton(c: [u32; 3], dim: usize) -> u64 {
    let bits = if dim == 3 { 21 } else { 64 / dim.max(2) };
    let mut code = 0u64;
    for b in 0..bits {
        for (k, &ck) in c.iter().enumerate().take(dim) {
            code |= (((ck >> b) & 1) as u64) << (b * dim + k);
        }
    }
    code
}

#[test]
fn morton_code_interleaves_bits() {
    let mut rng = XorShift(99);
    for dim in 1..=3 {
        for _ in 0..1000 {
            let mask = if dim == 3 { (1 << 21) - 1 } else { u32::MAX };
            let c = [rng.next() as u32 & mask, rng.next() as u32 & mask, rng.next() as u32 & mask];
            assert_eq!(morton_code(c, dim), naive_morton(c, dim), "dim {dim}, cell {c:?}");
        }
    }
    assert_eq!(morton_code([1, 0, 0], 3), 1);
    assert_eq!(morton_code([0, 1, 0], 3), 2);
    assert_eq!(morton_code([0, 0, 1], 3), 4);
    assert_eq!(morton_code([3, 0, 0], 2), 0b101);
}

#[test]
fn morton_permutation_sorts_and_preserves_neighbours() {
    let mut rng = XorShift(31337);
    for dim in 1..=3 {
        let n = 1000;
        let x = cloud(&mut rng, n, dim, 8.0);
        let h0 = 1.3 * 8.0 / (n as f64).powf(1.0 / dim as f64);
        let h: Vec<f64> = (0..n).map(|_| h0 * rng.range(0.5, 1.5)).collect();
        let cell = SUPPORT * h_max(&h);
        let perm = morton_permutation(&x, dim, cell);

        let mut sorted = perm.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..n as u32).collect::<Vec<_>>(), "not a permutation");

        let codes = morton_codes(&x, dim, cell);
        let grid = Grid::build(&x, dim, cell);
        for (i, &code) in codes.iter().enumerate() {
            assert_eq!(code, morton_code(grid.cell_coords(point_of(&x, dim, i)), dim));
        }
        for w in perm.windows(2) {
            let (a, b) = (w[0] as usize, w[1] as usize);
            assert!((codes[a], a) < (codes[b], b), "not sorted by (code, index)");
        }

        let new_x = apply_permutation(&x, dim, &perm);
        let new_h = apply_permutation(&h, 1, &perm);
        let new_grid = Grid::build(&new_x, dim, cell);
        let mut mapped: Vec<(u32, u32)> = via_grid(&new_grid, &new_x, dim, &new_h)
            .into_iter()
            .map(|(a, b)| (perm[a as usize], perm[b as usize]))
            .collect();
        mapped.sort_unstable();
        assert_eq!(mapped, brute_force(&x, dim, &h), "dim {dim}");
    }
}

#[test]
fn apply_permutation_gathers_components() {
    let data = [10, 11, 20, 21, 30, 31];
    assert_eq!(apply_permutation(&data, 2, &[2, 0, 1]), [30, 31, 10, 11, 20, 21]);
    assert_eq!(apply_permutation(&data, 1, &[5, 4, 3, 2, 1, 0]), [31, 30, 21, 20, 11, 10]);
}

/// The particles whose cells lie within one cell of `p`'s (clamped) cell, from scratch.
fn candidates_from_scratch(grid: &Grid, x: &[f64], dim: usize, p: [f64; 3]) -> Vec<u32> {
    let c = grid.cell_coords(p);
    let n = x.len() / dim;
    (0..n as u32)
        .filter(|&j| {
            let cj = grid.cell_coords(point_of(x, dim, j as usize));
            (0..dim).all(|k| c[k].abs_diff(cj[k]) <= 1)
        })
        .collect()
}

#[test]
fn cell_ranges_cover_the_candidates() {
    let mut rng = XorShift(2024);
    let mut ranges = Vec::new();
    for dim in 1..=3 {
        let n = 2000;
        let x = cloud(&mut rng, n, dim, 6.0);
        let grid = Grid::build(&x, dim, 0.9);
        let queries = (0..300).map(|_| {
            let mut p = [0.0; 3];
            p.iter_mut().for_each(|v| *v = rng.range(-5.0, 5.0));
            p
        });
        for p in queries.chain([[-1e9; 3], [1e9; 3], [-3.0, 3.0, -3.0]]) {
            let mut direct = Vec::new();
            grid.for_each_candidate(p, |j| direct.push(j));
            grid.cell_ranges_around(p, &mut ranges);
            assert!(ranges.iter().all(|&(a, b)| a < b), "empty range");
            assert!(ranges.windows(2).all(|w| w[0].1 < w[1].0), "ranges overlap, touch or go backwards");
            assert!(ranges.len() <= 3usize.pow(dim as u32 - 1));
            let from_ranges: Vec<u32> =
                ranges.iter().flat_map(|&(a, b)| grid.order()[a as usize..b as usize].iter().copied()).collect();
            assert_eq!(from_ranges, direct, "same particles, same order");
            direct.sort_unstable();
            assert_eq!(direct, candidates_from_scratch(&grid, &x, dim, p));
        }
    }
}

/// `cargo test --release --test grid -- --ignored --nocapture`
#[test]
#[ignore]
fn build_time_one_million_3d() {
    let n = 1_000_000;
    let mut rng = XorShift(1);
    let side = 100.0; // spacing ~ 1
    let x = cloud(&mut rng, n, 3, side);
    let x32: Vec<f32> = x.iter().map(|&v| v as f32).collect();
    let cell = SUPPORT * 1.3;
    let time = |label: &str, f: &dyn Fn()| {
        let mut best = f64::INFINITY;
        for _ in 0..5 {
            let t = std::time::Instant::now();
            f();
            best = best.min(t.elapsed().as_secs_f64());
        }
        println!("{label}: best of 5 {:.1} ms", best * 1e3);
    };
    time("Grid::build f64, random", &|| drop(std::hint::black_box(Grid::build(&x, 3, cell))));
    time("Grid::build f32, random", &|| drop(std::hint::black_box(Grid::build(&x32, 3, cell))));
    time("Grid::build f64, ~1 particle/cell", &|| drop(std::hint::black_box(Grid::build(&x, 3, 1.0))));
    time("morton_permutation f64", &|| drop(std::hint::black_box(morton_permutation(&x, 3, cell))));
    let perm = morton_permutation(&x, 3, cell);
    let xm = apply_permutation(&x, 3, &perm);
    time("apply_permutation 3 comps", &|| drop(std::hint::black_box(apply_permutation(&x, 3, &perm))));
    time("Grid::build f64, Morton-ordered", &|| drop(std::hint::black_box(Grid::build(&xm, 3, cell))));
    let grid = Grid::build(&xm, 3, cell);
    println!("cells {:?}, {} per cell", grid.cells_per_axis(), n as f64 / grid.num_cells() as f64);
}

/// `cell_ranges_within` on grids of cells finer than the radius (as the CPU backend builds them)
/// visits every particle within the radius, each once, for points inside the cloud, on its border
/// and far outside it (mirror images), in 1D, 2D and 3D.
#[test]
fn ranges_within_a_radius_hold_every_particle_within_it() {
    let mut rng = XorShift(0x1234_5678_9abc_def1);
    for dim in 1..=3 {
        for fine in [1.0, 2.0, 3.0] {
            let n = [0, 300, 600, 900][dim];
            let x = cloud(&mut rng, n, dim, 1.0);
            let radius = 0.2;
            let grid = Grid::build(&x, dim, radius / fine);
            let mut ranges = vec![];
            let mut visited = 0usize;
            for q in 0..200 {
                // Points inside, near the border and well beyond the cloud.
                let scale = [0.6, 1.1, 2.0][q % 3];
                let mut p = [0.0; 3];
                for v in p.iter_mut().take(dim) {
                    *v = rng.range(-0.5 * scale, 0.5 * scale);
                }
                grid.cell_ranges_within(p, radius, &mut ranges);
                let mut seen = vec![false; n];
                for w in ranges.windows(2) {
                    assert!(w[0].1 < w[1].0, "ranges overlap or are not increasing: {ranges:?}");
                }
                for &(a, b) in &ranges {
                    for &j in &grid.order()[a as usize..b as usize] {
                        assert!(!std::mem::replace(&mut seen[j as usize], true), "{j} visited twice");
                        visited += 1;
                    }
                }
                for (j, s) in seen.iter().enumerate() {
                    let q = point_of(&x, dim, j);
                    let r: f64 = (0..dim).map(|k| (q[k] - p[k]).powi(2)).sum::<f64>().sqrt();
                    assert!(*s || r >= radius, "{dim}D, cells of radius/{fine}: particle {j} at {r} missed");
                }
            }
            // The queries did reach particles (the check above is not vacuous).
            assert!(visited > 0);
        }
    }
}

/// `Grid::nearby_max` bounds each particle's neighbourhood: no particle within `reach` of i has a
/// value above i's bound, in clouds graded from fine to four times coarser (with far debris, which
/// coarsens the blocks); and the bound stays local: fine particles farther than 2 reach from every
/// coarse one get the fine value, not the coarse one.
#[test]
fn nearby_max_bounds_every_neighbourhood_and_stays_local() {
    let mut rng = XorShift(4242);
    for dim in 1..=3 {
        for debris in [false, true] {
            let n = 1200;
            let mut x = cloud(&mut rng, n, dim, 10.0);
            if debris {
                x[dim * 5] = 1e7;
            }
            // Coarse (h = 0.8) beyond x = 3, fine (h = 0.2) elsewhere.
            let h: Vec<f64> = (0..n).map(|i| if x[i * dim] > 3.0 { 0.8 } else { 0.2 }).collect();
            let reach = SUPPORT * h_max(&h);
            let near = Grid::nearby_max(&x, dim, &h, reach);
            let mut far_fine = 0;
            for i in 0..n {
                let (a, mut truth, mut nearest_coarse) = (point_of(&x, dim, i), h[i], f64::INFINITY);
                for (j, hj) in h.iter().enumerate() {
                    let b = point_of(&x, dim, j);
                    let r = (0..dim).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt();
                    if r < reach {
                        truth = truth.max(*hj);
                    }
                    if *hj > 0.5 {
                        nearest_coarse = nearest_coarse.min(r);
                    }
                }
                assert!(near[i] >= truth, "dim {dim}, particle {i}: bound {} below {truth}", near[i]);
                if !debris && nearest_coarse > 2.0 * reach {
                    assert_eq!(near[i], 0.2, "dim {dim}, particle {i}, {nearest_coarse} from the coarse ones");
                    far_fine += 1;
                }
            }
            assert!(debris || far_fine > 0, "dim {dim}: no fine particle far from the coarse ones");
        }
    }
}

/// The CPU backend's graded search (`SizeLevels`): a grid per factor of two in h, each walked
/// as far as `support · (h_i + min(h_hi, h_near_i))/2`, finds exactly the brute-force pairs in
/// graded clouds (with far debris too); each level holds the particles of its sizes once, and its
/// cells are finer than one grid's under the same `4 n` cap where the whole bounding box is mostly
/// empty (a thin wide plate under a tall column of fine particles). Sizes within a factor of two
/// give one level, the single grid of before.
#[test]
fn size_levels_over_a_graded_cloud_find_every_pair() {
    let mut rng = XorShift(0x5eed_f1e5);
    for dim in 1..=3 {
        for debris in [false, true] {
            let n = 1500;
            // A wide thin coarse slab (h ≈ 0.8), a narrow fine column (h ≈ 0.2) standing on it,
            // and between them particles of h ≈ 0.35 (a level of their own).
            let mut x = cloud(&mut rng, n, dim, 1.0);
            let h: Vec<f64> = (0..n).map(|i| [0.8, 0.2, 0.2, 0.35][i % 4] * rng.range(0.75, 1.0)).collect();
            for i in 0..n {
                let (wide, tall) = if h[i] > 0.45 { (30.0, 2.0) } else { (1.5, 10.0) };
                for k in 0..dim {
                    x[i * dim + k] *= if k + 1 == dim && dim > 1 { tall } else { wide };
                }
            }
            if debris {
                x[dim * 7] = 1e6;
            }
            let levels = SizeLevels::build(&x, dim, &h, SUPPORT, 0.0);
            assert_eq!(levels.levels().len(), 3, "dim {dim}: levels of h 0.8, 0.35 and 0.2");
            let mut members = vec![0; n];
            for level in levels.levels() {
                // Each member sits in the cell that holds its position, in increasing order.
                let (g, start) = (&level.grid, level.grid.cell_start());
                for c in 0..g.num_cells() {
                    let cell = &g.order()[start[c] as usize..start[c + 1] as usize];
                    assert!(cell.windows(2).all(|w| w[0] < w[1]), "cell {c} is not stable");
                    for &j in cell {
                        assert_eq!(g.linear_index(g.cell_coords(point_of(&x, dim, j as usize))), c);
                    }
                }
                assert!(level.grid.num_cells() <= max_cells(level.grid.num_particles()));
                for &j in level.grid.order() {
                    members[j as usize] += 1;
                    assert!((level.h_lo..=level.h_hi).contains(&h[j as usize]));
                }
                assert!(level.h_hi <= 2.0 * level.h_lo);
            }
            assert!(members.iter().all(|&m| m == 1), "dim {dim}: a particle in no level or in two");
            if dim == 3 && !debris {
                let one_grid = Grid::build(&x, dim, 0.5 * SUPPORT * 0.2);
                let finest = levels.levels().last().unwrap();
                assert!(finest.grid.cell_size() < 0.5 * one_grid.cell_size(), "3D: the fine level's cells");
            }
            let near = Grid::nearby_max(&x, dim, &h, SUPPORT * h_max(&h));
            let (mut pairs, mut ranges) = (vec![], vec![]);
            for i in 0..n {
                let reach = |level: &Level| level.reach(SUPPORT, h[i], near[i], 0.0);
                levels.for_each_candidate(point_of(&x, dim, i), reach, &mut ranges, |j| {
                    if j as usize != i && interacts(&x, dim, &h, i, j as usize) {
                        pairs.push((i as u32, j));
                    }
                });
            }
            pairs.sort_unstable();
            let truth = brute_force(&x, dim, &h);
            assert!(truth.len() > n, "dim {dim}: only {} pairs, the check is too sparse", truth.len());
            assert_eq!(pairs, truth, "dim {dim}, debris {debris}");
        }
        // Sizes within a factor of two: one level, the grid of half the largest cut-off (plus
        // the skin) that `Grid::build` gives, as the backend had before the levels.
        let x = cloud(&mut rng, 400, dim, 1.0);
        let h: Vec<f64> = (0..400).map(|_| rng.range(0.03, 0.05)).collect();
        let levels = SizeLevels::build(&x, dim, &h, SUPPORT, 0.01);
        assert_eq!(levels.levels().len(), 1);
        let alone = Grid::build(&x, dim, 0.5 * (SUPPORT * h_max(&h) + 0.01));
        assert_eq!(levels.levels()[0].grid.order(), alone.order());
        assert_eq!(levels.levels()[0].grid.cell_size(), alone.cell_size());
    }
}

/// Recursive coordinate bisection into 5 domains of random weights in [0.5, 1.5): each domain's
/// weight is its share of the total to within one particle's weight per level of cuts (three).
#[test]
fn bisection_into_five_domains_gives_each_its_share_of_the_weight_to_a_particle_per_cut() {
    use pairsum::grid::decompose::bisect;
    let mut rng = XorShift(0x5eed_d0e5);
    let (n, dim, parts) = (3000, 3, 5);
    let x = cloud(&mut rng, n, dim, 1.0);
    let w: Vec<f64> = (0..n).map(|_| rng.range(0.5, 1.5)).collect();
    let domain = bisect(&x, dim, &w, parts).expect("finite");
    let total: f64 = w.iter().sum();
    for d in 0..parts {
        let mine: f64 = w.iter().zip(&domain).filter(|(_, k)| **k as usize == d).map(|(w, _)| *w).sum();
        let off = (mine - total / parts as f64).abs();
        assert!(off <= 3.0 * 1.5, "domain {d}: weight {mine}, its share {}", total / parts as f64);
    }
}

/// Two domains of a box three times longer in x than across are cut across x: every particle of
/// the first lies at or below every particle of the second, and the first holds 501 of 1001.
#[test]
fn two_domains_of_a_long_box_are_cut_across_its_length() {
    use pairsum::grid::decompose::bisect;
    let mut rng = XorShift(0xb15ec7);
    let n = 1001;
    let x: Vec<f64> = (0..n).flat_map(|_| [rng.range(0.0, 3.0), rng.range(0.0, 1.0), rng.range(0.0, 1.0)]).collect();
    let domain = bisect(&x, 3, &vec![1.0; n], 2).expect("finite");
    let along = |d: u32| -> Vec<f64> { (0..n).filter(|i| domain[*i] == d).map(|i| x[3 * i]).collect() };
    let low_max = pairsum::compare::extremes(&along(0)).expect("finite").1;
    let high_min = pairsum::compare::extremes(&along(1)).expect("finite").0;
    assert!(low_max <= high_min, "domain 1 reaches x = {low_max}, domain 2 starts at {high_min}");
    // The cut comes at the first count whose weight reaches half of 1001.
    assert_eq!(along(0).len(), 501);
}

/// The halo of each of three domains of a 2D cloud with variable h: the particles of the other
/// domains within a pair's cut-off of one of its own, as a brute-force count finds them.
#[test]
fn each_domains_halo_is_what_brute_force_finds_within_the_cut_off() {
    use pairsum::grid::decompose::{bisect, halo_sizes};
    let mut rng = XorShift(0x4a10);
    let (n, dim, parts) = (800, 2, 3);
    let x = cloud(&mut rng, n, dim, 1.0);
    let h: Vec<f64> = (0..n).map(|_| rng.range(0.01, 0.04)).collect();
    let domain = bisect(&x, dim, &vec![1.0; n], parts).expect("finite");
    let got = halo_sizes(&x, dim, &h, SUPPORT, &domain, parts).expect("finite");
    for d in 0..parts as u32 {
        let expected = (0..n)
            .filter(|j| domain[*j] != d && (0..n).any(|i| domain[i] == d && interacts(&x, dim, &h, i, *j)))
            .count();
        assert_eq!(got[d as usize], expected, "domain {d}");
        assert!(expected > 10, "domain {d}: a halo of {expected} tests little");
    }
}
