//! Particle placement: primitives filled on a Cartesian lattice, graded (two-resolution) fills,
//! cylinders in rings about their axis ([`fill_rings`]), and imported node lists (CSV, LS-DYNA
//! `*NODE`).
//!
//! # Conventions
//!
//! - Positions are `[f64; 3]`; in 1D and 2D the unused coordinates are 0 (and are ignored on input).
//! - `dim` ∈ {1, 2, 3}. A 2D model is a slab of unit thickness (1 m) and a 1D model a bar of unit
//!   cross-section (1 m²), so a particle's volume is always in m³: `dx^dim × 1 m^(3−dim)`,
//!   numerically `dx^dim`.
//! - Lattice nodes sit at cell centres: a box `[0, L]` filled at spacing `dx` holds particles at
//!   `dx/2, 3dx/2, …`, and no particle lies on a box face, so a symmetry plane through a face sees a
//!   mirror image at the right distance.
//! - Every primitive except the axis-aligned [`Primitive::Box`] has its volumes rescaled so that
//!   they sum to the exact (analytic) volume of the shape; [`Particles::volume_scale`] reports the
//!   factor. A box keeps `dx^dim` per particle: give it extents that are multiples of `dx`.
//! - Nothing here panics on bad input: parameters are checked ([`GeometryError`]) and node files are
//!   parsed with positioned errors ([`NodeError`]).
//!
//! # Primitives in 1D and 2D
//!
//! A 2D (1D) shape is the section of the 3D primitive by the model plane (line):
//!
//! - `Box`, `Sphere`: the first `dim` coordinates (a rectangle/disc in 2D, a segment in 1D);
//! - `Cylinder`, `HollowCylinder`, `Plate` whose axis (normal) lies in the model's axes: the section
//!   through the axis — a rectangle of width `2 radius` (two strips of width `outer − inner` for a
//!   hollow cylinder) in 2D, a segment of length `length` (`thickness`) in 1D. A hollow cylinder
//!   along the 1D line is empty and rejected;
//! - the same primitives with the axis perpendicular to the model's axes (along z in 2D, along y or z
//!   in 1D): the cross-section — a disc (`Cylinder`, `Plate`) or an annulus (`HollowCylinder`) in 2D,
//!   a segment or a pair of segments in 1D. `length` and `thickness` are then irrelevant;
//! - an oblique axis (neither in nor perpendicular to the model's axes) is an error.
//!
//! # Graded fills
//!
//! [`fill_graded`] partitions the shape's bounding box into coarse cells (the coarse lattice's cells,
//! anchored at the bounding box minimum, or at a corner given: on the symmetry planes). A coarse
//! cell is *refined* when a fine lattice node inside both the shape and the fine region falls in
//! it. Refined cells hold the fine lattice nodes inside the shape (all of them: the fine region is
//! widened to whole coarse cells); the other cells hold their coarse node when it lies inside the
//! shape. Both lattices are anchored at the same corner, so when `coarse = m × fine` (m integer)
//! the fine nodes tile each refined cell exactly.
//!
//! Guarantees: fine–fine distances are ≥ `fine`, coarse–coarse ≥ `coarse`, and coarse–fine ≥
//! `coarse/2` (≥ `coarse/2 + fine/2` when `coarse/fine` is an integer), so the minimum pair distance
//! is ≥ `min(fine, coarse/2)` (= `fine` for an integer ratio); every coarse cell whose centre lies
//! in the shape holds at least one particle, so no gap is larger than a coarse cell.

mod fill;
mod lattice;
mod nodes;
mod primitive;
mod rings;
mod spacing;

pub use fill::{at_corners, fill, fill_graded, fill_graded_with_limit, fill_with, fill_with_limit, Fill, Particles};
pub use nodes::{read_csv_nodes, read_lsdyna_nodes, NodeError, NodeList};
pub use primitive::Primitive;
pub(crate) use rings::axis_index;
pub use rings::{fill_rings, Core, Rings};
pub use spacing::estimate_spacing;

use std::fmt;

/// The most particles a single fill (or node list) may produce.
pub const MAX_PARTICLES: u64 = 50_000_000;

/// Why a shape could not be filled, or a node list turned into particles.
#[derive(Clone, Debug, PartialEq)]
pub enum GeometryError {
    /// A dimension other than 1, 2 or 3.
    Dimension(usize),
    /// A parameter is out of range: non-positive, NaN or infinite, a zero or oblique axis, …
    Parameter {
        /// The parameter's name, as in [`Primitive`] (`radius`, `axis`, `spacing`, …).
        name: &'static str,
        /// What is wrong with it, with the value.
        message: String,
    },
    /// The shape would hold more than [`MAX_PARTICLES`] particles.
    TooManyParticles {
        /// The number of particles (exact, or estimated from the volume when `estimated`).
        count: u64,
        /// Whether `count` is an estimate (volume / spacing^dim) rather than an exact count.
        estimated: bool,
        /// The limit, [`MAX_PARTICLES`].
        limit: u64,
    },
    /// The shape's bounding box spans too many lattice rows to scan (a very thin oblique shape).
    TooManyRows {
        /// The number of lattice rows of the bounding box.
        rows: u64,
    },
    /// No lattice node lies inside the shape: the spacing is too coarse for it.
    Empty {
        /// The spacing that was asked for.
        spacing: f64,
    },
    /// A node list cannot become particles (no nodes, coincident nodes, nodes off the model plane).
    Nodes(String),
}

impl fmt::Display for GeometryError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            GeometryError::Dimension(d) => write!(f, "dimension must be 1, 2 or 3, found {d}"),
            GeometryError::Parameter { message, .. } => f.write_str(message),
            GeometryError::TooManyParticles { count, estimated, limit } => {
                let about = if *estimated { "about " } else { "" };
                write!(f, "the shape would hold {about}{count} particles, more than the limit of {limit}; ")?;
                f.write_str("use a coarser spacing")
            }
            GeometryError::TooManyRows { rows } => {
                write!(f, "the shape's bounding box spans {rows} lattice rows, too many to scan; use a coarser spacing")
            }
            GeometryError::Empty { spacing } => {
                write!(f, "no lattice node at spacing {spacing} lies inside the shape; use a finer spacing")
            }
            GeometryError::Nodes(message) => f.write_str(message),
        }
    }
}

impl std::error::Error for GeometryError {}

/// Which of `points` lie inside `shape` (in `dim` dimensions, with a small tolerance).
pub fn inside(shape: &Primitive, dim: usize, points: &[[f64; 3]]) -> Result<Vec<bool>, GeometryError> {
    let s = primitive::Shape::resolve(shape, dim)?;
    let (lo, hi) = s.bbox();
    let size = super::max_keeping_nan(0.0, (0..dim).map(|k| hi[k] - lo[k]));
    let tol = 1e-9 * size.max(1e-300);
    Ok(points.iter().map(|p| s.contains(*p, tol)).collect())
}
