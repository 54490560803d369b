//! Dead-code elimination and storage: which (field, group) pairs the scene needs, which
//! equations compute them on which groups, and from that where each field is stored.

use super::{FieldLayout, Plan, PlanError, SceneSpec};
use crate::ir::{self, EqId, Equation, EquationKind, ExprKind, FieldId, GroupSet, Model, Side, Storage};
use std::collections::{BTreeMap, BTreeSet};

/// The result of the analysis.
pub struct Live {
    /// Live equations and the groups each runs on.
    pub dest: BTreeMap<EqId, GroupSet>,
    /// State fields whose initial value is computed from their `= expr`, in dependency order.
    pub initial: Vec<FieldId>,
    pub timesteps: Vec<usize>,
    /// Outputs of live equations that nothing needs: their statements are removed (`pruned`).
    pub unneeded: BTreeMap<EqId, BTreeSet<FieldId>>,
}

pub fn stmts_of(e: &Equation) -> Vec<&[ir::Stmt]> {
    match &e.kind {
        EquationKind::PairSum { init, body, finally, .. } => vec![init, body, finally],
        EquationKind::Particle { body } => vec![body],
    }
}

/// The statement lists of an equation, to rewrite in place.
pub fn stmts_of_mut(e: &mut Equation) -> Vec<&mut Vec<ir::Stmt>> {
    match &mut e.kind {
        EquationKind::PairSum { init, body, finally, .. } => vec![init, body, finally],
        EquationKind::Particle { body } => vec![body],
    }
}

fn expr_fields(e: &ir::Expr, out: &mut BTreeSet<FieldId>) {
    ir::walk_expr(e, &mut |x| {
        if let ExprKind::Field(f, _) = x.kind {
            out.insert(f);
        }
    });
}

/// Fields the engine itself needs on every group: positions and smoothing lengths for the
/// neighbour search, velocity for the integrator, the body index when the scene refers to bodies.
pub fn engine_fields(model: &Model, scene: &SceneSpec) -> Vec<FieldId> {
    let mut names = vec!["x", "h", "v"];
    let targets = scene.loads.iter().map(|l| l.target).chain(scene.constraints.iter().map(|c| c.target));
    for t in targets {
        let name = match t {
            super::Target::Body(_) => "body",
            super::Target::Part(_) => "part",
        };
        if !names.contains(&name) {
            names.push(name);
        }
    }
    names.iter().filter_map(|n| model.field_id(n)).collect()
}

pub fn analyse(model: &Model, scene: &SceneSpec) -> Result<Live, PlanError> {
    let present = scene.groups;
    let mut needed: BTreeMap<FieldId, GroupSet> = BTreeMap::new();
    let need = |needed: &mut BTreeMap<FieldId, GroupSet>, f: FieldId, g: GroupSet| -> bool {
        if model.field(f).storage == Storage::Temp || g.is_empty() {
            return false;
        }
        let e = needed.entry(f).or_default();
        let before = *e;
        *e = e.union(g);
        *e != before
    };
    for f in engine_fields(model, scene) {
        need(&mut needed, f, present);
    }
    for r in &model.rates {
        let g = r.dest.intersect(present);
        need(&mut needed, r.state, g);
        for f in &r.reads {
            need(&mut needed, *f, g);
        }
    }
    let timesteps: Vec<usize> = (0..model.timesteps.len()).collect();
    for t in &model.timesteps {
        for f in &t.reads {
            need(&mut needed, *f, present);
        }
    }
    for f in &scene.outputs {
        need(&mut needed, *f, output_groups(model, *f, present));
    }
    // Fixed point: an equation is live on a group where one of its outputs is needed; then what
    // it reads is needed (at i on that group, at j on its sources).
    let mut dest: BTreeMap<EqId, GroupSet> = BTreeMap::new();
    loop {
        let mut changed = false;
        for (k, e) in model.equations.iter().enumerate() {
            let id = EqId(k as u32);
            let wanted =
                e.writes.iter().fold(GroupSet::default(), |a, f| a.union(needed.get(f).copied().unwrap_or_default()));
            let on = e.dest.intersect(present).intersect(wanted);
            if on.is_empty() {
                continue;
            }
            let entry = dest.entry(id).or_default();
            if entry.union(on) != *entry {
                *entry = entry.union(on);
                changed = true;
            }
            let on = *entry;
            // Only the outputs something needs are computed (and then on every group the
            // equation runs on); the statements of the others are dropped, with what they read.
            let unneeded = unneeded_outputs(e, &needed, on);
            for f in e.writes.iter().filter(|f| !unneeded.contains(f)) {
                changed |= need(&mut needed, *f, on);
            }
            let kept = if unneeded.is_empty() { e.clone() } else { pruned(e, model, &unneeded) };
            for (f, side) in live_reads(model, &kept) {
                let g = if side == Side::I { on } else { e.sources().intersect(present) };
                changed |= need(&mut needed, f, g);
            }
        }
        if !changed {
            break;
        }
    }
    let unneeded = dest
        .iter()
        .map(|(id, on)| (*id, unneeded_outputs(&model.equations[id.index()], &needed, *on)))
        .filter(|(_, u)| !u.is_empty())
        .collect();
    let initial = initial_order(model, &needed)?;
    Ok(Live { dest, initial, timesteps, unneeded })
}

/// The groups on which a field the case writes out or measures is stored: where an equation
/// writes it or a rate integrates it; a state nothing updates (set by the scene) everywhere.
fn output_groups(model: &Model, f: FieldId, present: GroupSet) -> GroupSet {
    let writers = model.equations.iter().filter(|e| e.writes.contains(&f)).map(|e| e.dest);
    let rates = model.rates.iter().filter(|r| r.state == f).map(|r| r.dest);
    let on = writers.chain(rates).fold(GroupSet::default(), |a, g| a.union(g)).intersect(present);
    if on.is_empty() && model.field(f).storage == Storage::State {
        present
    } else {
        on
    }
}

fn unneeded_outputs(e: &Equation, needed: &BTreeMap<FieldId, GroupSet>, on: GroupSet) -> BTreeSet<FieldId> {
    e.writes.iter().copied().filter(|f| needed.get(f).is_none_or(|g| g.intersect(on).is_empty())).collect()
}

/// What an equation needs stored: its reads, and the state it updates from its own value
/// (`eps_p = eps_p + d`).
fn live_reads(model: &Model, e: &Equation) -> BTreeSet<(FieldId, Side)> {
    let mut reads = e.reads.clone();
    for s in stmts_of(e) {
        ir::walk_stmts(s, &mut |x| {
            if let ExprKind::Field(f, side) = x.kind {
                if e.writes.contains(&f) && model.field(f).storage == Storage::State {
                    reads.insert((f, side));
                }
            }
        });
    }
    reads
}

/// The equation without the statements that compute `drop` (and the `let`s only they used), with
/// its writes, reads and parameters recomputed.
pub fn pruned(e: &Equation, model: &Model, drop: &BTreeSet<FieldId>) -> Equation {
    let mut out = e.clone();
    for stmts in stmts_of_mut(&mut out) {
        drop_writes(stmts, drop);
        drop_unused_lets(stmts);
    }
    out.writes.retain(|f| !drop.contains(f));
    drop_unread_accumulators(&mut out);
    let (mut reads, mut params) = (BTreeSet::new(), BTreeSet::new());
    for s in stmts_of(&out) {
        ir::walk_stmts(s, &mut |x| match x.kind {
            ExprKind::Field(f, side) if !out.writes.contains(&f) && model.field(f).storage != Storage::Temp => {
                reads.insert((f, side));
            }
            ExprKind::Param(p, side) => {
                params.insert((p, side));
            }
            _ => {}
        });
    }
    out.reads = reads;
    out.params = params;
    out
}

/// Removes a pair sum's accumulators that are not its outputs and that nothing reads any more
/// (only a dropped output read them), with the statements that fold into them, until none is left.
fn drop_unread_accumulators(e: &mut Equation) {
    loop {
        let mut read: BTreeSet<FieldId> = e.writes.iter().copied().collect();
        for stmts in stmts_of(e) {
            ir::walk_stmts(stmts, &mut |x| {
                if let ExprKind::Field(f, _) = x.kind {
                    read.insert(f);
                }
            });
        }
        let EquationKind::PairSum { accumulators, .. } = &mut e.kind else { return };
        let unread: BTreeSet<FieldId> = accumulators.iter().map(|a| a.field).filter(|f| !read.contains(f)).collect();
        if unread.is_empty() {
            return;
        }
        accumulators.retain(|a| !unread.contains(&a.field));
        for stmts in stmts_of_mut(e) {
            drop_writes(stmts, &unread);
            drop_unused_lets(stmts);
        }
    }
}

fn drop_writes(stmts: &mut Vec<ir::Stmt>, drop: &BTreeSet<FieldId>) {
    stmts.retain_mut(|s| match s {
        ir::Stmt::Set(f, _) | ir::Stmt::Accum(f, _, _) => !drop.contains(f),
        ir::Stmt::If(_, a, b) => {
            drop_writes(a, drop);
            drop_writes(b, drop);
            !(a.is_empty() && b.is_empty())
        }
        ir::Stmt::Let(..) => true,
    });
}

fn drop_unused_lets(stmts: &mut Vec<ir::Stmt>) {
    loop {
        let mut used = BTreeSet::new();
        ir::walk_stmts(stmts, &mut |x| {
            if let ExprKind::Local(l) = x.kind {
                used.insert(l);
            }
        });
        let before = count_lets(stmts);
        remove_lets(stmts, &used);
        if count_lets(stmts) == before {
            return;
        }
    }
}

fn count_lets(stmts: &[ir::Stmt]) -> usize {
    stmts
        .iter()
        .map(|s| match s {
            ir::Stmt::Let(..) => 1,
            ir::Stmt::If(_, a, b) => count_lets(a) + count_lets(b),
            _ => 0,
        })
        .sum()
}

fn remove_lets(stmts: &mut Vec<ir::Stmt>, used: &BTreeSet<ir::LocalId>) {
    stmts.retain_mut(|s| match s {
        ir::Stmt::Let(l, _) => used.contains(l),
        ir::Stmt::If(_, a, b) => {
            remove_lets(a, used);
            remove_lets(b, used);
            !(a.is_empty() && b.is_empty())
        }
        _ => true,
    });
}

/// State fields with an initial-value expression, ordered so that each comes after what it reads.
fn initial_order(model: &Model, needed: &BTreeMap<FieldId, GroupSet>) -> Result<Vec<FieldId>, PlanError> {
    let mut want: BTreeSet<FieldId> = needed.keys().copied().filter(|f| model.field(*f).init.is_some()).collect();
    // Initial values read other state (m = rho0 * vol): those are computed first.
    let mut grew = true;
    while grew {
        grew = false;
        for f in want.clone() {
            let mut reads = BTreeSet::new();
            if let Some(init) = &model.field(f).init {
                expr_fields(init, &mut reads);
            }
            for r in reads {
                if model.field(r).init.is_some() && want.insert(r) {
                    grew = true;
                }
            }
        }
    }
    let mut order = vec![];
    let mut done: BTreeSet<FieldId> = BTreeSet::new();
    while order.len() < want.len() {
        let before = order.len();
        for &f in &want {
            if done.contains(&f) {
                continue;
            }
            let mut reads = BTreeSet::new();
            if let Some(init) = &model.field(f).init {
                expr_fields(init, &mut reads);
            }
            if reads.iter().all(|r| !want.contains(r) || done.contains(r) || *r == f) {
                order.push(f);
                done.insert(f);
            }
        }
        if order.len() == before {
            let stuck = want.iter().find(|f| !done.contains(f)).map(|f| model.field(*f));
            let e = PlanError::new("P0006", "the initial values of the state fields depend on each other");
            return Err(match stuck {
                Some(field) => e.at(field.span, &format!("`{}` waits on another", field.name)),
                None => e,
            });
        }
    }
    Ok(order)
}

/// Where each needed field is stored: on the groups that need it. Saved copies follow their
/// originals.
pub fn layout(plan: &Plan, scene: &SceneSpec) -> Vec<FieldLayout> {
    let mut out: Vec<FieldLayout> = vec![];
    let mut add = |f: FieldId, groups: GroupSet| {
        if groups.is_empty() {
            return;
        }
        match out.iter_mut().find(|l| l.field == f) {
            Some(l) => l.groups = l.groups.union(groups),
            None => out.push(FieldLayout {
                field: f,
                comps: ir::components(plan.model.field(f).ty.shape, plan.dim),
                groups,
            }),
        }
    };
    for (f, g) in &plan_needed(plan) {
        add(*f, *g);
    }
    // What the case writes out or measures, though no equation of the step reads it.
    for f in &scene.outputs {
        if plan.model.field(*f).storage != Storage::Temp {
            add(*f, output_groups(&plan.model, *f, plan.groups));
        }
    }
    out.sort_by_key(|l| l.field);
    out
}

/// Every (field, groups) the plan's blocks touch: recomputed from the plan itself so that the
/// integrator's saved copies and any synthesised statements are included.
fn plan_needed(plan: &Plan) -> BTreeMap<FieldId, GroupSet> {
    let model = &plan.model;
    let mut m: BTreeMap<FieldId, GroupSet> = BTreeMap::new();
    let mut touch = |f: FieldId, g: GroupSet| {
        if model.field(f).storage != Storage::Temp {
            let e = m.entry(f).or_default();
            *e = e.union(g.intersect(plan.groups));
        }
    };
    for f in engine_fields_of_plan(plan) {
        touch(f, plan.groups);
    }
    let stmt_fields = |stmts: &[ir::Stmt], touch: &mut dyn FnMut(FieldId, Side)| {
        ir::walk_stmts(stmts, &mut |e| {
            if let ExprKind::Field(f, side) = e.kind {
                touch(f, side);
            }
        });
        visit_sets(stmts, &mut |f| touch(f, Side::I));
    };
    for p in &plan.passes {
        for v in &p.variants {
            let g = GroupSet::default().with(v.group);
            for e in &v.pair_sums {
                let eq = plan.equation(*e);
                // At j, only the groups this equation sums over on this group.
                let sources = v.sources_of(eq);
                for s in stmts_of(eq) {
                    stmt_fields(s, &mut |f, side| touch(f, if side == Side::I { g } else { sources }));
                }
                for f in &eq.writes {
                    touch(*f, g);
                }
            }
            for b in plan.tail_blocks(&v.tail) {
                stmt_fields(&b.stmts, &mut |f, _| touch(f, g));
            }
        }
    }
    for st in &plan.stages {
        for b in &st.updates {
            stmt_fields(&b.stmts, &mut |f, _| touch(f, b.dest));
        }
    }
    for e in plan.corrections.iter().chain(&plan.derived) {
        let eq = plan.equation(*e);
        let dest = plan_dest(plan, *e);
        for s in stmts_of(eq) {
            stmt_fields(s, &mut |f, _| touch(f, dest));
        }
    }
    for t in &plan.timesteps {
        for f in &model.timesteps[*t].reads {
            touch(*f, plan.groups);
        }
    }
    m
}

/// Groups a live update-phase equation runs on.
pub fn plan_dest(plan: &Plan, e: EqId) -> GroupSet {
    plan.equation(e).dest.intersect(plan.groups)
}

fn engine_fields_of_plan(plan: &Plan) -> Vec<FieldId> {
    ["x", "h", "v"].iter().filter_map(|n| plan.model.field_id(n)).collect()
}

fn visit_sets(stmts: &[ir::Stmt], f: &mut dyn FnMut(FieldId)) {
    for s in stmts {
        match s {
            ir::Stmt::Set(x, _) | ir::Stmt::Accum(x, _, _) => f(*x),
            ir::Stmt::If(_, a, b) => {
                visit_sets(a, f);
                visit_sets(b, f);
            }
            ir::Stmt::Let(..) => {}
        }
    }
}
