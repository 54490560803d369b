//! Morton (Z-order) reordering: sorting particles by the interleaved bits of their cell
//! coordinates puts particles that are close in space close in memory.
//!
//! The cells are those of [`Grid::build`](super::Grid::build) at the same cell size (same bounding
//! box, same cap on the number of cells), further coarsened if an axis needs more cells than its
//! Morton bits hold (21 bits per axis in 3D, 32 in 2D and 1D).

use super::geometry::{check_layout, Geometry};
use super::{max_cells, Coord, Grid};
use rayon::prelude::*;

/// Bits of each cell coordinate that enter the code: 32 in 1D and 2D, 21 in 3D.
fn bits_per_axis(dim: usize) -> u32 {
    if dim == 3 {
        21
    } else {
        32
    }
}

/// Spreads the low 32 bits of `v` to the even bits of the result.
fn part1by1(v: u32) -> u64 {
    let mut x = v as u64;
    x = (x | (x << 16)) & 0x0000_FFFF_0000_FFFF;
    x = (x | (x << 8)) & 0x00FF_00FF_00FF_00FF;
    x = (x | (x << 4)) & 0x0F0F_0F0F_0F0F_0F0F;
    x = (x | (x << 2)) & 0x3333_3333_3333_3333;
    (x | (x << 1)) & 0x5555_5555_5555_5555
}

/// Spreads the low 21 bits of `v` to every third bit of the result.
fn part1by2(v: u32) -> u64 {
    let mut x = (v & 0x1F_FFFF) as u64;
    x = (x | (x << 32)) & 0x001F_0000_0000_FFFF;
    x = (x | (x << 16)) & 0x001F_0000_FF00_00FF;
    x = (x | (x << 8)) & 0x100F_00F0_0F00_F00F;
    x = (x | (x << 4)) & 0x10C3_0C30_C30C_30C3;
    (x | (x << 2)) & 0x1249_2492_4924_9249
}

/// The Morton code of cell coordinates `c`: bit b of axis k goes to bit `b * dim + k`
/// (x lowest). Coordinates beyond `dim` are ignored; in 3D only the low 21 bits count.
pub fn morton_code(c: [u32; 3], dim: usize) -> u64 {
    match dim {
        1 => c[0] as u64,
        2 => part1by1(c[0]) | (part1by1(c[1]) << 1),
        _ => part1by2(c[0]) | (part1by2(c[1]) << 1) | (part1by2(c[2]) << 2),
    }
}

fn morton_geometry<T: Coord>(x: &[T], dim: usize, cell_size: f64) -> Geometry {
    let n = check_layout(x, dim);
    Geometry::fit(x, dim, cell_size, max_cells(n), 1usize << bits_per_axis(dim))
}

/// The Morton code of each particle's cell (see the module documentation for the cells).
pub fn morton_codes<T: Coord>(x: &[T], dim: usize, cell_size: f64) -> Vec<u64> {
    let geom = morton_geometry(x, dim, cell_size);
    geom.cells_of_all(x).into_par_iter().map(|c| morton_code(c, dim)).collect()
}

/// The permutation that orders particles by the Morton code of their cell, ties by index:
/// particle `perm[k]` goes to new position k (use it with [`apply_permutation`]).
///
/// Counting-sorts the particles by cell (stable, so by index within a cell), then sorts the
/// non-empty cells by code: distinct cells have distinct codes, as each coordinate fits its bits.
pub fn morton_permutation<T: Coord>(x: &[T], dim: usize, cell_size: f64) -> Vec<u32> {
    let grid = Grid::with_geometry(x, morton_geometry(x, dim, cell_size));
    let start = grid.cell_start();
    let mut cells: Vec<(u64, u32)> = (0..grid.num_cells())
        .filter(|&c| start[c] < start[c + 1])
        .map(|c| (morton_code(grid.cell_coords_of_index(c), dim), c as u32))
        .collect();
    cells.par_sort_unstable();
    let mut perm = Vec::with_capacity(grid.num_particles());
    for (_, c) in cells {
        let c = c as usize;
        perm.extend_from_slice(&grid.order()[start[c] as usize..start[c + 1] as usize]);
    }
    perm
}

/// Gathers `comps` interleaved components per particle: `new[k] = old[perm[k]]`.
///
/// Panics if `data.len() != perm.len() * comps` or an index is out of range.
pub fn apply_permutation<T: Copy>(data: &[T], comps: usize, perm: &[u32]) -> Vec<T> {
    assert_eq!(data.len(), perm.len() * comps, "apply_permutation: {} values for {} particles", data.len(), perm.len());
    let mut out = Vec::with_capacity(data.len());
    for &p in perm {
        let p = p as usize;
        out.extend_from_slice(&data[p * comps..(p + 1) * comps]);
    }
    out
}
