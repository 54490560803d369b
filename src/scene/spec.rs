//! What a loaded case is: the scene (model, particles, materials, bodies, symmetry planes, run
//! configuration) and what it measures (probes and results), with the options it was loaded with.
//! `build` makes it from a case file; `measure` and the runner read it.

use super::measure::Measure;
use crate::backend::Mirror;
use crate::engine::setup::{MaterialInput, ParticleInput};
use crate::engine::RunConfig;
use crate::ir::{FieldId, GroupId, Model};
use crate::schedule::SceneSpec;
use std::path::PathBuf;

/// A resolution as asked for: a name (`ci`), a spacing (`"2 mm"`), or a named resolution's
/// settings at another spacing (`ci@2mm`: its time scale, end time and parameters, this spacing).
/// Returns the name whose settings apply and the spacing that replaces its own.
pub fn split_resolution(wanted: &str) -> (&str, Option<&str>) {
    match wanted.split_once('@') {
        Some((name, spacing)) => (name.trim(), Some(spacing.trim())),
        None => (wanted, None),
    }
}

/// What to run: the resolution by name (`ci`, `paper`), a spacing, or a name's settings at a
/// spacing (`ci@2mm`, see [`split_resolution`]), and overrides.
#[derive(Clone, Debug, Default)]
pub struct Options {
    pub resolution: Option<String>,
    pub end_time: Option<f64>,
    /// Values for the case's `[parameters]` (`${name}` in the case file), e.g. from a study.
    pub set: Vec<(String, String)>,
    /// Verlet lists with this skin, overriding the case's `[neighbours]` (`pairsum run --verlet`).
    pub verlet: Option<f64>,
}

#[derive(Clone, Debug)]
pub struct BodyInfo {
    pub name: String,
    pub group: GroupId,
    pub material: usize,
    /// Indices of its particles in the scene's order.
    pub particles: std::ops::Range<usize>,
    pub mass: f64,
}

#[derive(Clone, Debug)]
pub enum ProbeKind {
    /// A field component reduced over a set of particles (by their index in the scene).
    Field {
        select: Option<Vec<bool>>,
        value: ProbeValue,
        pick: Pick,
        reduce: String,
        /// Report this coordinate of the particle where `reduce` (min, max, abs_max) is reached.
        locate: Option<usize>,
    },
    /// A named measurement (`scene::measure`).
    Measure(Measure),
}

/// Every selected particle's values of `fields` at `times` (s), one CSV file per time, rows sorted
/// along axis `along` (`[[profiles]]`).
#[derive(Clone, Debug)]
pub struct ProfileSpec {
    pub name: String,
    pub fields: Vec<FieldId>,
    pub times: Vec<f64>,
    pub body: Option<usize>,
    /// Only the particles inside it when the profile is written.
    pub region: Option<super::geometry::Primitive>,
    pub along: usize,
}

/// What a field probe takes of each particle: a stored field, or an expression of fields and the
/// material's parameters (`expression = "s - p * I"`), evaluated on the host (`host_eval`).
#[derive(Clone, Debug)]
pub enum ProbeValue {
    Field(FieldId),
    Expression(crate::ir::Expr),
}

impl ProbeValue {
    /// The fields it reads.
    pub fn fields(&self) -> Vec<FieldId> {
        match self {
            ProbeValue::Field(f) => vec![*f],
            ProbeValue::Expression(e) => {
                let mut out = vec![];
                crate::ir::walk_expr(e, &mut |x| {
                    if let crate::ir::ExprKind::Field(f, _) = x.kind {
                        if !out.contains(&f) {
                            out.push(f);
                        }
                    }
                });
                out
            }
        }
    }
}

/// What a field probe reads of each particle's value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pick {
    /// One stored component (`v.z` → `component = "z"`, `s.xy`, a scalar).
    Component(usize),
    /// The length of a vec (`component = "norm"`).
    Norm,
    /// √(3/2 s:s) of a deviatoric symtensor (`component = "von_mises"`), with the out-of-plane
    /// diagonal of 1D and 2D implied by a zero trace.
    VonMises,
}

/// What a probe's history holds of the values it samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Record {
    /// Each value as sampled.
    Value,
    /// The change from the first value, a field's or a measure's (`relative = true`).
    Change,
    /// The integral in time from the first sample, by the trapezoidal rule over the samples
    /// (`integrate = true`): a power's work, a force's impulse.
    Integral,
}

#[derive(Clone, Debug)]
pub struct ProbeSpec {
    pub name: String,
    pub kind: ProbeKind,
    /// What the history holds of the sampled values.
    pub record: Record,
    pub unit: String,
    pub every: u64,
}

#[derive(Clone, Debug)]
pub struct ResultSpec {
    pub quantity: String,
    pub probe: usize,
    pub at: String,
    pub from: Option<f64>,
    pub to: Option<f64>,
    /// The time of `at_time` (s, multiplied by the resolution's `time_scale`).
    pub time: Option<f64>,
    pub scale: f64,
    /// Added after `scale` (SI).
    pub offset: f64,
    pub unit: String,
    pub reference: Option<f64>,
    pub source: Option<String>,
    pub tolerance: Option<f64>,
    pub tolerance_why: Option<String>,
}

pub struct Scene {
    /// The case's warnings, each rendered with file, line and column; a run, `pairsum plan` and
    /// `pairsum check` print them, loading does not.
    pub warnings: Vec<String>,
    pub name: String,
    pub title: String,
    pub path: PathBuf,
    pub model: Model,
    pub spec: SceneSpec,
    pub kernel: Option<String>,
    pub particles: ParticleInput,
    pub materials: Vec<MaterialInput>,
    /// Where each material's keys begin in the case file (its first key), for the errors found
    /// once the plan is built (a parameter the model reads that a material leaves unbound).
    pub material_spans: Vec<Option<crate::diag::Span>>,
    pub bodies: Vec<BodyInfo>,
    pub mirrors: Vec<Mirror>,
    pub config: RunConfig,
    pub resolution: String,
    pub dx: f64,
    /// The resolution's `time_scale` (1: the paper's timing).
    pub time_scale: f64,
    /// Relative tolerance the CI test asserts for every result at this resolution, if given.
    pub tolerance: Option<f64>,
    pub output_interval: Option<f64>,
    pub output_fields: Vec<FieldId>,
    pub probes: Vec<ProbeSpec>,
    pub results: Vec<ResultSpec>,
    pub profiles: Vec<ProfileSpec>,
    /// Per resolution name: its dx (for listings).
    pub resolutions: Vec<(String, f64)>,
}
