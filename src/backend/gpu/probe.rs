//! A probe's reduction on the GPU: the largest, least, sum or mean of one component (or the
//! length) of a field over the selected particles, so that a probe reads back two numbers instead
//! of the field and the ids (`pairsum run` probes every few steps; on a million particles the
//! read-back and the host's pass over it cost more than the step).
//!
//! One kernel, the same for every model: it finds the field through the column's offset and
//! per-group row bases (as the host store lays it out), the particle's group in `ints`, its scene
//! index in `ids` and the selection as a bit set over scene indices. It writes each particle's
//! value (the reduction's identity where the particle is not selected, its group does not store the
//! field, or the value is NaN, which the host's probes leave out too) and a 1 or 0 to count it,
//! into two scratch arrays that [`super::reduce::Reducer`] then reduces.

use super::device::{Gpu, GpuError};
use wgpu::util::DeviceExt;

const WGSL: &str = r#"
// The values of a probe's reduction, one per particle (see src/backend/gpu/probe.rs).
// probe: [n, field offset, comps, pick (0 component, 1 length, 2 absolute component), component,
//         output offset, selecting (0/1), identity (f32 bits), row base of group g at 8 + g]
@group(0) @binding(0) var<storage, read_write> data: array<f32>;
@group(0) @binding(1) var<storage, read> ints: array<u32>;
@group(0) @binding(2) var<storage, read> ids: array<u32>;
@group(0) @binding(3) var<storage, read> probe: array<u32>;
@group(0) @binding(4) var<storage, read> selected: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    let i = (wg.x + wg.y * nwg.x) * 64u + li;
    let n = probe[0];
    if (i >= n) { return; }
    var value = bitcast<f32>(probe[7]);
    var counted = 0.0;
    let base = bitcast<i32>(probe[8u + ints[i]]);
    let id = ids[i];
    let chosen = probe[6] == 0u || ((selected[id / 32u] >> (id % 32u)) & 1u) == 1u;
    if (chosen && base != bitcast<i32>(0x80000000u)) {
        let comps = probe[2];
        let at = probe[1] + u32(i32(i) + base) * comps;
        var v = data[at + probe[4]];
        if (probe[3] == 1u) {
            var s = 0.0;
            for (var k = 0u; k < comps; k++) {
                s = s + data[at + k] * data[at + k];
            }
            v = sqrt(s);
        } else if (probe[3] == 2u) {
            v = abs(v);
        }
        if (v == v) {
            value = v;
            counted = 1.0;
        }
    }
    let out = probe[5];
    data[out + i] = value;
    data[out + n + i] = counted;
}
"#;

/// What the host's probe asks for, in the store's layout.
pub struct ProbeQuery<'a> {
    /// Element offset of the field's column in `data`.
    pub offset: u32,
    pub comps: u32,
    /// Per model group: the row base of the column (`row = i + base`), or `i32::MIN` where the
    /// group does not store it.
    pub base: Vec<i32>,
    /// `None`: the length of the vector; otherwise this component.
    pub component: Option<u32>,
    /// Take the absolute value (for `abs_max`).
    pub abs: bool,
    /// The identity of the reduction, for the particles it leaves out.
    pub identity: f32,
    /// By scene index, the selected particles; `None`: all.
    pub select: Option<&'a [bool]>,
}

pub struct ProbeKernel {
    pipeline: wgpu::ComputePipeline,
}

impl ProbeKernel {
    pub fn new(gpu: &Gpu) -> Result<ProbeKernel, GpuError> {
        Ok(ProbeKernel { pipeline: gpu.compile("probe values", WGSL, "main")? })
    }

    /// Records the per-particle values of `q` at `data[out..out + n]` and their 1/0 counts at
    /// `data[out + n..out + 2n]`.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        q: &ProbeQuery,
        n: u32,
        out: u32,
        data: &wgpu::Buffer,
        ints: &wgpu::Buffer,
        ids: &wgpu::Buffer,
    ) {
        let pick = match (q.component, q.abs) {
            (None, _) => 1,
            (Some(_), false) => 0,
            (Some(_), true) => 2,
        };
        let mut words = vec![
            n,
            q.offset,
            q.comps,
            pick,
            q.component.unwrap_or(0),
            out,
            q.select.is_some() as u32,
            q.identity.to_bits(),
        ];
        words.extend(q.base.iter().map(|b| *b as u32));
        let mut bits = vec![0u32; q.select.map_or(1, |s| s.len().div_ceil(32).max(1))];
        for (k, _) in q.select.unwrap_or(&[]).iter().enumerate().filter(|(_, s)| **s) {
            bits[k / 32] |= 1 << (k % 32);
        }
        let storage = |label: &str, contents: &[u32]| {
            gpu.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytemuck::cast_slice(contents),
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let (params, selected) = (storage("probe: params", &words), storage("probe: selection", &bits));
        let bind = gpu.bind("probe values", &self.pipeline, &[data, ints, ids, &params, &selected]);
        gpu.dispatch(encoder, "probe values", &self.pipeline, &bind, n.div_ceil(64));
    }
}
