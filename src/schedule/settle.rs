//! Choices the case's parameters settle. Where every material with particles binds a parameter
//! to the same value, a `select` or an `if` whose condition reads only such parameters (and
//! constants, `dim`) is replaced by the branch it takes, before the dead-code analysis: what only
//! the other branch reads is then neither computed nor stored. The damage modules' nonlocal
//! driver is the case in point: with `damage_length = 0` its Laplacian sum and the nonlocal
//! strain it smooths are gone from the plan (`damage/nonlocal_strain.sph`).
//!
//! A state that nothing writes (no equation, no rate, not the scene: it places `x`, `v`, `vol`,
//! `dx`, `body`, `part` and the bodies' `initial` values) and whose initial value is a scalar
//! constant keeps that value all run: every read of it becomes the constant
//! ([`fold_constant_states`]), so it is neither stored nor gathered. A module may then read a
//! state another module may set, as `solid/shaped_hourglass.sph` reads the damage `D` to spare
//! failed pairs, and a model without damage pays nothing for it.
//!
//! The backends fold such conditions too (the CPU lowering's known parameters, the shader
//! compiler's constants), but only inside a program; settling them here is what lets the plan
//! drop a whole pair sum and its stored fields.

use super::SceneSpec;
use crate::host_eval;
use crate::ir::{self, Equation, Expr, ExprKind, FieldId, Global, LocalId, Model, ParamId, Reduce, Stmt, Storage};

/// Settles every equation of `model` by the parameter values `settled` (by parameter id; `None`
/// or missing: not the same on every material; empty: no materials known, nothing settled). An
/// equation that changes has its reads and parameters recomputed (`live::pruned` with nothing to
/// drop).
pub fn settle(model: &mut Model, settled: &[Option<Vec<f64>>], dim: usize) {
    if settled.is_empty() {
        return;
    }
    for k in 0..model.equations.len() {
        let mut e = model.equations[k].clone();
        if settle_equation(&mut e, settled, dim) {
            let kept: Vec<FieldId> = e
                .writes
                .iter()
                .copied()
                .filter(|f| model.field(*f).storage != Storage::State || sets(&e, *f))
                .collect();
            e.writes = kept;
            model.equations[k] = super::live::pruned(&e, model, &Default::default());
        }
    }
    // A rate settled to 0 (an axisymmetric model's `m' = hoop_mass_rate()` in a planar case) is
    // dropped: the state keeps its value, and one that nothing else writes is folded.
    let settled_rates: Vec<bool> = model.rates.iter_mut().map(|r| settle_expr(&mut r.rate, settled, dim)).collect();
    drop_zero_rates(model, &settled_rates);
    fold_constant_outputs(model);
}

/// Drops each rate that `changed` marks and that is now the constant 0, and recomputes the reads
/// of the others it marks.
fn drop_zero_rates(model: &mut Model, changed: &[bool]) {
    let mut k = 0;
    model.rates.retain_mut(|r| {
        k += 1;
        if !changed[k - 1] {
            return true;
        }
        r.reads.clear();
        ir::walk_expr(&r.rate, &mut |x| {
            if let ExprKind::Field(f, _) = x.kind {
                r.reads.insert(f);
            }
        });
        host_eval::constant(&r.rate) != Some(0.0)
    });
}

/// Whether a statement of `e` still writes `f` (a correction whose settled branch no longer
/// updates a state leaves it as it was: `s_hoop` in a planar case, plasticity/radial_return_jc.sph).
fn sets(e: &Equation, f: FieldId) -> bool {
    fn any(stmts: &[Stmt], f: FieldId) -> bool {
        stmts.iter().any(|s| match s {
            Stmt::Set(g, _) | Stmt::Accum(g, _, _) => *g == f,
            Stmt::If(_, a, b) => any(a, f) || any(b, f),
            Stmt::Let(..) => false,
        })
    }
    super::live::stmts_of(e).into_iter().any(|stmts| any(stmts, f))
}

/// A scalar output that the only equation writing it, a particle equation, sets to a constant (a
/// branch settled to `0`) is that constant wherever it is read, in equations and in rates; a rate
/// that is then 0 is dropped, so that the state it integrated, written by nothing else, is folded
/// by [`fold_constant_states`]. A planar case's `ds_hoop` (solid/hoop_stress.sph) goes so, and
/// `s_hoop` with it.
fn fold_constant_outputs(model: &mut Model) {
    let constants: Vec<(FieldId, f64)> = (0..model.fields.len())
        .map(|k| FieldId(k as u32))
        .filter(|f| model.field(*f).ty.shape == ir::Shape::Scalar && model.field(*f).storage != Storage::State)
        .filter_map(|f| {
            let mut writers = model.equations.iter().filter(|e| e.writes.contains(&f));
            let (Some(writer), None) = (writers.next(), writers.next()) else { return None };
            let ir::EquationKind::Particle { body } = &writer.kind else { return None };
            let mut values = body.iter().filter_map(|s| match s {
                Stmt::Set(g, e) if *g == f => Some(host_eval::constant(e)),
                _ => None,
            });
            let (Some(Some(value)), None) = (values.next(), values.next()) else { return None };
            (!sets_nested(body, f)).then_some((f, value))
        })
        .collect();
    if constants.is_empty() {
        return;
    }
    fold_into_equations(model, &constants);
    let folded: Vec<bool> = model.rates.iter_mut().map(|r| fold_fields(&mut r.rate, &constants)).collect();
    drop_zero_rates(model, &folded);
}

/// Whether `f` is written inside an `if` of `stmts` (then its value is no one constant).
fn sets_nested(stmts: &[Stmt], f: FieldId) -> bool {
    stmts.iter().any(|s| match s {
        Stmt::If(_, a, b) => {
            let both: Vec<Stmt> = a.iter().chain(b.iter()).cloned().collect();
            both.iter().any(|s| matches!(s, Stmt::Set(g, _) | Stmt::Accum(g, _, _) if *g == f)) || sets_nested(&both, f)
        }
        _ => false,
    })
}

/// Replaces every read of a state nothing writes by its constant initial value (in a scene whose
/// materials are known: `scene.settled` not empty). An equation that changes has its reads
/// recomputed, as `settle` does.
pub fn fold_constant_states(model: &mut Model, scene: &SceneSpec) {
    if scene.settled.is_empty() {
        return;
    }
    let constants: Vec<(FieldId, f64)> = unwritten_states(model, scene)
        .into_iter()
        .filter_map(|f| {
            let value = model.field(f).init.as_ref().map_or(Some(0.0), host_eval::constant)?;
            Some((f, value))
        })
        .collect();
    fold_into_equations(model, &constants);
}

/// Every read of these fields in the equations that do not write them becomes its constant; an
/// equation that changes has its reads recomputed, as `settle` does.
fn fold_into_equations(model: &mut Model, constants: &[(FieldId, f64)]) {
    if constants.is_empty() {
        return;
    }
    for k in 0..model.equations.len() {
        if constants.iter().any(|(f, _)| model.equations[k].writes.contains(f)) {
            continue;
        }
        let mut e = model.equations[k].clone();
        let mut changed = false;
        for stmts in super::live::stmts_of_mut(&mut e) {
            for s in stmts.iter_mut() {
                changed |= fold_in_stmt(s, constants);
            }
        }
        if changed {
            model.equations[k] = super::live::pruned(&e, model, &Default::default());
        }
    }
}

/// Every read of these fields in `e` becomes its constant; whether there was one.
fn fold_fields(e: &mut Expr, constants: &[(FieldId, f64)]) -> bool {
    let mut changed = false;
    ir::walk_expr_mut(e, &mut |x| {
        if let ExprKind::Field(f, _) = x.kind {
            if let Some((_, value)) = constants.iter().find(|(c, _)| *c == f) {
                *x = Expr::constant(*value, x.ty);
                changed = true;
            }
        }
    });
    changed
}

/// The scalar states that no equation or rate writes and the scene does not set.
fn unwritten_states(model: &Model, scene: &SceneSpec) -> Vec<FieldId> {
    let written: std::collections::BTreeSet<FieldId> = model
        .equations
        .iter()
        .flat_map(|e| e.writes.iter().copied())
        .chain(model.rates.iter().map(|r| r.state))
        .chain(scene.initialised.iter().copied())
        .collect();
    (0..model.fields.len())
        .map(|k| FieldId(k as u32))
        .filter(|f| {
            let field = model.field(*f);
            field.storage == Storage::State
                && field.ty.shape == ir::Shape::Scalar
                && field.name != "v"
                && !ir::PLACED.contains(&field.name.as_str())
                && !written.contains(f)
        })
        .collect()
}

fn fold_in_stmt(s: &mut Stmt, constants: &[(FieldId, f64)]) -> bool {
    match s {
        Stmt::Let(_, e) | Stmt::Set(_, e) | Stmt::Accum(_, _, e) => fold_fields(e, constants),
        Stmt::If(c, a, b) => {
            let mut changed = fold_fields(c, constants);
            for s in a.iter_mut().chain(b.iter_mut()) {
                changed |= fold_in_stmt(s, constants);
            }
            changed
        }
    }
}

fn settle_equation(e: &mut Equation, settled: &[Option<Vec<f64>>], dim: usize) -> bool {
    let mut changed = false;
    for stmts in super::live::stmts_of_mut(e) {
        changed |= settle_stmts(stmts, settled, dim);
    }
    changed
}

fn settle_stmts(stmts: &mut Vec<Stmt>, settled: &[Option<Vec<f64>>], dim: usize) -> bool {
    let mut changed = false;
    let mut out = Vec::with_capacity(stmts.len());
    for mut s in std::mem::take(stmts) {
        match &mut s {
            Stmt::Let(_, e) | Stmt::Set(_, e) | Stmt::Accum(_, _, e) => changed |= settle_expr(e, settled, dim),
            Stmt::If(c, a, b) => {
                changed |= settle_expr(c, settled, dim);
                changed |= settle_stmts(a, settled, dim);
                changed |= settle_stmts(b, settled, dim);
                if let Some(taken) = truth(c, settled, dim) {
                    out.extend(std::mem::take(if taken { a } else { b }));
                    changed = true;
                    continue;
                }
            }
        }
        out.push(s);
    }
    *stmts = out;
    changed
}

fn settle_expr(e: &mut Expr, settled: &[Option<Vec<f64>>], dim: usize) -> bool {
    let mut changed = false;
    ir::walk_expr_mut(e, &mut |x| match &x.kind {
        ExprKind::Select(c, a, b) => {
            if let Some(taken) = truth(c, settled, dim) {
                *x = if taken { (**a).clone() } else { (**b).clone() };
                changed = true;
            }
        }
        // An inlined helper's argument that the branch taken no longer reads (post-order: the
        // body is settled first).
        ExprKind::Let(l, _, body) if changed && !reads_local(body, *l) => *x = (**body).clone(),
        _ => {}
    });
    changed
}

fn reads_local(e: &Expr, l: LocalId) -> bool {
    let mut found = false;
    ir::walk_expr(e, &mut |x| found |= matches!(x.kind, ExprKind::Local(k) if k == l));
    found
}

/// The value of a condition that reads only settled parameters, constants and `dim`.
fn truth(c: &Expr, settled: &[Option<Vec<f64>>], dim: usize) -> Option<bool> {
    let value = host_eval::eval(c, dim, &mut Settled { settled, dim }).ok()?;
    Some(value.first()? != &0.0)
}

struct Settled<'a> {
    settled: &'a [Option<Vec<f64>>],
    dim: usize,
}

impl host_eval::Leaves for Settled<'_> {
    fn field(&mut self, _: FieldId) -> Result<Vec<f64>, String> {
        Err("a field".into())
    }
    fn param(&mut self, p: ParamId) -> Result<Vec<f64>, String> {
        self.settled.get(p.index()).cloned().flatten().ok_or_else(|| "a parameter the materials differ in".into())
    }
    fn global(&mut self, g: Global) -> Result<f64, String> {
        match g {
            Global::Dim => Ok(self.dim as f64),
            Global::Time | Global::Dt => Err("the clock".into()),
        }
    }
    fn reduction(&mut self, _: Reduce, _: &Expr) -> Result<f64, String> {
        Err("a reduction".into())
    }
}
