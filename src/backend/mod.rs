//! Backends run a plan: the CPU one as compiled closures under rayon, the GPU one as WGSL through
//! wgpu. The engine drives either through `Backend`, one integrator action at a time.

pub mod cpu;
pub mod domains;
pub mod gpu;
pub mod timestep;
pub mod transport;
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

/// A probe's reduction of one field over selected particles (see [`Backend::reduce_field`]).
pub struct FieldReduction<'a> {
    pub field: FieldId,
    /// `None`: the length of the vector; otherwise this stored component.
    pub component: Option<usize>,
    /// `min`, `max`, `abs_max`, `sum` or `mean`, over the values that are not NaN.
    pub reduce: &'a str,
    /// By scene index, the particles it takes; `None`: every particle that stores the field.
    pub select: Option<&'a [bool]>,
}

/// A probe's reduction over some of the particles: what it has reduced so far and how many values
/// that took. NaN values (a group that does not store the field) are left out. Parts merge in any
/// grouping, so the host, each rank of a split run and the GPU reduce by this one rule: a rank
/// reduces its own particles, the ranks' parts merge in rank order, and [`value`](Self::value)
/// is the probe's value (NaN when no value was taken).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Partial {
    kind: Reduction,
    value: f64,
    count: f64,
}

/// The reductions a probe may ask for (`reduce` in case files).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reduction {
    Min,
    Max,
    AbsMax,
    Sum,
    Mean,
}

impl Partial {
    /// Nothing reduced yet by `reduce` (`min`, `max`, `abs_max`, `sum`; anything else is `mean`).
    pub fn new(reduce: &str) -> Partial {
        let kind = match reduce {
            "min" => Reduction::Min,
            "max" => Reduction::Max,
            "abs_max" => Reduction::AbsMax,
            "sum" => Reduction::Sum,
            _ => Reduction::Mean,
        };
        let value = match kind {
            Reduction::Min => f64::INFINITY,
            Reduction::Max | Reduction::AbsMax => f64::NEG_INFINITY,
            Reduction::Sum | Reduction::Mean => 0.0,
        };
        Partial { kind, value, count: 0.0 }
    }

    /// `reduce` of `values`.
    pub fn of(reduce: &str, values: impl IntoIterator<Item = f64>) -> Partial {
        values.into_iter().fold(Partial::new(reduce), Partial::taking)
    }

    /// A part reduced elsewhere (on the device, by another rank) from its value and count.
    pub fn from_parts(reduce: &str, value: f64, count: f64) -> Partial {
        Partial { value, count, ..Partial::new(reduce) }
    }

    /// The value and the count, to send to the other ranks.
    pub fn parts(&self) -> [f64; 2] {
        [self.value, self.count]
    }

    /// This part with `v` taken in (left out if NaN).
    pub fn taking(self, v: f64) -> Partial {
        if v.is_nan() {
            return self;
        }
        let value = match self.kind {
            Reduction::Min => self.value.min(v),
            Reduction::Max => self.value.max(v),
            Reduction::AbsMax => self.value.max(v.abs()),
            Reduction::Sum | Reduction::Mean => self.value + v,
        };
        Partial { value, count: self.count + 1.0, ..self }
    }

    /// This part with `v` of weight `w` taken in (left out if NaN): a sum adds `w v`, a mean
    /// counts `w` (an axisymmetric case's particle weighs as its ring, 2π r); the extremes ignore
    /// the weight.
    pub fn taking_weighted(self, v: f64, w: f64) -> Partial {
        match self.kind {
            _ if v.is_nan() => self,
            Reduction::Sum => Partial { value: self.value + w * v, count: self.count + 1.0, ..self },
            Reduction::Mean => Partial { value: self.value + w * v, count: self.count + w, ..self },
            _ => self.taking(v),
        }
    }

    /// Both parts reduced as one.
    pub fn merge(self, other: Partial) -> Partial {
        if other.count == 0.0 {
            return self;
        }
        if self.count == 0.0 {
            return other;
        }
        let value = match self.kind {
            Reduction::Min => self.value.min(other.value),
            Reduction::Max | Reduction::AbsMax => self.value.max(other.value),
            Reduction::Sum | Reduction::Mean => self.value + other.value,
        };
        Partial { value, count: self.count + other.count, ..self }
    }

    /// Every rank's [`parts`](Self::parts) (this one's among them), merged in order.
    pub fn merge_all(self, parts: &[Vec<f64>]) -> Partial {
        let none = Partial { value: 0.0, count: 0.0, ..self };
        parts.iter().fold(none, |all, p| all.merge(Partial { value: p[0], count: p[1], ..self }))
    }

    /// The probe's value: NaN when no value was taken; the sum over the count for a mean.
    pub fn value(&self) -> f64 {
        match self.kind {
            _ if self.count == 0.0 => f64::NAN,
            Reduction::Mean => self.value / self.count,
            _ => self.value,
        }
    }
}

/// The watchdog's reductions over the particles that store `x`, `v` and `m` (see
/// [`crate::engine::watchdog`]), in the backend's precision.
#[derive(Debug, Clone, Copy)]
pub struct WatchValues {
    /// The largest speed.
    pub max_speed: f64,
    /// `Σ m (½|v|² + e − g·x)`.
    pub energy: f64,
    /// `Σ |m (½|v|² + e − g·x)|`, the scale of the energy sum's rounding.
    pub energy_magnitude: f64,
    /// `Σ ½ m |v|²`.
    pub kinetic: f64,
}

#[derive(Debug, Clone)]
pub struct BackendError(pub String);

impl std::fmt::Display for BackendError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// This rank's own particles, then the others near them ([`Backend::nearby`]).
#[derive(Clone, Debug)]
pub struct Nearby {
    /// Positions: this rank's own particles' (in the order of [`Backend::read_own`]), then the
    /// others'.
    pub x: Vec<[f64; 3]>,
    /// Each one's index at creation.
    pub ids: Vec<u32>,
    /// How many of them are this rank's own.
    pub own: usize,
    /// Every particle within this distance of one of the rank's own is among them (infinite in a
    /// run in one piece).
    pub reach: f64,
}

/// A position of up to three coordinates as three.
pub fn padded(x: &[f64]) -> [f64; 3] {
    let mut p = [0.0; 3];
    p[..x.len().min(3)].copy_from_slice(&x[..x.len().min(3)]);
    p
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
    /// In a run split into domains ([`domains`]): this rank and the number of ranks. `None` for a
    /// run in one piece.
    fn rank(&self) -> Option<(usize, usize)> {
        None
    }
    /// Waits for every rank of a split run (none to wait for otherwise).
    fn synchronise(&self) {
        self.all_gather(vec![]);
    }
    /// Every rank's `part`, in rank order: a collective, which every rank of a split run calls
    /// alike; `[part]` in a run in one piece.
    fn all_gather(&self, part: Vec<f64>) -> Vec<Vec<f64>> {
        vec![part]
    }
    /// [`read`](Self::read) over this rank's own particles only, without the other ranks (the
    /// pieces of a partitioned VTK snapshot); every particle in a run in one piece.
    fn read_own(&self, f: FieldId) -> Result<Option<(usize, Vec<f64>)>, BackendError> {
        self.read(f)
    }
    /// [`ids`](Self::ids) of this rank's own particles, in the order of [`read_own`](Self::read_own).
    fn ids_own(&self) -> Result<Vec<u32>, BackendError> {
        self.ids()
    }
    /// The positions of this rank's own particles and of every other particle within
    /// [`Nearby::reach`] of one of them: what a measure that compares neighbours reduces on each
    /// rank. In a run in one piece, every particle, with no limit to the reach.
    fn nearby(&self) -> Result<Option<Nearby>, BackendError> {
        let Some(x) = self.plan().model.field_id("x") else { return Ok(None) };
        let Some((comps, values)) = self.read(x)? else { return Ok(None) };
        let x: Vec<[f64; 3]> = values.chunks(comps.max(1)).map(padded).collect();
        Ok(Some(Nearby { own: x.len(), x, ids: self.ids()?, reach: f64::INFINITY }))
    }
    /// Each particle's group, in the current order.
    fn groups(&self) -> Vec<u32>;
    fn snapshot(&self) -> Result<Snapshot, BackendError>;
    fn restore(&mut self, s: &Snapshot) -> Result<(), BackendError>;
    /// Keeps the current state as the last good one, where the state lives (the watchdog keeps
    /// one every few steps; on the GPU it is a copy on the device, nothing read back).
    fn keep(&mut self) -> Result<(), BackendError>;
    /// The state last kept by [`keep`](Self::keep).
    fn kept(&self) -> Result<Snapshot, BackendError>;
    /// Goes back to the state last kept by [`keep`](Self::keep).
    fn restore_kept(&mut self) -> Result<(), BackendError>;
    /// The watchdog's reductions computed where the state lives (on the GPU, so that a check
    /// reads back three numbers instead of the particles), or None where the engine reads the
    /// fields itself (the CPU).
    fn watch_values(&self) -> Result<Option<WatchValues>, BackendError> {
        Ok(None)
    }
    /// Whether probes and measures are better reduced by the backend than read back and reduced
    /// by the caller ([`reduce_field`](Self::reduce_field), [`watch_values`](Self::watch_values)).
    fn reduces_probes(&self) -> bool {
        false
    }
    /// A probe's reduction computed where the state lives (on the GPU, so that a probe reads back
    /// two numbers instead of the field and the ids), or None where the caller reduces the
    /// fields it reads (the CPU). NaN when no selected particle has a value.
    fn reduce_field(&self, r: &FieldReduction) -> Result<Option<f64>, BackendError> {
        let _ = r;
        Ok(None)
    }
    /// Where the run's time went on this backend, per step over `steps` steps, when it was asked
    /// to time the run (`pairsum run --timing`).
    fn timing(&self, steps: u64) -> Option<String> {
        let _ = steps;
        None
    }
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
