//! The CPU neighbour search: a uniform cell grid built by counting sort, one per particle size in
//! graded scenes ([`SizeLevels`]), and Morton reordering.
//!
//! This module owns the spatial index the CPU backend iterates to find interacting pairs. It knows
//! nothing about fields or equations: it takes interleaved positions (`x.len() == n * dim`,
//! `dim` ∈ {1, 2, 3}, `f32` or `f64` via [`Coord`]) and a cell size, and answers "which particles
//! may lie within one cell of this point".
//!
//! # Completeness
//!
//! The caller chooses `cell_size = support * h_max`. A pair (i, j) interacts when
//! `r_ij < support * (h_i + h_j) / 2`, and since `(h_i + h_j) / 2 <= h_max`, every interacting
//! pair has `r_ij < cell_size`, hence `|x_i - x_j| < cell_size` along every axis, hence the cells of
//! i and j differ by at most one along every axis: j is among the 3^dim cells around i's cell. This
//! holds with variable h; the grid only returns *candidates*, and the caller filters by distance.
//! With graded spacing the caller can search less: [`Grid::nearby_max`] bounds the largest h
//! within the largest cut-off of each particle, so `support * (h_i + that) / 2` also holds every
//! pair; and [`SizeLevels`] gives each particle size its own grid, searched with
//! [`Grid::cell_ranges_within`].
//! The grid enlarges the requested cell size by a relative [`CELL_MARGIN`] so that a distance the
//! caller rounds to just below the support still lands in adjacent cells.
//!
//! # Invariants of a [`Grid`]
//!
//! - `order` is a permutation of `0..n`, sorted by linear cell index (x fastest, then y, then z)
//!   and, within a cell, by particle index (the counting sort is stable);
//! - `cell_start.len() == cells + 1`, `cell_start[0] == 0`, `cell_start[cells] == n`, and the
//!   particles of cell `c` are `order[cell_start[c]..cell_start[c + 1]]`;
//! - the number of cells is at most `max(4 n, 4096)`: when the bounding box would need more (a
//!   few particles flung far away), the cell size is doubled until it fits. Larger cells are still
//!   complete, only slower;
//! - a non-finite coordinate puts the particle in cell 0 of that axis, and a query point is clamped
//!   to the grid, so building and querying never panic on NaN or infinite positions.

pub mod decompose;
mod geometry;
mod levels;
mod morton;

pub use geometry::{point_of, CELL_MARGIN};
pub use levels::{Level, SizeLevels};
pub use morton::{apply_permutation, morton_code, morton_codes, morton_permutation};

use geometry::{check_layout, Geometry};
use rayon::prelude::*;

/// A coordinate type the grid accepts; cell coordinates are computed in f64.
pub trait Coord: Copy + Send + Sync + 'static {
    fn to_f64(self) -> f64;
}

impl Coord for f32 {
    #[inline]
    fn to_f64(self) -> f64 {
        self as f64
    }
}

impl Coord for f64 {
    #[inline]
    fn to_f64(self) -> f64 {
        self
    }
}

/// The cap on the number of cells for `n` particles: `max(4 n, 4096)`, and at most `u32::MAX`.
pub fn max_cells(n: usize) -> usize {
    (4 * n).max(4096).min(u32::MAX as usize)
}

/// A uniform cell grid over a set of particles, with the particles counting-sorted by cell.
#[derive(Clone, Debug)]
pub struct Grid {
    geom: Geometry,
    cell_start: Vec<u32>,
    order: Vec<u32>,
}

impl Grid {
    /// Builds the grid of the `x.len() / dim` particles at (at least) `cell_size`.
    ///
    /// Panics if `dim` is not 1, 2 or 3, or `x.len()` is not a multiple of `dim`. A non-positive
    /// or non-finite `cell_size` gives a single cell holding every particle.
    pub fn build<T: Coord>(x: &[T], dim: usize, cell_size: f64) -> Grid {
        let n = check_layout(x, dim);
        Grid::with_geometry(x, Geometry::fit(x, dim, cell_size, max_cells(n), usize::MAX))
    }

    /// For each particle, an upper bound on `values` over every particle within `reach` of it:
    /// the largest value in the blocks (of a quarter of `reach`, or larger where the cell cap
    /// says) that a cube of half-side `reach` around its block covers. With graded spacing it
    /// lets a fine particle away from the coarse ones search only as far as its own
    /// neighbourhood needs, not the coarsest particle's cut-off. Cost: one pass over the
    /// particles and a running maximum along each axis over the blocks.
    pub fn nearby_max<T: Coord>(x: &[T], dim: usize, values: &[T], reach: f64) -> Vec<f64> {
        let n = check_layout(x, dim);
        let g = Geometry::fit(x, dim, 0.25 * reach, max_cells(n), usize::MAX);
        let blocks = g.linear_of_all(x);
        let mut near = vec![f64::NEG_INFINITY; g.num_cells()];
        for (b, v) in blocks.iter().zip(values) {
            let m = &mut near[*b as usize];
            *m = m.max(v.to_f64());
        }
        // Two points within `reach` lie in blocks at most `w` apart along every axis.
        let w = if g.cell_size.is_finite() { (reach / g.cell_size).ceil().max(1.0) as usize } else { 0 };
        for axis in 0..dim {
            near = max_within_along(&g, &near, axis, w);
        }
        blocks.iter().map(|b| near[*b as usize]).collect()
    }

    pub(crate) fn with_geometry<T: Coord>(x: &[T], geom: Geometry) -> Grid {
        let cells = geom.linear_of_all(x);
        let (cell_start, order) = counting_sort(&cells, geom.num_cells());
        Grid { geom, cell_start, order }
    }

    /// Particle indices sorted by cell, stable within a cell.
    pub fn order(&self) -> &[u32] {
        &self.order
    }

    /// Start of each cell's particles in [`order`](Self::order); one more entry than cells.
    pub fn cell_start(&self) -> &[u32] {
        &self.cell_start
    }

    /// The cell size in use: the requested one times `1 + CELL_MARGIN`, doubled as often as the
    /// cell cap required (infinite for the single-cell fallback).
    pub fn cell_size(&self) -> f64 {
        self.geom.cell_size
    }

    /// Cells along each axis; 1 for the axes beyond `dim`.
    pub fn cells_per_axis(&self) -> [usize; 3] {
        self.geom.counts
    }

    /// Lower corner of the bounding box of the finite coordinates (0 beyond `dim`).
    pub fn origin(&self) -> [f64; 3] {
        self.geom.origin
    }

    pub fn dim(&self) -> usize {
        self.geom.dim
    }

    pub fn num_cells(&self) -> usize {
        self.cell_start.len() - 1
    }

    pub fn num_particles(&self) -> usize {
        self.order.len()
    }

    /// Cell coordinates of point `p`, clamped to the grid (0 beyond `dim`).
    pub fn cell_coords(&self, p: [f64; 3]) -> [u32; 3] {
        self.geom.cell_of(p)
    }

    /// Linear index of the cell with coordinates `c`: `cx + nx * (cy + ny * cz)`.
    pub fn linear_index(&self, c: [u32; 3]) -> usize {
        self.geom.linear(c)
    }

    /// Coordinates of the cell with linear index `c`.
    pub fn cell_coords_of_index(&self, c: usize) -> [u32; 3] {
        let [nx, ny, _] = self.geom.counts;
        [(c % nx) as u32, (c / nx % ny) as u32, (c / (nx * ny)) as u32]
    }

    /// Calls `f(j)` for every particle j in the 3^dim cells around the cell of `p` (fewer at the
    /// border of the grid; no cell twice). Visits cells in increasing linear order.
    pub fn for_each_candidate(&self, p: [f64; 3], mut f: impl FnMut(u32)) {
        self.for_each_range(p, |a, b| self.order[a as usize..b as usize].iter().for_each(|&j| f(j)));
    }

    /// Replaces `out` with the ranges into [`order`](Self::order) of the cells around `p` that
    /// [`for_each_candidate`](Self::for_each_candidate) visits: one per row along x, rows that end
    /// where the next begins merged, empty ones left out. The ranges are disjoint and increasing.
    pub fn cell_ranges_around(&self, p: [f64; 3], out: &mut Vec<(u32, u32)>) {
        out.clear();
        self.for_each_range(p, |a, b| push_range(out, a, b));
    }

    /// Replaces `out` with the ranges into [`order`](Self::order) of the cells that may hold a
    /// particle within `radius` of `p`: of each row of cells along x whose y–z distance from `p`
    /// is below `radius`, the run of cells that the sphere of `radius` reaches along x. On a grid
    /// of cells finer than `radius` this visits far fewer candidates than the 3^dim cells around
    /// `p` on a grid of cells of `radius`. The ranges are disjoint and increasing; cells on the
    /// grid's border count as reaching to infinity (points beyond it are clamped into them).
    pub fn cell_ranges_within(&self, p: [f64; 3], radius: f64, out: &mut Vec<(u32, u32)>) {
        out.clear();
        let g = &self.geom;
        if !g.cell_size.is_finite() || radius.is_nan() || !radius.is_finite() {
            if !self.order.is_empty() {
                out.push((0, self.order.len() as u32));
            }
            return;
        }
        let c = g.cell_of(p);
        let reach = (radius * g.inv).ceil().min(u32::MAX as f64 / 2.0) as u32;
        // Distance from p to cell k's slab along axis a.
        let gap = |a: usize, k: u32| -> f64 {
            if a >= g.dim {
                return 0.0;
            }
            let last = g.counts[a] as u32 - 1;
            let lo = if k == 0 { f64::NEG_INFINITY } else { g.origin[a] + k as f64 * g.cell_size };
            let hi = if k == last { f64::INFINITY } else { g.origin[a] + (k + 1) as f64 * g.cell_size };
            if p[a] < lo {
                lo - p[a]
            } else if p[a] > hi {
                p[a] - hi
            } else {
                0.0
            }
        };
        let span = |a: usize| {
            let last = g.counts[a] as u32 - 1;
            (c[a].saturating_sub(reach), (c[a].saturating_add(reach)).min(last))
        };
        let ((z0, z1), (y0, y1)) = (span(2), span(1));
        let r2 = radius * radius;
        for z in z0..=z1 {
            let dz = gap(2, z);
            for y in y0..=y1 {
                let dy = gap(1, y);
                let d2 = dy * dy + dz * dz;
                if d2 > r2 {
                    continue;
                }
                let ext = (r2 - d2).sqrt();
                let (x0, x1) = (g.axis_cell(0, p[0] - ext), g.axis_cell(0, p[0] + ext));
                let a = self.cell_start[g.linear([x0, y, z])];
                let b = self.cell_start[g.linear([x1, y, z]) + 1];
                if a < b {
                    push_range(out, a, b);
                }
            }
        }
    }

    /// Calls `g(a, b)` for each non-empty row of neighbouring cells, in increasing order.
    fn for_each_range(&self, p: [f64; 3], mut g: impl FnMut(u32, u32)) {
        let (lo, hi) = self.neighbourhood(p);
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                let a = self.cell_start[self.geom.linear([lo[0], y, z])];
                let b = self.cell_start[self.geom.linear([hi[0], y, z]) + 1];
                if a < b {
                    g(a, b);
                }
            }
        }
    }

    /// The inclusive box of cell coordinates within one cell of `p`'s cell, clamped to the grid.
    fn neighbourhood(&self, p: [f64; 3]) -> ([u32; 3], [u32; 3]) {
        let c = self.geom.cell_of(p);
        let (mut lo, mut hi) = (c, c);
        for k in 0..self.geom.dim {
            lo[k] = c[k].saturating_sub(1);
            hi[k] = (c[k] + 1).min(self.geom.counts[k] as u32 - 1);
        }
        (lo, hi)
    }
}

/// Appends the range `a..b` of [`Grid::order`], merged into the last one when it ends at `a`.
fn push_range(out: &mut Vec<(u32, u32)>, a: u32, b: u32) {
    match out.last_mut() {
        Some(last) if last.1 == a => last.1 = b,
        _ => out.push((a, b)),
    }
}

/// The largest value of each block and of the blocks up to `w` away from it along `axis` (a size:
/// NaN is left out).
fn max_within_along(g: &Geometry, v: &[f64], axis: usize, w: usize) -> Vec<f64> {
    let stride = match axis {
        0 => 1,
        1 => g.counts[0],
        _ => g.counts[0] * g.counts[1],
    };
    let count = g.counts[axis];
    (0..v.len())
        .into_par_iter()
        .map(|k| {
            let along = (k / stride) % count;
            let first = k - along.min(w) * stride;
            let last = k + (count - 1 - along).min(w) * stride;
            crate::compare::largest_number(f64::NEG_INFINITY, (first..=last).step_by(stride).map(|j| v[j]))
        })
        .collect()
}

/// Stable counting sort of particle indices by cell: returns `(cell_start, order)`.
fn counting_sort(cells: &[u32], num_cells: usize) -> (Vec<u32>, Vec<u32>) {
    let mut start = vec![0u32; num_cells + 1];
    for &c in cells {
        start[c as usize + 1] += 1;
    }
    for c in 0..num_cells {
        start[c + 1] += start[c];
    }
    // Scatter with `start[c]` as the cursor of cell c; afterwards it holds the start of c + 1.
    let mut order = vec![0u32; cells.len()];
    for (i, &c) in cells.iter().enumerate() {
        let s = &mut start[c as usize];
        order[*s as usize] = i as u32;
        *s += 1;
    }
    start.copy_within(0..num_cells, 1);
    start[0] = 0;
    (start, order)
}
