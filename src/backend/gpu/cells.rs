//! The GPU cell list: the same grid as the CPU's [`crate::grid::Grid`], built entirely on the GPU
//! and recorded into the caller's command encoder (nothing is read back).
//!
//! # What `record` computes, in order
//!
//! 1. `bbox`: per-workgroup partial bounding boxes of the finite coordinates and the largest
//!    smoothing length (NaN ignored, starting from 0 like the CPU backend's `h_max`), compared as
//!    order-preserving integer keys so the result is exact (no flush of subnormals, no NaN
//!    surprises in `min`/`max`).
//! 2. `geometry` (one workgroup, then one thread): combines the partials and replicates
//!    `grid::geometry::Geometry::fit` **bit for bit**: the CPU works in f64, so this kernel (and
//!    the per-particle cell computation) uses a small software f64 (`cl_*` functions below: add,
//!    multiply, reciprocal, floor, all rounded to nearest even). The requested cell size is
//!    `support as f64 * h_max as f64 / cells_per_cutoff`, times `1 + CELL_MARGIN`, doubled until
//!    the cell count fits `max_cells(n)`, exactly like
//!    `Grid::build(x, dim, support as f64 * h_max as f64 / cells_per_cutoff as f64)`.
//!
//! With `cells_per_cutoff` = 2 a walk covers the cut-off with 5 cells along each axis instead of
//! 3, and [`wgsl_helpers`]' `walk_skips` drops the cells wholly beyond the radius r. In 3D the
//! cells left hold on average 10.5 r³ of space, against 27 r³ for the 27 cells of side r (Steiner's
//! formula: a cube of side r/2 grown by r), so a pass loads and tests 2.6× fewer candidates; with
//! one cell per cut-off the skip alone leaves 20.6 r³. In 2D: 5.4 r² with two cells per
//! cut-off, 8.1 r² with one, against 9 r².
//! 3. `assign`: each particle's clamped cell (non-finite coordinate → cell 0 of that axis) and
//!    an atomic count per cell (the pre-increment value is the particle's arbitrary slot in it).
//! 4. `scan`/`add`: an exclusive prefix sum over the `max_cells + 1` counts, in blocks of 256
//!    with block sums scanned recursively (3 levels up to 16.7 M cells, more if needed).
//! 5. `scatter`: particles to their arbitrary slots in a scratch array.
//! 6. `rank`: each particle counts the particles of its cell with a smaller index (so the order
//!    within a cell is by index, like the CPU's stable counting sort) and writes itself to its
//!    final slot. Work is the sum of squared cell occupancies, ~10–60 per particle.
//!
//! # Buffers (u32 words)
//!
//! `grid` (16 words): `[0..3)` origin (f32 bits), `[3]` cell size (f32 bits, rounded from the
//! f64 in use; +inf for the single-cell fallback), `[4..7)` cells per axis (1 beyond `dim`),
//! `[7]` cells used, `[8]` offset of the sorted particle indices in `cells` (`max_cells + 1`),
//! `[9]` h_max (f32 bits), `[10..12)` `1 / cell size` as f64 bits (low word, high word), the
//! value the cell coordinates are computed with, `[12..14)` the cell size as f64 bits, `[14..16)` 0.
//!
//! `cells` (`max_cells + 1 + n` words): `[c]` first sorted slot of cell `c` for `c` in
//! `0..=cells used` (entries up to `max_cells` are valid and equal `n` past the last cell), cell
//! `c = x + nx * (y + ny * z)`; then at `grid[8]` the `n` particle indices sorted by (cell, index).

use super::device::{Gpu, GpuError};

/// Threads per workgroup of the reductions and scans.
const WG: u32 = 256;
/// Threads per workgroup of the per-particle kernels.
const WG_PARTICLE: u32 = 64;
/// At most this many partial results in the two-level reductions.
const MAX_PARTS: u32 = 1024;
/// Words per partial bounding box: lo x, y, z, hi x, y, z, h_max, padding.
const PART_WORDS: u64 = 8;

/// Declarations shared by the kernels: order-preserving keys of f32 bit patterns.
const COMMON_WGSL: &str = r#"
// ---- f32 bit patterns as order-preserving u32 keys: -inf < ... < -0 < +0 < ... < +inf ----
fn cl_key(b: u32) -> u32 {
    return select(b | 0x80000000u, ~b, (b & 0x80000000u) != 0u);
}
fn cl_unkey(k: u32) -> u32 {
    return select(~k, k & 0x7fffffffu, (k & 0x80000000u) != 0u);
}
fn cl_finite_bits(b: u32) -> bool {
    return (b & 0x7f800000u) != 0x7f800000u;
}
fn cl_nan_bits(b: u32) -> bool {
    return (b & 0x7fffffffu) > 0x7f800000u;
}
"#;

/// A software f64 in WGSL, enough to replicate the CPU grid's arithmetic exactly: conversion
/// from f32, addition, multiplication, reciprocal, floor; round to nearest even; no subnormals
/// (results below 2^-1022 flush to zero, unreachable from f32 inputs).
const SOFT_F64_WGSL: &str = r#"
// ---- Software f64 (the CPU grid computes cells in f64; this replicates it bit for bit) ----
// 64-bit unsigned integers are vec2<u32>(low word, high word).
fn cl_shl(a: vec2<u32>, k: u32) -> vec2<u32> {
    if (k == 0u) { return a; }
    if (k >= 64u) { return vec2<u32>(0u); }
    if (k >= 32u) { return vec2<u32>(0u, a.x << (k - 32u)); }
    return vec2<u32>(a.x << k, (a.y << k) | (a.x >> (32u - k)));
}
fn cl_shr(a: vec2<u32>, k: u32) -> vec2<u32> {
    if (k == 0u) { return a; }
    if (k >= 64u) { return vec2<u32>(0u); }
    if (k >= 32u) { return vec2<u32>(a.y >> (k - 32u), 0u); }
    return vec2<u32>((a.x >> k) | (a.y << (32u - k)), a.y >> k);
}
// a >> k, with every bit shifted out ORed into bit 0 (the "sticky" bit of the rounding).
fn cl_shr_jam(a: vec2<u32>, k: u32) -> vec2<u32> {
    if (k == 0u) { return a; }
    var lost: bool;
    if (k >= 64u) {
        lost = any(a != vec2<u32>(0u));
    } else {
        lost = any(cl_shl(a, 64u - k) != vec2<u32>(0u));
    }
    var r = cl_shr(a, k);
    if (lost) { r.x = r.x | 1u; }
    return r;
}
fn cl_add64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let lo = a.x + b.x;
    return vec2<u32>(lo, a.y + b.y + select(0u, 1u, lo < a.x));
}
fn cl_sub64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    return vec2<u32>(a.x - b.x, a.y - b.y - select(0u, 1u, a.x < b.x));
}
fn cl_lt64(a: vec2<u32>, b: vec2<u32>) -> bool {
    return a.y < b.y || (a.y == b.y && a.x < b.x);
}
fn cl_clz64(a: vec2<u32>) -> u32 {
    if (a.y != 0u) { return countLeadingZeros(a.y); }
    return 32u + countLeadingZeros(a.x);
}
// The full 64-bit product of two u32.
fn cl_mul32(a: u32, b: u32) -> vec2<u32> {
    let a0 = a & 0xffffu;
    let a1 = a >> 16u;
    let b0 = b & 0xffffu;
    let b1 = b >> 16u;
    let p00 = a0 * b0;
    let p01 = a0 * b1;
    let p10 = a1 * b0;
    let p11 = a1 * b1;
    let mid = (p00 >> 16u) + (p01 & 0xffffu) + (p10 & 0xffffu);
    return vec2<u32>((p00 & 0xffffu) | (mid << 16u), p11 + (p01 >> 16u) + (p10 >> 16u) + (mid >> 16u));
}

// A finite f64 is (-1)^neg * m * 2^(e - 52) with m a 53-bit integer whose bit 52 is set, or zero
// (m = 0). inf = 1 marks an infinity (m, e unused).
struct ClF64 {
    neg: u32,
    e: i32,
    m: vec2<u32>,
    inf: u32,
}
fn cl_zero() -> ClF64 {
    return ClF64(0u, 0, vec2<u32>(0u), 0u);
}
fn cl_inf(neg: u32) -> ClF64 {
    return ClF64(neg, 0, vec2<u32>(0u), 1u);
}
fn cl_is_zero(a: ClF64) -> bool {
    return a.inf == 0u && a.m.x == 0u && a.m.y == 0u;
}
// Rounds sig * 2^(e - 62) (sig != 0 any 64-bit value, sticky bits jammed into bit 0) to a
// 53-bit mantissa, to nearest, ties to even.
fn cl_round(neg: u32, e0: i32, sig0: vec2<u32>) -> ClF64 {
    var sig = sig0;
    var e = e0;
    if (sig.x == 0u && sig.y == 0u) { return cl_zero(); }
    let lz = cl_clz64(sig);
    if (lz == 0u) {
        sig = cl_shr_jam(sig, 1u);
        e = e + 1;
    } else if (lz > 1u) {
        sig = cl_shl(sig, lz - 1u);
        e = e - i32(lz - 1u);
    }
    // The leading bit is bit 62: keep bits 62..10, round on bits 9..0.
    let low = sig.x & 0x3ffu;
    var m = cl_shr(sig, 10u);
    if (low > 0x200u || (low == 0x200u && (m.x & 1u) == 1u)) {
        m = cl_add64(m, vec2<u32>(1u, 0u));
        if (m.y >= 0x200000u) {
            m = cl_shr(m, 1u);
            e = e + 1;
        }
    }
    if (e > 1023) { return cl_inf(neg); }
    if (e < -1022) { return ClF64(neg, 0, vec2<u32>(0u), 0u); }
    return ClF64(neg, e, m, 0u);
}
// An f32 as f64 (exact). Callers pass finite values; non-finite ones give an infinity.
fn cl_from_f32(x: f32) -> ClF64 {
    let b = bitcast<u32>(x);
    let neg = b >> 31u;
    let ex = (b >> 23u) & 0xffu;
    var mant = b & 0x7fffffu;
    if (ex == 255u) { return cl_inf(neg); }
    var e: i32;
    if (ex == 0u) {
        if (mant == 0u) { return ClF64(neg, 0, vec2<u32>(0u), 0u); }
        // Subnormal: mant * 2^-149; normalise to a leading bit 23.
        let s = countLeadingZeros(mant) - 8u;
        mant = mant << s;
        e = -126 - i32(s);
    } else {
        mant = mant | 0x800000u;
        e = i32(ex) - 127;
    }
    // mant * 2^(e - 23) = (mant << 29) * 2^(e - 52)
    return ClF64(neg, e, vec2<u32>(mant << 29u, mant >> 3u), 0u);
}
// From f64 bits (low word, high word); subnormals read as zero.
fn cl_from_bits(b: vec2<u32>) -> ClF64 {
    let neg = b.y >> 31u;
    let ex = (b.y >> 20u) & 0x7ffu;
    if (ex == 0x7ffu) { return cl_inf(neg); }
    if (ex == 0u) { return ClF64(neg, 0, vec2<u32>(0u), 0u); }
    return ClF64(neg, i32(ex) - 1023, vec2<u32>(b.x, (b.y & 0xfffffu) | 0x100000u), 0u);
}
fn cl_bits(a: ClF64) -> vec2<u32> {
    let sign = a.neg << 31u;
    if (a.inf != 0u) { return vec2<u32>(0u, sign | 0x7ff00000u); }
    if (cl_is_zero(a)) { return vec2<u32>(0u, sign); }
    return vec2<u32>(a.m.x, sign | (u32(a.e + 1023) << 20u) | (a.m.y & 0xfffffu));
}
// Rounded to the nearest f32 (zero below the normal f32 range).
fn cl_to_f32(a: ClF64) -> f32 {
    let sign = a.neg << 31u;
    if (a.inf != 0u) { return bitcast<f32>(sign | 0x7f800000u); }
    if (cl_is_zero(a)) { return bitcast<f32>(sign); }
    var m = cl_shr(a.m, 29u).x;
    let rest = a.m.x & 0x1fffffffu;
    var e = a.e;
    if (rest > 0x10000000u || (rest == 0x10000000u && (m & 1u) == 1u)) {
        m = m + 1u;
        if (m == 0x1000000u) {
            m = 0x800000u;
            e = e + 1;
        }
    }
    if (e > 127) { return bitcast<f32>(sign | 0x7f800000u); }
    if (e < -126) { return bitcast<f32>(sign); }
    return bitcast<f32>(sign | (u32(e + 127) << 23u) | (m & 0x7fffffu));
}
fn cl_add(a: ClF64, b: ClF64) -> ClF64 {
    if (a.inf != 0u) { return a; }
    if (b.inf != 0u) { return b; }
    if (cl_is_zero(a)) { return b; }
    if (cl_is_zero(b)) { return a; }
    // x: the operand of larger magnitude.
    var x = a;
    var y = b;
    if (b.e > a.e || (b.e == a.e && cl_lt64(a.m, b.m))) {
        x = b;
        y = a;
    }
    let sx = cl_shl(x.m, 10u);
    let sy = cl_shr_jam(cl_shl(y.m, 10u), u32(x.e - y.e));
    if (x.neg == y.neg) { return cl_round(x.neg, x.e, cl_add64(sx, sy)); }
    return cl_round(x.neg, x.e, cl_sub64(sx, sy));
}
fn cl_sub(a: ClF64, b: ClF64) -> ClF64 {
    var nb = b;
    nb.neg = 1u - b.neg;
    return cl_add(a, nb);
}
fn cl_mul(a: ClF64, b: ClF64) -> ClF64 {
    let neg = a.neg ^ b.neg;
    if (a.inf != 0u || b.inf != 0u) { return cl_inf(neg); }
    if (cl_is_zero(a) || cl_is_zero(b)) { return ClF64(neg, 0, vec2<u32>(0u), 0u); }
    // The 106-bit product w3:w2:w1:w0 of the mantissas.
    let p00 = cl_mul32(a.m.x, b.m.x);
    let p01 = cl_mul32(a.m.x, b.m.y);
    let p10 = cl_mul32(a.m.y, b.m.x);
    let p11 = cl_mul32(a.m.y, b.m.y);
    let t1 = cl_add64(cl_add64(vec2<u32>(p00.y, 0u), vec2<u32>(p01.x, 0u)), vec2<u32>(p10.x, 0u));
    let t2 = cl_add64(cl_add64(cl_add64(vec2<u32>(p01.y, 0u), vec2<u32>(p10.y, 0u)), vec2<u32>(p11.x, 0u)),
                      vec2<u32>(t1.y, 0u));
    let w0 = p00.x;
    let w1 = t1.x;
    let w2 = t2.x;
    let w3 = p11.y + t2.y;
    // product >> 42 (64 bits, leading bit 62 or 63), the 42 bits shifted out jammed into bit 0.
    var sig = vec2<u32>((w1 >> 10u) | (w2 << 22u), (w2 >> 10u) | (w3 << 22u));
    if (w0 != 0u || (w1 & 0x3ffu) != 0u) { sig.x = sig.x | 1u; }
    return cl_round(neg, a.e + b.e, sig);
}
// 1 / a = (2^115 / m) * 2^(-e - 63), the quotient by restoring division.
fn cl_recip(a: ClF64) -> ClF64 {
    if (a.inf != 0u) { return ClF64(a.neg, 0, vec2<u32>(0u), 0u); }
    if (cl_is_zero(a)) { return cl_inf(a.neg); }
    let m = a.m;
    var r = vec2<u32>(0u, 0x200000u);
    var q = vec2<u32>(0u);
    // Integer part of 2^53 / m: 1, or 2 when m = 2^52.
    for (var k = 0u; k < 2u; k++) {
        if (!cl_lt64(r, m)) {
            r = cl_sub64(r, m);
            q = cl_add64(q, vec2<u32>(1u, 0u));
        }
    }
    for (var k = 0u; k < 62u; k++) {
        r = cl_shl(r, 1u);
        q = cl_shl(q, 1u);
        if (!cl_lt64(r, m)) {
            r = cl_sub64(r, m);
            q.x = q.x | 1u;
        }
    }
    if (r.x != 0u || r.y != 0u) { q.x = q.x | 1u; }
    return cl_round(a.neg, -a.e - 1, q);
}
// floor(a) as u32 for a >= 1, saturated at 0xffffffff; 0 for a < 1 (negative values included).
fn cl_floor_u32(a: ClF64) -> u32 {
    if (a.inf != 0u) { return select(0xffffffffu, 0u, a.neg != 0u); }
    if (a.neg != 0u || cl_is_zero(a) || a.e < 0) { return 0u; }
    if (a.e >= 32) { return 0xffffffffu; }
    return cl_shr(a.m, u32(52 - a.e)).x;
}
// The CPU grid's `axis_cell`: floor((v - o) * inv) in f64, clamped to [0, n - 1]; a
// non-finite coordinate goes to cell 0.
fn cl_axis_cell(v: f32, o: f32, inv: ClF64, n: u32) -> u32 {
    if ((bitcast<u32>(v) & 0x7f800000u) == 0x7f800000u) { return 0u; }
    let c = cl_floor_u32(cl_mul(cl_sub(cl_from_f32(v), cl_from_f32(o)), inv));
    return min(c, n - 1u);
}
"#;

/// Accessors of the `grid` buffer (bound as `grid: array<u32>`).
const GRID_HELPERS_WGSL: &str = r#"
// ---- GPU cell list accessors (backend::gpu::cells); need `grid: array<u32>` ----
fn grid_origin() -> vec3<f32> {
    return vec3<f32>(bitcast<f32>(grid[0]), bitcast<f32>(grid[1]), bitcast<f32>(grid[2]));
}
// The cell size in use, rounded to f32 (+inf for the single-cell fallback).
fn grid_cell_size() -> f32 {
    return bitcast<f32>(grid[3]);
}
// Cells per axis (1 beyond the dimension).
fn grid_dims() -> vec3<u32> {
    return vec3<u32>(grid[4], grid[5], grid[6]);
}
// The cell of point p (unused components 0), clamped to the grid; a non-finite component goes
// to cell 0 of its axis. Bit-identical to the CPU grid (computed in software f64).
fn cell_coords(p: vec3<f32>) -> vec3<u32> {
    let o = grid_origin();
    let n = grid_dims();
    let inv = cl_from_bits(vec2<u32>(grid[10], grid[11]));
    return vec3<u32>(cl_axis_cell(p.x, o.x, inv, n.x), cl_axis_cell(p.y, o.y, inv, n.y),
                     cl_axis_cell(p.z, o.z, inv, n.z));
}
// Linear index, x fastest.
fn cell_index(c: vec3<u32>) -> u32 {
    let n = grid_dims();
    return c.x + n.x * (c.y + n.y * c.z);
}
// A walk over the cells that may hold a particle within `radius` of point p: from `lo` to `hi`
// (grid[14] cells on each side of p's cell `c`, clamped to the grid), less the cells that
// `walk_skips`. `q` is p's place inside its cell, in cells; `reach2` the squared radius in cells.
struct CellWalk {
    c: vec3<u32>,
    lo: vec3<u32>,
    hi: vec3<u32>,
    q: vec3<f32>,
    reach2: f32,
}
fn walk_cells(p: vec3<f32>, radius: f32) -> CellWalk {
    let c = cell_coords(p);
    let n = grid_dims();
    let w = vec3<u32>(grid[14]);
    let cs = grid_cell_size();
    let q = (p - grid_origin()) / cs - vec3<f32>(c);
    // q's f32 rounding grows with the cells along an axis; the slack keeps every cell that may
    // hold a particle within the radius (it is many times the rounding).
    let reach = radius / cs + 1e-3 + 1e-6 * f32(max(n.x, max(n.y, n.z)));
    return CellWalk(c, c - min(c, w), min(c + w, n - vec3<u32>(1u)), q, reach * reach);
}
// How many cells from the walk's point to the nearest face of cell a, along one axis.
fn cell_gap(a: u32, c: u32, q: f32) -> f32 {
    if (a > c) { return max(f32(a - c) - q, 0.0); }
    if (a < c) { return max(f32(c - a - 1u) + q, 0.0); }
    return 0.0;
}
// Whether every point of `cell` is beyond the walk's radius (a NaN point skips nothing).
fn walk_skips(wk: CellWalk, cell: vec3<u32>) -> bool {
    let g = vec3<f32>(cell_gap(cell.x, wk.c.x, wk.q.x), cell_gap(cell.y, wk.c.y, wk.q.y),
                      cell_gap(cell.z, wk.c.z, wk.q.z));
    return dot(g, g) > wk.reach2;
}
"#;

/// Accessors of the `cells` buffer (bound as `cells: array<u32>`).
const CELLS_HELPERS_WGSL: &str = r#"
// ---- GPU cell list: need `cells: array<u32>` (and `grid`) ----
// First sorted slot of cell c; cell c holds slots cell_start(c) .. cell_start(c + 1).
fn cell_start(c: u32) -> u32 {
    return cells[c];
}
// The particle in sorted slot `slot`.
fn sorted_particle(slot: u32) -> u32 {
    return cells[grid[8] + slot];
}
"#;

/// The uniform of the cell-list kernels (written for each `record`).
const PARAMS_WGSL: &str = r#"
struct Params {
    n: u32,
    dim: u32,
    x_offset: u32,
    h_offset: u32,
    max_cells: u32,
    support_bits: u32,
    parts: u32,
    // log2 of the cells per cut-off: the requested cell size is support * h_max / 2^this.
    split_log2: u32,
}
"#;

/// Per workgroup: the bounding box of the finite coordinates and the largest non-NaN h, as keys.
const BBOX_WGSL: &str = r#"
@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> data: array<f32>;
@group(0) @binding(2) var<storage, read_write> partials: array<u32>;

const WG: u32 = 256u;
// Seven reduced quantities (lo x y z, hi x y z, h_max), 256 lanes each.
var<workgroup> sh: array<u32, 1792>;

fn combine(k: u32, a: u32, b: u32) -> u32 {
    return select(max(a, b), min(a, b), k < 3u);
}

@compute @workgroup_size(256)
fn main(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wg: vec3<u32>,
        @builtin(num_workgroups) nwg: vec3<u32>) {
    // Workgroup `part` of `params.parts` (the dispatch may be 2D and have a few more).
    let part = wg.x + wg.y * nwg.x;
    // Identities: lo above every key, hi below every key, h_max from +0.
    var acc = array<u32, 7>(0xffffffffu, 0xffffffffu, 0xffffffffu, 0u, 0u, 0u, 0x80000000u);
    let stride = params.parts * WG;
    let begin = select(part * WG + lid, params.n, part >= params.parts);
    for (var i = begin; i < params.n; i += stride) {
        for (var k = 0u; k < params.dim; k++) {
            let b = bitcast<u32>(data[params.x_offset + i * params.dim + k]);
            if (cl_finite_bits(b)) {
                acc[k] = min(acc[k], cl_key(b));
                acc[3u + k] = max(acc[3u + k], cl_key(b));
            }
        }
        let hb = bitcast<u32>(data[params.h_offset + i]);
        if (!cl_nan_bits(hb)) {
            acc[6] = max(acc[6], cl_key(hb));
        }
    }
    for (var k = 0u; k < 7u; k++) {
        sh[k * WG + lid] = acc[k];
    }
    workgroupBarrier();
    for (var s = WG / 2u; s > 0u; s >>= 1u) {
        if (lid < s) {
            for (var k = 0u; k < 7u; k++) {
                sh[k * WG + lid] = combine(k, sh[k * WG + lid], sh[k * WG + lid + s]);
            }
        }
        workgroupBarrier();
    }
    if (lid == 0u && part < params.parts) {
        for (var k = 0u; k < 7u; k++) {
            partials[part * 8u + k] = sh[k * WG];
        }
    }
}
"#;

/// One workgroup: combines the partial boxes, then thread 0 fits the grid (Geometry::fit).
const GEOMETRY_WGSL: &str = r#"
@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> partials: array<u32>;
@group(0) @binding(2) var<storage, read_write> grid: array<u32>;

const WG: u32 = 256u;
var<workgroup> sh: array<u32, 1792>;

fn combine(k: u32, a: u32, b: u32) -> u32 {
    return select(max(a, b), min(a, b), k < 3u);
}

// Geometry::fit on the reduced box: origin, cell size, counts, written to `grid`.
fn fit() {
    let dim = params.dim;
    var lo = vec3<f32>(0.0);
    var extent = array<ClF64, 3>(cl_zero(), cl_zero(), cl_zero());
    for (var k = 0u; k < 3u; k++) {
        let klo = sh[k * WG];
        let khi = sh[(3u + k) * WG];
        // An axis without finite coordinates, or beyond dim, spans [0, 0].
        if (k < dim && klo <= khi) {
            let l = bitcast<f32>(cl_unkey(klo));
            lo[k] = l;
            extent[k] = cl_sub(cl_from_f32(bitcast<f32>(cl_unkey(khi))), cl_from_f32(l));
        }
    }
    let h_max = bitcast<f32>(cl_unkey(sh[6u * WG]));
    let support = bitcast<f32>(params.support_bits);
    // The requested cell size support * h_max (exact in f64), times 1 + CELL_MARGIN.
    var cell = cl_zero();
    if (cl_finite_bits(params.support_bits) && cl_finite_bits(bitcast<u32>(h_max))) {
        cell = cl_mul(cl_mul(cl_from_f32(support), cl_from_f32(h_max)), cl_from_bits(MARGIN));
        // Divided by 2^split_log2: exact, as the CPU's support * h_max / cells_per_cutoff.
        if (!cl_is_zero(cell) && cell.inf == 0u) { cell.e = cell.e - i32(params.split_log2); }
    }
    var doublings = 0u;
    var counts = vec3<u32>(1u);
    var inv = cl_zero();
    var found = false;
    // Double the cell size until the counts fit max_cells (and stop at infinity).
    loop {
        if (cell.inf != 0u || cell.neg != 0u || cl_is_zero(cell)) { break; }
        let inv_try = cl_recip(cell);
        var c = vec3<u32>(1u);
        var total = 1u;
        var fits = true;
        for (var k = 0u; k < dim; k++) {
            let f = cl_floor_u32(cl_mul(extent[k], inv_try));
            if (f >= params.max_cells) {
                fits = false;
                break;
            }
            let ck = f + 1u;
            if (ck > params.max_cells / total) {
                fits = false;
                break;
            }
            total = total * ck;
            c[k] = ck;
        }
        if (fits) {
            counts = c;
            inv = inv_try;
            found = true;
            break;
        }
        cell.e = cell.e + 1;
        doublings++;
        if (cell.e > 1023) { cell = cl_inf(0u); }
    }
    if (!found) {
        // Single-cell fallback: infinite cell, inv = 0.
        cell = cl_inf(0u);
        inv = cl_zero();
        counts = vec3<u32>(1u);
    }
    grid[0] = bitcast<u32>(lo.x);
    grid[1] = bitcast<u32>(lo.y);
    grid[2] = bitcast<u32>(lo.z);
    grid[3] = bitcast<u32>(cl_to_f32(cell));
    grid[4] = counts.x;
    grid[5] = counts.y;
    grid[6] = counts.z;
    grid[7] = counts.x * counts.y * counts.z;
    grid[8] = params.max_cells + 1u;
    grid[9] = bitcast<u32>(h_max);
    let ib = cl_bits(inv);
    grid[10] = ib.x;
    grid[11] = ib.y;
    let cb = cl_bits(cell);
    grid[12] = cb.x;
    grid[13] = cb.y;
    // Cells a walk takes on each side to cover the cut-off: the cells per cut-off, halved by
    // every doubling the cap forced (each side of the walk always takes at least one).
    grid[14] = max(1u, (1u << params.split_log2) >> min(doublings, 31u));
    if (!found) { grid[14] = 1u; }
    grid[15] = 0u;
}

@compute @workgroup_size(256)
fn main(@builtin(local_invocation_index) lid: u32) {
    var acc = array<u32, 7>(0xffffffffu, 0xffffffffu, 0xffffffffu, 0u, 0u, 0u, 0x80000000u);
    for (var p = lid; p < params.parts; p += WG) {
        for (var k = 0u; k < 7u; k++) {
            acc[k] = combine(k, acc[k], partials[p * 8u + k]);
        }
    }
    for (var k = 0u; k < 7u; k++) {
        sh[k * WG + lid] = acc[k];
    }
    workgroupBarrier();
    for (var s = WG / 2u; s > 0u; s >>= 1u) {
        if (lid < s) {
            for (var k = 0u; k < 7u; k++) {
                sh[k * WG + lid] = combine(k, sh[k * WG + lid], sh[k * WG + lid + s]);
            }
        }
        workgroupBarrier();
    }
    if (lid == 0u) {
        fit();
    }
}
"#;

/// Per particle: its cell, and an atomic count per cell (the old count is its slot in the cell).
const ASSIGN_WGSL: &str = r#"
@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> data: array<f32>;
@group(0) @binding(2) var<storage, read> grid: array<u32>;
@group(0) @binding(3) var<storage, read_write> counts: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read_write> cell_of: array<u32>;
@group(0) @binding(5) var<storage, read_write> local_slot: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wg: vec3<u32>,
        @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = (wg.x + wg.y * nwg.x) * 64u + lid;
    if (i >= params.n) { return; }
    var p = vec3<f32>(0.0);
    for (var k = 0u; k < params.dim; k++) {
        p[k] = data[params.x_offset + i * params.dim + k];
    }
    let c = cell_index(cell_coords(p));
    cell_of[i] = c;
    local_slot[i] = atomicAdd(&counts[c], 1u);
}
"#;

/// Exclusive scan of each block of 256 values in place; the block's total goes to `sums`.
const SCAN_WGSL: &str = r#"
struct Level {
    len: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}
@group(0) @binding(0) var<uniform> level: Level;
@group(0) @binding(1) var<storage, read_write> values: array<u32>;
@group(0) @binding(2) var<storage, read_write> sums: array<u32>;

var<workgroup> sh: array<u32, 256>;

@compute @workgroup_size(256)
fn main(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wg: vec3<u32>,
        @builtin(num_workgroups) nwg: vec3<u32>) {
    let block = wg.x + wg.y * nwg.x;
    let i = block * 256u + lid;
    var v = 0u;
    if (i < level.len) { v = values[i]; }
    sh[lid] = v;
    workgroupBarrier();
    // Hillis-Steele inclusive scan.
    for (var off = 1u; off < 256u; off <<= 1u) {
        var t = 0u;
        if (lid >= off) { t = sh[lid - off]; }
        workgroupBarrier();
        sh[lid] = sh[lid] + t;
        workgroupBarrier();
    }
    if (i < level.len) { values[i] = sh[lid] - v; }
    if (lid == 255u && block < (level.len + 255u) / 256u) { sums[block] = sh[255]; }
}
"#;

/// Adds the scanned block sums back: values[i] += sums[i / 256].
const ADD_WGSL: &str = r#"
struct Level {
    len: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}
@group(0) @binding(0) var<uniform> level: Level;
@group(0) @binding(1) var<storage, read_write> values: array<u32>;
@group(0) @binding(2) var<storage, read> sums: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wg: vec3<u32>,
        @builtin(num_workgroups) nwg: vec3<u32>) {
    let block = wg.x + wg.y * nwg.x;
    let i = block * 256u + lid;
    if (i < level.len) { values[i] = values[i] + sums[block]; }
}
"#;

/// Per particle: to its (arbitrary) slot of its cell in the scratch order.
const SCATTER_WGSL: &str = r#"
@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> cells: array<u32>;
@group(0) @binding(2) var<storage, read> cell_of: array<u32>;
@group(0) @binding(3) var<storage, read> local_slot: array<u32>;
@group(0) @binding(4) var<storage, read_write> unordered: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wg: vec3<u32>,
        @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = (wg.x + wg.y * nwg.x) * 64u + lid;
    if (i >= params.n) { return; }
    unordered[cells[cell_of[i]] + local_slot[i]] = i;
}
"#;

/// Per particle: its rank among the particles of its cell (by index), then its final slot.
const RANK_WGSL: &str = r#"
@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read_write> cells: array<u32>;
@group(0) @binding(2) var<storage, read> cell_of: array<u32>;
@group(0) @binding(3) var<storage, read> unordered: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wg: vec3<u32>,
        @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = (wg.x + wg.y * nwg.x) * 64u + lid;
    if (i >= params.n) { return; }
    let c = cell_of[i];
    let start = cells[c];
    let end = cells[c + 1u];
    var rank = 0u;
    for (var s = start; s < end; s++) {
        rank += select(0u, 1u, unordered[s] < i);
    }
    cells[params.max_cells + 1u + start + rank] = i;
}
"#;

/// The WGSL a pass shader pastes to read the cell list. It expects the bindings
/// `grid: array<u32>` and `cells: array<u32>` (both `var<storage, read>`), and defines
/// `grid_origin`, `grid_cell_size`, `grid_dims`, `cell_coords`, `cell_index`, `cell_start` and
/// `sorted_particle`, plus private helpers prefixed `cl_` (a software f64) and the struct `ClF64`.
pub fn wgsl_helpers() -> &'static str {
    static HELPERS: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    HELPERS.get_or_init(|| format!("{SOFT_F64_WGSL}{GRID_HELPERS_WGSL}{CELLS_HELPERS_WGSL}"))
}

/// `1 + CELL_MARGIN` as f64 bits, as the WGSL constant `MARGIN`.
fn margin_const() -> String {
    let bits = (1.0 + crate::grid::CELL_MARGIN).to_bits();
    format!(
        "// 1 + grid::CELL_MARGIN as f64 bits (low, high).\nconst MARGIN = vec2<u32>({:#010x}u, {:#010x}u);\n",
        bits as u32,
        (bits >> 32) as u32
    )
}

/// One level of the prefix scan: `values` (len entries) scanned in blocks, block sums to `sums`.
struct ScanLevel {
    len: u32,
    scan: wgpu::BindGroup,
    add: wgpu::BindGroup,
}

/// The GPU cell list of `n` particles in `dim` dimensions (see the module documentation).
pub struct CellList {
    n: u32,
    dim: u32,
    split_log2: u32,
    max_cells: u32,
    parts: u32,
    grid: wgpu::Buffer,
    cells: wgpu::Buffer,
    params: wgpu::Buffer,
    partials: wgpu::Buffer,
    cell_of: wgpu::Buffer,
    local_slot: wgpu::Buffer,
    _unordered: wgpu::Buffer,
    _sums: Vec<wgpu::Buffer>,
    _level_uniforms: Vec<wgpu::Buffer>,
    levels: Vec<ScanLevel>,
    bbox: wgpu::ComputePipeline,
    geometry: wgpu::ComputePipeline,
    assign: wgpu::ComputePipeline,
    scan: wgpu::ComputePipeline,
    add: wgpu::ComputePipeline,
    scatter: wgpu::ComputePipeline,
    rank: wgpu::ComputePipeline,
    geometry_bind: wgpu::BindGroup,
    scatter_bind: wgpu::BindGroup,
    rank_bind: wgpu::BindGroup,
}

/// Entries of the scan levels: `max_cells + 1`, then ceil(previous / 256) until one block.
fn scan_lengths(max_cells: usize) -> Vec<u64> {
    let mut lens = vec![max_cells as u64 + 1];
    while *lens.last().expect("non-empty") > WG as u64 {
        let l = lens.last().expect("non-empty").div_ceil(WG as u64);
        lens.push(l);
    }
    lens
}

impl CellList {
    /// The dispatches [`record`](Self::record) makes for `n` particles: bounding box, geometry,
    /// assignment, scatter and rank, a scan per level and an add per level but the last.
    pub fn dispatches(n: usize) -> usize {
        5 + 2 * scan_lengths(crate::grid::max_cells(n)).len() - 1
    }

    /// The buffers `new` allocates for `n` particles, `(name, bytes)`, for
    /// [`Gpu::estimate_fits`] before a scene is uploaded.
    pub fn planned_buffers(n: usize) -> Vec<(&'static str, u64)> {
        let max_cells = crate::grid::max_cells(n) as u64;
        let n = n as u64;
        let mut out = vec![
            ("cell list: grid", 64),
            ("cell list: cells", 4 * (max_cells + 1 + n)),
            ("cell list: cell of each particle", 4 * n),
            ("cell list: slot of each particle", 4 * n),
            ("cell list: unordered particles", 4 * n),
            ("cell list: bounding box partials", 4 * PART_WORDS * MAX_PARTS as u64),
        ];
        for l in scan_lengths(max_cells as usize).into_iter().skip(1) {
            out.push(("cell list: scan block sums", 4 * l));
        }
        out
    }

    /// Allocates the buffers and compiles the kernels for `n` particles in `dim` dimensions, with
    /// cells of the cut-off divided by `cells_per_cutoff` (1, 2, 4 or 8).
    pub fn new(gpu: &Gpu, n: usize, dim: usize, cells_per_cutoff: u32) -> Result<CellList, GpuError> {
        if !(1..=3).contains(&dim) {
            return Err(GpuError::Device(format!("cell list: dim must be 1, 2 or 3, got {dim}")));
        }
        if !matches!(cells_per_cutoff, 1 | 2 | 4 | 8) {
            return Err(GpuError::Device(format!(
                "cell list: cells per cut-off must be 1, 2, 4 or 8, got {cells_per_cutoff}"
            )));
        }
        if n >= u32::MAX as usize / 8 {
            return Err(GpuError::TooLarge {
                what: "cell list: particles".into(),
                needed: n as u64,
                limit: u32::MAX as u64 / 8,
            });
        }
        gpu.estimate_fits(&CellList::planned_buffers(n))?;
        let max_cells = crate::grid::max_cells(n);
        let none = wgpu::BufferUsages::empty();
        let grid = gpu.storage_buffer("cell list: grid", 64, none)?;
        let cells = gpu.storage_buffer("cell list: cells", 4 * (max_cells as u64 + 1 + n as u64), none)?;
        let cell_of = gpu.storage_buffer("cell list: cell of each particle", 4 * n as u64, none)?;
        let local_slot = gpu.storage_buffer("cell list: slot of each particle", 4 * n as u64, none)?;
        let unordered = gpu.storage_buffer("cell list: unordered particles", 4 * n as u64, none)?;
        let partials =
            gpu.storage_buffer("cell list: bounding box partials", 4 * PART_WORDS * MAX_PARTS as u64, none)?;
        let params = gpu.uniform_buffer("cell list: params", &[0u32; 8]);

        let common = format!("{COMMON_WGSL}{PARAMS_WGSL}");
        let bbox = gpu.compile("cell list: bbox", &format!("{common}{BBOX_WGSL}"), "main")?;
        let geometry = gpu.compile(
            "cell list: geometry",
            &format!("{common}{SOFT_F64_WGSL}{}{GEOMETRY_WGSL}", margin_const()),
            "main",
        )?;
        let assign = gpu.compile(
            "cell list: assign",
            &format!("{common}{SOFT_F64_WGSL}{GRID_HELPERS_WGSL}{ASSIGN_WGSL}"),
            "main",
        )?;
        let scan = gpu.compile("cell list: scan", SCAN_WGSL, "main")?;
        let add = gpu.compile("cell list: add", ADD_WGSL, "main")?;
        let scatter = gpu.compile("cell list: scatter", &format!("{common}{SCATTER_WGSL}"), "main")?;
        let rank = gpu.compile("cell list: rank", &format!("{common}{RANK_WGSL}"), "main")?;

        // Scan levels: values of level 0 are the counts in `cells`, of level l > 0 the block
        // sums of level l - 1; the top level's single total goes to a 1-word buffer.
        let lens = scan_lengths(max_cells);
        let mut sums = Vec::new();
        for (k, &l) in lens.iter().enumerate().skip(1) {
            sums.push(gpu.storage_buffer(&format!("cell list: scan sums {k}"), 4 * l, none)?);
        }
        sums.push(gpu.storage_buffer("cell list: scan total", 4, none)?);
        let mut level_uniforms = Vec::new();
        let mut levels = Vec::new();
        for (k, &len) in lens.iter().enumerate() {
            let uniform = gpu.uniform_buffer("cell list: scan level", &[len as u32, 0, 0, 0]);
            let values = if k == 0 { &cells } else { &sums[k - 1] };
            let scan_bind = gpu.bind("cell list: scan", &scan, &[&uniform, values, &sums[k]]);
            let add_bind = gpu.bind("cell list: add", &add, &[&uniform, values, &sums[k]]);
            levels.push(ScanLevel { len: len as u32, scan: scan_bind, add: add_bind });
            level_uniforms.push(uniform);
        }
        let geometry_bind = gpu.bind("cell list: geometry", &geometry, &[&params, &partials, &grid]);
        let scatter_bind =
            gpu.bind("cell list: scatter", &scatter, &[&params, &cells, &cell_of, &local_slot, &unordered]);
        let rank_bind = gpu.bind("cell list: rank", &rank, &[&params, &cells, &cell_of, &unordered]);
        gpu.check()?;
        Ok(CellList {
            n: n as u32,
            dim: dim as u32,
            split_log2: cells_per_cutoff.trailing_zeros(),
            max_cells: max_cells as u32,
            parts: (n as u32).div_ceil(WG).clamp(1, MAX_PARTS),
            grid,
            cells,
            params,
            partials,
            cell_of,
            local_slot,
            _unordered: unordered,
            _sums: sums,
            _level_uniforms: level_uniforms,
            levels,
            bbox,
            geometry,
            assign,
            scan,
            add,
            scatter,
            rank,
            geometry_bind,
            scatter_bind,
            rank_bind,
        })
    }

    pub fn particles(&self) -> usize {
        self.n as usize
    }

    pub fn dim(&self) -> usize {
        self.dim as usize
    }

    /// The cells per cut-off it was made with.
    pub fn cells_per_cutoff(&self) -> u32 {
        1 << self.split_log2
    }

    /// The cap on the number of cells, `crate::grid::max_cells(n)`.
    pub fn max_cells(&self) -> usize {
        self.max_cells as usize
    }

    /// The 16-word grid description (see the module documentation).
    pub fn grid_buffer(&self) -> &wgpu::Buffer {
        &self.grid
    }

    /// Cell starts, then the sorted particle indices (see the module documentation).
    pub fn cells_buffer(&self) -> &wgpu::Buffer {
        &self.cells
    }

    /// The linear index of each particle's cell (`n` words), as of the last build.
    pub fn cell_of_buffer(&self) -> &wgpu::Buffer {
        &self.cell_of
    }

    /// Records the construction of the cell list into `encoder`. Positions are `n × dim` f32,
    /// interleaved, from element `x_offset` of the f32 storage buffer `data`; smoothing lengths
    /// `n` f32 from element `h_offset`. The cell size is that of
    /// `Grid::build(x, dim, support as f64 * h_max as f64 / cells_per_cutoff)` with `h_max` the largest non-NaN h
    /// (at least 0), left in `grid[9]`: the caller should check it (a zero, infinite or NaN
    /// `h_max` gives the single-cell fallback, where the CPU backend refuses to run).
    pub fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        data: &wgpu::Buffer,
        x_offset: u32,
        h_offset: u32,
        support: f32,
    ) {
        let p = [self.n, self.dim, x_offset, h_offset, self.max_cells, support.to_bits(), self.parts, self.split_log2];
        let staging = gpu.uniform_buffer("cell list: params of this build", &p);
        encoder.copy_buffer_to_buffer(&staging, 0, &self.params, 0, 32);
        let bbox = gpu.bind("cell list: bbox", &self.bbox, &[&self.params, data, &self.partials]);
        gpu.dispatch(encoder, "cell list: bbox", &self.bbox, &bbox, self.parts);
        gpu.dispatch(encoder, "cell list: geometry", &self.geometry, &self.geometry_bind, 1);
        encoder.clear_buffer(&self.cells, 0, Some(4 * (self.max_cells as u64 + 1)));
        let assign = gpu.bind(
            "cell list: assign",
            &self.assign,
            &[&self.params, data, &self.grid, &self.cells, &self.cell_of, &self.local_slot],
        );
        let particle_groups = self.n.div_ceil(WG_PARTICLE);
        gpu.dispatch(encoder, "cell list: assign", &self.assign, &assign, particle_groups);
        for l in &self.levels {
            gpu.dispatch(encoder, "cell list: scan", &self.scan, &l.scan, l.len.div_ceil(WG));
        }
        for l in self.levels.iter().rev().skip(1) {
            gpu.dispatch(encoder, "cell list: add", &self.add, &l.add, l.len.div_ceil(WG));
        }
        gpu.dispatch(encoder, "cell list: scatter", &self.scatter, &self.scatter_bind, particle_groups);
        gpu.dispatch(encoder, "cell list: rank", &self.rank, &self.rank_bind, particle_groups);
    }
}
