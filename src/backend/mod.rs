//! Backends run a plan: the CPU one as compiled closures under rayon, the GPU one as WGSL through
//! wgpu. The engine drives either through `Backend`, one integrator action at a time.

pub mod cpu;
pub mod gpu;
pub mod timestep;
pub mod wgsl;

use crate::ir::FieldId;
use crate::schedule::Plan;

/// Simulated time and the current time step, as the programs see them.
#[derive(Clone, Copy, Debug, Default)]
pub struct Globals {
    pub time: f64,
    pub dt: f64,
}

pub use crate::schedule::Mirror;

/// Err when a periodic domain is no longer than twice the largest cut-off (`support · h_max`):
/// a particle would then meet its own image, or one neighbour twice.
pub fn check_periods(planes: &[Mirror], support: f64, h_max: f64) -> Result<(), BackendError> {
    let cut_off = support * h_max;
    match planes.iter().find(|p| p.shift > 0.0 && p.shift <= 2.0 * cut_off) {
        Some(p) => Err(BackendError(format!(
            "the periodic domain along {} is {} m long, no longer than twice the largest cut-off ({cut_off} m): \
             make it longer or the particles smaller",
            crate::ir::AXIS_NAMES[p.axis],
            p.shift
        ))),
        None => Ok(()),
    }
}

/// A backend-independent copy of the particle state (checkpoints, restarts, last good state).
#[derive(Clone, Debug, Default)]
pub struct Snapshot {
    /// Per stored field (by id): the raw column data as f64.
    pub columns: Vec<Option<Vec<f64>>>,
    pub id: Vec<u32>,
    pub material: Vec<u32>,
}

#[derive(Debug, Clone)]
pub struct BackendError(pub String);

impl std::fmt::Display for BackendError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

pub trait Backend {
    /// "cpu (f64, 2 threads)", "gpu (llvmpipe, f32)".
    fn describe(&self) -> String;
    fn plan(&self) -> &Plan;
    fn particles(&self) -> usize;
    /// Runs the state-only particle equations on the initial state (initial values are set by
    /// `engine::setup`).
    fn initialise(&mut self) -> Result<(), BackendError>;
    /// Copies the evolving state to its saved copy.
    fn save(&mut self) -> Result<(), BackendError>;
    /// Builds the neighbour search and runs every pass.
    fn evaluate(&mut self, g: Globals) -> Result<(), BackendError>;
    /// The values of the time-step reductions (`min_over` …), in the order of
    /// `timestep::reductions`.
    fn reductions(&mut self, g: Globals) -> Result<Vec<f64>, BackendError>;
    /// Runs integrator stage `stage`.
    fn update(&mut self, stage: usize, g: Globals) -> Result<(), BackendError>;
    /// Reorders particles along a space-filling curve for memory locality.
    fn reorder(&mut self) -> Result<(), BackendError>;
    /// A field for every particle in the current order (`n × comps`, NaN where not stored);
    /// `None` when the field is stored nowhere.
    fn read(&self, f: FieldId) -> Result<Option<(usize, Vec<f64>)>, BackendError>;
    /// Each particle's index at creation, in the current order.
    fn ids(&self) -> Result<Vec<u32>, BackendError>;
    /// Each particle's group, in the current order.
    fn groups(&self) -> Vec<u32>;
    fn snapshot(&self) -> Result<Snapshot, BackendError>;
    fn restore(&mut self, s: &Snapshot) -> Result<(), BackendError>;
    /// The first particle (in the current order) and field that is NaN or infinite among `fields`.
    fn first_non_finite(&mut self, fields: &[FieldId]) -> Result<Option<(usize, FieldId)>, BackendError>;
    /// What the neighbour search has done so far (rebuilds of kept lists).
    fn search_stats(&self) -> crate::schedule::SearchStats {
        crate::schedule::SearchStats::default()
    }
    /// A whole step on the device in one submission, for backends that can (the GPU): from the
    /// clock (time, last dt, step) to the new one. `None`: the engine runs the actions itself.
    fn device_step(
        &mut self,
        time: f64,
        dt_prev: f64,
        step: u64,
        end_time: f64,
        dt_max: f64,
    ) -> Option<Result<(f64, f64, u64), BackendError>> {
        let _ = (time, dt_prev, step, end_time, dt_max);
        None
    }
}
