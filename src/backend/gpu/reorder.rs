//! Reordering the particle data by cell, on the GPU: particles close in space end up close in
//! memory, so a pass's neighbour reads hit the same cache lines.
//!
//! Each particle gets a key `(group, Morton code of its cell, cell, index)` from the cell list just
//! built (its `cell_of`), the keys are sorted by a bitonic sort, and every stored column, the
//! materials and the particle ids are gathered in the sorted order. Groups stay contiguous (the
//! group leads the key), so each group's range is unchanged. The Morton code interleaves the
//! cell coordinates, coarsened where an axis has more cells than the code's bits per axis
//! (10 in 3D, 16 in 2D, 32 in 1D); ties are broken by the linear cell index, then by the particle
//! index, so the order is fully determined by the cell list. Nothing is read back.

use super::cells::CellList;
use super::device::{Gpu, GpuError};

const WG: u32 = 64;

/// The uniform of the key and gather kernels.
const PARAMS_WGSL: &str = r#"
struct Params {
    n: u32,
    n_pad: u32,
    dim: u32,
    words: u32,
    starts: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}
"#;

const KEYS_WGSL: &str = r#"
@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> ints: array<u32>;
@group(0) @binding(2) var<storage, read> grid: array<u32>;
@group(0) @binding(3) var<storage, read> cell_of: array<u32>;
@group(0) @binding(4) var<storage, read_write> keys: array<vec4<u32>>;

// The low 16 bits of v spread to the even bits.
fn spread2(v: u32) -> u32 {
    var x = v & 0xffffu;
    x = (x | (x << 8u)) & 0x00ff00ffu;
    x = (x | (x << 4u)) & 0x0f0f0f0fu;
    x = (x | (x << 2u)) & 0x33333333u;
    return (x | (x << 1u)) & 0x55555555u;
}

// The low 10 bits of v spread to every third bit.
fn spread3(v: u32) -> u32 {
    var x = v & 0x3ffu;
    x = (x | (x << 16u)) & 0x030000ffu;
    x = (x | (x << 8u)) & 0x0300f00fu;
    x = (x | (x << 4u)) & 0x030c30c3u;
    return (x | (x << 2u)) & 0x09249249u;
}

@compute @workgroup_size(64)
fn main(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wg: vec3<u32>,
        @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = (wg.x + wg.y * nwg.x) * 64u + lid;
    if (i >= params.n_pad) { return; }
    if (i >= params.n) {
        keys[i] = vec4<u32>(0xffffffffu);
        return;
    }
    let dims = vec3<u32>(grid[4], grid[5], grid[6]);
    let cell = cell_of[i];
    let c = vec3<u32>(cell % dims.x, (cell / dims.x) % dims.y, cell / (dims.x * dims.y));
    let largest = max(dims.x, max(dims.y, dims.z));
    let needed = 32u - countLeadingZeros(max(largest, 1u) - 1u);
    var code = c.x;
    if (params.dim == 2u) {
        let s = select(0u, needed - 16u, needed > 16u);
        code = spread2(c.x >> s) | (spread2(c.y >> s) << 1u);
    } else if (params.dim == 3u) {
        let s = select(0u, needed - 10u, needed > 10u);
        code = spread3(c.x >> s) | (spread3(c.y >> s) << 1u) | (spread3(c.z >> s) << 2u);
    }
    keys[i] = vec4<u32>(ints[i], code, cell, i);
}
"#;

const SORT_WGSL: &str = r#"
struct Step {
    j: u32,
    k: u32,
    n_pad: u32,
    pad: u32,
}
@group(0) @binding(0) var<uniform> step: Step;
@group(0) @binding(1) var<storage, read_write> keys: array<vec4<u32>>;

fn greater(a: vec4<u32>, b: vec4<u32>) -> bool {
    if (a.x != b.x) { return a.x > b.x; }
    if (a.y != b.y) { return a.y > b.y; }
    if (a.z != b.z) { return a.z > b.z; }
    return a.w > b.w;
}

// One compare-exchange stage of a bitonic sort (ascending overall).
@compute @workgroup_size(64)
fn main(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wg: vec3<u32>,
        @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = (wg.x + wg.y * nwg.x) * 64u + lid;
    let l = i ^ step.j;
    if (i >= step.n_pad || l <= i) { return; }
    let a = keys[i];
    let b = keys[l];
    if (greater(a, b) == ((i & step.k) == 0u)) {
        keys[i] = b;
        keys[l] = a;
    }
}
"#;

const GATHER_WGSL: &str = r#"
@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> keys: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read> old: array<u32>;
@group(0) @binding(3) var<storage, read_write> data: array<u32>;
@group(0) @binding(4) var<storage, read_write> ints: array<u32>;
@group(0) @binding(5) var<storage, read_write> ids: array<u32>;
@group(0) @binding(6) var<storage, read> table: array<u32>;

// Particle k takes the values of particle p = keys[k].w of the copy `old` (the data's words,
// then groups and materials, then ids). `table`: for group g, its columns are the entries
// table[g] .. table[g + 1] of the (base, components) pairs from word `params.starts` on.
@compute @workgroup_size(64)
fn main(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wg: vec3<u32>,
        @builtin(num_workgroups) nwg: vec3<u32>) {
    let k = (wg.x + wg.y * nwg.x) * 64u + lid;
    if (k >= params.n) { return; }
    let p = keys[k].w;
    let g = ints[k];
    let n = params.n;
    ints[n + k] = old[params.words + n + p];
    ids[k] = old[params.words + 2u * n + p];
    let first = table[g];
    let last = table[g + 1u];
    for (var e = first; e < last; e++) {
        let base = bitcast<i32>(table[params.starts + 2u * e]);
        let comps = table[params.starts + 2u * e + 1u];
        for (var c = 0u; c < comps; c++) {
            data[u32(base + i32(k * comps + c))] = old[u32(base + i32(p * comps + c))];
        }
    }
}
"#;

/// The reordering of one backend's buffers (see the module documentation).
pub struct Reorder {
    n: u32,
    n_pad: u32,
    words: u64,
    _keys: wgpu::Buffer,
    old: wgpu::Buffer,
    _table: wgpu::Buffer,
    _params: wgpu::Buffer,
    _steps: Vec<wgpu::Buffer>,
    keys_pipeline: wgpu::ComputePipeline,
    sort_pipeline: wgpu::ComputePipeline,
    gather_pipeline: wgpu::ComputePipeline,
    keys_bind: wgpu::BindGroup,
    sort_binds: Vec<wgpu::BindGroup>,
    gather_bind: wgpu::BindGroup,
}

/// The buffers the particle data of `n` particles lives in, as [`Reorder`] permutes them.
pub struct Particles<'a> {
    /// The stored columns (`words` 32-bit words from the start; anything after is not permuted).
    pub data: &'a wgpu::Buffer,
    pub words: u64,
    /// Groups (`n` words, kept), then materials (`n` words, permuted).
    pub ints: &'a wgpu::Buffer,
    /// The particle ids (`n` words, permuted).
    pub ids: &'a wgpu::Buffer,
}

impl Reorder {
    /// The buffers `new` allocates, `(name, bytes)`, for [`Gpu::estimate_fits`].
    pub fn planned_buffers(n: usize, words: u64) -> Vec<(&'static str, u64)> {
        let n_pad = (n.max(1)).next_power_of_two() as u64;
        vec![("reorder: keys", 16 * n_pad), ("reorder: copy of the particle data", 4 * (words + 3 * n as u64))]
    }

    /// Compiles the kernels and binds them to `particles` and `cells`. `columns[g]` lists the
    /// `(first word, components)` of every column stored on group g, the first word being that
    /// of particle 0 (so possibly negative when the group's rows start later).
    pub fn new(
        gpu: &Gpu,
        particles: &Particles,
        cells: &CellList,
        columns: &[Vec<(i64, u32)>],
    ) -> Result<Reorder, GpuError> {
        let n = cells.particles() as u32;
        let n_pad = n.max(1).next_power_of_two();
        let words = particles.words;
        let none = wgpu::BufferUsages::empty();
        let keys = gpu.storage_buffer("reorder: keys", 16 * n_pad as u64, none)?;
        let old = gpu.storage_buffer("reorder: copy of the particle data", 4 * (words + 3 * n as u64), none)?;
        let mut table: Vec<u32> = vec![0; columns.len() + 1];
        let mut entries = vec![];
        for (g, cols) in columns.iter().enumerate() {
            for (base, comps) in cols {
                let base = i32::try_from(*base).map_err(|_| GpuError::TooLarge {
                    what: "reorder: column offset".into(),
                    needed: base.unsigned_abs(),
                    limit: i32::MAX as u64,
                })?;
                entries.extend([base as u32, *comps]);
            }
            table[g + 1] = (entries.len() / 2) as u32;
        }
        let starts = table.len() as u32;
        table.extend(entries);
        let table_buffer = gpu.storage_buffer("reorder: columns", 4 * table.len() as u64, none)?;
        gpu.upload(&table_buffer, 0, &table)?;
        let words_u32 = u32::try_from(words).map_err(|_| GpuError::TooLarge {
            what: "reorder: particle data words".into(),
            needed: words,
            limit: u32::MAX as u64,
        })?;
        let params = gpu.uniform_buffer("reorder: params", &[n, n_pad, cells.dim() as u32, words_u32, starts, 0, 0, 0]);

        let keys_pipeline = gpu.compile("reorder: keys", &format!("{PARAMS_WGSL}{KEYS_WGSL}"), "main")?;
        let sort_pipeline = gpu.compile("reorder: sort", SORT_WGSL, "main")?;
        let gather_pipeline = gpu.compile("reorder: gather", &format!("{PARAMS_WGSL}{GATHER_WGSL}"), "main")?;

        let keys_bind = gpu.bind(
            "reorder: keys",
            &keys_pipeline,
            &[&params, particles.ints, cells.grid_buffer(), cells.cell_of_buffer(), &keys],
        );
        let mut steps = vec![];
        let mut sort_binds = vec![];
        let mut k = 2u32;
        while k <= n_pad {
            let mut j = k / 2;
            while j > 0 {
                let step = gpu.uniform_buffer("reorder: sort step", &[j, k, n_pad, 0]);
                sort_binds.push(gpu.bind("reorder: sort", &sort_pipeline, &[&step, &keys]));
                steps.push(step);
                j /= 2;
            }
            k *= 2;
        }
        let gather_bind = gpu.bind(
            "reorder: gather",
            &gather_pipeline,
            &[&params, &keys, &old, particles.data, particles.ints, particles.ids, &table_buffer],
        );
        gpu.check()?;
        Ok(Reorder {
            n,
            n_pad,
            words,
            _keys: keys,
            old,
            _table: table_buffer,
            _params: params,
            _steps: steps,
            keys_pipeline,
            sort_pipeline,
            gather_pipeline,
            keys_bind,
            sort_binds,
            gather_bind,
        })
    }

    /// Records the reordering into `encoder`, after a cell list of the current positions has
    /// been recorded into it.
    pub fn record(&self, gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, particles: &Particles) {
        if self.n == 0 {
            return;
        }
        gpu.dispatch(encoder, "reorder: keys", &self.keys_pipeline, &self.keys_bind, self.n_pad.div_ceil(WG));
        for bind in &self.sort_binds {
            gpu.dispatch(encoder, "reorder: sort", &self.sort_pipeline, bind, self.n_pad.div_ceil(WG));
        }
        let n = self.n as u64;
        encoder.copy_buffer_to_buffer(particles.data, 0, &self.old, 0, 4 * self.words);
        encoder.copy_buffer_to_buffer(particles.ints, 0, &self.old, 4 * self.words, 8 * n);
        encoder.copy_buffer_to_buffer(particles.ids, 0, &self.old, 4 * (self.words + 2 * n), 4 * n);
        gpu.dispatch(encoder, "reorder: gather", &self.gather_pipeline, &self.gather_bind, self.n.div_ceil(WG));
    }
}
