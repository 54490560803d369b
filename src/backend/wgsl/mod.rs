//! Plan → WGSL: one compute kernel per pass and destination group, per integrator stage and
//! group, plus the save, time-step and initialisation kernels. Every module is parsed and
//! validated by naga before it reaches a driver (`validate`); a module naga rejects is a compiler
//! bug, reported with its text and naga's message.
//!
//! Data layout (shared with the GPU runtime, see `Layout`):
//! - `data: array<f32>`: every stored column; element of particle i, component c of field f:
//!   `info[BASES + slot(f) * NG + group(i)] + i * comps(f) + c` (`ABSENT` where not stored).
//! - `ints: array<u32>`: group of particle i at `[i]`, its material at `[n + i]`.
//! - `params: array<f32>`: material m's parameter p, component c at `m * STRIDE + OFF(p) + c`.
//! - `meta: array<i32>`: `[0]` n, `[1 + 2g]`/`[2 + 2g]` start and count of group g, then bases.
//! - `globals: array<f32>`: time, dt, the step's dt, end time, dt_max, reductions, image planes.
//! - `grid`, `cells`: the GPU cell list (`backend::gpu::cells`).
//! - `lists`: kept neighbour lists (`backend::gpu::lists`), when the plan's search keeps them.

mod emit;
pub mod names;
pub use emit::WORKGROUP;
pub mod prelude;

use crate::ir::{FieldId, GroupId};
use crate::schedule::Plan;

/// Indices into `globals`.
pub mod globals {
    /// Simulated time at the start of the step.
    pub const TIME: usize = 0;
    /// The last completed step's time step: what equations read as `dt` while evaluating.
    pub const DT_PREV: usize = 1;
    /// This step's time step (set by the time-step kernel, read by the updates).
    pub const DT: usize = 2;
    pub const END_TIME: usize = 3;
    pub const DT_MAX: usize = 4;
    /// Steps taken.
    pub const STEP: usize = 5;
    /// Always 0: XOR-ed into bits to hide values from the shader compiler's algebra (Kahan).
    pub const ZERO: usize = 6;
    /// The watchdog's reductions ([`super::WATCH_SLOTS`] of them): the largest |v|², the energy
    /// `Σ m (½|v|² + e − g·x)`, `Σ |m (½|v|² + e − g·x)|`, which bounds the rounding of the
    /// energy's f32 sum, and the kinetic energy `Σ ½ m |v|²` (also the `kinetic_energy` measure's).
    pub const WATCH: usize = 7;
    /// Values of the time-step reductions (up to `PLANES`).
    pub const REDUCTIONS: usize = 16;
    /// The number of image planes (symmetry planes, periodic sides), then (axis, offset, shift)
    /// triples, six at most.
    pub const PLANES: usize = 72;
    /// The last word is the watchdog scan's.
    pub const SIZE: usize = 96;
}

/// Per-particle values the watchdog reduces on the device (see [`globals::WATCH`]).
pub const WATCH_SLOTS: usize = 4;

/// Marks a (field, group) without storage in `meta`.
pub const ABSENT: i32 = i32::MIN;

/// Where things are in `meta` and `params`: everything a kernel needs to address memory.
#[derive(Clone, Debug)]
pub struct Layout {
    pub n_groups: usize,
    /// Layout slot of each stored field (index in `plan.layout`).
    pub slots: Vec<(FieldId, usize)>,
    /// Per slot: whether the field is stored on every group. Its rows are then the particles'
    /// indices and its base the same on every group (`meta` holds it for every group, present or
    /// not), so a kernel reads it from group 0's entry, one address for all threads, instead of
    /// looking up each neighbour's group first.
    pub everywhere: Vec<bool>,
    pub param_offset: Vec<usize>,
    pub param_stride: usize,
}

impl Layout {
    pub fn new(plan: &Plan) -> Layout {
        let slots = plan.layout.iter().enumerate().map(|(k, l)| (l.field, k)).collect();
        let n_groups = plan.model.groups.len();
        let everywhere =
            plan.layout.iter().map(|l| (0..n_groups).all(|g| l.groups.contains(GroupId(g as u32)))).collect();
        let mut param_offset = vec![];
        let mut stride = 0;
        for p in &plan.model.params {
            param_offset.push(stride);
            stride += crate::ir::components(p.ty.shape, plan.dim);
        }
        Layout { n_groups, slots, everywhere, param_offset, param_stride: stride }
    }
    pub fn slot(&self, f: FieldId) -> Option<usize> {
        self.slots.iter().find(|(g, _)| *g == f).map(|(_, s)| *s)
    }
    /// Index in `meta` of the base of slot `s` on group `g`.
    pub fn base_index(&self, slot: usize, g: usize) -> usize {
        1 + 2 * self.n_groups + slot * self.n_groups + g
    }
    /// The WGSL expression of slot `s`'s base for particle `p`'s group: group 0's entry when the
    /// field is stored on every group, else the entry of `ints[p]`.
    pub fn base_of(&self, slot: usize, p: &str) -> String {
        if self.everywhere[slot] {
            format!("info[{}u]", self.base_index(slot, 0))
        } else {
            format!("info[{}u + ints[{p}]]", self.base_index(slot, 0))
        }
    }
    pub fn meta_len(&self) -> usize {
        1 + 2 * self.n_groups + self.slots.len() * self.n_groups
    }
}

/// What a kernel is for, so the runtime knows when to dispatch it.
#[derive(Clone, Debug, PartialEq)]
pub enum KernelKind {
    /// Pass `pass` for destination group `group`: one invocation per particle of the group.
    Pass { pass: usize, group: GroupId },
    /// Integrator stage for one group.
    Update { stage: usize, group: GroupId },
    /// Copy the evolving state to its saved copy, for one group.
    Save { group: GroupId },
    /// The state-only particle equations on the initial state, for one group.
    Initialise { group: GroupId },
    /// Per-particle values of the time-step reductions into scratch (all particles).
    ReductionValues,
    /// Per-particle values of the watchdog's reductions into scratch, after the time step's.
    WatchValues,
    /// One invocation: the time step from the reductions, written to `globals`.
    Timestep,
    /// One invocation: advance the clock after a step.
    Advance,
}

#[derive(Clone, Debug)]
pub struct Kernel {
    /// File name stem, e.g. `pass1_solid`.
    pub name: String,
    pub kind: KernelKind,
    pub wgsl: String,
    /// The bindings the kernel declares (the runtime binds exactly these).
    pub bindings: Vec<Binding>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Binding {
    Data = 0,
    Ints = 1,
    Params = 2,
    Meta = 3,
    Grid = 4,
    Cells = 5,
    Globals = 6,
    /// Kept neighbour lists (`backend::gpu::lists`), walked instead of the cells.
    Lists = 7,
}

impl Binding {
    pub const ALL: [Binding; 8] = [
        Binding::Data,
        Binding::Ints,
        Binding::Params,
        Binding::Meta,
        Binding::Grid,
        Binding::Cells,
        Binding::Globals,
        Binding::Lists,
    ];
    fn declaration(self) -> &'static str {
        match self {
            Binding::Data => "@group(0) @binding(0) var<storage, read_write> data: array<f32>;",
            Binding::Ints => "@group(0) @binding(1) var<storage, read> ints: array<u32>;",
            Binding::Params => "@group(0) @binding(2) var<storage, read> params: array<f32>;",
            Binding::Meta => "@group(0) @binding(3) var<storage, read> info: array<i32>;",
            Binding::Grid => "@group(0) @binding(4) var<storage, read> grid: array<u32>;",
            Binding::Cells => "@group(0) @binding(5) var<storage, read> cells: array<u32>;",
            Binding::Globals => "@group(0) @binding(6) var<storage, read_write> globals: array<f32>;",
            Binding::Lists => "@group(0) @binding(7) var<storage, read> lists: array<u32>;",
        }
    }
}

/// Every kernel of the plan. `cell_helpers` is the WGSL of the GPU cell list's accessors
/// (`backend::gpu::cells::wgsl_helpers`), pasted into the pass kernels; `scratch` is the element
/// offset in `data` where reduction values may be written (`n` per reduction).
pub fn generate(plan: &Plan, cell_helpers: &str) -> Result<Vec<Kernel>, String> {
    emit::generate(plan, cell_helpers)
}

/// Every kernel as (file name, text), for `pairsum emit` and `shaders_gen/`.
pub fn files(plan: &Plan) -> Result<Vec<(String, String)>, String> {
    Ok(generate(plan, crate::backend::gpu::cells::wgsl_helpers())?
        .into_iter()
        .map(|k| (format!("{}.wgsl", k.name), k.wgsl))
        .collect())
}

/// Parses and validates a module with naga.
pub fn validate(label: &str, wgsl: &str) -> Result<(), String> {
    let module = naga::front::wgsl::parse_str(wgsl)
        .map_err(|e| format!("{label}: naga rejects the WGSL:\n{}", e.emit_to_string(wgsl)))?;
    let mut v = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::default());
    v.validate(&module).map_err(|e| format!("{label}: naga rejects the WGSL:\n{}", e.emit_to_string(wgsl)))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check::{check_stdlib_modules, Stdlib};
    use crate::diag::{render, Sources};
    use crate::schedule::{IntegratorKind, SceneSpec};

    #[test]
    fn every_stdlib_model_generates_wgsl_that_naga_accepts() {
        let cells = crate::backend::gpu::cells::wgsl_helpers();
        for m in [
            "models/elastic_solid.sph",
            "models/elastic_solid_corrected.sph",
            "models/wcsph_fluid.sph",
            "models/wcsph_dbc.sph",
            "models/wcsph_adami.sph",
            "models/lsm_solid.sph",
            "models/wcsph_lsm.sph",
            "models/ek18_fsi.sph",
            "models/ek18_solid_failure.sph",
        ] {
            let mut sources = Sources::new();
            let checked = check_stdlib_modules(&mut sources, &[m], Stdlib::locate());
            assert!(!checked.has_errors(), "{}", render(&sources, &checked.diags));
            for dim in 1..=3 {
                let scene = SceneSpec {
                    dim,
                    groups: checked.model.all_groups(),
                    outputs: vec![],
                    integrator: IntegratorKind::PredictorCorrector,
                    gravity: None,
                    loads: vec![],
                    constraints: vec![],
                    planes: vec![],
                    search: Default::default(),
                    damping: None,
                    settled: vec![],
                    initialised: vec![],
                    axisymmetric: false,
                };
                let plan = Plan::build(&checked.model, &scene, None).expect("plan");
                let kernels = generate(&plan, cells).unwrap_or_else(|e| panic!("{m} {dim}D: {e}"));
                assert!(!kernels.is_empty());
                if let Ok(dir) = std::env::var("PAIRSUM_DUMP_WGSL") {
                    for k in &kernels {
                        let name =
                            format!("{dir}/{}_{dim}d_{}.wgsl", m.replace('/', "_").trim_end_matches(".sph"), k.name);
                        std::fs::write(name, &k.wgsl).expect("dump");
                    }
                }
            }
        }
    }
}
