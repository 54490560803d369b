//! Choices the case's parameters settle. Where every material with particles binds a parameter
//! to the same value, a `select` or an `if` whose condition reads only such parameters (and
//! constants, `dim`) is replaced by the branch it takes, before the dead-code analysis: what only
//! the other branch reads is then neither computed nor stored. The damage modules' nonlocal
//! driver is the case in point: with `damage_length = 0` its Laplacian sum and the nonlocal
//! strain it smooths are gone from the plan (`damage/nonlocal_strain.sph`).
//!
//! The backends fold such conditions too (the CPU lowering's known parameters, the shader
//! compiler's constants), but only inside a program; settling them here is what lets the plan
//! drop a whole pair sum and its stored fields.

use crate::host_eval;
use crate::ir::{self, Equation, Expr, ExprKind, FieldId, Global, LocalId, Model, ParamId, Reduce, Stmt};

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
            model.equations[k] = super::live::pruned(&e, model, &Default::default());
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
