//! The scheduler: from a checked model and what a scene needs, the plan of one step.
//!
//! - **Dead code**: only the fields that a rate, a time step, a correction or an output needs are
//!   kept, and only the equations that compute them (`live.rs`), after the branches the case's
//!   parameters decide are taken (`settle.rs`).
//! - **Storage by group**: a field is stored only on the groups that read or write it.
//! - **Fusion**: pair sums that do not depend on each other share one neighbour pass; per-particle
//!   equations and `finally` blocks run in the tail of the pass that produces their inputs;
//!   particle equations that need only state run in the per-particle update of the integrator
//!   (`fuse.rs`).
//! - **Group specialisation**: every pass has one variant per destination group present.
//! - **Integrator stages** are generated as IR statements (`integrator.rs`), so both backends run
//!   them with the same machinery as the model's own particle equations.

mod fuse;
pub mod halo;
mod integrator;
mod live;
mod print;
pub mod search;
mod settle;

pub use integrator::IntegratorKind;
pub use live::stmts_of;
pub use search::{Drift, Rebuild, Search, SearchStats};

use crate::diag::{Diagnostic, Span};
use crate::ir::{self, EqId, FieldId, GroupId, GroupSet, Model, ParamId, Storage};
use crate::units::Unit;
use std::collections::BTreeMap;

/// A plane `x[axis] = offset` that gives the particles within reach of it an image their
/// neighbours see: a symmetry plane (`shift` 0) reflects them across it, and the particles live
/// on its `side` (+1: `x[axis] > offset`, −1: below); a side of a periodic domain (`shift` ±L,
/// the domain's length) moves them by `shift` along the axis, the lower side by +L, the upper by
/// −L (`side` +1 and −1, the domain's side).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mirror {
    pub axis: usize,
    pub offset: f64,
    pub shift: f64,
    pub side: f64,
}

impl Mirror {
    /// A symmetry plane whose particles live above it (`x[axis] > offset`).
    pub fn symmetry(axis: usize, offset: f64) -> Mirror {
        Mirror { axis, offset, shift: 0.0, side: 1.0 }
    }

    /// A symmetry plane whose particles live below it (`x[axis] < offset`): the upper of two
    /// planes on one axis.
    pub fn symmetry_below(axis: usize, offset: f64) -> Mirror {
        Mirror { axis, offset, shift: 0.0, side: -1.0 }
    }

    /// The two sides of a periodic domain `[lo, hi)` along `axis`.
    pub fn periodic(axis: usize, lo: f64, hi: f64) -> [Mirror; 2] {
        [
            Mirror { axis, offset: lo, shift: hi - lo, side: 1.0 },
            Mirror { axis, offset: hi, shift: lo - hi, side: -1.0 },
        ]
    }

    /// Whether a position along the plane's axis lies on the particles' side of it.
    pub fn keeps(&self, along: f64) -> bool {
        self.side * (along - self.offset) > 0.0
    }
}

/// What a scene asks of the model; the scene module fills it from a case file.
#[derive(Clone, Debug)]
pub struct SceneSpec {
    pub dim: usize,
    /// The groups that have particles.
    pub groups: GroupSet,
    /// Fields the case writes out or reports (beyond what the step itself needs).
    pub outputs: Vec<FieldId>,
    pub integrator: IntegratorKind,
    /// Gravity (length `dim`), applied to the rate of `v`.
    pub gravity: Option<Vec<f64>>,
    /// Forces on whole bodies, spread over the body's mass and ramped linearly in time.
    pub loads: Vec<Load>,
    /// Bodies whose velocity is prescribed.
    pub constraints: Vec<Constraint>,
    /// The image planes: symmetry planes (the particles live on the side `x[axis] > offset`, and
    /// one that crosses a plane is reflected back, its normal velocity reversed) and the sides of
    /// periodic axes (a particle that leaves the domain `[lo, hi)` comes back in at the other
    /// side).
    pub planes: Vec<Mirror>,
    /// How neighbours are found, and when kept lists are rebuilt.
    pub search: Search,
    /// Mass-proportional damping c (1/s): `−c v` joins the rate of `v` of every particle, to bring
    /// a loaded body to rest.
    pub damping: Option<f64>,
    /// By parameter id: the value every material with particles binds it to, where they agree
    /// (`settle.rs` takes the branches it decides); empty where no materials are known.
    pub settled: Vec<Option<Vec<f64>>>,
    /// A 2D case about the y axis, x the radius (`axisymmetric = true`): the prelude's
    /// `axisymmetric` is 1.
    pub axisymmetric: bool,
    /// State fields some body's `initial` sets (beyond those the scene places): with `settled`,
    /// what tells a state that nothing writes, which `settle.rs` folds to its initial value.
    pub initialised: Vec<FieldId>,
}

/// The particles a load or a constraint acts on: a whole body, or a part (a region of a body).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    Body(usize),
    Part(usize),
}

#[derive(Clone, Debug)]
pub struct Load {
    pub target: Target,
    /// Acceleration at full load: the force divided by the body's mass (length `dim`).
    pub accel: Vec<f64>,
    /// Time over which the load ramps from 0; 0 for a step load.
    pub ramp: f64,
}

#[derive(Clone, Debug)]
pub struct Constraint {
    pub target: Target,
    /// The groups of the target's body.
    pub groups: GroupSet,
    /// The velocity at the end of the ramp (zeros: a fixed body); with a rotation, the velocity
    /// of its centre.
    pub velocity: Vec<f64>,
    /// A rigid rotation, its angular speed ramped like the velocity.
    pub rotation: Option<Rotation>,
    pub ramp: f64,
}

/// A rigid rotation about an axis through `center` (at t = 0) at angular speed `omega` (rad/s, the
/// right-hand rule about `axis`; in 2D the axis is z).
#[derive(Clone, Debug)]
pub struct Rotation {
    /// Length `dim`.
    pub center: Vec<f64>,
    /// A unit vector.
    pub axis: [f64; 3],
    pub omega: f64,
}

/// A per-particle block: a particle equation, a pair sum's `finally`, or integrator statements.
#[derive(Clone, Debug)]
pub struct Block {
    pub name: String,
    pub dest: GroupSet,
    pub stmts: Vec<ir::Stmt>,
}

/// What runs after a pass's neighbour loop, per particle, in this order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TailItem {
    /// The `finally` block of a pair sum of this pass.
    Finally(EqId),
    /// A particle equation.
    Particle(EqId),
}

/// A neighbour pass specialised for one destination group.
#[derive(Clone, Debug)]
pub struct PassVariant {
    pub group: GroupId,
    pub pair_sums: Vec<EqId>,
    pub tail: Vec<TailItem>,
    /// The groups any of the pair sums reads neighbours from.
    pub sources: GroupSet,
}

impl PassVariant {
    /// The groups one of its pair sums reads neighbours from on this variant's group (`from own`,
    /// or a `use … on G from S`, narrows the variant's).
    pub fn sources_of(&self, eq: &crate::ir::Equation) -> GroupSet {
        eq.sources_for(self.group).intersect(self.sources)
    }
}

/// One traversal of the neighbours of every particle, with the per-particle work fused after it.
#[derive(Clone, Debug)]
pub struct Pass {
    pub pair_sums: Vec<EqId>,
    pub tail: Vec<TailItem>,
    pub variants: Vec<PassVariant>,
    /// Fields read (either side) and written, for the plan's report.
    pub reads: Vec<FieldId>,
    pub writes: Vec<FieldId>,
}

/// One per-particle update of the integrator: rates applied to the state, constraints, then the
/// corrections (return maps, damage) and the particle equations that need only state.
#[derive(Clone, Debug)]
pub struct Stage {
    pub name: &'static str,
    pub updates: Vec<Block>,
    pub corrections: Vec<EqId>,
    pub derived: Vec<EqId>,
}

/// The steps of the integrator, in order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Action {
    /// Copy the evolving state to its saved copy (start of a multi-stage step).
    Save,
    /// Build the neighbour search and run every pass: the rates at the current state.
    Evaluate,
    /// Compute the time step from the `timestep` limits (after the step's first evaluation).
    Timestep,
    /// Run stage k at time t + fraction × dt.
    Update { stage: usize, time_fraction: f64 },
}

/// Where a live field is stored.
#[derive(Clone, Debug)]
pub struct FieldLayout {
    pub field: FieldId,
    pub comps: usize,
    pub groups: GroupSet,
}

/// A synthesised scene constant: a value of the plan's own parameters (gravity, loads).
#[derive(Clone, Debug)]
pub struct SceneParam {
    pub param: ParamId,
    pub value: Vec<f64>,
    /// What the scene uses it for.
    pub role: SceneRole,
}

/// What a parameter the scene adds to a plan stands for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneRole {
    Gravity,
    /// The acceleration of load `k`.
    Load(usize),
    /// The prescribed velocity of constraint `k`.
    Constraint(usize),
    /// Rotating constraint `k`: its centre at t = 0 (m).
    Center(usize),
    /// Rotating constraint `k`: its angular speed at the end of the ramp (rad/s).
    AngularSpeed(usize),
    /// Rotating constraint `k`: the matrix of the cross product with its unit axis, `â × u`.
    AxisCross(usize),
    /// Rotating constraint `k` in 3D: the projection onto its axis, `axis ⊗ axis`.
    AxisProjection(usize),
    /// The unit normal of symmetry plane `k` (of `SceneSpec::planes`).
    Symmetry(usize),
    /// The period of the periodic axis whose lower side is plane `k`: its length along the axis.
    Period(usize),
    /// The case's mass-proportional damping (1/s).
    Damping,
    /// 1 in an axisymmetric case (the prelude's `axisymmetric`).
    Axisymmetric,
}

#[derive(Clone, Debug)]
pub struct Plan {
    /// The model, extended with the plan's synthetic fields (saved state) and parameters.
    pub model: Model,
    pub dim: usize,
    pub groups: GroupSet,
    pub kernel: ir::KernelId,
    pub layout: Vec<FieldLayout>,
    pub passes: Vec<Pass>,
    pub stages: Vec<Stage>,
    pub actions: Vec<Action>,
    pub integrator: IntegratorKind,
    /// Live equations that run in the update (corrections, then state-only particle equations).
    pub corrections: Vec<EqId>,
    pub derived: Vec<EqId>,
    /// State fields whose initial value the engine computes, in dependency order.
    pub initial: Vec<FieldId>,
    pub timesteps: Vec<usize>,
    pub scene_params: Vec<SceneParam>,
    /// Saved copies of the evolving state (multi-stage integrators): (field, copy).
    pub saved: Vec<(FieldId, FieldId)>,
    /// How neighbours are found, and when kept lists are rebuilt (the backends follow it).
    pub search: Search,
    /// The image planes: symmetry planes and the sides of periodic axes.
    pub planes: Vec<Mirror>,
}

/// A reason the plan cannot be made for this scene: a diagnostic with a code (`P…`, listed in
/// `docs/ERRORS.md`) and, where the model has one, the span of what caused it.
#[derive(Debug, Clone)]
pub struct PlanError(pub Box<Diagnostic>);

impl PlanError {
    pub(crate) fn new(code: &'static str, message: impl Into<String>) -> PlanError {
        PlanError(Box::new(Diagnostic::error(code, message.into())))
    }

    pub(crate) fn at(self, span: Span, label: &str) -> PlanError {
        PlanError(Box::new(self.0.at(span, label)))
    }
}

impl std::fmt::Display for PlanError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "error[{}]: {}", self.0.code, self.0.message)
    }
}

/// What a particle of an axisymmetric case stands for in a sum over particles (masses, energies):
/// its ring, 2π r over the 1 m a 2D case's particle is thick, r its x.
pub fn ring(radius: f64) -> f64 {
    2.0 * std::f64::consts::PI * radius
}

impl Plan {
    /// Whether the case is axisymmetric (x the radius, each particle its ring).
    pub fn axisymmetric(&self) -> bool {
        self.scene_params.iter().any(|p| p.role == SceneRole::Axisymmetric)
    }

    pub fn build(model: &Model, scene: &SceneSpec, kernel: Option<&str>) -> Result<Plan, PlanError> {
        let kernel = match kernel {
            Some(name) => model.kernel_id(name).ok_or_else(|| {
                let names: Vec<&str> = model.kernels.iter().map(|k| k.name.as_str()).collect();
                PlanError::new("P0001", format!("unknown kernel `{name}`; the model defines: {}", names.join(", ")))
            })?,
            None => model.kernel.ok_or_else(|| {
                PlanError::new("P0002", "the model names no kernel (`kernel = name`) and the case sets none")
            })?,
        };
        check_components(model, scene.dim)?;
        let mut model = model.clone();
        let scene_params = integrator::scene_params(&mut model, scene);
        settle::settle(&mut model, &scene.settled, scene.dim);
        settle::fold_constant_states(&mut model, scene);
        let live = live::analyse(&model, scene)?;
        for (id, drop) in &live.unneeded {
            model.equations[id.index()] = live::pruned(&model.equations[id.index()], &model, drop);
        }
        let fuse::Fused { passes, corrections, derived } = fuse::fuse(&model, scene, &live)?;
        let mut plan = Plan {
            dim: scene.dim,
            groups: scene.groups,
            kernel,
            layout: vec![],
            passes,
            stages: vec![],
            actions: vec![],
            integrator: scene.integrator,
            corrections,
            derived,
            initial: live.initial.clone(),
            timesteps: live.timesteps.clone(),
            scene_params,
            saved: vec![],
            search: scene.search.clone(),
            planes: scene.planes.clone(),
            model,
        };
        integrator::build(&mut plan, scene, &live);
        plan.layout = live::layout(&plan, scene);
        Ok(plan)
    }

    pub fn field_layout(&self, f: FieldId) -> Option<&FieldLayout> {
        self.layout.iter().find(|l| l.field == f)
    }

    pub fn equation(&self, e: EqId) -> &ir::Equation {
        &self.model.equations[e.index()]
    }

    /// The blocks a pass variant runs after its neighbour loop.
    pub fn tail_blocks(&self, tail: &[TailItem]) -> Vec<Block> {
        tail.iter()
            .map(|t| match *t {
                TailItem::Finally(e) | TailItem::Particle(e) => {
                    let eq = self.equation(e);
                    let stmts = match &eq.kind {
                        ir::EquationKind::PairSum { finally, .. } => finally.clone(),
                        ir::EquationKind::Particle { body } => body.clone(),
                    };
                    Block { name: eq.name.clone(), dest: eq.dest, stmts }
                }
            })
            .collect()
    }

    /// The stored fields a NaN/Inf watchdog scans: every one but the saved copies of a step.
    pub fn watched_fields(&self) -> Vec<FieldId> {
        let watched =
            |f: &FieldId| self.model.field(*f).storage != Storage::Temp && self.model.field(*f).saved_of.is_none();
        self.layout.iter().map(|l| l.field).filter(watched).collect()
    }

    /// Bytes of particle state per particle of a group (all live fields stored there).
    pub fn bytes_per_particle(&self, g: GroupId, real_bytes: usize) -> usize {
        self.layout.iter().filter(|l| l.groups.contains(g)).map(|l| l.comps * real_bytes).sum::<usize>()
    }

    pub fn describe(&self, real_bytes: usize) -> String {
        print::describe(self, real_bytes)
    }

    /// `params_read`, with the parameters their defaults read (`G = E / (2 (1 + ν))` reads `E`
    /// and `nu`), on the same groups: what a material may bind.
    pub fn params_a_material_binds(&self) -> BTreeMap<ParamId, GroupSet> {
        let mut read = self.params_read();
        let mut todo: Vec<_> = read.iter().map(|(p, g)| (*p, *g)).collect();
        while let Some((p, groups)) = todo.pop() {
            let Some(default) = &self.model.params[p.index()].default else { continue };
            ir::walk_expr(default, &mut |e| {
                if let ir::ExprKind::Param(q, _) = e.kind {
                    let entry = read.entry(q).or_default();
                    if entry.union(groups) != *entry {
                        *entry = entry.union(groups);
                        todo.push((q, *entry));
                    }
                }
            });
        }
        read
    }

    /// Parameters the plan reads on each group (at i on the group, at j on the sources).
    pub fn params_read(&self) -> BTreeMap<ParamId, GroupSet> {
        let mut used: BTreeMap<ParamId, GroupSet> = BTreeMap::new();
        let mut note = |p: ParamId, g: GroupSet| {
            let e = used.entry(p).or_default();
            *e = e.union(g.intersect(self.groups));
        };
        let walk = |stmts: &[ir::Stmt], i: GroupSet, j: GroupSet, note: &mut dyn FnMut(ParamId, GroupSet)| {
            ir::walk_stmts(stmts, &mut |e| {
                if let ir::ExprKind::Param(p, side) = e.kind {
                    note(p, if side == ir::Side::I { i } else { j });
                }
            });
        };
        for pass in &self.passes {
            for v in &pass.variants {
                let g = GroupSet::default().with(v.group);
                for e in &v.pair_sums {
                    let eq = self.equation(*e);
                    for s in stmts_of(eq) {
                        walk(s, g, v.sources.intersect(eq.sources()), &mut note);
                    }
                }
                for b in self.tail_blocks(&v.tail) {
                    walk(&b.stmts, g, g, &mut note);
                }
            }
        }
        for st in &self.stages {
            for b in &st.updates {
                walk(&b.stmts, b.dest, b.dest, &mut note);
            }
            for e in st.corrections.iter().chain(&st.derived) {
                let eq = self.equation(*e);
                for s in stmts_of(eq) {
                    walk(s, eq.dest, eq.dest, &mut note);
                }
            }
        }
        let all = self.groups;
        for f in &self.initial {
            if let Some(init) = &self.model.field(*f).init {
                ir::walk_expr(init, &mut |e| {
                    if let ir::ExprKind::Param(p, _) = e.kind {
                        note(p, all);
                    }
                });
            }
        }
        for t in &self.timesteps {
            let ts = &self.model.timesteps[*t];
            ir::walk_expr(&ts.value, &mut |e| {
                if let ir::ExprKind::Param(p, _) = e.kind {
                    note(p, ts.dest.intersect(all));
                }
            });
        }
        used
    }
}

/// Components `.z`, `.xz`… must exist in the scene's dimension.
fn check_components(model: &Model, dim: usize) -> Result<(), PlanError> {
    let mut bad = None;
    let mut visit = |e: &ir::Expr| {
        if let ir::ExprKind::Component(_, r, c) = e.kind {
            if r as usize >= dim || c as usize >= dim {
                bad = Some(e.span);
            }
        }
    };
    for e in &model.equations {
        for s in live::stmts_of(e) {
            ir::walk_stmts(s, &mut visit);
        }
    }
    match bad {
        Some(span) => Err(PlanError::new(
            "P0003",
            format!("the model reads a component that a {dim}D scene does not have (`.z` in 2D?)"),
        )
        .at(span, &format!("not in {dim}D"))),
        None => Ok(()),
    }
}

/// A parameter added by the plan, if the model does not have it yet.
pub(crate) fn synthetic_param(model: &mut Model, name: &str, shape: ir::Shape, unit: Unit) -> ParamId {
    if let Some(p) = model.param_id(name) {
        return p;
    }
    model.params.push(ir::Param {
        name: name.into(),
        ty: ir::Type::new(shape, unit),
        default: None,
        span: Default::default(),
        declared: format!("{name}: {}", shape.name()),
        doc: "set by the scene".into(),
        location: String::new(),
        also_declared: vec![],
    });
    ParamId(model.params.len() as u32 - 1)
}
