//! Local spacing of a node cloud: the mean distance of each node to its nearest neighbours, found
//! with a uniform bin grid and an expanding ring search.

use rayon::prelude::*;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// The most nodes × sample pairs the cell-size estimate may test by brute force.
const SAMPLE_WORK: usize = 20_000_000;

/// Estimates a local spacing for every node: the mean distance to its `2 dim` nearest neighbours
/// (2 in 1D, 4 in 2D, 6 in 3D; fewer when there are fewer other nodes). Only the first `dim`
/// coordinates count; `dim` outside 1..=3 is clamped into it.
///
/// On a regular lattice this recovers the spacing exactly for interior nodes; nodes on the boundary
/// lack neighbours on one side and get more: in 3D 1.07 × dx on a face and 1.21 × dx at a corner,
/// in 2D 1.10 × dx on an edge and 1.35 × dx at a corner, in 1D 1.5 × dx at an end (so volumes
/// `spacing^dim` overestimate a body's total by a few per cent; prefer a volume column or rescale
/// to a known mass). A lone node gets 0, and a node with a non-finite coordinate NaN (it is nobody's
/// neighbour).
///
/// Nodes are binned in a uniform grid (occupied cells only, hashed) whose cell size is the median
/// nearest-neighbour distance of a sample, and each node's neighbours are searched in rings of
/// cells of growing radius until the k-th nearest is closer than the rings searched, so graded
/// clouds cost little more than uniform ones. A node whose search would visit more than
/// `max(n / 8, 1000)` cells (an outlier far from the rest) tests every node instead.
pub fn estimate_spacing(positions: &[[f64; 3]], dim: usize) -> Vec<f64> {
    let dim = dim.clamp(1, 3);
    let points: Vec<[f64; 3]> = positions.iter().map(|p| project(*p, dim)).collect();
    let finite: Vec<u32> = (0..points.len() as u32).filter(|&i| is_finite(&points[i as usize])).collect();
    if finite.len() < 2 {
        return points.iter().map(|p| if is_finite(p) { 0.0 } else { f64::NAN }).collect();
    }
    let k = (2 * dim).min(finite.len() - 1);
    let bins = Bins::build(&points, &finite, dim);
    (0..points.len())
        .into_par_iter()
        .map(|i| if is_finite(&points[i]) { bins.mean_nearest(&points, i, k) } else { f64::NAN })
        .collect()
}

fn project(mut p: [f64; 3], dim: usize) -> [f64; 3] {
    p.iter_mut().skip(dim).for_each(|v| *v = 0.0);
    p
}

fn is_finite(p: &[f64; 3]) -> bool {
    p.iter().all(|v| v.is_finite())
}

fn dist2(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
}

/// The median nearest-neighbour distance of a strided sample of the (finite) nodes, by brute force.
fn sample_median(points: &[[f64; 3]], finite: &[u32]) -> f64 {
    let n = finite.len();
    let m = (SAMPLE_WORK / n).clamp(16, 256).min(n);
    let mut nearest: Vec<f64> = (0..m)
        .into_par_iter()
        .map(|s| {
            let i = finite[s * n / m] as usize;
            let d2 = finite.iter().filter(|&&j| j as usize != i).map(|&j| dist2(&points[i], &points[j as usize]));
            d2.fold(f64::INFINITY, f64::min).sqrt()
        })
        .collect();
    nearest.sort_unstable_by(f64::total_cmp);
    nearest[m / 2]
}

/// The most cells per axis (so that a cell key fits in 120 bits).
const MAX_PER_AXIS: f64 = (1u64 << 40) as f64;

/// A multiply-shift hasher for cell keys (the default SipHash is needlessly slow here).
#[derive(Default)]
struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(8) ^ u64::from(b)).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        }
    }

    fn write_u64(&mut self, v: u64) {
        self.0 = (v ^ (v >> 31)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    }

    fn write_u128(&mut self, v: u128) {
        self.write_u64(v as u64 ^ ((v >> 64) as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15));
    }

    fn finish(&self) -> u64 {
        self.0 ^ (self.0 >> 29)
    }
}

/// The finite nodes binned in a uniform grid; only occupied cells are stored.
struct Bins {
    dim: usize,
    origin: [f64; 3],
    h: f64,
    counts: [usize; 3],
    /// Occupied cell key → range of `items`.
    cells: HashMap<u128, (u32, u32), BuildHasherDefault<KeyHasher>>,
    /// The finite nodes sorted by cell key.
    items: Vec<u32>,
    /// The most cells one query visits before it falls back to testing every node.
    budget: usize,
}

impl Bins {
    fn build(points: &[[f64; 3]], finite: &[u32], dim: usize) -> Bins {
        let (lo, hi) = bounds(points, finite);
        let h = cell_size(points, finite, dim, (lo, hi));
        let mut counts = [1; 3];
        for i in 0..dim {
            counts[i] = ((hi[i] - lo[i]) / h) as usize + 1;
        }
        let budget = (finite.len() / 8).max(1000);
        let mut bins = Bins { dim, origin: lo, h, counts, cells: HashMap::default(), items: Vec::new(), budget };
        bins.fill(points, finite);
        bins
    }

    /// Sorts the finite nodes by cell and records each occupied cell's range.
    fn fill(&mut self, points: &[[f64; 3]], finite: &[u32]) {
        let mut keyed: Vec<(u128, u32)> =
            finite.iter().map(|&i| (self.key(self.cell_of(&points[i as usize])), i)).collect();
        keyed.par_sort_unstable();
        let mut run = 0;
        for j in 1..=keyed.len() {
            if j == keyed.len() || keyed[j].0 != keyed[run].0 {
                self.cells.insert(keyed[run].0, (run as u32, j as u32));
                run = j;
            }
        }
        self.items = keyed.into_iter().map(|(_, i)| i).collect();
    }

    fn cell_of(&self, p: &[f64; 3]) -> [usize; 3] {
        let mut c = [0; 3];
        for i in 0..self.dim {
            c[i] = (((p[i] - self.origin[i]) / self.h).max(0.0) as usize).min(self.counts[i] - 1);
        }
        c
    }

    fn key(&self, c: [usize; 3]) -> u128 {
        (c[0] as u128) | (c[1] as u128) << 40 | (c[2] as u128) << 80
    }

    /// The mean distance from node `i` to its `k` nearest neighbours.
    fn mean_nearest(&self, points: &[[f64; 3]], i: usize, k: usize) -> f64 {
        let p = &points[i];
        let c = self.cell_of(p);
        let mut best = Nearest::new(k);
        let max_r = self.counts.iter().copied().max().unwrap_or(1);
        let mut visited = 0;
        for r in 0..=max_r {
            visited += self.ring(c, r, &mut |j| best.offer_node(points, i, j));
            if visited > self.budget {
                return self.brute_force(points, i, k);
            }
            if best.full() && best.worst() <= (r as f64 * self.h).powi(2) {
                break;
            }
        }
        best.mean_distance()
    }

    /// [`Bins::mean_nearest`] by testing every node.
    fn brute_force(&self, points: &[[f64; 3]], i: usize, k: usize) -> f64 {
        let mut best = Nearest::new(k);
        self.items.iter().for_each(|&j| best.offer_node(points, i, j));
        best.mean_distance()
    }

    /// Calls `f` for every node in the cells at Chebyshev distance exactly `r` from cell `c`
    /// (clipped to the grid); returns the number of cells looked up.
    fn ring(&self, c: [usize; 3], r: usize, f: &mut impl FnMut(u32)) -> usize {
        let (x_lo, x_hi) = self.clip(c, 0, r);
        let (y_lo, y_hi) = self.clip(c, 1, r);
        let (z_lo, z_hi) = self.clip(c, 2, r);
        let mut visited = 0;
        for z in z_lo..=z_hi {
            for y in y_lo..=y_hi {
                if c[1].abs_diff(y) == r || c[2].abs_diff(z) == r {
                    (x_lo..=x_hi).for_each(|x| self.visit([x, y, z], f));
                    visited += x_hi - x_lo + 1;
                    continue;
                }
                // Here r > 0 (at r = 0 the single row is full): only the two ends of the x-run.
                for x in [c[0].checked_sub(r), Some(c[0] + r)].into_iter().flatten() {
                    if x <= x_hi {
                        self.visit([x, y, z], f);
                        visited += 1;
                    }
                }
            }
        }
        visited
    }

    /// The cells `c[axis] − r ..= c[axis] + r` inside the grid.
    fn clip(&self, c: [usize; 3], axis: usize, r: usize) -> (usize, usize) {
        (c[axis].saturating_sub(r), (c[axis] + r).min(self.counts[axis] - 1))
    }

    /// Calls `f` for the nodes of cell `c`.
    fn visit(&self, c: [usize; 3], f: &mut impl FnMut(u32)) {
        if let Some(&(a, b)) = self.cells.get(&self.key(c)) {
            self.items[a as usize..b as usize].iter().for_each(|&j| f(j));
        }
    }
}

/// The grid's cell size: the sample median nearest-neighbour distance (or, for a degenerate
/// sample, the extent over the node count per axis), enlarged until every axis has at most
/// [`MAX_PER_AXIS`] cells.
fn cell_size(points: &[[f64; 3]], finite: &[u32], dim: usize, (lo, hi): ([f64; 3], [f64; 3])) -> f64 {
    let extent = crate::scene::max_keeping_nan(0.0, (0..dim).map(|i| hi[i] - lo[i]));
    let mut h = sample_median(points, finite);
    if !(h > 0.0 && h.is_finite()) {
        h = extent / (finite.len() as f64).powf(1.0 / dim as f64);
    }
    if !(h > 0.0 && h.is_finite()) {
        h = 1.0;
    }
    while extent / h >= MAX_PER_AXIS && h < f64::MAX / 4.0 {
        h *= 2.0;
    }
    h
}

/// The bounding box of the finite nodes.
fn bounds(points: &[[f64; 3]], finite: &[u32]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for &i in finite {
        for a in 0..3 {
            lo[a] = lo[a].min(points[i as usize][a]);
            hi[a] = hi[a].max(points[i as usize][a]);
        }
    }
    (lo, hi)
}

/// The `k` smallest squared distances offered so far, sorted ascending.
struct Nearest {
    k: usize,
    d2: Vec<f64>,
}

impl Nearest {
    fn new(k: usize) -> Nearest {
        Nearest { k, d2: Vec::with_capacity(k + 1) }
    }

    fn offer(&mut self, d2: f64) {
        if self.full() && d2 >= self.worst() {
            return;
        }
        let at = self.d2.partition_point(|&v| v <= d2);
        self.d2.insert(at, d2);
        self.d2.truncate(self.k);
    }

    /// Offers node `j` as a neighbour of node `i` (not itself).
    fn offer_node(&mut self, points: &[[f64; 3]], i: usize, j: u32) {
        if j as usize != i {
            self.offer(dist2(&points[i], &points[j as usize]));
        }
    }

    fn full(&self) -> bool {
        self.d2.len() >= self.k
    }

    fn worst(&self) -> f64 {
        self.d2.last().copied().unwrap_or(f64::INFINITY)
    }

    fn mean_distance(&self) -> f64 {
        if self.d2.is_empty() {
            return 0.0;
        }
        self.d2.iter().map(|d| d.sqrt()).sum::<f64>() / self.d2.len() as f64
    }
}
