//! The Cartesian lattice `origin + index × dx`, boxes of lattice indices, and the row scan that
//! enumerates the lattice nodes of a shape run by run.

use super::primitive::Shape;
use super::GeometryError;

/// The most lattice rows a scan may visit: this many per particle the fill may place, and
/// [`MIN_ROWS`] more (a bounding box much larger than its shape's volume).
const ROWS_PER_PARTICLE: f64 = 4.0;
const MIN_ROWS: f64 = 1e6;

/// Relative tolerance (of the spacing) by which shape boundaries are widened, so that a node on a
/// boundary up to rounding counts as inside.
pub(crate) const REL_TOL: f64 = 1e-9;

/// Indices beyond this are clamped (an f64 → i64 conversion of a huge quotient).
const INDEX_LIMIT: f64 = 1e15;

/// The nodes `origin + index × dx` along the model's `dim` axes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Lattice {
    pub origin: [f64; 3],
    pub dx: f64,
    pub dim: usize,
}

/// An inclusive box of lattice indices; the axes beyond `dim` are `0..=0`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct IndexBox {
    pub lo: [i64; 3],
    pub hi: [i64; 3],
}

impl Lattice {
    /// The position of node `idx` (unused coordinates 0).
    pub fn position(&self, idx: [i64; 3]) -> [f64; 3] {
        let mut p = [0.0; 3];
        for i in 0..self.dim {
            p[i] = self.origin[i] + idx[i] as f64 * self.dx;
        }
        p
    }

    /// The smallest index whose node is ≥ `v` along axis `i`.
    fn ceil_index(&self, i: usize, v: f64) -> i64 {
        ((v - self.origin[i]) / self.dx).ceil().clamp(-INDEX_LIMIT, INDEX_LIMIT) as i64
    }

    /// The largest index whose node is ≤ `v` along axis `i`.
    fn floor_index(&self, i: usize, v: f64) -> i64 {
        ((v - self.origin[i]) / self.dx).floor().clamp(-INDEX_LIMIT, INDEX_LIMIT) as i64
    }

    /// The nodes inside the box `[min, max]` (widened by the boundary tolerance).
    pub fn index_box(&self, min: [f64; 3], max: [f64; 3]) -> IndexBox {
        let tol = REL_TOL * self.dx;
        let (mut lo, mut hi) = ([0; 3], [0; 3]);
        for i in 0..self.dim {
            lo[i] = self.ceil_index(i, min[i] - tol);
            hi[i] = self.floor_index(i, max[i] + tol);
        }
        IndexBox { lo, hi }
    }
}

impl IndexBox {
    /// The number of indices along axis `i` (0 when empty).
    pub fn len(&self, i: usize) -> u64 {
        (self.hi[i] - self.lo[i] + 1).max(0) as u64
    }

    /// Whether the box holds no index.
    pub fn is_empty(&self) -> bool {
        (0..3).any(|i| self.len(i) == 0)
    }

    /// The box's intersection with `other`.
    pub fn intersect(&self, other: &IndexBox) -> IndexBox {
        let mut b = *self;
        for i in 0..3 {
            b.lo[i] = b.lo[i].max(other.lo[i]);
            b.hi[i] = b.hi[i].min(other.hi[i]);
        }
        b
    }
}

/// The row axis of a scan: the longest axis of the box, so that rows are few and long.
fn row_axis(b: &IndexBox, dim: usize) -> usize {
    (0..dim).rev().max_by_key(|&i| b.len(i)).unwrap_or(0)
}

/// The number of rows of a scan of `b` along axis `k`.
fn rows(b: &IndexBox, k: usize) -> f64 {
    (0..3).filter(|&i| i != k).map(|i| b.len(i) as f64).product()
}

/// Calls `f(row, k, lo, hi)` for each run of consecutive nodes of `shape` in `b`: the nodes `row`
/// with `row[k]` in `lo..=hi`. Fails when the scan would visit more rows than a fill of at most
/// `max` particles may.
pub(crate) fn scan(
    shape: &Shape,
    lat: &Lattice,
    b: &IndexBox,
    max: u64,
    mut f: impl FnMut([i64; 3], usize, i64, i64),
) -> Result<(), GeometryError> {
    if b.is_empty() {
        return Ok(());
    }
    let k = row_axis(b, lat.dim);
    let n_rows = rows(b, k);
    if n_rows > ROWS_PER_PARTICLE * max as f64 + MIN_ROWS {
        return Err(GeometryError::TooManyRows { rows: n_rows as u64 });
    }
    let others: Vec<usize> = (0..3).filter(|&i| i != k).collect();
    let (o0, o1) = (others[0], others[1]);
    let tol = REL_TOL * lat.dx;
    let mut intervals = Vec::with_capacity(2);
    for a in b.lo[o0]..=b.hi[o0] {
        for c in b.lo[o1]..=b.hi[o1] {
            let mut row = [0; 3];
            (row[o0], row[o1]) = (a, c);
            shape.row_intervals(lat.position(row), k, tol, &mut intervals);
            for &(t0, t1) in &intervals {
                let lo = lat.ceil_index(k, t0).max(b.lo[k]);
                let hi = lat.floor_index(k, t1).min(b.hi[k]);
                if lo <= hi {
                    f(row, k, lo, hi);
                }
            }
        }
    }
    Ok(())
}

/// The number of nodes of `shape` in `b` (the scan bounded as for `max` particles).
pub(crate) fn count(shape: &Shape, lat: &Lattice, b: &IndexBox, max: u64) -> Result<u64, GeometryError> {
    let mut n = 0u64;
    scan(shape, lat, b, max, |_, _, lo, hi| n += (hi - lo + 1) as u64)?;
    Ok(n)
}

/// Appends the positions of the nodes of `shape` in `b` to `out`, in scan order.
pub(crate) fn collect(
    shape: &Shape,
    lat: &Lattice,
    b: &IndexBox,
    max: u64,
    out: &mut Vec<[f64; 3]>,
) -> Result<(), GeometryError> {
    scan(shape, lat, b, max, |mut row, k, lo, hi| {
        for i in lo..=hi {
            row[k] = i;
            out.push(lat.position(row));
        }
    })
}
