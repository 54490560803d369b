//! Grid geometry: the bounding box, the (possibly enlarged) cell size and the cell counts, and the
//! mapping from a point to its clamped cell coordinates and linear cell index.
//!
//! Invariants of a [`Geometry`]:
//! - `counts[a] >= 1` for every axis, and `counts[a] == 1` for the axes `a >= dim`;
//! - the product of the counts is at most the `max_cells` it was fitted with, and each count at
//!   most `max_per_axis`;
//! - `cell_of` is monotone and 1-Lipschitz in cells along each axis (a floor followed by a clamp),
//!   so two points closer than `cell_size` along an axis land in the same or adjacent cells.

use super::Coord;
use rayon::prelude::*;

/// Relative margin added to the requested cell size, so that a pair whose distance the caller
/// computes (in f32 or f64, with rounding) as just below the support still lands in adjacent cells.
pub const CELL_MARGIN: f64 = 1e-5;

/// Particles per rayon task in the parallel passes.
pub(crate) const CHUNK: usize = 4096;

#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Geometry {
    pub dim: usize,
    pub origin: [f64; 3],
    pub cell_size: f64,
    pub inv: f64,
    pub counts: [usize; 3],
}

/// Reads particle `i` of the interleaved positions `x` as a 3-vector (zeros beyond `dim`).
pub fn point_of<T: Coord>(x: &[T], dim: usize, i: usize) -> [f64; 3] {
    point(&x[i * dim..(i + 1) * dim])
}

pub(crate) fn point<T: Coord>(p: &[T]) -> [f64; 3] {
    let mut out = [0.0; 3];
    for (o, v) in out.iter_mut().zip(p) {
        *o = v.to_f64();
    }
    out
}

pub(crate) fn check_layout<T>(x: &[T], dim: usize) -> usize {
    assert!((1..=3).contains(&dim), "grid: dim must be 1, 2 or 3, got {dim}");
    assert!(x.len().is_multiple_of(dim), "grid: {} coordinates are not a multiple of dim = {dim}", x.len());
    let n = x.len() / dim;
    assert!(n <= u32::MAX as usize, "grid: {n} particles do not fit u32 indices");
    n
}

type Bounds = ([f64; 3], [f64; 3]);

fn merge(a: Bounds, b: Bounds) -> Bounds {
    let mut out = a;
    for k in 0..3 {
        out.0[k] = a.0[k].min(b.0[k]);
        out.1[k] = a.1[k].max(b.1[k]);
    }
    out
}

fn bounds_serial<T: Coord>(x: &[T], dim: usize) -> Bounds {
    let mut b = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in x.chunks_exact(dim) {
        for (k, v) in p.iter().enumerate() {
            let v = v.to_f64();
            if v.is_finite() {
                b.0[k] = b.0[k].min(v);
                b.1[k] = b.1[k].max(v);
            }
        }
    }
    b
}

/// Bounding box of the finite coordinates, per axis; an axis without any finite value gets [0, 0].
fn bounding_box<T: Coord>(x: &[T], dim: usize) -> Bounds {
    let empty = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    let (mut lo, mut hi) = x.par_chunks(dim * CHUNK).map(|c| bounds_serial(c, dim)).reduce(|| empty, merge);
    for k in 0..3 {
        if lo[k] > hi[k] || k >= dim {
            (lo[k], hi[k]) = (0.0, 0.0);
        }
    }
    (lo, hi)
}

/// Cell counts per axis for `extent` at cell size `cell`, if they fit both caps.
fn counts_if_fit(extent: [f64; 3], dim: usize, cell: f64, max_cells: usize, max_axis: usize) -> Option<[usize; 3]> {
    let inv = 1.0 / cell;
    let mut counts = [1usize; 3];
    let mut total = 1.0f64;
    for k in 0..dim {
        let c = (extent[k] * inv).floor() + 1.0;
        if !c.is_finite() || c > max_axis as f64 {
            return None;
        }
        total *= c;
        counts[k] = c as usize;
    }
    (total <= max_cells as f64).then_some(counts)
}

impl Geometry {
    /// Fits a grid of cells of at least `cell_size` (times `1 + CELL_MARGIN`) over the bounding box
    /// of the finite coordinates of `x`, doubling the cell size until the caps hold. A non-positive
    /// or non-finite `cell_size`, or an infinite extent, gives a single cell (always correct).
    pub fn fit<T: Coord>(x: &[T], dim: usize, cell_size: f64, max_cells: usize, max_axis: usize) -> Geometry {
        let (lo, hi) = bounding_box(x, dim);
        let extent = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
        let mut cell = cell_size * (1.0 + CELL_MARGIN);
        while cell.is_finite() && cell > 0.0 {
            if let Some(counts) = counts_if_fit(extent, dim, cell, max_cells, max_axis) {
                return Geometry { dim, origin: lo, cell_size: cell, inv: 1.0 / cell, counts };
            }
            cell *= 2.0;
        }
        Geometry { dim, origin: lo, cell_size: f64::INFINITY, inv: 0.0, counts: [1; 3] }
    }

    pub fn num_cells(&self) -> usize {
        self.counts.iter().product()
    }

    /// Cell coordinate along axis `k`: floor of the offset in cells, clamped to the grid; a
    /// non-finite coordinate goes to cell 0.
    #[inline]
    pub fn axis_cell(&self, k: usize, v: f64) -> u32 {
        let c = (v - self.origin[k]) * self.inv;
        let last = (self.counts[k] - 1) as f64;
        // Truncation is the floor for c >= 0, and below 0 we clamp anyway (no libm `floor` call
        // on baseline x86-64). c is NaN for an infinite offset in the single-cell fallback.
        if !v.is_finite() || c.is_nan() || c < 1.0 {
            0
        } else if c >= last {
            last as u32
        } else {
            c as u32
        }
    }

    #[inline]
    pub fn cell_of(&self, p: [f64; 3]) -> [u32; 3] {
        let mut c = [0u32; 3];
        for (k, ck) in c.iter_mut().enumerate().take(self.dim) {
            *ck = self.axis_cell(k, p[k]);
        }
        c
    }

    /// Linear index, x fastest: `cx + nx * (cy + ny * cz)`.
    #[inline]
    pub fn linear(&self, c: [u32; 3]) -> usize {
        let [nx, ny, _] = self.counts;
        c[0] as usize + nx * (c[1] as usize + ny * c[2] as usize)
    }

    /// Cell coordinates of every particle, computed in parallel.
    pub fn cells_of_all<T: Coord>(&self, x: &[T]) -> Vec<[u32; 3]> {
        let n = x.len() / self.dim;
        let mut out = vec![[0u32; 3]; n];
        out.par_chunks_mut(CHUNK).zip(x.par_chunks(self.dim * CHUNK)).for_each(|(o, xs)| {
            for (c, p) in o.iter_mut().zip(xs.chunks_exact(self.dim)) {
                *c = self.cell_of(point(p));
            }
        });
        out
    }

    /// Linear cell index of every particle, computed in parallel.
    pub fn linear_of_all<T: Coord>(&self, x: &[T]) -> Vec<u32> {
        let n = x.len() / self.dim;
        let mut out = vec![0u32; n];
        out.par_chunks_mut(CHUNK).zip(x.par_chunks(self.dim * CHUNK)).for_each(|(o, xs)| {
            for (c, p) in o.iter_mut().zip(xs.chunks_exact(self.dim)) {
                *c = self.linear(self.cell_of(point(p))) as u32;
            }
        });
        out
    }
}
