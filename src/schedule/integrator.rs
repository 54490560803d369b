//! Integrators as generated IR: each stage is a list of per-particle statements that both backends
//! compile like any particle equation.
//!
//! - Euler: S ← S + Δt Ṡ(S).
//! - Predictor–corrector (FTLR19 Fig 5, Monaghan's midpoint form): S½ = S⁰ + Δt/2 Ṡ(S⁰);
//!   S¹ = S⁰ + Δt Ṡ(S½) (equal to FTLR19's S¹ = 2 S½′ − S⁰ with S½′ = S⁰ + Δt/2 Ṡ(S½)).
//! - Symplectic (DualSPHysics, Monaghan 2005): the same predictor, then v¹ = v⁰ + Δt v̇(S½),
//!   x¹ = x⁰ + Δt (v⁰ + v¹)/2 (and so every state whose rate is v), ρ¹ = ρ⁰ (2 − ε)/(2 + ε) with
//!   ε = −(ρ̇/ρ)½ Δt, others midpoint.
//! - Their one-evaluation forms, `pec` and `symplectic_pec` (PySPH's PEC): the predictor takes the
//!   rates of the step before's evaluation (at its half step; at the first step, those at t = 0)
//!   instead of evaluating at S⁰, so a step costs one evaluation, not two.
//!
//! State that corrections change without a rate (plastic strain, damage) restarts every stage from
//! its value at the start of the step, so a two-stage step counts its increment once.
//! Gravity, body loads and the case's damping (−c v) are added to the rate of `v`; prescribed velocities replace `v`; a
//! particle that crosses a symmetry plane is reflected back with its normal velocity reversed.

use super::live::Live;
use super::{synthetic_param, Action, Block, Plan, SceneParam, SceneRole, SceneSpec, Stage};
use crate::ir::{self, Expr, ExprKind, FieldId, Global, GroupSet, Model, Op, Shape, Stmt, Storage, Type};
use crate::units::Unit;
use std::collections::BTreeSet;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IntegratorKind {
    Euler,
    PredictorCorrector,
    Symplectic,
    /// The predictor–corrector with the predictor on the last evaluation's rates.
    Pec,
    /// The symplectic scheme with the predictor on the last evaluation's rates.
    SymplecticPec,
}

impl IntegratorKind {
    pub const NAMES: &'static str = "euler, predictor_corrector, symplectic, pec, symplectic_pec";

    pub fn name(self) -> &'static str {
        match self {
            IntegratorKind::Euler => "euler",
            IntegratorKind::PredictorCorrector => "predictor_corrector",
            IntegratorKind::Symplectic => "symplectic",
            IntegratorKind::Pec => "pec",
            IntegratorKind::SymplecticPec => "symplectic_pec",
        }
    }
    pub fn parse(s: &str) -> Option<IntegratorKind> {
        match s {
            "euler" => Some(IntegratorKind::Euler),
            "predictor_corrector" | "pc" => Some(IntegratorKind::PredictorCorrector),
            "symplectic" => Some(IntegratorKind::Symplectic),
            "pec" => Some(IntegratorKind::Pec),
            "symplectic_pec" => Some(IntegratorKind::SymplecticPec),
            _ => None,
        }
    }
    /// Whether the corrector is the symplectic one (velocity-averaged positions, ρ's ratio form).
    pub fn is_symplectic(self) -> bool {
        matches!(self, IntegratorKind::Symplectic | IntegratorKind::SymplecticPec)
    }
    /// Neighbour evaluations per step.
    pub fn evaluations(self) -> usize {
        match self {
            IntegratorKind::PredictorCorrector | IntegratorKind::Symplectic => 2,
            _ => 1,
        }
    }
}

fn accel_unit() -> Unit {
    crate::units::parse_simple("m/s^2").unwrap_or(Unit::ONE)
}

fn speed_unit() -> Unit {
    crate::units::parse_simple("m/s").unwrap_or(Unit::ONE)
}

/// Adds the scene's constants (gravity, loads, prescribed velocities) as parameters of the plan's
/// model, with their values.
pub fn scene_params(model: &mut Model, scene: &SceneSpec) -> Vec<SceneParam> {
    let mut out = vec![];
    if let Some(g) = &scene.gravity {
        // The prelude's `gravity`, so that a model may read it (a wall's hydrostatic pressure).
        let p = synthetic_param(model, ir::GRAVITY, Shape::Vec, accel_unit());
        out.push(SceneParam { param: p, value: g.clone(), role: SceneRole::Gravity });
    }
    for (k, l) in scene.loads.iter().enumerate() {
        let p = synthetic_param(model, &format!("@load{k}"), Shape::Vec, accel_unit());
        out.push(SceneParam { param: p, value: l.accel.clone(), role: SceneRole::Load(k) });
    }
    for (k, c) in scene.constraints.iter().enumerate() {
        let p = synthetic_param(model, &format!("@constraint{k}"), Shape::Vec, speed_unit());
        out.push(SceneParam { param: p, value: c.velocity.clone(), role: SceneRole::Constraint(k) });
        if let Some(r) = &c.rotation {
            out.extend(rotation_params(model, scene.dim, k, r));
        }
    }
    if scene.axisymmetric {
        let p = synthetic_param(model, ir::AXISYMMETRIC, Shape::Scalar, Unit::ONE);
        out.push(SceneParam { param: p, value: vec![1.0], role: SceneRole::Axisymmetric });
    }
    if let Some(c) = scene.damping {
        let per_second = Unit::ONE.div(&Unit::S).unwrap_or(Unit::ONE);
        let p = synthetic_param(model, "@damping", Shape::Scalar, per_second);
        out.push(SceneParam { param: p, value: vec![c], role: SceneRole::Damping });
    }
    for (k, plane) in scene.planes.iter().enumerate() {
        let along = |length: f64| (0..scene.dim).map(|c| if c == plane.axis { length } else { 0.0 }).collect();
        if plane.shift == 0.0 {
            let p = synthetic_param(model, &format!("@symmetry{k}"), Shape::Vec, Unit::ONE);
            out.push(SceneParam { param: p, value: along(plane.side), role: SceneRole::Symmetry(k) });
        } else if plane.shift > 0.0 {
            let p = synthetic_param(model, &format!("@period{k}"), Shape::Vec, Unit::M);
            out.push(SceneParam { param: p, value: along(plane.shift), role: SceneRole::Period(k) });
        }
    }
    out
}

/// The parameters of a rotating constraint: its centre, its angular speed, the cross-product
/// matrix [â]ₓ of its axis (its in-plane block in 2D, where the axis is z) and, in 3D, â ⊗ â.
fn rotation_params(model: &mut Model, dim: usize, k: usize, r: &super::Rotation) -> Vec<SceneParam> {
    let [a, b, c] = r.axis;
    let cross = [[0.0, -c, b], [c, 0.0, -a], [-b, a, 0.0]];
    let tensor = |m: &dyn Fn(usize, usize) -> f64| -> Vec<f64> {
        (0..dim).flat_map(|i| (0..dim).map(move |j| (i, j))).map(|(i, j)| m(i, j)).collect()
    };
    let per_second = Unit::ONE.div(&Unit::S).unwrap_or(Unit::ONE);
    let mut param = |name: &str, shape, unit, value: Vec<f64>, role| {
        let p = synthetic_param(model, &format!("@{name}{k}"), shape, unit);
        SceneParam { param: p, value, role }
    };
    let mut out = vec![
        param("center", Shape::Vec, Unit::M, r.center.clone(), SceneRole::Center(k)),
        param("omega", Shape::Scalar, per_second, vec![r.omega], SceneRole::AngularSpeed(k)),
        param("cross", Shape::Tensor, Unit::ONE, tensor(&|i, j| cross[i][j]), SceneRole::AxisCross(k)),
    ];
    if dim == 3 {
        let projection = tensor(&|i, j| r.axis[i] * r.axis[j]);
        out.push(param("axis", Shape::Tensor, Unit::ONE, projection, SceneRole::AxisProjection(k)));
    }
    out
}

/// `min(t / ramp, 1)`, or 1 for a step.
fn ramp(ramp: f64) -> Expr {
    let one = Type::scalar(Unit::ONE);
    if ramp <= 0.0 {
        return Expr::constant(1.0, one);
    }
    let frac = Expr::global(Global::Time).divided_by(Expr::constant(ramp, Type::scalar(Unit::S)));
    Expr::new(ExprKind::Call(ir::Builtin::Min, vec![frac, Expr::constant(1.0, one)]), one)
}

/// `body == k` or `part == k`: whether a particle is in a load's or a constraint's target.
fn on_target(model: &Model, target: super::Target) -> Option<Expr> {
    let (name, k) = match target {
        super::Target::Body(b) => ("body", b),
        super::Target::Part(p) => ("part", p),
    };
    let f = model.field_id(name)?;
    let ty = model.field(f).ty;
    Some(Expr::binary(Op::Eq, Expr::field(f, ty), Expr::constant(k as f64, ty), Type::BOOL))
}

/// `∫₀ᵗ ramp`: the time over which a ramped speed has acted at full value (`t` for a step).
fn ramped_time(ramp: f64) -> Expr {
    let t = || Expr::global(Global::Time);
    if ramp <= 0.0 {
        return t();
    }
    let s = Type::scalar(Unit::S);
    let early = t().scaled_by(t()).divided_by(Expr::constant(2.0 * ramp, s));
    let late = t().minus(Expr::constant(ramp / 2.0, s));
    Expr::select(Expr::binary(Op::Lt, t(), Expr::constant(ramp, s), Type::BOOL), early, late)
}

fn zero_vec(unit: Unit) -> Expr {
    Expr::constant(0.0, Type::new(Shape::Vec, unit))
}

/// The rate of `v` with gravity, loads and damping added.
fn velocity_rate(plan: &Plan, scene: &SceneSpec, rate: Expr) -> Expr {
    let model = &plan.model;
    let mut r = rate;
    for sp in &plan.scene_params {
        let p = Expr::param(sp.param, model.params[sp.param.index()].ty);
        if sp.role == SceneRole::Gravity {
            r = r.plus(p);
        } else if sp.role == SceneRole::Damping {
            if let Some(v) = model.field_id("v") {
                r = r.minus(Expr::field(v, model.field(v).ty).scaled_by(p));
            }
        } else if let SceneRole::Load(k) = sp.role {
            let load = &scene.loads[k];
            if let Some(cond) = on_target(model, load.target) {
                let a = p.scaled_by(ramp(load.ramp));
                r = r.plus(Expr::select(cond, a, zero_vec(accel_unit())));
            }
        }
    }
    r
}

/// Prescribed velocities, applied after `v` is updated.
fn constrain(plan: &Plan, scene: &SceneSpec, v: FieldId) -> Vec<Stmt> {
    let model = &plan.model;
    let ty = model.field(v).ty;
    let mut out = vec![];
    for sp in &plan.scene_params {
        let SceneRole::Constraint(k) = sp.role else { continue };
        let c = &scene.constraints[k];
        if c.rotation.is_some() {
            continue; // `rigid_motion` sets both x and v after the stage
        }
        let Some(cond) = on_target(model, c.target) else { continue };
        let target = Expr::param(sp.param, model.params[sp.param.index()].ty).scaled_by(ramp(c.ramp));
        out.push(Stmt::Set(v, Expr::select(cond, target, Expr::field(v, ty))));
    }
    out
}

/// Whether constraint `k` sets positions as well as velocities: when it rotates its body, or when
/// it moves a body whose positions the model does not integrate (a wall moved as a whole).
fn prescribes_position(scene: &SceneSpec, rates: &[ir::Rate], x: Option<FieldId>, k: usize) -> bool {
    let c = &scene.constraints[k];
    let integrated = rates.iter().filter(|r| Some(r.state) == x).fold(GroupSet::default(), |a, r| a.union(r.dest));
    let on = c.groups.intersect(scene.groups);
    let moves = c.velocity.iter().any(|v| *v != 0.0);
    c.rotation.is_some() || (moves && on.intersect(integrated) != on)
}

/// The reference position `x` at t = 0 of the particles whose motion is prescribed.
fn reference_positions(plan: &mut Plan) -> Option<FieldId> {
    let x = plan.model.field_id("x")?;
    let x_ty = plan.model.field(x).ty;
    let span = plan.model.field(x).span;
    plan.model.fields.push(ir::Field {
        name: "x@ref".into(),
        ty: x_ty,
        storage: Storage::State,
        init: Some(Expr::field(x, x_ty)),
        span,
        saved_of: None,
    });
    let id = FieldId(plan.model.fields.len() as u32 - 1);
    plan.initial.push(id);
    Some(id)
}

/// The rigid motion of the constraints that set positions, after the stage's integration: from
/// the reference position `X` (`x` at t = 0), the centre's displacement `d = V s(t)` and the
/// angle `θ = ω s(t)` (`s = ∫ ramp`), Rodrigues' rotation
///   `x = c + d + cos θ (X − c) + sin θ â×(X − c) + (1 − cos θ) â(â·(X − c))`,
///   `v = V r(t) + r(t) ω â×(x − c − d)`   (`r` the ramp).
fn rigid_motion(plan: &Plan, scene: &SceneSpec, k: usize, x_ref: FieldId) -> Option<Block> {
    let model = &plan.model;
    let c = &scene.constraints[k];
    let (x, v) = (model.field_id("x")?, model.field_id("v")?);
    let cond = on_target(model, c.target)?;
    let param_of = |role: SceneRole| {
        let sp = plan.scene_params.iter().find(|sp| sp.role == role)?;
        Some(Expr::param(sp.param, model.params[sp.param.index()].ty))
    };
    let x_ty = model.field(x).ty;
    let v_ty = model.field(v).ty;
    let speed = param_of(SceneRole::Constraint(k))?;
    let shift = speed.clone().scaled_by(ramped_time(c.ramp));
    let mut position = Expr::field(x_ref, x_ty).plus(shift.clone());
    let mut velocity = speed.scaled_by(ramp(c.ramp));
    if c.rotation.is_some() {
        let center = param_of(SceneRole::Center(k))?;
        let omega = param_of(SceneRole::AngularSpeed(k))?;
        let cross = param_of(SceneRole::AxisCross(k))?;
        let one = Type::scalar(Unit::ONE);
        let angle = ramped_time(c.ramp).scaled_by(omega.clone());
        let trig = |name: &str| {
            let (f, _) = ir::Builtin::by_name(name).expect("sin and cos are builtins");
            Expr::new(ExprKind::Call(f, vec![angle.clone()]), one)
        };
        let arm = Expr::field(x_ref, x_ty).minus(center.clone());
        let mat_vec = |m: Expr, u: Expr| {
            let unit = m.ty.unit.mul(&u.ty.unit).unwrap_or(u.ty.unit);
            Expr::binary(Op::MatVec, m, u, Type::new(Shape::Vec, unit))
        };
        let mut rotated =
            arm.clone().scaled_by(trig("cos")).plus(mat_vec(cross.clone(), arm.clone()).scaled_by(trig("sin")));
        // The component along the axis, which a 2D (in-plane) arm lacks.
        if let Some(axis) = param_of(SceneRole::AxisProjection(k)) {
            let along = mat_vec(axis, arm).scaled_by(Expr::constant(1.0, one).minus(trig("cos")));
            rotated = rotated.plus(along);
        }
        position = center.plus(shift).plus(rotated.clone());
        velocity = velocity.plus(mat_vec(cross, rotated).scaled_by(omega.scaled_by(ramp(c.ramp))));
    }
    let stmts = vec![
        Stmt::Set(x, Expr::select(cond.clone(), position, Expr::field(x, x_ty))),
        Stmt::Set(v, Expr::select(cond, velocity, Expr::field(v, v_ty))),
    ];
    Some(Block { name: format!("prescribed motion {k}"), dest: c.groups.intersect(scene.groups), stmts })
}

/// Periodic axes, after `x` is updated in the step's last stage: a particle at or beyond the
/// upper side `hi` moves back by the period L, one below the lower side `lo` forward by it
/// (`@period{k}`, L along the axis).
fn wrap(plan: &Plan, scene: &SceneSpec, x: FieldId) -> Vec<Stmt> {
    let model = &plan.model;
    let x_ty = model.field(x).ty;
    let mut out = vec![];
    for sp in &plan.scene_params {
        let SceneRole::Period(k) = sp.role else { continue };
        let plane = scene.planes[k];
        let (lo, hi) = (plane.offset, plane.offset + plane.shift);
        let period = Expr::param(sp.param, model.params[sp.param.index()].ty);
        let along = Expr::new(
            ExprKind::Component(Box::new(Expr::field(x, x_ty)), plane.axis as u8, 0),
            Type::scalar(x_ty.unit),
        );
        let at = |v: f64| Expr::constant(v, Type::scalar(x_ty.unit));
        let beyond = Expr::binary(Op::Ge, along.clone(), at(hi), Type::BOOL);
        let below = Expr::binary(Op::Lt, along, at(lo), Type::BOOL);
        let x_now = Expr::field(x, x_ty);
        let wrapped = Expr::select(
            beyond,
            x_now.clone().minus(period.clone()),
            Expr::select(below, x_now.clone().plus(period), x_now),
        );
        out.push(Stmt::Set(x, wrapped));
    }
    out
}

/// Reflection at the symmetry planes, after `x` and `v` are updated in the step's last stage
/// (a predictor may leave a particle behind a plane for half a step): where `x` lies behind the
/// plane (`x[axis] < offset` for a plane whose particles live above it, `>` below), `v[axis]`
/// changes sign and `x[axis]` becomes `2 offset − x[axis]` (`n` is the plane's unit normal into
/// the particles' side, the parameter `@symmetry{k}`).
fn reflect(plan: &Plan, scene: &SceneSpec, x: FieldId, v: Option<FieldId>) -> Vec<Stmt> {
    let model = &plan.model;
    let mut out = wrap(plan, scene, x);
    for sp in &plan.scene_params {
        let SceneRole::Symmetry(k) = sp.role else { continue };
        let (axis, offset, side) = (scene.planes[k].axis, scene.planes[k].offset, scene.planes[k].side);
        let n = Expr::param(sp.param, model.params[sp.param.index()].ty);
        let component = |f: FieldId| {
            let ty = model.field(f).ty;
            Expr::new(ExprKind::Component(Box::new(Expr::field(f, ty)), axis as u8, 0), Type::scalar(ty.unit))
        };
        let x_ty = model.field(x).ty;
        // how far behind the plane, along n
        let plane = Expr::constant(offset, Type::scalar(x_ty.unit));
        let depth = if side > 0.0 { plane.minus(component(x)) } else { component(x).minus(plane) };
        let crossed = || Expr::binary(Op::Gt, depth.clone(), Expr::constant(0.0, depth.ty), Type::BOOL);
        let two = || Expr::constant(2.0, Type::scalar(Unit::ONE));
        if let Some(v) = v {
            let ty = model.field(v).ty;
            // 2 (v · n), with n = ±e_axis
            let twice_normal = component(v).scaled_by(Expr::constant(2.0 * side, Type::scalar(Unit::ONE)));
            let flipped = Expr::field(v, ty).minus(n.clone().scaled_by(twice_normal));
            out.push(Stmt::Set(v, Expr::select(crossed(), flipped, Expr::field(v, ty))));
        }
        let back = Expr::field(x, x_ty).plus(n.scaled_by(depth.clone().scaled_by(two())));
        out.push(Stmt::Set(x, Expr::select(crossed(), back, Expr::field(x, x_ty))));
    }
    out
}

pub fn build(plan: &mut Plan, scene: &SceneSpec, live: &Live) {
    let present = scene.groups;
    let rates: Vec<ir::Rate> =
        plan.model.rates.iter().filter(|r| !r.dest.intersect(present).is_empty()).cloned().collect();
    // Evolving state: integrated, or changed by a live correction from its own value (`eps_p =
    // eps_p + d` must restart from the step's start in a second stage; `T = T_room + e / C_v`
    // need not).
    let mut evolving: BTreeSet<FieldId> = rates.iter().map(|r| r.state).collect();
    for e in &plan.corrections {
        let eq = &plan.model.equations[e.index()];
        for f in &eq.writes {
            if plan.model.field(*f).storage == Storage::State && reads_own(eq, *f) {
                evolving.insert(*f);
            }
        }
    }
    let _ = live;
    let multi = scene.integrator != super::IntegratorKind::Euler;
    if multi {
        for f in &evolving {
            let orig = plan.model.field(*f).clone();
            plan.model.fields.push(ir::Field {
                name: format!("{}@0", orig.name),
                ty: orig.ty,
                storage: Storage::State,
                init: None,
                span: orig.span,
                saved_of: Some(*f),
            });
            plan.saved.push((*f, FieldId(plan.model.fields.len() as u32 - 1)));
        }
    }
    let x = plan.model.field_id("x");
    let moving: Vec<usize> =
        (0..scene.constraints.len()).filter(|k| prescribes_position(scene, &rates, x, *k)).collect();
    let x_ref = if moving.is_empty() { None } else { reference_positions(plan) };
    let stage_count = if multi { 2 } else { 1 };
    for stage in 0..stage_count {
        let (mut updates, locals) = stage_blocks(plan, scene, &rates, &evolving, stage);
        plan.model.locals.extend(locals);
        if let Some(x_ref) = x_ref {
            updates.extend(moving.iter().filter_map(|k| rigid_motion(plan, scene, *k, x_ref)));
        }
        let name = match (scene.integrator, stage) {
            (super::IntegratorKind::Euler, _) => "euler",
            (_, 0) => "predict",
            _ => "correct",
        };
        plan.stages.push(Stage { name, updates, corrections: plan.corrections.clone(), derived: plan.derived.clone() });
    }
    plan.actions = if multi {
        let mut actions = vec![Action::Save];
        // With one evaluation a step the rates of the last one (the engine evaluates once at
        // t = 0) predict.
        if scene.integrator.evaluations() == 2 {
            actions.push(Action::Evaluate);
        }
        actions.extend([
            Action::Timestep,
            Action::Update { stage: 0, time_fraction: 0.5 },
            Action::Evaluate,
            Action::Update { stage: 1, time_fraction: 1.0 },
        ]);
        actions
    } else {
        vec![Action::Evaluate, Action::Timestep, Action::Update { stage: 0, time_fraction: 1.0 }]
    };
}

/// The statements of one stage, one block per distinct set of groups the rates apply to.
fn stage_blocks(
    plan: &Plan,
    scene: &SceneSpec,
    rates: &[ir::Rate],
    evolving: &BTreeSet<FieldId>,
    stage: usize,
) -> (Vec<Block>, Vec<ir::Local>) {
    let model = &plan.model;
    let saved = |f: FieldId| plan.saved.iter().find(|(o, _)| *o == f).map(|(_, s)| *s);
    let dt = || Expr::global(Global::Dt);
    let half = |e: Expr| e.scaled_by(Expr::constant(0.5, Type::scalar(Unit::ONE)));
    let x = model.field_id("x");
    let v = model.field_id("v");
    let rho = model.field_id("rho");
    let kind = scene.integrator;
    let mut groupsets: Vec<GroupSet> = vec![];
    for r in rates {
        let g = r.dest.intersect(scene.groups);
        if !groupsets.contains(&g) {
            groupsets.push(g);
        }
    }
    let mut blocks = vec![];
    let mut new_locals = vec![];
    for gs in groupsets {
        let mut lets = vec![];
        let mut sets = vec![];
        // All rates are read at the evaluation state before any state changes.
        let mut rate_locals: Vec<(FieldId, ir::LocalId, Type)> = vec![];
        for r in rates.iter().filter(|r| r.dest.intersect(scene.groups) == gs) {
            let mut rate = r.rate.clone();
            if Some(r.state) == v {
                rate = velocity_rate(plan, scene, rate);
            }
            let id = ir::LocalId((model.locals.len() + new_locals.len()) as u32);
            new_locals.push(ir::Local { name: format!("rate of {}", model.field(r.state).name), ty: rate.ty });
            rate_locals.push((r.state, id, rate.ty));
            lets.push(Stmt::Let(id, rate));
        }
        let rate_of = |f: FieldId| {
            rate_locals.iter().find(|(s, _, _)| *s == f).map(|(_, id, ty)| Expr::new(ExprKind::Local(*id), *ty))
        };
        // v first: the symplectic position update reads the new velocity.
        let mut order: Vec<&(FieldId, ir::LocalId, Type)> = rate_locals.iter().collect();
        order.sort_by_key(|(f, _, _)| if Some(*f) == v { 0 } else { 1 });
        for (f, _, _) in order {
            let f = *f;
            let ty = model.field(f).ty;
            let rate = rate_of(f).expect("rate bound above");
            let base = match (kind, saved(f)) {
                (super::IntegratorKind::Euler, _) | (_, None) => Expr::field(f, ty),
                (_, Some(s)) => Expr::field(s, ty),
            };
            let value = match (kind, stage) {
                (super::IntegratorKind::Euler, _) => base.plus(rate.scaled_by(dt())),
                (_, 0) => base.plus(half(rate.scaled_by(dt()))),
                (k, _) if k.is_symplectic() && is_field(&rate_expr(rates, f), v) => {
                    // x¹ = x⁰ + Δt (v⁰ + v¹)/2, for x and any other state whose rate is v (a total
                    // Lagrangian solid's displacement): advanced another way, its forces would
                    // see an explicit-Euler oscillator, which grows every step.
                    let v = v.expect("x' = v names v");
                    let vty = model.field(v).ty;
                    let v0 = saved(v).map(|s| Expr::field(s, vty)).unwrap_or_else(|| Expr::field(v, vty));
                    base.plus(half(v0.plus(Expr::field(v, vty)).scaled_by(dt())))
                }
                (k, _) if k.is_symplectic() && Some(f) == rho => {
                    // ρ¹ = ρ⁰ (2 − ε)/(2 + ε), ε = −(ρ̇/ρ) Δt at the half step
                    let one = Type::scalar(Unit::ONE);
                    let eps = Expr::new(
                        ExprKind::Unary(Op::Neg, Box::new(rate.divided_by(Expr::field(f, ty)).scaled_by(dt()))),
                        one,
                    );
                    let two = || Expr::constant(2.0, one);
                    let factor = Expr::binary(Op::Div, two().minus(eps.clone()), two().plus(eps), one);
                    base.scaled_by(factor)
                }
                _ => base.plus(rate.scaled_by(dt())),
            };
            sets.push(Stmt::Set(f, value));
            if Some(f) == v {
                sets.extend(constrain(plan, scene, f));
            }
        }
        // At the end of the step only: a two-stage step restarts from the saved state.
        let last_stage = kind == super::IntegratorKind::Euler || stage == 1;
        if let Some(x) = x.filter(|x| last_stage && rate_locals.iter().any(|(f, _, _)| f == x)) {
            sets.extend(reflect(plan, scene, x, v));
        }
        lets.extend(sets);
        blocks.push(Block { name: format!("integrate ({})", model.group_names(gs)), dest: gs, stmts: lets });
    }
    // Corrected state without a rate restarts from the step's start (multi-stage only), on the
    // groups its corrections run on.
    if stage > 0 {
        let integrated: BTreeSet<FieldId> = rates.iter().map(|r| r.state).collect();
        for f in evolving.iter().filter(|f| !integrated.contains(f)) {
            let Some(s) = saved(*f) else { continue };
            let dest = plan
                .corrections
                .iter()
                .filter(|e| model.equations[e.index()].writes.contains(f))
                .fold(GroupSet::default(), |a, e| a.union(model.equations[e.index()].dest))
                .intersect(scene.groups);
            let ty = model.field(*f).ty;
            let name = format!("restore {}", model.field(*f).name);
            blocks.push(Block { name, dest, stmts: vec![Stmt::Set(*f, Expr::field(s, ty))] });
        }
    }
    (blocks, new_locals)
}

/// Whether an equation reads the value of a field it writes.
fn reads_own(eq: &ir::Equation, f: FieldId) -> bool {
    let mut found = false;
    for s in super::live::stmts_of(eq) {
        ir::walk_stmts(s, &mut |x| found |= matches!(x.kind, ir::ExprKind::Field(g, _) if g == f));
    }
    found
}

fn rate_expr(rates: &[ir::Rate], f: FieldId) -> Expr {
    rates.iter().find(|r| r.state == f).map(|r| r.rate.clone()).unwrap_or_else(|| Expr::constant(0.0, Type::BOOL))
}

fn is_field(e: &Expr, f: Option<FieldId>) -> bool {
    matches!(e.kind, ExprKind::Field(g, _) if Some(g) == f)
}
