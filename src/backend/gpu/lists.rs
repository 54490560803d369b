//! Kept neighbour lists on the GPU: the device side of the plan's [`Search`] (Verlet lists with a
//! skin, F-ANS's adaptive rebuild), recorded into the step's command encoder like the cell list.
//!
//! # What `record` computes, before the passes of an evaluation
//!
//! 1. The cell list, with cells of the cut-off plus the skin (the caller builds it).
//! 2. `drift` (Verlet, per particle): the largest squared displacement and growth of h since the
//!    last full build, as atomic maxima of their f32 bits (non-negative floats order as their
//!    bits; NaN is above every number, so a NaN forces a rebuild).
//! 3. `decide` (one thread): a full build when there are no lists yet, or when the Verlet bound
//!    `2 · displacement + support · h growth > skin` holds ([`crate::schedule::Drift::exceeds`],
//!    the same rule in WGSL); it counts full builds and records the skin's length.
//! 4. `build` (per particle): rebuilds the list of every particle on a full build, and on the
//!    adaptive search the lists of the particles whose field grew by more than the threshold since
//!    their last rebuild. On a full build each particle first counts its candidates and takes room
//!    for them from one pool (an atomic counter: lists of every length packed end to end, so that
//!    a few coarse particles among fine ones, which see thousands, do not size every list), as
//!    [`room`] says; on the adaptive search its later rebuilds fill that room. A particle
//!    with more candidates than its room, or none left in the pool, records its count, and the
//!    runtime stops the run with an error.
//!
//! # The `lists` buffer (u32 words)
//! `[CAPACITY]` entries the pool holds, `[BUILT]` 1 once built, `[REBUILD]` this evaluation's full
//! build flag, `[DISPLACEMENT]`/`[H_GROWTH]` the drift maxima (f32 bits), `[LARGEST]` the largest
//! candidate count, `[FULL_BUILDS]`/`[PARTICLE_REBUILDS]`/`[EVALUATIONS]` counters, `[SKIN_LEN]` the
//! skin's length (f32 bits), `[TAKEN]` the entries handed out since the last full build, `[SHORT]`
//! the most candidates of a particle whose list could not hold them all (0: none); from `HEADER`
//! the `n` counts, the `n` starts (in the pool), the `n` rooms, then the pool from `HEADER + 3n`:
//! each entry the neighbour's index with the mirror transform of its image in the top bits (as the
//! CPU's [`crate::backend::cpu::lists`]).

use super::device::{Gpu, GpuError};
use crate::schedule::Search;

pub use crate::backend::cpu::lists::{INDEX_MASK, TRANSFORM_SHIFT};

pub const CAPACITY: usize = 0;
pub const BUILT: usize = 1;
pub const REBUILD: usize = 2;
pub const DISPLACEMENT: usize = 3;
pub const H_GROWTH: usize = 4;
pub const LARGEST: usize = 5;
pub const FULL_BUILDS: usize = 6;
pub const PARTICLE_REBUILDS: usize = 7;
pub const SKIN_LEN: usize = 8;
pub const EVALUATIONS: usize = 9;
pub const TAKEN: usize = 10;
pub const SHORT: usize = 11;
/// Words before the counts.
pub const HEADER: usize = 16;

const WG_PARTICLE: u32 = 64;

/// The uniform of the list kernels.
const PARAMS_WGSL: &str = r#"
struct ListParams {
    n: u32,
    dim: u32,
    x_offset: u32,
    h_offset: u32,
    support: f32,
    skin: f32,
    // 1: Verlet, 2: adaptive.
    mode: u32,
    threshold: f32,
    // Index in `info` of the adaptive field's base on group 0 (groups follow), or -1.
    field_base: i32,
    mirrors: u32,
    // Half the shortest periodic domain (0: none): a particle that moved that far crossed a side,
    // and the adaptive search rebuilds every list.
    half_period: f32,
    pad1: u32,
    // Per image plane m: axis[m / 4][m % 4], at and shift likewise (shift 0: a symmetry plane).
    axis: array<vec4<u32>, 2>,
    at: array<vec4<f32>, 2>,
    shift: array<vec4<f32>, 2>,
}
"#;

const DRIFT_WGSL: &str = r#"
@group(0) @binding(0) var<uniform> params: ListParams;
@group(0) @binding(1) var<storage, read> data: array<f32>;
@group(0) @binding(2) var<storage, read_write> lists: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read> state: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let i = (wg.x + wg.y * nwg.x) * 64u + li;
    let watched = params.mode == 1u || (params.mode == 2u && params.half_period > 0.0);
    if (i >= params.n || !watched || atomicLoad(&lists[1]) == 0u) { return; }
    var d2 = 0.0;
    for (var k = 0u; k < params.dim; k++) {
        let d = data[params.x_offset + i * params.dim + k] - state[i * 3u + k];
        d2 += d * d;
    }
    let dh = max(data[params.h_offset + i] - state[3u * params.n + i], 0.0);
    atomicMax(&lists[3], bitcast<u32>(abs(d2)));
    atomicMax(&lists[4], bitcast<u32>(abs(dh)));
}
"#;

const DECIDE_WGSL: &str = r#"
@group(0) @binding(0) var<uniform> params: ListParams;
@group(0) @binding(1) var<storage, read_write> lists: array<u32>;
@group(0) @binding(2) var<storage, read> grid: array<u32>;

@compute @workgroup_size(1)
fn main() {
    let displacement = sqrt(bitcast<f32>(lists[3]));
    let growth = bitcast<f32>(lists[4]);
    let reach = 2.0 * displacement + params.support * growth;
    let exceeded = reach > bitcast<f32>(lists[8]) || reach != reach;
    let wrapped = params.mode == 2u && params.half_period > 0.0 && !(displacement < params.half_period);
    let rebuild = lists[1] == 0u || (params.mode == 1u && exceeded) || wrapped;
    lists[2] = select(0u, 1u, rebuild);
    if (rebuild) {
        lists[6] += 1u;
        lists[10] = 0u;
        lists[8] = bitcast<u32>(params.skin * params.support * bitcast<f32>(grid[9]));
    }
    lists[1] = 1u;
    lists[9] += 1u;
    lists[3] = 0u;
    lists[4] = 0u;
}
"#;

const BUILD_WGSL: &str = r#"
@group(0) @binding(0) var<uniform> params: ListParams;
@group(0) @binding(1) var<storage, read> data: array<f32>;
@group(0) @binding(2) var<storage, read_write> lists: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read_write> state: array<f32>;
@group(0) @binding(4) var<storage, read> grid: array<u32>;
@group(0) @binding(5) var<storage, read> cells: array<u32>;
@group(0) @binding(6) var<storage, read> ints: array<u32>;
@group(0) @binding(7) var<storage, read> info: array<i32>;

fn pos(p: u32) -> vec3<f32> {
    var v = vec3<f32>(0.0);
    for (var k = 0u; k < params.dim; k++) {
        v[k] = data[params.x_offset + p * params.dim + k];
    }
    return v;
}

// Particle i's candidates within `radius` (each pair's own reach within it): their count, the
// first `room` stored from word `first` when `keep`.
fn walk(i: u32, xi: vec3<f32>, hi: f32, radius: f32, skin_len: f32, first: u32, room: u32, keep: bool) -> u32 {
    var count = 0u;
    for (var tr = 0u; tr < (1u << params.mirrors); tr++) {
        var yi = xi;
        var far = false;
        var shifted = vec3<u32>(0u);
        for (var m = 0u; m < params.mirrors; m++) {
            if (((tr >> m) & 1u) == 1u) {
                let axis = params.axis[m / 4u][m % 4u];
                let at = params.at[m / 4u][m % 4u];
                let shift = params.shift[m / 4u][m % 4u];
                if (abs(xi[axis] - at) >= radius) { far = true; }
                if (shift == 0.0) {
                    yi[axis] = 2.0 * at - xi[axis];
                } else {
                    yi[axis] = xi[axis] + shift;
                    shifted[axis] += 1u;
                }
            }
        }
        // Both sides of one periodic axis together move i nowhere.
        if (far || any(shifted > vec3<u32>(1u))) { continue; }
        let wk = walk_cells(yi, radius);
        for (var z = wk.lo.z; z <= wk.hi.z; z++) {
        for (var y = wk.lo.y; y <= wk.hi.y; y++) {
        for (var x = wk.lo.x; x <= wk.hi.x; x++) {
            if (walk_skips(wk, vec3<u32>(x, y, z))) { continue; }
            let cell = cell_index(vec3<u32>(x, y, z));
            for (var s = cell_start(cell); s < cell_start(cell + 1u); s++) {
                let j = sorted_particle(s);
                if (tr == 0u && j == i) { continue; }
                let d = yi - pos(j);
                // Each pair's own reach: its cut-off support · h_ij plus the skin.
                let reach = min(params.support * 0.5 * (hi + data[params.h_offset + j]) + skin_len, radius);
                if (dot(d, d) < reach * reach) {
                    if (keep && count < room) { atomicStore(&lists[first + count], j | (tr << TRANSFORM_SHIFTu)); }
                    count++;
                }
            }
        }}}
    }
    return count;
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let i = (wg.x + wg.y * nwg.x) * 64u + li;
    let n = params.n;
    if (i >= n) { return; }
    let all = atomicLoad(&lists[2]) == 1u;
    // The adaptive field of particle i (NaN where its group does not store it).
    var f = bitcast<f32>(0x7fc00000u);
    if (params.field_base >= 0) {
        let base = info[u32(params.field_base) + ints[i]];
        if (base != i32(-2147483648)) { f = data[u32(base) + i]; }
    }
    let grown = params.mode == 2u && f - state[4u * n + i] > params.threshold;
    if (!all && !grown) { return; }
    let xi = pos(i);
    let hi = data[params.h_offset + i];
    if (all) {
        for (var k = 0u; k < 3u; k++) { state[i * 3u + k] = xi[k]; }
        state[3u * n + i] = hi;
    } else {
        atomicAdd(&lists[7], 1u);
    }
    state[4u * n + i] = f;
    let h_max = bitcast<f32>(grid[9]);
    // The walk's cells hold everything within grid[14] cell sizes: a skin from an earlier full
    // build, with a larger h_max then, may not reach further (the adaptive search's rebuilds).
    let skin_len = bitcast<f32>(atomicLoad(&lists[8]));
    let radius = min(params.support * 0.5 * (hi + h_max) + skin_len, f32(grid[14]) * bitcast<f32>(grid[3]));
    var start = atomicLoad(&lists[16u + n + i]);
    var room = atomicLoad(&lists[16u + 2u * n + i]);
    if (all) {
        // Room from the pool (`room`, rendered from the host's rule): none when the pool has run out.
        let wanted = walk(i, xi, hi, radius, skin_len, 0u, 0u, false);
        room = select(ROOM_VERLET, ROOM_ADAPTIVE, params.mode == 2u);
        start = atomicAdd(&lists[10], room);
        let capacity = atomicLoad(&lists[0]);
        if (start > capacity || room > capacity - start) { room = 0u; }
        atomicStore(&lists[16u + n + i], start);
        atomicStore(&lists[16u + 2u * n + i], room);
    }
    let count = walk(i, xi, hi, radius, skin_len, 16u + 3u * n + start, room, true);
    atomicStore(&lists[16u + i], min(count, room));
    atomicMax(&lists[5], count);
    if (count > room) { atomicMax(&lists[11], count); }
}
"#;

/// The room rules, Verlet's then the adaptive search's ([`room`] says why these).
const ROOM: [RoomRule; 2] =
    [RoomRule { times: 1, over: Some(8), extra: 8 }, RoomRule { times: 2, over: None, extra: 16 }];

/// One search's room: `count · times + count / over + extra` (no `over`: no fraction).
struct RoomRule {
    times: u64,
    over: Option<u64>,
    extra: u64,
}

/// The room a particle with `count` candidates takes from the pool at a full build: with Verlet
/// lists, rebuilt only whole, its count and an eighth more plus 8, since the walk that counts and
/// the walk that stores may round a pair at the cut-off differently (a compiler may contract one
/// and not the other: lavapipe did, by one candidate); on the adaptive search, whose particles
/// rebuild their own lists in their room, twice the count plus 16. The host sizes the pool by it
/// and the build kernel takes by it, rendered from the same [`ROOM`] ([`room_wgsl`]).
pub fn room(count: u64, adaptive: bool) -> u64 {
    let RoomRule { times, over, extra } = ROOM[adaptive as usize];
    count * times + over.map_or(0, |over| count / over) + extra
}

/// [`room`] as a WGSL expression of the build kernel's `wanted`.
fn room_wgsl(adaptive: bool) -> String {
    let RoomRule { times, over, extra } = ROOM[adaptive as usize];
    let fraction = over.map_or(String::new(), |over| format!(" + wanted / {over}u"));
    format!("(wanted * {times}u{fraction} + {extra}u)")
}

/// The pool of entries every list takes its room from: its size, the entries handed out since the
/// last full build, and the most candidates any particle had (the header's words).
#[derive(Clone, Copy, Debug)]
pub struct ListPool {
    pub capacity: u32,
    pub taken: u32,
    pub largest: u32,
}

/// The device's lists and the kernels that keep them.
pub struct GpuLists {
    n: u32,
    /// Entries the pool holds.
    capacity: u32,
    lists: wgpu::Buffer,
    state: wgpu::Buffer,
    params: wgpu::Buffer,
    drift: wgpu::ComputePipeline,
    decide: wgpu::ComputePipeline,
    build: wgpu::ComputePipeline,
}

/// What the list kernels need to know of the scene.
pub struct ListScene<'a> {
    pub n: usize,
    pub dim: usize,
    pub x_offset: u32,
    pub h_offset: u32,
    pub support: f32,
    pub mirrors: &'a [crate::backend::Mirror],
    /// Index in `info` of the adaptive field's base on group 0, when the search is adaptive.
    pub field_base: Option<usize>,
    /// Entries the pool holds, for every list together.
    pub capacity: u32,
}

/// The dispatches of [`GpuLists::record`]: drift, decide, build.
pub const DISPATCHES: usize = 3;

impl GpuLists {
    /// The buffers for `n` particles with a pool of `capacity` entries, `(name, bytes)`.
    pub fn planned_buffers(n: usize, capacity: u32) -> Vec<(&'static str, u64)> {
        vec![
            ("neighbour lists", 4 * (HEADER as u64 + 3 * n as u64 + capacity as u64)),
            ("neighbour lists: state at the build", 4 * 5 * n as u64),
        ]
    }

    pub fn new(gpu: &Gpu, search: &Search, scene: &ListScene, cell_helpers: &str) -> Result<GpuLists, GpuError> {
        let (n, capacity) = (scene.n, scene.capacity);
        let planned = GpuLists::planned_buffers(n, capacity);
        gpu.estimate_fits(&planned)?;
        let none = wgpu::BufferUsages::empty();
        let lists = gpu.storage_buffer("neighbour lists", planned[0].1, none)?;
        let state = gpu.storage_buffer("neighbour lists: state at the build", 4 * 5 * n.max(1) as u64, none)?;
        let mut header = [0u32; HEADER];
        header[CAPACITY] = capacity;
        gpu.upload(&lists, 0, &header)?;
        let (mode, threshold) = match search {
            Search::Cells => (0u32, 0.0f32),
            Search::Verlet { .. } => (1, 0.0),
            Search::Adaptive { threshold, .. } => (2, threshold.min(f32::MAX as f64) as f32),
        };
        let mut axis = [0u32; 8];
        let mut at = [0f32; 8];
        let mut shift = [0f32; 8];
        for (k, m) in scene.mirrors.iter().enumerate().take(crate::backend::cpu::lists::MAX_PLANES) {
            axis[k] = m.axis as u32;
            at[k] = m.offset as f32;
            shift[k] = m.shift as f32;
        }
        let words: Vec<u32> = [
            n as u32,
            scene.dim as u32,
            scene.x_offset,
            scene.h_offset,
            scene.support.to_bits(),
            (search.skin() as f32).to_bits(),
            mode,
            threshold.to_bits(),
            scene.field_base.map(|b| b as i32).unwrap_or(-1) as u32,
            scene.mirrors.len() as u32,
            (crate::backend::cpu::lists::half_period(scene.mirrors).unwrap_or(0.0) as f32).to_bits(),
            0,
        ]
        .into_iter()
        .chain(axis)
        .chain(at.map(f32::to_bits))
        .chain(shift.map(f32::to_bits))
        .collect();
        let params = gpu.uniform_buffer("neighbour lists: params", &words);
        let drift = gpu.compile("neighbour lists: drift", &format!("{PARAMS_WGSL}{DRIFT_WGSL}"), "main")?;
        let decide = gpu.compile("neighbour lists: decide", &format!("{PARAMS_WGSL}{DECIDE_WGSL}"), "main")?;
        let build = gpu.compile(
            "neighbour lists: build",
            &format!(
                "{PARAMS_WGSL}{cell_helpers}{}",
                BUILD_WGSL
                    .replace("TRANSFORM_SHIFT", &TRANSFORM_SHIFT.to_string())
                    .replace("ROOM_VERLET", &room_wgsl(false))
                    .replace("ROOM_ADAPTIVE", &room_wgsl(true))
            ),
            "main",
        )?;
        Ok(GpuLists { n: n as u32, capacity, lists, state, params, drift, decide, build })
    }

    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.lists
    }

    /// Records steps 2–4 (the cell list must be recorded first, with cells of the cut-off plus
    /// the skin): [`DISPATCHES`] dispatches.
    pub fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        data: &wgpu::Buffer,
        cells: &super::cells::CellList,
        ints: &wgpu::Buffer,
        info: &wgpu::Buffer,
    ) {
        let groups = self.n.div_ceil(WG_PARTICLE);
        let drift = gpu.bind("neighbour lists: drift", &self.drift, &[&self.params, data, &self.lists, &self.state]);
        gpu.dispatch(encoder, "neighbour lists: drift", &self.drift, &drift, groups);
        let decide =
            gpu.bind("neighbour lists: decide", &self.decide, &[&self.params, &self.lists, cells.grid_buffer()]);
        gpu.dispatch(encoder, "neighbour lists: decide", &self.decide, &decide, 1);
        let entries =
            [&self.params, data, &self.lists, &self.state, cells.grid_buffer(), cells.cells_buffer(), ints, info];
        let build = gpu.bind("neighbour lists: build", &self.build, &entries);
        gpu.dispatch(encoder, "neighbour lists: build", &self.build, &build, groups);
    }

    /// Forgets the lists (particles were reordered or the state replaced): the next evaluation
    /// builds them all.
    pub fn invalidate(&self, gpu: &Gpu) -> Result<(), GpuError> {
        gpu.upload(&self.lists, 4 * BUILT as u64, &[0u32])
    }

    /// The header: counters and the largest candidate count.
    pub fn header(&self, gpu: &Gpu) -> Result<Vec<u32>, GpuError> {
        gpu.download(&self.lists, 0, HEADER)
    }

    /// An error when a particle had more candidates than its list holds (its list was cut short,
    /// so the last evaluation missed pairs).
    pub fn check_overflow(&self, gpu: &Gpu) -> Result<(), GpuError> {
        self.check_short(self.header(gpu)?[SHORT])
    }

    /// Records a copy of the most candidates of a list cut short (the word
    /// [`GpuLists::check_short`] takes) into `to` at byte `at`, so that a step's own read-back
    /// carries it.
    pub fn record_short_copy(&self, encoder: &mut wgpu::CommandEncoder, to: &wgpu::Buffer, at: u64) {
        encoder.copy_buffer_to_buffer(&self.lists, 4 * SHORT as u64, to, at, 4);
    }

    /// An error if a particle found more candidates than its list could hold (`short`: their
    /// count, 0 when every list held all of its own).
    pub fn check_short(&self, short: u32) -> Result<(), GpuError> {
        if short > 0 {
            return Err(GpuError::Device(format!(
                "a particle has {short} neighbour candidates, more than the room its list was given: the lists share \
                 {} entries, twice the room they took at the start plus 16 per particle, and the particles have clumped \
                 far beyond their initial packing",
                self.capacity
            )));
        }
        Ok(())
    }

    pub fn pool(&self, gpu: &Gpu) -> Result<ListPool, GpuError> {
        let h = self.header(gpu)?;
        Ok(ListPool { capacity: h[CAPACITY], taken: h[TAKEN], largest: h[LARGEST] })
    }

    pub fn stats(&self, gpu: &Gpu) -> Result<crate::schedule::SearchStats, GpuError> {
        let h = self.header(gpu)?;
        Ok(crate::schedule::SearchStats {
            evaluations: h[EVALUATIONS] as u64,
            full_builds: h[FULL_BUILDS] as u64,
            particle_rebuilds: h[PARTICLE_REBUILDS] as u64,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What naga's constant evaluation makes of the build kernel's room for `wanted` candidates.
    fn room_on_the_device(wanted: u32, adaptive: bool) -> u32 {
        let src = format!("const wanted: u32 = {wanted}u;\nconst room: u32 = {};\n", room_wgsl(adaptive));
        let module = naga::front::wgsl::parse_str(&src).expect("the room's WGSL parses");
        let (_, room) =
            module.constants.iter().find(|(_, c)| c.name.as_deref() == Some("room")).expect("a constant `room`");
        match module.global_expressions[room.init] {
            naga::Expression::Literal(naga::Literal::U32(v)) => v,
            ref e => panic!("the room did not evaluate to a u32: {e:?}"),
        }
    }

    #[test]
    fn the_build_kernels_room_is_the_hosts_for_both_searches() {
        for adaptive in [false, true] {
            for wanted in [0u32, 1, 7, 8, 9, 63, 64, 1000, 123_457] {
                assert_eq!(
                    room_on_the_device(wanted, adaptive) as u64,
                    room(wanted as u64, adaptive),
                    "{wanted}, {adaptive}"
                );
            }
        }
        assert_eq!(room(1000, false), 1133);
        assert_eq!(room(1000, true), 2016);
    }
}
