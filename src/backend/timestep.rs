//! The time step from the model's `timestep` limits: every reduction over particles is computed
//! by the backend; the rest of the expression (constants, arithmetic) here, in f64.

use crate::host_eval;
use crate::ir::{Expr, ExprKind, FieldId, Global, Model, ParamId, Reduce};

/// The reductions of all timestep expressions, in order: (reduce, per-particle expression).
pub fn reductions(model: &Model, timesteps: &[usize]) -> Vec<(Reduce, Expr)> {
    let limits = timesteps.iter().map(|t| &model.timesteps[*t].value);
    limits.flat_map(reductions_in).map(|(r, e)| (r, e.clone())).collect()
}

/// The reductions of one limit, in the order the backend computes them.
fn reductions_in(e: &Expr) -> Vec<(Reduce, &Expr)> {
    let mut out = vec![];
    crate::ir::walk_expr(e, &mut |x| {
        if let ExprKind::Reduction(r, inner) = &x.kind {
            out.push((*r, &**inner));
        }
    });
    out
}

/// The least of the limits, given the reduction values (in `reductions` order).
pub fn value(model: &Model, timesteps: &[usize], values: &[f64], time: f64, dt: f64) -> f64 {
    let mut best = f64::INFINITY;
    for v in limits(model, timesteps, values, time, dt) {
        if v.is_finite() && v > 0.0 {
            best = best.min(v);
        }
    }
    best
}

/// Each limit's value and the fields it reads, for an error that names the limit that failed.
pub fn describe(model: &Model, timesteps: &[usize], values: &[f64], time: f64, dt: f64) -> String {
    let values = limits(model, timesteps, values, time, dt);
    let limits = timesteps.iter().zip(values).map(|(t, value)| {
        let limit = &model.timesteps[*t];
        let reads: Vec<String> = limit.reads.iter().map(|f| format!("`{}`", model.field(*f).name)).collect();
        format!("`{}` gives {value:e} s (it reads {})", limit.name, reads.join(", "))
    });
    limits.collect::<Vec<_>>().join("; ")
}

/// The value of each limit (NaN where the host cannot evaluate it).
fn limits(model: &Model, timesteps: &[usize], values: &[f64], time: f64, dt: f64) -> Vec<f64> {
    let mut next = 0;
    timesteps
        .iter()
        .map(|t| {
            let limit = &model.timesteps[*t].value;
            let order: Vec<&Expr> = reductions_in(limit).into_iter().map(|(_, e)| e).collect();
            let mine = values.get(next..next + order.len()).unwrap_or(&[]);
            next += order.len();
            let mut leaves = TimestepLeaves { order, values: mine, time, dt };
            host_eval::eval(limit, 1, &mut leaves).map_or(f64::NAN, |v| v[0])
        })
        .collect()
}

/// A limit's leaves: its reductions' values and the clock; fields, parameters and `dim` only
/// inside a reduction (evaluated by the backend).
struct TimestepLeaves<'a> {
    /// The limit's reductions, found by address whatever order the evaluator meets them in.
    order: Vec<&'a Expr>,
    values: &'a [f64],
    time: f64,
    dt: f64,
}

impl host_eval::Leaves for TimestepLeaves<'_> {
    fn field(&mut self, _: FieldId) -> Result<Vec<f64>, String> {
        Err("it reads a field outside a reduction".into())
    }
    fn param(&mut self, _: ParamId) -> Result<Vec<f64>, String> {
        Err("it reads a parameter outside a reduction".into())
    }
    fn global(&mut self, g: Global) -> Result<f64, String> {
        match g {
            Global::Time => Ok(self.time),
            Global::Dt => Ok(self.dt),
            Global::Dim => Err("it reads `dim` outside a reduction".into()),
        }
    }
    fn reduction(&mut self, _: Reduce, e: &Expr) -> Result<f64, String> {
        let at = self.order.iter().position(|p| std::ptr::eq(*p, e)).ok_or("it takes a reduction never collected")?;
        self.values.get(at).copied().ok_or_else(|| "a reduction without its value".into())
    }
}
