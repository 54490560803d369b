//! Reductions recorded into the caller's command encoder, result left on the GPU.
//!
//! - [`Reducer::record`]: min, max or sum of `count` f32 values of a storage buffer (from an
//!   element offset, with a stride), written as f32 to element `dst_index` of a destination
//!   buffer. Two levels: up to 1024 workgroups of 256 threads reduce strided slices into
//!   partials (each thread sequentially, then a tree), then one workgroup reduces the partials.
//!   Min and max ignore NaN like `f32::min`/`f32::max` and are exact (compared as
//!   order-preserving integer keys); an empty or all-NaN input gives the identity (+inf for
//!   min, -inf for max, 0 for sum). Sum propagates NaN and infinities; its rounding follows the
//!   fixed tree order (deterministic for a given count, not equal to a sequential sum).
//! - [`Reducer::record_first_non_finite`]: the smallest particle index with a NaN or infinite
//!   value in a [`SegmentList`], written as u32 (`0xffffffff` when all values are finite).

use super::device::{Gpu, GpuError};

const WG: u32 = 256;
const MAX_PARTS: u32 = 1024;

/// What [`Reducer::record`] computes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReduceOp {
    Min,
    Max,
    Sum,
}

impl ReduceOp {
    fn code(self) -> u32 {
        match self {
            ReduceOp::Min => 0,
            ReduceOp::Max => 1,
            ReduceOp::Sum => 2,
        }
    }
}

/// Written by [`Reducer::record_first_non_finite`] when every value is finite.
pub const ALL_FINITE: u32 = u32::MAX;

/// A run of particles of one field: the values of particle `first + p`, component `c` are at
/// element `offset + p * comps + c`, for `p < count`, `c < comps`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Segment {
    pub offset: u32,
    pub first: u32,
    pub count: u32,
    pub comps: u32,
}

/// Segments uploaded once (a storage buffer of 4 words per segment), scanned each time
/// [`Reducer::record_first_non_finite`] is recorded.
pub struct SegmentList {
    buffer: wgpu::Buffer,
    len: u32,
    /// The largest `count * comps`: sizes the dispatch.
    max_values: u64,
}

impl SegmentList {
    pub fn len(&self) -> usize {
        self.len as usize
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

const PARAMS_WGSL: &str = r#"
struct Params {
    offset: u32,
    count: u32,
    stride: u32,
    op: u32,
    parts: u32,
    dst_index: u32,
    segments: u32,
    pad: u32,
}
@group(0) @binding(0) var<uniform> params: Params;

const WG: u32 = 256u;
var<workgroup> sh: array<u32, 256>;

// f32 bits as order-preserving keys: -inf < ... < -0 < +0 < ... < +inf.
fn key(b: u32) -> u32 {
    return select(b | 0x80000000u, ~b, (b & 0x80000000u) != 0u);
}
fn unkey(k: u32) -> u32 {
    return select(~k, k & 0x7fffffffu, (k & 0x80000000u) != 0u);
}
fn is_nan(b: u32) -> bool {
    return (b & 0x7fffffffu) > 0x7f800000u;
}
// Accumulators are keys for min (op 0) and max (op 1), f32 bits for sum (op 2), plain u32 for
// the minimum particle index (op 3).
fn identity(op: u32) -> u32 {
    if (op == 0u) { return 0xff800000u; } // key(+inf)
    if (op == 1u) { return 0x007fffffu; } // key(-inf)
    if (op == 3u) { return 0xffffffffu; }
    return 0u;
}
fn combine(op: u32, a: u32, b: u32) -> u32 {
    if (op == 0u || op == 3u) { return min(a, b); }
    if (op == 1u) { return max(a, b); }
    return bitcast<u32>(bitcast<f32>(a) + bitcast<f32>(b));
}
fn tree(lid: u32, v: u32) -> u32 {
    sh[lid] = v;
    workgroupBarrier();
    for (var s = WG / 2u; s > 0u; s >>= 1u) {
        if (lid < s) { sh[lid] = combine(params.op, sh[lid], sh[lid + s]); }
        workgroupBarrier();
    }
    return sh[0];
}
"#;

const PARTIAL_WGSL: &str = r#"
@group(0) @binding(1) var<storage, read> src: array<u32>;
@group(0) @binding(2) var<storage, read_write> partials: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wg: vec3<u32>,
        @builtin(num_workgroups) nwg: vec3<u32>) {
    let part = wg.x + wg.y * nwg.x;
    let op = params.op;
    var acc = identity(op);
    let begin = select(part * WG + lid, params.count, part >= params.parts);
    for (var i = begin; i < params.count; i += params.parts * WG) {
        let b = src[params.offset + i * params.stride];
        if (op == 2u) {
            acc = combine(op, acc, b);
        } else if (!is_nan(b)) {
            acc = combine(op, acc, key(b));
        }
    }
    let r = tree(lid, acc);
    if (lid == 0u && part < params.parts) { partials[part] = r; }
}
"#;

const FINAL_WGSL: &str = r#"
@group(0) @binding(1) var<storage, read> partials: array<u32>;
@group(0) @binding(2) var<storage, read_write> dst: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(local_invocation_index) lid: u32) {
    let op = params.op;
    var acc = identity(op);
    for (var p = lid; p < params.parts; p += WG) {
        acc = combine(op, acc, partials[p]);
    }
    let r = tree(lid, acc);
    if (lid == 0u) { dst[params.dst_index] = select(r, unkey(r), op < 2u); }
}
"#;

const NONFINITE_PARTIAL_WGSL: &str = r#"
@group(0) @binding(1) var<storage, read> segments: array<u32>;
@group(0) @binding(2) var<storage, read> src: array<u32>;
@group(0) @binding(3) var<storage, read_write> partials: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wg: vec3<u32>,
        @builtin(num_workgroups) nwg: vec3<u32>) {
    let part = wg.x + wg.y * nwg.x;
    var best = 0xffffffffu;
    // Workgroups past `parts` (a 2D dispatch may have a few) scan nothing.
    let nseg = select(params.segments, 0u, part >= params.parts);
    for (var s = 0u; s < nseg; s++) {
        let offset = segments[4u * s];
        let first = segments[4u * s + 1u];
        let comps = max(segments[4u * s + 3u], 1u);
        let total = segments[4u * s + 2u] * comps;
        // Each thread's values are in increasing order: its first hit is its smallest.
        for (var e = part * WG + lid; e < total; e += params.parts * WG) {
            if ((src[offset + e] & 0x7f800000u) == 0x7f800000u) {
                best = min(best, first + e / comps);
                break;
            }
        }
    }
    let r = tree(lid, best);
    if (lid == 0u && part < params.parts) { partials[part] = r; }
}
"#;

/// The reduction kernels; bind groups and parameters are made per recorded reduction.
pub struct Reducer {
    partials: wgpu::Buffer,
    partial: wgpu::ComputePipeline,
    final_: wgpu::ComputePipeline,
    nonfinite: wgpu::ComputePipeline,
}

fn parts_for(values: u64) -> u32 {
    values.div_ceil(WG as u64).clamp(1, MAX_PARTS as u64) as u32
}

impl Reducer {
    pub fn new(gpu: &Gpu) -> Result<Reducer, GpuError> {
        let partials = gpu.storage_buffer("reduce: partials", 4 * MAX_PARTS as u64, wgpu::BufferUsages::empty())?;
        let partial = gpu.compile("reduce: partial", &format!("{PARAMS_WGSL}{PARTIAL_WGSL}"), "main")?;
        let final_ = gpu.compile("reduce: final", &format!("{PARAMS_WGSL}{FINAL_WGSL}"), "main")?;
        let nonfinite =
            gpu.compile("reduce: first non-finite", &format!("{PARAMS_WGSL}{NONFINITE_PARTIAL_WGSL}"), "main")?;
        Ok(Reducer { partials, partial, final_, nonfinite })
    }

    /// Records `dst[dst_index] = op(src[offset .. offset + count])` (f32 elements); see the
    /// module documentation for NaN and empty inputs.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        op: ReduceOp,
        src: &wgpu::Buffer,
        offset: u32,
        count: u32,
        dst: &wgpu::Buffer,
        dst_index: u32,
    ) {
        self.record_strided(gpu, encoder, op, src, offset, count, 1, dst, dst_index);
    }

    /// Like [`record`](Self::record) over `src[offset + k * stride]` for `k < count` (one
    /// component of an interleaved field).
    #[allow(clippy::too_many_arguments)]
    pub fn record_strided(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        op: ReduceOp,
        src: &wgpu::Buffer,
        offset: u32,
        count: u32,
        stride: u32,
        dst: &wgpu::Buffer,
        dst_index: u32,
    ) {
        let parts = parts_for(count as u64);
        let params = gpu.uniform_buffer("reduce: params", &[offset, count, stride, op.code(), parts, dst_index, 0, 0]);
        let b = gpu.bind("reduce: partial", &self.partial, &[&params, src, &self.partials]);
        gpu.dispatch(encoder, "reduce: partial", &self.partial, &b, parts);
        let b = gpu.bind("reduce: final", &self.final_, &[&params, &self.partials, dst]);
        gpu.dispatch(encoder, "reduce: final", &self.final_, &b, 1);
    }

    /// Uploads segments for [`record_first_non_finite`](Self::record_first_non_finite).
    pub fn segments(&self, gpu: &Gpu, segments: &[Segment]) -> Result<SegmentList, GpuError> {
        let buffer = gpu.storage_buffer("reduce: segments", 16 * segments.len() as u64, wgpu::BufferUsages::empty())?;
        gpu.upload(&buffer, 0, segments)?;
        let max_values = segments.iter().map(|s| s.count as u64 * s.comps.max(1) as u64).max().unwrap_or(0);
        Ok(SegmentList { buffer, len: segments.len() as u32, max_values })
    }

    /// Records `dst[dst_index] = ` the smallest particle index with a NaN or infinite value in
    /// the segments of `src` (u32; [`ALL_FINITE`] if none).
    pub fn record_first_non_finite(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        src: &wgpu::Buffer,
        segments: &SegmentList,
        dst: &wgpu::Buffer,
        dst_index: u32,
    ) {
        let parts = parts_for(segments.max_values);
        // op 3: minimum of plain u32 values (particle indices).
        let params = gpu.uniform_buffer("reduce: params", &[0, 0, 1, 3, parts, dst_index, segments.len, 0]);
        let b =
            gpu.bind("reduce: first non-finite", &self.nonfinite, &[&params, &segments.buffer, src, &self.partials]);
        gpu.dispatch(encoder, "reduce: first non-finite", &self.nonfinite, &b, parts);
        let b = gpu.bind("reduce: final", &self.final_, &[&params, &self.partials, dst]);
        gpu.dispatch(encoder, "reduce: final", &self.final_, &b, 1);
    }
}
