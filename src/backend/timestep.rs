//! The time step from the model's `timestep` limits: every reduction over particles is computed
//! by the backend; the rest of the expression (constants, arithmetic) here, in f64.

use crate::ir::{Builtin, Expr, ExprKind, Global, Model, Op, Reduce};

/// The reductions of all timestep expressions, in order: (reduce, per-particle expression).
pub fn reductions(model: &Model, timesteps: &[usize]) -> Vec<(Reduce, Expr)> {
    let mut out = vec![];
    for t in timesteps {
        collect(&model.timesteps[*t].value, &mut out);
    }
    out
}

fn collect(e: &Expr, out: &mut Vec<(Reduce, Expr)>) {
    crate::ir::walk_expr(e, &mut |x| {
        if let ExprKind::Reduction(r, inner) = &x.kind {
            out.push((*r, (**inner).clone()));
        }
    });
}

/// The least of the limits, given the reduction values (in `reductions` order).
pub fn value(model: &Model, timesteps: &[usize], values: &[f64], time: f64, dt: f64) -> f64 {
    let mut next = 0;
    let mut best = f64::INFINITY;
    for t in timesteps {
        let v = eval(&model.timesteps[*t].value, values, &mut next, time, dt);
        if v.is_finite() && v > 0.0 {
            best = best.min(v);
        }
    }
    best
}

/// Each limit's value and the fields it reads, for an error that names the limit that failed.
pub fn describe(model: &Model, timesteps: &[usize], values: &[f64], time: f64, dt: f64) -> String {
    let mut next = 0;
    let limits = timesteps.iter().map(|t| {
        let limit = &model.timesteps[*t];
        let value = eval(&limit.value, values, &mut next, time, dt);
        let reads: Vec<String> = limit.reads.iter().map(|f| format!("`{}`", model.field(*f).name)).collect();
        format!("`{}` gives {value:e} s (it reads {})", limit.name, reads.join(", "))
    });
    limits.collect::<Vec<_>>().join("; ")
}

fn eval(e: &Expr, values: &[f64], next: &mut usize, time: f64, dt: f64) -> f64 {
    let mut go = |x: &Expr| eval(x, values, next, time, dt);
    match &e.kind {
        ExprKind::Const(v) => *v,
        ExprKind::Reduction(..) => {
            let v = values.get(*next).copied().unwrap_or(f64::NAN);
            *next += 1;
            v
        }
        ExprKind::Global(Global::Time) => time,
        ExprKind::Global(Global::Dt) => dt,
        ExprKind::Unary(Op::Neg, a) => -go(a),
        ExprKind::Binary(op, a, b) => {
            let (x, y) = (go(a), go(b));
            match op {
                Op::Add => x + y,
                Op::Sub => x - y,
                Op::Scale => x * y,
                Op::Div => x / y,
                Op::Pow => x.powf(y),
                _ => f64::NAN,
            }
        }
        ExprKind::Call(f, args) => {
            let a: Vec<f64> = args.iter().map(&mut go).collect();
            match f {
                Builtin::Sqrt => a[0].sqrt(),
                Builtin::Min => a.iter().copied().fold(f64::INFINITY, f64::min),
                Builtin::Max => a.iter().copied().fold(f64::NEG_INFINITY, f64::max),
                Builtin::Abs => a[0].abs(),
                Builtin::Exp => a[0].exp(),
                Builtin::Ln => a[0].ln(),
                Builtin::Sin => a[0].sin(),
                Builtin::Cos => a[0].cos(),
                Builtin::Acos => a[0].acos(),
                _ => f64::NAN,
            }
        }
        ExprKind::Let(_, _, body) => go(body),
        _ => f64::NAN,
    }
}
