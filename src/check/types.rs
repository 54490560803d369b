//! Shape and unit rules of operators and builtins: given typed operands, the result type and the
//! IR node, or what is wrong and how to fix it.

use crate::ir::{Builtin, Expr, ExprKind, Op, Type};
use crate::syntax::ast::{BinOp, Shape};
use crate::units::{Ratio, Unit};

/// What went wrong, ready for a diagnostic.
pub struct TypeError {
    /// E0201 (units) or E0202 (shapes and the rest).
    pub code: &'static str,
    pub message: String,
    pub label: String,
    pub help: Option<String>,
}

fn err(message: impl Into<String>, label: impl Into<String>, help: Option<String>) -> TypeError {
    TypeError { code: "E0202", message: message.into(), label: label.into(), help }
}

/// An error about units.
fn unit_err(message: impl Into<String>, label: impl Into<String>, help: Option<String>) -> TypeError {
    TypeError { code: "E0201", ..err(message, label, help) }
}

pub fn is_tensor_like(s: Shape) -> bool {
    matches!(s, Shape::SymTensor | Shape::SkewTensor | Shape::Tensor)
}

pub fn is_numeric(s: Shape) -> bool {
    s != Shape::Bool
}

fn unit_overflow() -> TypeError {
    err("unit exponent out of range", "this unit cannot be represented", None)
}

/// Widens a symtensor or skewtensor to a full tensor.
pub fn to_tensor(e: Expr) -> Expr {
    if e.ty.shape == Shape::Tensor {
        return e;
    }
    let ty = Type::new(Shape::Tensor, e.ty.unit);
    let span = e.span;
    Expr { kind: ExprKind::ToTensor(Box::new(e)), ty, span }
}

/// Brings two operands to a common shape for +, −, min, max, select: equal shapes stay, mixed
/// tensor kinds widen to a full tensor.
pub fn unify_shapes(a: Expr, b: Expr, what: &str) -> Result<(Expr, Expr), TypeError> {
    let (sa, sb) = (a.ty.shape, b.ty.shape);
    if sa == sb {
        return Ok((a, b));
    }
    if is_tensor_like(sa) && is_tensor_like(sb) {
        return Ok((to_tensor(a), to_tensor(b)));
    }
    let help = if sa == Shape::Scalar || sb == Shape::Scalar {
        Some("to add a scalar to a tensor's diagonal, multiply it by the identity: `x * I`".to_string())
    } else {
        None
    };
    Err(err(
        format!("shape mismatch in {what}: {} and {}", sa.name(), sb.name()),
        format!("{} {what} {}", sa.name(), sb.name()),
        help,
    ))
}

pub fn same_unit(a: &Type, b: &Type, what: &str) -> Result<(), TypeError> {
    if a.unit == b.unit {
        return Ok(());
    }
    Err(unit_err(format!("unit mismatch in {what}: {} and {}", a.unit, b.unit), "these have different units", None))
}

fn binary(op: Op, a: Expr, b: Expr, ty: Type, span: crate::diag::Span) -> Expr {
    Expr { kind: ExprKind::Binary(op, Box::new(a), Box::new(b)), ty, span }
}

/// Types `a op b`. `a` and `b` are already typed (and free zeros already given the other side's unit).
pub fn binary_op(op: BinOp, a: Expr, b: Expr, span: crate::diag::Span) -> Result<Expr, TypeError> {
    let (ta, tb) = (a.ty, b.ty);
    match op {
        BinOp::Add | BinOp::Sub => {
            if !is_numeric(ta.shape) || !is_numeric(tb.shape) {
                return Err(err("arithmetic on a bool", "bool operand", None));
            }
            let what = if op == BinOp::Add { "a sum" } else { "a difference" };
            same_unit(&ta, &tb, what)?;
            let (a, b) = unify_shapes(a, b, op.text())?;
            let ty = a.ty;
            Ok(binary(if op == BinOp::Add { Op::Add } else { Op::Sub }, a, b, ty, span))
        }
        BinOp::Mul => {
            let unit = ta.unit.mul(&tb.unit).ok_or_else(unit_overflow)?;
            match (ta.shape, tb.shape) {
                (Shape::Bool, _) | (_, Shape::Bool) => Err(err("arithmetic on a bool", "bool operand", None)),
                (Shape::Scalar, s) => Ok(binary(Op::Scale, a, b, Type::new(s, unit), span)),
                (s, Shape::Scalar) => Ok(binary(Op::Scale, b, a, Type::new(s, unit), span)),
                (l, Shape::Vec) if is_tensor_like(l) => {
                    Ok(binary(Op::MatVec, to_tensor(a), b, Type::new(Shape::Vec, unit), span))
                }
                (l, r) if is_tensor_like(l) && is_tensor_like(r) => {
                    Ok(binary(Op::MatMul, to_tensor(a), to_tensor(b), Type::new(Shape::Tensor, unit), span))
                }
                (Shape::Vec, Shape::Vec) => Err(err(
                    "cannot multiply a vec by a vec",
                    "vec * vec",
                    Some("use `dot(a, b)` for the scalar product or `outer(a, b)` for the tensor product".into()),
                )),
                (Shape::Vec, r) => Err(err(
                    format!("cannot multiply a vec by a {} from the right", r.name()),
                    format!("vec * {}", r.name()),
                    Some("write the tensor first: `transpose(A) * v`".into()),
                )),
                (l, r) => Err(err(format!("cannot multiply {} by {}", l.name(), r.name()), "here", None)),
            }
        }
        BinOp::Div => {
            if tb.shape != Shape::Scalar {
                return Err(err(
                    format!("cannot divide by a {}", tb.shape.name()),
                    format!("divisor is a {}", tb.shape.name()),
                    (is_tensor_like(tb.shape)).then(|| "multiply by `inv(A)` to apply an inverse".to_string()),
                ));
            }
            if ta.shape == Shape::Bool {
                return Err(err("arithmetic on a bool", "bool operand", None));
            }
            let unit = ta.unit.div(&tb.unit).ok_or_else(unit_overflow)?;
            Ok(binary(Op::Div, a, b, Type::new(ta.shape, unit), span))
        }
        BinOp::Pow => power(a, b, span),
        BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge => {
            if ta.shape != Shape::Scalar || tb.shape != Shape::Scalar {
                return Err(err(
                    format!("comparison of a {} and a {}", ta.shape.name(), tb.shape.name()),
                    "only scalars can be ordered",
                    Some("compare a norm or a component, e.g. `norm(v[i]) < 1 [m/s]`".into()),
                ));
            }
            same_unit(&ta, &tb, "a comparison")?;
            let o = match op {
                BinOp::Lt => Op::Lt,
                BinOp::Le => Op::Le,
                BinOp::Gt => Op::Gt,
                _ => Op::Ge,
            };
            Ok(binary(o, a, b, Type::BOOL, span))
        }
        BinOp::Eq | BinOp::Ne => {
            let ok = (ta.shape == Shape::Scalar && tb.shape == Shape::Scalar)
                || (ta.shape == Shape::Bool && tb.shape == Shape::Bool);
            if !ok {
                return Err(err(
                    format!(
                        "`{}` compares two scalars or two bools, not {} and {}",
                        op.text(),
                        ta.shape.name(),
                        tb.shape.name()
                    ),
                    "here",
                    None,
                ));
            }
            same_unit(&ta, &tb, "a comparison")?;
            Ok(binary(if op == BinOp::Eq { Op::Eq } else { Op::Ne }, a, b, Type::BOOL, span))
        }
        BinOp::And | BinOp::Or => {
            if ta.shape != Shape::Bool || tb.shape != Shape::Bool {
                return Err(err(format!("`{}` needs two bools", op.text()), "here", None));
            }
            Ok(binary(if op == BinOp::And { Op::And } else { Op::Or }, a, b, Type::BOOL, span))
        }
    }
}

/// A constant's value, if the expression is a scalar made of literals and constants only (the
/// host's one evaluator, `host_eval::constant`).
pub fn const_value(e: &Expr) -> Option<f64> {
    crate::host_eval::constant(e)
}

fn power(a: Expr, b: Expr, span: crate::diag::Span) -> Result<Expr, TypeError> {
    if a.ty.shape != Shape::Scalar || b.ty.shape != Shape::Scalar {
        return Err(err(
            format!("`^` raises a scalar to a scalar power, not a {} to a {}", a.ty.shape.name(), b.ty.shape.name()),
            "here",
            (a.ty.shape != Shape::Scalar)
                .then(|| "for a tensor squared, write `A * A`; for a vector's length squared, `dot(v, v)`".to_string()),
        ));
    }
    if !b.ty.unit.is_one() {
        return Err(unit_err(
            format!("an exponent must be dimensionless, but this one is {}", b.ty.unit),
            format!("exponent is {}", b.ty.unit),
            None,
        ));
    }
    let unit = if a.ty.unit.is_one() {
        Unit::ONE
    } else {
        let reads_dim = {
            let mut found = false;
            crate::ir::walk_expr(&b, &mut |e| found |= matches!(e.kind, ExprKind::Global(crate::ir::Global::Dim)));
            found
        };
        if reads_dim {
            return Err(unit_err(
                format!(
                    "a quantity with units ({}) cannot be raised to a power that depends on `dim`: a model's units are checked once, for every dimension",
                    a.ty.unit
                ),
                "this exponent reads `dim`",
                Some(
                    "make the base dimensionless: a particle's volume m / rho is in m^3 in every dimension (a 1D bar has a 1 m^2 section, a 2D slab is 1 m thick), so its spacing is `dx * (m / (rho * vol))^(1/dim)`, with `dx` and `vol` where it was placed"
                        .into(),
                ),
            ));
        }
        let p = const_value(&b).and_then(Ratio::from_f64).ok_or_else(|| {
            unit_err(
                format!("a quantity with units ({}) can only be raised to a constant rational power", a.ty.unit),
                "this exponent is not a constant",
                Some("make the base dimensionless, e.g. `(rho[i] / rho0)^gamma`".into()),
            )
        })?;
        a.ty.unit.powr(p).ok_or_else(unit_overflow)?
    };
    Ok(binary(Op::Pow, a, b, Type::scalar(unit), span))
}

/// The argument types of a builtin whose arguments have one type each, where free literals
/// (`0`, `inf`) take it.
pub fn fixed_arguments(f: Builtin) -> Option<Vec<Type>> {
    let m = |shape| Type::new(shape, Unit::M);
    match f {
        Builtin::KernelAt => Some(vec![m(Shape::Scalar), m(Shape::Scalar)]),
        Builtin::KernelGradAt => Some(vec![m(Shape::Vec), m(Shape::Scalar)]),
        _ => None,
    }
}

/// Types a builtin call. `args` are typed; arity was checked by the caller.
pub fn builtin(f: Builtin, mut args: Vec<Expr>, span: crate::diag::Span) -> Result<Expr, TypeError> {
    let shapes: Vec<Shape> = args.iter().map(|a| a.ty.shape).collect();
    let units: Vec<Unit> = args.iter().map(|a| a.ty.unit).collect();
    let bad = |expected: &str, help: Option<String>| {
        let found: Vec<&str> = shapes.iter().map(|s| s.name()).collect();
        err(
            format!("`{}` takes {expected}, found ({})", f.name(), found.join(", ")),
            format!("{}({})", f.name(), found.join(", ")),
            help,
        )
    };
    let call = |args: Vec<Expr>, ty: Type| Expr { kind: ExprKind::Call(f, args), ty, span };
    let dimensionless = |what: &str| -> Result<(), TypeError> {
        if units[0].is_one() {
            Ok(())
        } else {
            Err(unit_err(
                format!("`{}` needs a dimensionless argument, found {}", f.name(), units[0]),
                format!("argument is {}", units[0]),
                Some(format!("divide by a reference {what} to make it dimensionless")),
            ))
        }
    };
    match f {
        Builtin::Dot => {
            if shapes != [Shape::Vec, Shape::Vec] {
                let help = if is_tensor_like(shapes[0]) && shapes[1] == Shape::Vec {
                    Some("for a tensor times a vector, write `A * v`".to_string())
                } else if is_tensor_like(shapes[0]) && is_tensor_like(shapes[1]) {
                    Some("for the double contraction A:B, write `ddot(A, B)`".to_string())
                } else {
                    None
                };
                return Err(bad("two vecs", help));
            }
            let u = units[0].mul(&units[1]).ok_or_else(unit_overflow)?;
            Ok(call(args, Type::scalar(u)))
        }
        Builtin::Outer => {
            if shapes != [Shape::Vec, Shape::Vec] {
                return Err(bad("two vecs", None));
            }
            let u = units[0].mul(&units[1]).ok_or_else(unit_overflow)?;
            Ok(call(args, Type::new(Shape::Tensor, u)))
        }
        Builtin::DDot => {
            if !is_tensor_like(shapes[0]) || !is_tensor_like(shapes[1]) {
                return Err(bad("two tensors", Some("for two vectors, use `dot(a, b)`".into())));
            }
            let u = units[0].mul(&units[1]).ok_or_else(unit_overflow)?;
            let b = to_tensor(args.pop().expect("two args"));
            let a = to_tensor(args.pop().expect("two args"));
            Ok(call(vec![a, b], Type::scalar(u)))
        }
        Builtin::Sym | Builtin::Skew => {
            if !is_tensor_like(shapes[0]) {
                return Err(bad("a tensor", None));
            }
            let shape = if f == Builtin::Sym { Shape::SymTensor } else { Shape::SkewTensor };
            let a = to_tensor(args.pop().expect("one arg"));
            Ok(call(vec![a], Type::new(shape, units[0])))
        }
        Builtin::Dev | Builtin::Transpose => {
            if !is_tensor_like(shapes[0]) {
                return Err(bad("a tensor", None));
            }
            let ty = args[0].ty;
            Ok(call(args, ty))
        }
        Builtin::Trace => {
            if !is_tensor_like(shapes[0]) {
                return Err(bad("a tensor", None));
            }
            Ok(call(args, Type::scalar(units[0])))
        }
        Builtin::Norm => {
            if !is_numeric(shapes[0]) {
                return Err(bad("a vec or a tensor", None));
            }
            Ok(call(args, Type::scalar(units[0])))
        }
        Builtin::Inv => {
            if !matches!(shapes[0], Shape::SymTensor | Shape::Tensor) {
                return Err(bad("a symtensor or tensor", None));
            }
            let u = Unit::ONE.div(&units[0]).ok_or_else(unit_overflow)?;
            Ok(call(args, Type::new(shapes[0], u)))
        }
        Builtin::Det => {
            if !is_tensor_like(shapes[0]) {
                return Err(bad("a tensor", None));
            }
            if !units[0].is_one() {
                return Err(unit_err(
                    format!("`det` of a tensor with units ({}) depends on the dimension", units[0]),
                    format!("tensor is {}", units[0]),
                    Some("take the determinant of a dimensionless tensor".into()),
                ));
            }
            let a = to_tensor(args.pop().expect("one arg"));
            Ok(call(vec![a], Type::scalar(Unit::ONE)))
        }
        Builtin::Sqrt => {
            if shapes[0] != Shape::Scalar {
                return Err(bad("a scalar", None));
            }
            let u = units[0].powr(Ratio { num: 1, den: 2 }).ok_or_else(unit_overflow)?;
            Ok(call(args, Type::scalar(u)))
        }
        Builtin::Exp | Builtin::Ln | Builtin::Elementary(_) => {
            if shapes[0] != Shape::Scalar {
                return Err(bad("a scalar", None));
            }
            dimensionless("value")?;
            Ok(call(args, Type::scalar(Unit::ONE)))
        }
        Builtin::Abs => {
            if !is_numeric(shapes[0]) {
                return Err(bad("a number", None));
            }
            let ty = args[0].ty;
            Ok(call(args, ty))
        }
        Builtin::Min | Builtin::Max => {
            let mut it = args.into_iter();
            let mut acc = it.next().expect("at least two args");
            for b in it {
                if !is_numeric(acc.ty.shape) || !is_numeric(b.ty.shape) {
                    return Err(bad("numbers", None));
                }
                same_unit(&acc.ty, &b.ty, &format!("`{}`", f.name()))?;
                let (a2, b2) = unify_shapes(acc, b, f.name())?;
                let ty = a2.ty;
                acc = call(vec![a2, b2], ty);
            }
            Ok(acc)
        }
        Builtin::Diag => {
            if shapes[0] != Shape::Vec {
                return Err(bad("a vec", None));
            }
            Ok(call(args, Type::new(Shape::SymTensor, units[0])))
        }
        Builtin::KernelAt => {
            let m = Unit::M;
            if shapes != [Shape::Scalar, Shape::Scalar] || units[0] != m || units[1] != m {
                return Err(unit_err(
                    format!(
                        "`W_at(r, h)` takes a distance and a smoothing length in m, found ({} [{}], {} [{}])",
                        shapes[0].name(),
                        units[0],
                        shapes[1].name(),
                        units[1]
                    ),
                    "here",
                    None,
                ));
            }
            let u = Unit::ONE.div(&m.powr(Ratio::int(3)).ok_or_else(unit_overflow)?).ok_or_else(unit_overflow)?;
            Ok(call(args, Type::scalar(u)))
        }
        Builtin::KernelGradAt => {
            let m = Unit::M;
            if shapes != [Shape::Vec, Shape::Scalar] || units[0] != m || units[1] != m {
                return Err(unit_err(
                    format!(
                        "`gradW_at(r, h)` takes a separation vec and a smoothing length in m, found ({} [{}], {} [{}])",
                        shapes[0].name(),
                        units[0],
                        shapes[1].name(),
                        units[1]
                    ),
                    "here",
                    None,
                ));
            }
            let u = Unit::ONE.div(&m.powr(Ratio::int(4)).ok_or_else(unit_overflow)?).ok_or_else(unit_overflow)?;
            Ok(call(args, Type::new(Shape::Vec, u)))
        }
        Builtin::Vector => {
            if args.len() > 3 || shapes.iter().any(|s| *s != Shape::Scalar) {
                return Err(bad("two or three scalars", None));
            }
            for u in &units[1..] {
                if *u != units[0] {
                    return Err(unit_err(
                        format!("the components of a `vec` have one unit, found [{}] and [{}]", units[0], u),
                        "here",
                        None,
                    ));
                }
            }
            let u = units[0];
            Ok(call(args, Type::new(Shape::Vec, u)))
        }
    }
}

/// Builtins by name, with their arity (None: two or more).
pub fn builtin_by_name(name: &str) -> Option<(Builtin, Option<usize>)> {
    Builtin::by_name(name)
}

/// Every callable name the language knows besides user helpers and builtins (for suggestions).
pub const CALLABLE: [&str; 6] = ["pow", "select", "avg", "min_over", "max_over", "sum_over"];

/// Every callable name the language knows besides user helpers (for suggestions).
pub fn callable() -> impl Iterator<Item = &'static str> {
    Builtin::names().chain(CALLABLE)
}
