//! The engine: the time loop around a backend. It runs the integrator's actions (save, evaluate,
//! time step, update), reorders particles for locality, watches for NaN/Inf (and then finds the
//! exact step, particle, group and field, and keeps the last good state) and for a time step that
//! collapses (a particle running away at finite but absurd speed), and writes and reads
//! checkpoints. It knows nothing of how a backend computes.

pub mod checkpoint;
pub mod setup;
pub mod watchdog;

use crate::backend::{timestep, Backend, BackendError, Globals, Snapshot, WatchValues};
use crate::ir::FieldId;
use crate::schedule::Action;
use std::time::Instant;

#[derive(Clone, Debug)]
pub struct RunConfig {
    pub end_time: f64,
    /// Upper bound of the time step (also the step when the model declares no `timestep`).
    pub dt_max: f64,
    /// Reorder particles along the Morton curve every this many steps (0: never).
    pub reorder_every: u64,
    /// Check for NaN/Inf every this many steps.
    pub watch_every: u64,
    pub max_steps: Option<u64>,
    /// The run is unstable when the time step falls below this fraction of the initial one.
    pub min_dt_ratio: f64,
    /// A particle faster than this many times the case's speed scale stops the run
    /// ([`watchdog`]).
    pub speed_factor: f64,
    /// The run stops when its energy has grown by more than this many times the energy in play
    /// at the start ([`watchdog`]).
    pub energy_factor: f64,
}

impl Default for RunConfig {
    fn default() -> Self {
        RunConfig {
            end_time: 1.0,
            dt_max: f64::INFINITY,
            reorder_every: 25,
            watch_every: 10,
            max_steps: None,
            min_dt_ratio: 1e-4,
            speed_factor: 3.0,
            energy_factor: 1.0,
        }
    }
}

/// Where a run went unstable.
#[derive(Clone, Debug)]
pub struct Instability {
    pub step: u64,
    pub time: f64,
    /// The particle's index when the scene created it.
    pub particle: u32,
    pub group: String,
    pub field: String,
    pub cause: Cause,
    /// The last state the watchdog found finite (for a non-finite value: the state before that
    /// step).
    pub last_good: Snapshot,
    pub last_good_time: f64,
}

/// What made a run unstable.
#[derive(Clone, Debug, PartialEq)]
pub enum Cause {
    /// The field of the particle is NaN or infinite.
    NonFinite,
    /// The time step fell to `dt`, below `RunConfig::min_dt_ratio` of the initial `dt0`; the
    /// particle is the fastest one, at `speed`.
    TimestepCollapse { dt: f64, dt0: f64, speed: f64 },
    /// The particle moves at `speed`, faster than `bound`, `speed_factor` times the case's speed
    /// scale `scale`.
    TooFast { speed: f64, bound: f64, scale: f64, scale_from: &'static str },
    /// The energy grew by `growth` since t = 0, more than `bound`; the particle is the fastest,
    /// at `speed`.
    EnergyGrowth { growth: f64, bound: f64, speed: f64 },
}

#[derive(Debug)]
pub enum RunError {
    Unstable(Box<Instability>),
    Backend(BackendError),
    /// The time step is not positive or not finite; `limits` says what each `timestep` limit
    /// gave and which fields it reads.
    BadTimestep {
        step: u64,
        dt: f64,
        limits: String,
    },
}

impl std::fmt::Display for RunError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RunError::Unstable(u) => {
                write!(f, "the run went unstable at step {} (t = {:.6e} s): ", u.step, u.time)?;
                match u.cause {
                    Cause::NonFinite => {
                        write!(f, "field `{}` of particle {} (group {}) is not finite", u.field, u.particle, u.group)?
                    }
                    Cause::TimestepCollapse { dt, dt0, speed } => write!(
                        f,
                        "the time step fell to {dt:.3e} s from {dt0:.3e} s at the start; the fastest particle, {} \
                         (group {}), has `{}` = {speed:.3e} m/s",
                        u.particle, u.group, u.field
                    )?,
                    Cause::TooFast { speed, bound, scale, scale_from } => write!(
                        f,
                        "particle {} (group {}) moves at `{}` = {speed:.3e} m/s, faster than the watchdog's bound \
                         {bound:.3e} m/s ({:.3} × the case's speed scale, {scale:.3e} m/s, from {scale_from}; \
                         where such a speed is real, a fragment thrown off, `[watchdog] speed_factor` raises the bound)",
                        u.particle,
                        u.group,
                        u.field,
                        bound / scale
                    )?,
                    Cause::EnergyGrowth { growth, bound, speed } => write!(
                        f,
                        "the energy (kinetic, internal and gravity's potential) grew by {growth:.3e} J since t = 0, \
                         more than the watchdog's bound {bound:.3e} J in a case without loads or moving \
                         constraints; the fastest particle, {} (group {}), has `{}` = {speed:.3e} m/s",
                        u.particle, u.group, u.field
                    )?,
                }
                write!(f, "; the last good state (t = {:.6e} s) was kept", u.last_good_time)
            }
            RunError::Backend(e) => write!(f, "{e}"),
            RunError::BadTimestep { step, dt, limits } => {
                write!(
                    f,
                    "the time step at step {step} is {dt:e} s: the `timestep` limits gave no positive finite \
                     value: {limits}"
                )
            }
        }
    }
}

impl From<BackendError> for RunError {
    fn from(e: BackendError) -> Self {
        RunError::Backend(e)
    }
}

pub struct Engine<B: Backend> {
    pub backend: B,
    pub config: RunConfig,
    pub time: f64,
    pub step: u64,
    /// The last time step (what equations read as `dt`).
    pub dt: f64,
    watched: Vec<FieldId>,
    /// The clock (time, step, dt) of the state the backend last kept as good.
    good: Option<(f64, u64, f64)>,
    /// The first time step, against which a collapse is measured.
    dt0: f64,
    /// The watchdog's bounds on speed and energy (none for a model without `x`, `v` and `m`).
    pub bounds: Option<watchdog::Bounds>,
    /// Host time spent in each part of [`run`](Self::run).
    pub phases: Phases,
    /// The backend's own watchdog reductions at t = 0, where it computes them (the GPU).
    watch0: Option<WatchValues>,
}

/// Where [`Engine::run`]'s time went, measured on the host: the steps (on the GPU, recording,
/// submitting and waiting for the clock), the watchdog's checks and the last good state it keeps,
/// and what the caller does after each step (probes, output, checkpoints).
#[derive(Clone, Debug, Default)]
pub struct Phases {
    pub steps: std::time::Duration,
    pub watchdog: std::time::Duration,
    pub after_step: std::time::Duration,
}

impl Phases {
    /// One line per phase, with its time per step over `steps` steps.
    pub fn describe(&self, steps: u64) -> String {
        let per = |d: std::time::Duration| d.as_secs_f64() * 1e3 / steps.max(1) as f64;
        format!(
            "host time: steps {:.3} s ({:.3} ms per step), watchdog {:.3} s ({:.3} ms per step), \
             probes and output {:.3} s ({:.3} ms per step)\n",
            self.steps.as_secs_f64(),
            per(self.steps),
            self.watchdog.as_secs_f64(),
            per(self.watchdog),
            self.after_step.as_secs_f64(),
            per(self.after_step)
        )
    }
}

impl<B: Backend> Engine<B> {
    pub fn new(backend: B, config: RunConfig) -> Engine<B> {
        let plan = backend.plan();
        let watched = plan.watched_fields();
        Engine {
            backend,
            config,
            time: 0.0,
            step: 0,
            dt: 0.0,
            watched,
            good: None,
            dt0: 0.0,
            bounds: None,
            phases: Phases::default(),
            watch0: None,
        }
    }

    /// Initial values, state-only equations, every field the passes compute (so that the t = 0
    /// output, the first probes and the first time step see them, not zeros), and the first time
    /// step. The passes run once with a provisional step from the initial values (0 where those
    /// give none), for equations that read `dt`.
    pub fn initialise(&mut self) -> Result<(), RunError> {
        self.backend.initialise()?;
        let provisional = self.next_dt(Globals { time: 0.0, dt: 0.0 })?;
        let provisional = if provisional > 0.0 && provisional.is_finite() { provisional } else { 0.0 };
        self.backend.evaluate(Globals { time: 0.0, dt: provisional })?;
        self.dt = self.next_dt(Globals { time: 0.0, dt: provisional })?;
        if !(self.dt > 0.0 && self.dt.is_finite()) {
            return Err(self.bad_timestep(0, self.dt, Globals { time: 0.0, dt: provisional }));
        }
        self.dt0 = self.dt;
        self.bounds = self.measure_bounds()?;
        if self.bounds.is_some() {
            self.watch0 = self.backend.watch_values()?;
        }
        self.keep_good()?;
        Ok(())
    }

    fn measure_bounds(&self) -> Result<Option<watchdog::Bounds>, RunError> {
        let plan = self.backend.plan();
        let Some(motion) = watchdog::Motion::read(&self.backend)? else { return Ok(None) };
        let h = match plan.model.field_id("h") {
            Some(h) => self.backend.read(h)?.map(|(_, h)| h).unwrap_or_default(),
            None => vec![],
        };
        let factors = (self.config.speed_factor, self.config.energy_factor);
        Ok(Some(watchdog::Bounds::new(plan, &motion, &h, self.dt0, self.config.end_time, factors)))
    }

    /// The error of a time step `dt` that is not positive and finite, with what each limit gives
    /// now.
    fn bad_timestep(&mut self, step: u64, dt: f64, g: Globals) -> RunError {
        let timesteps = self.backend.plan().timesteps.clone();
        let limits = if timesteps.is_empty() {
            "the model declares none and `dt_max` is not set".into()
        } else {
            match self.backend.reductions(g) {
                Ok(values) => timestep::describe(&self.backend.plan().model, &timesteps, &values, g.time, g.dt),
                Err(e) => format!("reading the limits failed too: {e}"),
            }
        };
        RunError::BadTimestep { step, dt, limits }
    }

    fn next_dt(&mut self, g: Globals) -> Result<f64, RunError> {
        let plan = self.backend.plan();
        let limit = if plan.timesteps.is_empty() {
            f64::INFINITY
        } else {
            let timesteps = plan.timesteps.clone();
            let values = self.backend.reductions(g)?;
            timestep::value(&self.backend.plan().model, &timesteps, &values, g.time, g.dt)
        };
        Ok(limit.min(self.config.dt_max))
    }

    /// One step of the integrator.
    pub fn step(&mut self) -> Result<(), RunError> {
        if let Some(r) =
            self.backend.device_step(self.time, self.dt, self.step, self.config.end_time, self.config.dt_max)
        {
            let (time, dt, step) = r?;
            if !(dt > 0.0 && dt.is_finite()) {
                return Err(self.bad_timestep(self.step + 1, dt, Globals { time, dt: self.dt }));
            }
            (self.time, self.dt, self.step) = (time, dt, step);
            if self.config.reorder_every > 0 && self.step.is_multiple_of(self.config.reorder_every) {
                self.backend.reorder()?;
            }
            return Ok(());
        }
        let actions = self.backend.plan().actions.clone();
        let mut dt = self.dt;
        for a in actions {
            match a {
                Action::Save => self.backend.save()?,
                // Equations read `dt` as the last completed step's time step in every
                // evaluation, the corrector's too, as the GPU's step does (`globals::DT_PREV`):
                // the corrector's contact force took this step's `dt` here and was 1.1 % off the
                // GPU's where the step shrank in contact (the shaped Børvik plate).
                Action::Evaluate => self.backend.evaluate(Globals { time: self.time, dt: self.dt })?,
                Action::Timestep => {
                    dt = self.next_dt(Globals { time: self.time, dt: self.dt })?;
                    let remaining = self.config.end_time - self.time;
                    if remaining > 0.0 && remaining < dt * 1.000001 {
                        dt = remaining;
                    }
                    if !(dt > 0.0 && dt.is_finite()) {
                        return Err(self.bad_timestep(self.step + 1, dt, Globals { time: self.time, dt: self.dt }));
                    }
                }
                Action::Update { stage, time_fraction } => {
                    self.backend.update(stage, Globals { time: self.time + time_fraction * dt, dt })?
                }
            }
        }
        self.time += dt;
        self.dt = dt;
        self.step += 1;
        if self.config.reorder_every > 0 && self.step.is_multiple_of(self.config.reorder_every) {
            self.backend.reorder()?;
        }
        Ok(())
    }

    fn keep_good(&mut self) -> Result<(), RunError> {
        self.backend.keep()?;
        self.good = Some((self.time, self.step, self.dt));
        Ok(())
    }

    fn bad(&mut self) -> Result<Option<(usize, FieldId)>, RunError> {
        Ok(self.backend.first_non_finite(&self.watched)?)
    }

    /// Steps until the end time (or `max_steps`), calling `after_step` after each step; stops with
    /// the exact place of a NaN/Inf.
    pub fn run(&mut self, after_step: &mut dyn FnMut(&Engine<B>) -> Result<(), String>) -> Result<(), RunError> {
        while self.time < self.config.end_time * (1.0 - 1e-12) {
            if self.config.max_steps.is_some_and(|m| self.step >= m) {
                break;
            }
            let started = Instant::now();
            self.step()?;
            self.phases.steps += started.elapsed();
            let finished = self.time >= self.config.end_time * (1.0 - 1e-12);
            if !finished && self.dt < self.config.min_dt_ratio * self.dt0 {
                return Err(RunError::Unstable(Box::new(self.timestep_collapse()?)));
            }
            let watch = self.config.watch_every.max(1);
            if self.step.is_multiple_of(watch) || self.time >= self.config.end_time * (1.0 - 1e-12) {
                let started = Instant::now();
                if self.bad()?.is_some() {
                    return Err(RunError::Unstable(Box::new(self.locate_instability()?)));
                }
                if let Some(u) = self.out_of_bounds()? {
                    return Err(RunError::Unstable(Box::new(u)));
                }
                self.keep_good()?;
                self.phases.watchdog += started.elapsed();
            }
            let started = Instant::now();
            after_step(self).map_err(|e| RunError::Backend(BackendError(e)))?;
            self.phases.after_step += started.elapsed();
        }
        Ok(())
    }

    /// The instability of a collapsed time step, named after the fastest particle (a particle
    /// running away is what usually drives the step down).
    fn timestep_collapse(&self) -> Result<Instability, RunError> {
        let (i, speed) = watchdog::Motion::read(&self.backend)?.map_or((0, f64::NAN), |m| m.fastest());
        self.instability_at(i, Cause::TimestepCollapse { dt: self.dt, dt0: self.dt0, speed })
    }

    /// The instability of a particle too fast or of energy grown without a source, if any.
    fn out_of_bounds(&mut self) -> Result<Option<Instability>, RunError> {
        if self.bounds.is_none() {
            return Ok(None);
        }
        // Where the backend reduces on the device, the fields are read only near a bound.
        if let Some(start) = self.watch0 {
            let now = self.backend.watch_values()?;
            if now.zip(self.bounds.as_ref()).is_some_and(|(now, b)| b.clearly_within(&now, &start)) {
                return Ok(None);
            }
        }
        let Some(bounds) = &self.bounds else { return Ok(None) };
        let Some(now) = watchdog::Motion::read(&self.backend)? else { return Ok(None) };
        let (i, cause) = match bounds.check(&now) {
            None => return Ok(None),
            Some(watchdog::Breach::Speed { particle, speed }) => (
                particle,
                Cause::TooFast {
                    speed,
                    bound: bounds.max_speed,
                    scale: bounds.speed_scale,
                    scale_from: bounds.scale_from,
                },
            ),
            Some(watchdog::Breach::Energy { growth, particle, speed }) => {
                let bound = bounds.max_growth.unwrap_or(f64::INFINITY);
                (particle, Cause::EnergyGrowth { growth, bound, speed })
            }
        };
        Ok(Some(self.instability_at(i, cause)?))
    }

    /// An instability of particle `i`'s velocity (`i` in the backend's current order) now, with the
    /// last good state kept by the watchdog.
    fn instability_at(&self, i: usize, cause: Cause) -> Result<Instability, RunError> {
        let (last_good_time, _, _) = self.good.expect("kept at initialisation");
        let last_good = self.backend.kept()?;
        let plan = self.backend.plan();
        let group = self.backend.groups().get(i).map(|g| plan.model.groups[*g as usize].name.clone());
        Ok(Instability {
            step: self.step,
            time: self.time,
            particle: self.backend.ids()?.get(i).copied().unwrap_or(0),
            group: group.unwrap_or_default(),
            field: "v".into(),
            cause,
            last_good,
            last_good_time,
        })
    }

    /// Replays from the last good state one step at a time to the first step that produces a
    /// non-finite value.
    fn locate_instability(&mut self) -> Result<Instability, RunError> {
        let (time, step, dt) = self.good.expect("a good state is kept at initialisation");
        self.backend.restore_kept()?;
        (self.time, self.step, self.dt) = (time, step, dt);
        loop {
            let before = self.backend.snapshot()?;
            let before_time = self.time;
            self.step()?;
            if let Some((i, f)) = self.bad()? {
                let plan = self.backend.plan();
                let group = self.backend.groups()[i] as usize;
                return Ok(Instability {
                    step: self.step,
                    time: self.time,
                    particle: self.backend.ids()?[i],
                    group: plan.model.groups[group].name.clone(),
                    field: plan.model.field(f).name.clone(),
                    cause: Cause::NonFinite,
                    last_good: before,
                    last_good_time: before_time,
                });
            }
        }
    }
}
