//! The watchdog's bounds on motion: a particle faster than the case can explain, and energy that
//! grows without a source. Both are measured against the state at t = 0, from what the plan knows
//! of the scene (gravity, loads, prescribed motions), on any backend (it reads fields).
//!
//! - **Speed.** The case's speed scale is what drives its motion: the largest of the fastest
//!   particle at t = 0, the speed of a fall through the scene's height (or for the whole run, if
//!   that is longer), the speed of its moving constraints (a turning one's at the farthest
//!   particle), and the speed a load's acceleration gives over the whole run. Only a scene with
//!   none of these (at rest, without gravity, loads or drivers) falls back on the signal speed
//!   `min h / Δt₀` (about the fastest wave speed over the CFL number). A particle faster than
//!   `speed_factor` times the scale stops the run. The sound speed bounds nothing in a flow: next
//!   to a stiff solid it is km/s, and water running away at 50 m/s would pass it.
//! - **Energy.** `E = Σ ½ m |v|² + Σ m e − Σ m g·x` (kinetic, internal when the model has a state
//!   `e`, and gravity's potential) cannot grow in a case without loads or moving constraints: the
//!   energy stored in strain or compression is not counted, and that only ever takes energy out
//!   of `E`. The run stops when `E − E₀` passes `energy_factor` times the energy in play at the
//!   start, `Σ ½ m |v₀|² + Σ m |e₀| + Σ m |g| (z − z_lowest)` (each particle's fall to the scene's
//!   lowest point), or, for a scene at rest without gravity, `½ M (10⁻⁴ × speed scale)²`. In an
//!   axisymmetric case each mass is its ring's (`m 2π r`), whose energy is the one conserved.

use crate::backend::{Backend, BackendError, WatchValues};
use crate::ir::FieldId;
use crate::scene::max_keeping_nan;
use crate::schedule::{Plan, SceneRole};

/// The state the bounds read.
pub struct Motion {
    /// The masses, when the plan stores them (a model that never reads `m` does not).
    pub m: Option<Vec<f64>>,
    pub speed: Vec<f64>,
    /// Positions, `dim` per particle.
    pub x: Vec<f64>,
    /// The specific internal energy, when the model has a state `e`.
    pub e: Option<Vec<f64>>,
    pub dim: usize,
}

/// A field as a backend reads it (`n × comps` values), or `None` where it is not stored.
type Column = Result<Option<(usize, Vec<f64>)>, BackendError>;

impl Motion {
    /// Reads speeds, positions, masses and internal energies; `None` when the plan stores no `v` or
    /// `x`.
    pub fn read<B: Backend>(b: &B) -> Result<Option<Motion>, BackendError> {
        Self::read_with(b.plan(), |f| b.read(f))
    }

    /// As [`read`](Self::read), with each field from `read` (a rank's own particles).
    pub fn read_with(plan: &Plan, read: impl Fn(FieldId) -> Column) -> Result<Option<Motion>, BackendError> {
        let model = &plan.model;
        let column = |f: Option<FieldId>| f.map_or(Ok(None), &read);
        let id = |name: &str| model.field_id(name);
        let (Some((cv, v)), Some((cx, x))) = (column(id("v"))?, column(id("x"))?) else {
            return Ok(None);
        };
        let dim = cx.max(1);
        let mut m = column(id("m"))?.map(|(_, m)| m);
        if plan.axisymmetric() {
            // A particle's energy is its ring's: the planar mass alone grows as a ring moves inward.
            m.iter_mut().flatten().enumerate().for_each(|(i, m)| *m *= crate::schedule::ring(x[i * dim]));
        }
        let speed = v.chunks(cv.max(1)).map(|u| u.iter().map(|a| a * a).sum::<f64>().sqrt()).collect();
        let e = column(id("e").filter(|f| model.field(*f).ty.shape == crate::ir::Shape::Scalar))?.map(|(_, e)| e);
        Ok(Some(Motion { m, speed, x, e, dim }))
    }

    /// The watchdog's reductions over these particles, as a backend that reduces them itself
    /// gives them (NaN energies without masses).
    pub fn watch_values(&self, gravity: &[f64]) -> WatchValues {
        let m = self.m.clone().unwrap_or_else(|| vec![f64::NAN; self.speed.len()]);
        let each = |i: usize| self.particle_energy(m[i], gravity, i).abs();
        WatchValues {
            max_speed: max_keeping_nan(0.0, self.speed.iter().copied()),
            energy: self.energy(&m, gravity),
            energy_magnitude: (0..m.len()).map(each).sum(),
            kinetic: self.kinetic(&m),
        }
    }

    /// `m (½|v|² + e − g·x)` of particle i.
    fn particle_energy(&self, m: f64, g: &[f64], i: usize) -> f64 {
        let e = self.e.as_ref().map_or(0.0, |e| e[i]);
        m * (0.5 * self.speed[i] * self.speed[i] + e - self.along(g, i))
    }

    /// `g·x` of particle i.
    fn along(&self, g: &[f64], i: usize) -> f64 {
        self.x[i * self.dim..(i + 1) * self.dim].iter().zip(g).map(|(a, b)| a * b).sum()
    }

    /// The fastest particle (a NaN speed counts as the fastest) and its speed.
    pub fn fastest(&self) -> (usize, f64) {
        let mut best: Option<(usize, f64)> = None;
        for (i, s) in self.speed.iter().copied().enumerate() {
            match best {
                Some((_, b)) if b.is_nan() || !(s.is_nan() || s > b) => {}
                _ => best = Some((i, s)),
            }
        }
        best.unwrap_or((0, 0.0))
    }

    /// `Σ m f` over the particles, with `f` of each particle's index.
    fn mass_weighted(m: &[f64], f: impl Fn(usize) -> f64) -> f64 {
        m.iter().enumerate().map(|(i, m)| m * f(i)).sum()
    }

    fn kinetic(&self, m: &[f64]) -> f64 {
        Self::mass_weighted(m, |i| 0.5 * self.speed[i] * self.speed[i])
    }

    /// `Σ m e`, or with `abs`, `Σ m |e|`.
    fn internal(&self, m: &[f64], abs: bool) -> f64 {
        let e = |i: usize| self.e.as_ref().map_or(0.0, |e| if abs { e[i].abs() } else { e[i] });
        Self::mass_weighted(m, e)
    }

    /// Kinetic + internal + gravity's potential energy (`−Σ m g·x`).
    fn energy(&self, m: &[f64], g: &[f64]) -> f64 {
        self.kinetic(m) + self.internal(m, false) - Self::mass_weighted(m, |i| self.along(g, i))
    }
}

/// The case's gravity, `dim` components (zeros without gravity).
pub fn gravity(plan: &Plan, dim: usize) -> Vec<f64> {
    let g = plan.scene_params.iter().find(|p| p.role == SceneRole::Gravity);
    g.map_or(vec![0.0; dim], |p| p.value.clone())
}

/// The watchdog's bounds for one run.
#[derive(Clone, Debug)]
pub struct Bounds {
    pub speed_scale: f64,
    /// What set the speed scale, in words.
    pub scale_from: &'static str,
    pub max_speed: f64,
    gravity: Vec<f64>,
    energy0: f64,
    /// The energy growth that stops the run; none where loads or prescribed motions feed energy
    /// in, or where the model stores no mass.
    pub max_growth: Option<f64>,
}

/// What stopped a run in [`Bounds::check`].
pub enum Breach {
    Speed { particle: usize, speed: f64 },
    Energy { growth: f64, particle: usize, speed: f64 },
}

impl Bounds {
    /// The bounds from the state at t = 0 and the first time step.
    pub fn new(plan: &Plan, at_start: &Motion, h: &[f64], dt0: f64, end_time: f64, factors: (f64, f64)) -> Bounds {
        let (speed_factor, energy_factor) = factors;
        let gravity = gravity(plan, at_start.dim);
        let g = gravity.iter().map(|a| a * a).sum::<f64>().sqrt();
        // g·x of each particle (largest at the lowest), and the scene's height along gravity.
        let along: Vec<f64> =
            at_start.x.chunks(at_start.dim).map(|x| x.iter().zip(&gravity).map(|(a, b)| a * b).sum()).collect();
        let (low, high) = along.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), s| (l.min(*s), h.max(*s)));
        let height = if g > 0.0 && high >= low { (high - low) / g } else { 0.0 };
        let fall = (2.0 * g * height).sqrt().max(g * end_time.min(1e30));
        let least_h = -max_keeping_nan(f64::NEG_INFINITY, h.iter().map(|x| -x));
        let (speed_scale, scale_from) = speed_scale(plan, at_start, fall, least_h / dt0, end_time);
        let (max_growth, energy0) = match &at_start.m {
            Some(_) if feeds_energy(plan) => (None, 0.0),
            None => (None, 0.0),
            Some(m) => {
                let mass: f64 = m.iter().sum();
                // Gravity's share: each particle's fall to the scene's lowest point.
                let fall_energy: f64 = m.iter().zip(&along).map(|(m, s)| m * (high - s)).sum();
                let in_play = at_start.kinetic(m) + at_start.internal(m, true) + fall_energy;
                let in_play = if in_play > 0.0 { in_play } else { 0.5 * mass * (1e-4 * speed_scale).powi(2) };
                (Some(energy_factor * in_play), at_start.energy(m, &gravity))
            }
        };
        Bounds { speed_scale, scale_from, max_speed: speed_factor * speed_scale, energy0, gravity, max_growth }
    }

    /// Whether a backend's own reductions (f32 on the GPU) show the state inside both bounds with
    /// room to spare for their rounding, so that the fields need not be read. A state within 1 %
    /// of a bound, or NaN, is left to [`check`](Self::check) on the fields, which decides.
    pub fn clearly_within(&self, now: &WatchValues, start: &WatchValues) -> bool {
        let speed = now.max_speed < 0.99 * self.max_speed;
        let energy = self.max_growth.is_none_or(|max| {
            // An f32 sum of n terms is within about n ε Σ|terms| of the exact one, far less with
            // the device's tree reduction; 1e-3 Σ|terms| holds for any n up to 10⁴ per leaf.
            let rounding = 1e-3 * (now.energy_magnitude + start.energy_magnitude);
            now.energy - start.energy + rounding < 0.99 * max
        });
        speed && energy
    }

    /// The first bound the state passes, if any.
    pub fn check(&self, now: &Motion) -> Option<Breach> {
        let (particle, speed) = now.fastest();
        if speed > self.max_speed {
            return Some(Breach::Speed { particle, speed });
        }
        let (Some(max), Some(m)) = (&self.max_growth, &now.m) else { return None };
        let growth = now.energy(m, &self.gravity) - self.energy0;
        (growth > *max).then_some(Breach::Energy { growth, particle, speed })
    }
}

/// The case's speed scale and what set it: the fastest of what drives the motion (the initial
/// speeds, a fall, the drivers), or where nothing does, the signal speed.
fn speed_scale(plan: &Plan, at_start: &Motion, fall: f64, signal: f64, end_time: f64) -> (f64, &'static str) {
    let driven = [
        (at_start.fastest().1, "the fastest initial speed"),
        (fall, "a fall through the scene"),
        (driver_speed(plan, at_start, end_time), "the moving constraints and loads"),
    ];
    match driven.into_iter().fold((0.0, ""), |best, d| if d.0.is_nan() || d.0 > best.0 { d } else { best }) {
        (s, from) if s > 0.0 || s.is_nan() => (s, from),
        _ if signal.is_finite() => (signal, "nothing drives the motion: the signal speed min h / Δt₀"),
        _ => (0.0, "nothing drives the motion"),
    }
}

/// The fastest a load or a prescribed motion can drive a particle: a moving constraint's speed, a
/// turning one's at the particle farthest from its centre, and a load's acceleration over the
/// whole run (its ramp only makes it slower).
fn driver_speed(plan: &Plan, at_start: &Motion, end_time: f64) -> f64 {
    let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
    let farthest = |centre: &[f64]| {
        let distances = at_start
            .x
            .chunks(at_start.dim)
            .map(|x| x.iter().zip(centre).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt());
        max_keeping_nan(0.0, distances)
    };
    let speeds = plan.scene_params.iter().filter_map(|p| match p.role {
        SceneRole::Constraint(_) => Some(norm(&p.value)),
        SceneRole::Load(_) => Some(norm(&p.value) * end_time),
        SceneRole::AngularSpeed(k) => {
            let centre = plan.scene_params.iter().find(|c| c.role == SceneRole::Center(k));
            Some(norm(&p.value) * centre.map_or(0.0, |c| farthest(&c.value)))
        }
        _ => None,
    });
    max_keeping_nan(0.0, speeds)
}

/// Whether something feeds energy into the scene that the watchdog cannot account for: a load or
/// a prescribed motion.
fn feeds_energy(plan: &Plan) -> bool {
    plan.scene_params.iter().any(|p| {
        matches!(p.role, SceneRole::Load(_) | SceneRole::Constraint(_) | SceneRole::AngularSpeed(_))
            && p.value.iter().any(|a| *a != 0.0)
    })
}
