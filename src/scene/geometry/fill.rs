//! Filling primitives with particles: a uniform lattice ([`fill`], [`fill_with`]), a two-level
//! graded lattice ([`fill_graded`]), and either one node-centred ([`at_corners`]).

use super::lattice::{collect, count, scan, IndexBox, Lattice, REL_TOL};
use super::primitive::{finite_point, positive, Primitive, Shape};
use super::{GeometryError, MAX_PARTICLES};
use std::collections::{BTreeMap, HashSet};

/// How to fill a shape: the lattice spacing and, optionally, where to anchor the lattice.
#[derive(Clone, Debug, PartialEq)]
pub struct Fill {
    /// The lattice spacing `dx` (m), > 0.
    pub spacing: f64,
    /// A lattice node (the lattice is `origin + k dx`); by default the node at the shape's bounding
    /// box minimum + `dx/2` along every axis, so that a box `[0, L]` holds `dx/2, 3dx/2, …`.
    pub origin: Option<[f64; 3]>,
}

impl Fill {
    /// A fill at `spacing` with the default lattice anchor.
    pub fn new(spacing: f64) -> Fill {
        Fill { spacing, origin: None }
    }

    /// A fill at `spacing` whose cells have a corner at `corner` (its nodes half a spacing off).
    pub fn from_corner(spacing: f64, corner: [f64; 3], dim: usize) -> Fill {
        Fill { spacing, origin: Some(node_off(corner, spacing, dim)) }
    }
}

/// Particles placed in a shape: one entry per particle in each vector.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Particles {
    /// Positions (m); unused coordinates 0 in 1D and 2D.
    pub positions: Vec<[f64; 3]>,
    /// Volumes (m³, per the unit slab/bar convention): `spacing^dim × volume_scale`.
    pub volumes: Vec<f64>,
    /// Each particle's lattice spacing (m).
    pub spacing: Vec<f64>,
    /// The factor applied to `spacing^dim` so that the volumes sum to the shape's exact volume
    /// (1 for a box and for node lists).
    pub volume_scale: f64,
}

impl Particles {
    /// The number of particles.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether there is no particle.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// The sum of the volumes.
    pub fn total_volume(&self) -> f64 {
        self.volumes.iter().sum()
    }

    /// Particles with volumes `spacing^dim`, rescaled to sum to `exact` when given.
    pub(crate) fn from_parts(positions: Vec<[f64; 3]>, spacing: Vec<f64>, dim: usize, exact: Option<f64>) -> Particles {
        let volumes: Vec<f64> = spacing.iter().map(|s| s.powi(dim as i32)).collect();
        let scale = exact.map_or(1.0, |v| v / volumes.iter().sum::<f64>());
        let volumes = volumes.into_iter().map(|v| v * scale).collect();
        Particles { positions, volumes, spacing, volume_scale: scale }
    }
}

/// Fills `shape` at `spacing` in `dim` dimensions, the lattice anchored at the shape's bounding box
/// minimum + `spacing/2`. See [`fill_with`].
pub fn fill(shape: &Primitive, spacing: f64, dim: usize) -> Result<Particles, GeometryError> {
    fill_with(shape, &Fill::new(spacing), dim)
}

/// Fills `shape` with the lattice nodes inside it (boundaries included up to rounding): each particle
/// gets the volume `dx^dim`, rescaled to the exact volume for every primitive but a box.
///
/// Fails on bad parameters, when no node lies inside, or beyond [`MAX_PARTICLES`] particles.
pub fn fill_with(shape: &Primitive, how: &Fill, dim: usize) -> Result<Particles, GeometryError> {
    fill_with_limit(shape, how, dim, MAX_PARTICLES)
}

/// [`fill_with`], failing beyond `limit` particles instead of [`MAX_PARTICLES`]: before anything is
/// allocated when the shape's volume says so, else once they are counted.
pub fn fill_with_limit(shape: &Primitive, how: &Fill, dim: usize, limit: u64) -> Result<Particles, GeometryError> {
    let shape = Shape::resolve(shape, dim)?;
    let dx = positive("spacing", how.spacing)?;
    let origin = match how.origin {
        Some(o) => finite_point("origin", o)?,
        None => default_origin(&shape, dx),
    };
    let lat = Lattice { origin, dx, dim };
    let (min, max) = shape.bbox();
    let b = lat.index_box(min, max);
    check_estimate(shape.volume() / dx.powi(dim as i32), limit)?;
    let n = checked_count(&shape, &lat, &b, limit)?;
    if n == 0 {
        return Err(GeometryError::Empty { spacing: dx });
    }
    let mut positions = Vec::with_capacity(n as usize);
    collect(&shape, &lat, &b, limit, &mut positions)?;
    let exact = shape.rescaled().then(|| shape.volume());
    Ok(Particles::from_parts(positions, vec![dx; n as usize], dim, exact))
}

/// The default lattice anchor: the bounding box minimum + `dx/2` (unused coordinates 0).
fn default_origin(shape: &Shape, dx: f64) -> [f64; 3] {
    node_off(shape.bbox().0, dx, shape.dim)
}

/// The lattice node of the cell with corner `corner`: `corner + dx/2` (unused coordinates 0).
fn node_off(corner: [f64; 3], dx: f64, dim: usize) -> [f64; 3] {
    let mut o = [0.0; 3];
    for i in 0..dim {
        o[i] = corner[i] + 0.5 * dx;
    }
    o
}

fn too_many(count: u64, estimated: bool, limit: u64) -> GeometryError {
    GeometryError::TooManyParticles { count, estimated, limit }
}

/// Rejects early a shape whose volume alone says it holds far more than the limit `max`.
fn check_estimate(estimate: f64, max: u64) -> Result<(), GeometryError> {
    if estimate > 1.5 * max as f64 + 100.0 || estimate.is_nan() {
        let n = if estimate.is_finite() { estimate.round() as u64 } else { u64::MAX };
        return Err(too_many(n, true, max));
    }
    Ok(())
}

/// The exact node count of `shape` in `b`, failing beyond the limit `max`.
fn checked_count(shape: &Shape, lat: &Lattice, b: &IndexBox, max: u64) -> Result<u64, GeometryError> {
    let n = count(shape, lat, b, max)?;
    if n > max {
        return Err(too_many(n, false, max));
    }
    Ok(n)
}

/// Fills `shape` with two resolutions: `fine` spacing in and around `fine_region`, `coarse`
/// elsewhere (`fine ≤ coarse`; best with `coarse` an integer multiple of `fine`).
///
/// The rule (see the module documentation): the bounding box of `shape` is cut into coarse cells;
/// a cell holding a fine node inside both `shape` and `fine_region` is refined and gets all its fine
/// nodes inside `shape`; any other cell gets its coarse node (its centre) when inside `shape`. So
/// fine and coarse particles never overlap, the minimum pair distance is ≥ `min(fine, coarse/2)`
/// (`fine` for an integer ratio), and no cell whose centre lies in the shape is left empty. Each
/// particle's `spacing` is `fine` or `coarse`, its volume `spacing^dim`, and the total is rescaled
/// to the exact volume of `shape` (for every primitive, a box included).
///
/// `corner` is a corner of the coarse cells (their faces lie at `corner + k coarse` along each
/// axis, and the fine cells' at `corner + k fine`); by default the shape's bounding box minimum. A
/// symmetry plane must lie on a cell face, so that the first row of particles sits half a
/// spacing off it.
pub fn fill_graded(
    shape: &Primitive,
    fine: f64,
    coarse: f64,
    fine_region: &Primitive,
    dim: usize,
    corner: Option<[f64; 3]>,
) -> Result<Particles, GeometryError> {
    fill_graded_with_limit(shape, fine, coarse, fine_region, dim, corner, MAX_PARTICLES)
}

/// [`fill_graded`], failing beyond `max` particles instead of [`MAX_PARTICLES`].
pub fn fill_graded_with_limit(
    shape: &Primitive,
    fine: f64,
    coarse: f64,
    fine_region: &Primitive,
    dim: usize,
    corner: Option<[f64; 3]>,
    max: u64,
) -> Result<Particles, GeometryError> {
    let grading = Grading::new(shape, fine, coarse, fine_region, dim, corner, max)?;
    let refined = grading.refined_cells()?;
    let mut positions = Vec::new();
    grading.coarse_nodes(&refined, &mut positions)?;
    let n_coarse = positions.len();
    grading.fine_nodes(&refined, n_coarse, &mut positions)?;
    if positions.is_empty() {
        return Err(GeometryError::Empty { spacing: coarse });
    }
    let mut spacing = vec![grading.coarse.dx; n_coarse];
    spacing.resize(positions.len(), grading.fine.dx);
    Ok(Particles::from_parts(positions, spacing, dim, Some(grading.shape.volume())))
}

/// The two lattices of a graded fill, both anchored at one corner of the coarse cells.
struct Grading {
    shape: Shape,
    region: Shape,
    fine: Lattice,
    coarse: Lattice,
    /// The most particles the fill may place.
    max: u64,
}

/// A coarse cell, by the index of its coarse node.
type Cell = [i64; 3];

impl Grading {
    fn new(
        shape: &Primitive,
        fine: f64,
        coarse: f64,
        fine_region: &Primitive,
        dim: usize,
        corner: Option<[f64; 3]>,
        max: u64,
    ) -> Result<Grading, GeometryError> {
        let shape = Shape::resolve(shape, dim)?;
        let region = Shape::resolve(fine_region, dim)?;
        let (f, c) = (positive("fine", fine)?, positive("coarse", coarse)?);
        if c < f {
            let msg = format!("coarse spacing ({c}) must be ≥ fine spacing ({f})");
            return Err(GeometryError::Parameter { name: "coarse", message: msg });
        }
        let corner = match corner {
            Some(p) => finite_point("corner", p)?,
            None => shape.bbox().0,
        };
        let fine = Lattice { origin: node_off(corner, f, dim), dx: f, dim };
        let coarse = Lattice { origin: node_off(corner, c, dim), dx: c, dim };
        check_estimate(
            shape.volume() / c.powi(dim as i32) + region.volume().min(shape.volume()) / f.powi(dim as i32),
            max,
        )?;
        Ok(Grading { shape, region, fine, coarse, max })
    }

    /// The coarse cell holding fine node index `i` along an axis.
    fn cell_of(&self, i: i64) -> i64 {
        ((i as f64 + 0.5) * self.fine.dx / self.coarse.dx).floor() as i64
    }

    /// The fine node indices along an axis whose cell is `j` (inclusive; empty when lo > hi).
    fn fine_range(&self, j: i64) -> (i64, i64) {
        let ratio = self.coarse.dx / self.fine.dx;
        let mut lo = (j as f64 * ratio).floor() as i64 - 2;
        while self.cell_of(lo) < j {
            lo += 1;
        }
        let mut hi = lo - 1;
        while self.cell_of(hi + 1) == j {
            hi += 1;
        }
        (lo, hi)
    }

    /// The cells holding a fine node inside both the shape and the fine region.
    fn refined_cells(&self) -> Result<HashSet<Cell>, GeometryError> {
        let (smin, smax) = self.shape.bbox();
        let (rmin, rmax) = self.region.bbox();
        let b = self.fine.index_box(smin, smax).intersect(&self.fine.index_box(rmin, rmax));
        checked_count(&self.shape, &self.fine, &b, self.max)?;
        let tol = REL_TOL * self.fine.dx;
        let mut cells = HashSet::new();
        scan(&self.shape, &self.fine, &b, self.max, |mut row, k, lo, hi| {
            for i in lo..=hi {
                row[k] = i;
                if self.region.contains(self.fine.position(row), tol) {
                    cells.insert(self.cell_index(row));
                }
            }
        })?;
        Ok(cells)
    }

    fn cell_index(&self, fine_idx: [i64; 3]) -> Cell {
        let mut c = [0; 3];
        for i in 0..self.fine.dim {
            c[i] = self.cell_of(fine_idx[i]);
        }
        c
    }

    /// Appends the coarse nodes inside the shape whose cell is not refined.
    fn coarse_nodes(&self, refined: &HashSet<Cell>, out: &mut Vec<[f64; 3]>) -> Result<(), GeometryError> {
        let (min, max) = self.shape.bbox();
        let b = self.coarse.index_box(min, max);
        checked_count(&self.shape, &self.coarse, &b, self.max)?;
        scan(&self.shape, &self.coarse, &b, self.max, |mut row, k, lo, hi| {
            for i in lo..=hi {
                row[k] = i;
                if !refined.contains(&row) {
                    out.push(self.coarse.position(row));
                }
            }
        })
    }

    /// Appends the fine nodes inside the shape of every refined cell (cells in index order).
    fn fine_nodes(
        &self,
        refined: &HashSet<Cell>,
        n_coarse: usize,
        out: &mut Vec<[f64; 3]>,
    ) -> Result<(), GeometryError> {
        let per_cell = (self.coarse.dx / self.fine.dx).ceil().powi(self.fine.dim as i32);
        let estimate = n_coarse as f64 + refined.len() as f64 * per_cell;
        if estimate > self.max as f64 {
            return Err(too_many(estimate as u64, true, self.max));
        }
        let mut cells: Vec<Cell> = refined.iter().copied().collect();
        cells.sort_unstable();
        for cell in cells {
            collect(&self.shape, &self.fine, &self.cell_box(cell), self.max, out)?;
        }
        Ok(())
    }

    /// The fine indices of the nodes in `cell`.
    fn cell_box(&self, cell: Cell) -> IndexBox {
        let (mut lo, mut hi) = ([0; 3], [0; 3]);
        for i in 0..self.fine.dim {
            (lo[i], hi[i]) = self.fine_range(cell[i]);
        }
        IndexBox { lo, hi }
    }
}

/// The node-centred form of a cell-centred fill (EK18 §4: particles at the nodes of a hexahedral
/// mesh): the same cells — each particle's cell of its own spacing around it — with the particles
/// at their corners instead of their centres. A corner shared by several cells is one particle,
/// whose volume is `1/2^dim` of each of its cells' (so a box's face nodes get a half, its edges a
/// quarter, its corners an eighth, and the total is the fill's) and whose spacing is the mean of
/// its cells' spacings. A body then has a particle layer on each of its faces: a plate `t` thick
/// filled at `t` has two layers, where the cell-centred fill has one.
///
/// Corners closer than a quarter of the finest spacing are one node (exact for the fills of this
/// module when coarse/fine is a whole number or a half-integer); particles come in lattice order.
pub fn at_corners(cells: &Particles, dim: usize) -> Particles {
    let fine = cells.spacing.iter().copied().fold(f64::INFINITY, f64::min);
    let Some(anchor) = cells.positions.first() else { return cells.clone() };
    let step = 0.5 * fine;
    let key = |p: [f64; 3]| -> [i64; 3] {
        let mut k = [0; 3];
        for a in 0..dim {
            k[a] = ((p[a] - anchor[a]) / step).round() as i64;
        }
        k
    };
    // [z, y, x] keys: particles in lattice order. Value: position, volume, spacing sum, cells.
    let mut nodes: BTreeMap<[i64; 3], ([f64; 3], f64, f64, u32)> = BTreeMap::new();
    let share = 0.5f64.powi(dim as i32);
    for ((centre, &vol), &s) in cells.positions.iter().zip(&cells.volumes).zip(&cells.spacing) {
        for corner in 0..1usize << dim {
            let mut p = *centre;
            for (a, c) in p.iter_mut().enumerate().take(dim) {
                *c += if corner >> a & 1 == 1 { 0.5 * s } else { -0.5 * s };
            }
            let [x, y, z] = key(p);
            let node = nodes.entry([z, y, x]).or_insert((p, 0.0, 0.0, 0));
            node.1 += share * vol;
            node.2 += s;
            node.3 += 1;
        }
    }
    let mut out = Particles { volume_scale: cells.volume_scale, ..Particles::default() };
    for (p, vol, spacing_sum, count) in nodes.into_values() {
        out.positions.push(p);
        out.volumes.push(vol);
        out.spacing.push(spacing_sum / count as f64);
    }
    out
}
