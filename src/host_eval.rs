//! The one evaluator of IR expressions on the host, in f64: parameter defaults and initial values
//! (`engine::setup`) and the arithmetic of the time-step limits around their reductions
//! (`backend::timestep`). A value is the stored components of its shape (`ir::components`); what
//! a leaf is (a field of one particle, a parameter, a reduction's value) the caller says through
//! [`Leaves`]. Tensor products, inverses and kernels are not evaluated here: an expression that
//! needs them is an error that names them.

use crate::ir::{self, Builtin, Expr, ExprKind, FieldId, Global, LocalId, Op, ParamId, Reduce, Shape};

/// What the leaves of an expression are worth; each answers `Err` with a clause that says what
/// it cannot give ("it reads `rho`, which the scene does not set").
pub trait Leaves {
    fn field(&mut self, f: FieldId) -> Result<Vec<f64>, String>;
    fn param(&mut self, p: ParamId) -> Result<Vec<f64>, String>;
    /// `t`, `dt` or `dim`.
    fn global(&mut self, g: Global) -> Result<f64, String>;
    fn reduction(&mut self, r: Reduce, e: &Expr) -> Result<f64, String>;
}

/// The value of `e`, or a clause that says what in it the host cannot evaluate.
pub fn eval(e: &Expr, dim: usize, leaves: &mut dyn Leaves) -> Result<Vec<f64>, String> {
    Evaluator { dim, leaves, locals: vec![], every_branch: false, scalars_only: false }.value(e)
}

/// Whether `e` can be evaluated here, before any value is known: every branch of every `select`,
/// `&&` and `||` is taken, and `leaves` answer with stand-ins (zeros) or with what they cannot
/// give. `Err` is the clause `eval` would give for the first thing it cannot evaluate.
pub fn check(e: &Expr, dim: usize, leaves: &mut dyn Leaves) -> Result<(), String> {
    Evaluator { dim, leaves, locals: vec![], every_branch: true, scalars_only: false }.value(e).map(|_| ())
}

/// The value of a scalar `e` made of literals and constants only (no field, parameter, global or
/// reduction, and nothing whose value depends on the dimension): the checker's constant folding.
pub fn constant(e: &Expr) -> Option<f64> {
    struct Nothing;
    impl Leaves for Nothing {
        fn field(&mut self, _: FieldId) -> Result<Vec<f64>, String> {
            Err("it reads a field".into())
        }
        fn param(&mut self, _: ParamId) -> Result<Vec<f64>, String> {
            Err("it reads a parameter".into())
        }
        fn global(&mut self, _: Global) -> Result<f64, String> {
            Err("it reads a global".into())
        }
        fn reduction(&mut self, _: Reduce, _: &Expr) -> Result<f64, String> {
            Err("it reduces".into())
        }
    }
    let mut evaluator =
        Evaluator { dim: 0, leaves: &mut Nothing, locals: vec![], every_branch: false, scalars_only: true };
    evaluator.value(e).ok().map(|v| v[0])
}

/// What the host evaluates, for the errors of what it does not.
const BEYOND: &str = "which is not evaluated before the run (initial values, parameter defaults and time-step \
                      limits take arithmetic, comparisons, `select`, components and scalar functions)";

struct Evaluator<'a> {
    dim: usize,
    leaves: &'a mut dyn Leaves,
    locals: Vec<(LocalId, Vec<f64>)>,
    /// Evaluate both sides of every choice (`check`).
    every_branch: bool,
    /// Refuse every value that is not a scalar (`constant`, which knows no dimension).
    scalars_only: bool,
}

fn truth(b: bool) -> Vec<f64> {
    vec![if b { 1.0 } else { 0.0 }]
}

impl Evaluator<'_> {
    fn value(&mut self, e: &Expr) -> Result<Vec<f64>, String> {
        if self.scalars_only && !matches!(e.ty.shape, Shape::Scalar | Shape::Bool) {
            return Err("its value depends on the dimension".into());
        }
        let n = ir::components(e.ty.shape, self.dim);
        Ok(match &e.kind {
            ExprKind::Const(v) => vec![*v; n],
            ExprKind::Field(f, _) => self.leaves.field(*f)?,
            ExprKind::Param(p, _) => self.leaves.param(*p)?,
            ExprKind::Global(g) => vec![self.leaves.global(*g)?],
            ExprKind::Reduction(r, inner) => vec![self.leaves.reduction(*r, inner)?],
            ExprKind::Local(l) => {
                self.locals.iter().rev().find(|(k, _)| k == l).ok_or("it reads a local it never bound")?.1.clone()
            }
            ExprKind::Let(l, value, body) => {
                let v = self.value(value)?;
                self.locals.push((*l, v));
                let out = self.value(body);
                self.locals.pop();
                out?
            }
            ExprKind::Identity => ir::component_indices(e.ty.shape, self.dim)
                .iter()
                .map(|(a, b)| if a == b { 1.0 } else { 0.0 })
                .collect(),
            ExprKind::Component(a, r, c) => self.component(a, *r as usize, *c as usize)?,
            ExprKind::Unary(Op::Neg, a) => self.value(a)?.iter().map(|x| -x).collect(),
            ExprKind::Unary(Op::Not, a) => truth(self.value(a)?[0] == 0.0),
            ExprKind::Binary(op, a, b) => self.binary(*op, a, b)?,
            ExprKind::Select(c, a, b) if self.every_branch => {
                self.value(c)?;
                self.value(b)?;
                self.value(a)?
            }
            ExprKind::Select(c, a, b) => {
                if self.value(c)?[0] != 0.0 {
                    self.value(a)?
                } else {
                    self.value(b)?
                }
            }
            ExprKind::Call(f, args) => self.call(*f, args)?,
            ExprKind::ToTensor(a) => self.widened(a)?,
            ExprKind::Pair(_) | ExprKind::InGroup(..) => return Err("it reads a neighbour".into()),
            ExprKind::Unary(..) => return Err(format!("it takes an operator, {BEYOND}")),
        })
    }

    /// A symmetric or skew tensor's stored components spread over a full tensor's.
    fn widened(&mut self, a: &Expr) -> Result<Vec<f64>, String> {
        let v = self.value(a)?;
        let stored = ir::component_indices(a.ty.shape, self.dim);
        let at = |r: usize, c: usize| stored.iter().position(|&rc| rc == (r, c)).map(|k| v[k]);
        let full = ir::component_indices(Shape::Tensor, self.dim).into_iter().map(|(r, c)| match a.ty.shape {
            Shape::SymTensor => at(r.min(c), r.max(c)).unwrap_or(0.0),
            Shape::SkewTensor if r < c => at(r, c).unwrap_or(0.0),
            Shape::SkewTensor if r > c => -at(c, r).unwrap_or(0.0),
            Shape::SkewTensor => 0.0,
            _ => v.get(r * self.dim + c).copied().unwrap_or(0.0),
        });
        Ok(full.collect())
    }

    fn component(&mut self, a: &Expr, r: usize, c: usize) -> Result<Vec<f64>, String> {
        let v = self.value(a)?;
        let (r, c) = if a.ty.shape == Shape::SymTensor && r > c { (c, r) } else { (r, c) };
        let at = ir::component_indices(a.ty.shape, self.dim).iter().position(|&rc| rc == (r, c));
        Ok(vec![*at
            .and_then(|k| v.get(k))
            .ok_or_else(|| format!("it takes a component of a skew tensor, {BEYOND}"))?])
    }

    fn binary(&mut self, op: Op, a: &Expr, b: &Expr) -> Result<Vec<f64>, String> {
        // `&&` and `||` look at their right side only when they must, as the backends do.
        match op {
            Op::And | Op::Or if self.every_branch => {
                self.value(a)?;
                self.value(b)?;
                return Ok(truth(false));
            }
            Op::And => return Ok(truth(self.value(a)?[0] != 0.0 && self.value(b)?[0] != 0.0)),
            Op::Or => return Ok(truth(self.value(a)?[0] != 0.0 || self.value(b)?[0] != 0.0)),
            _ => {}
        }
        let (x, y) = (self.value(a)?, self.value(b)?);
        let elementwise = |f: fn(f64, f64) -> f64| x.iter().zip(&y).map(|(p, q)| f(*p, *q)).collect();
        Ok(match op {
            Op::Add => elementwise(|p, q| p + q),
            Op::Sub => elementwise(|p, q| p - q),
            Op::Scale => y.iter().map(|q| x[0] * q).collect(),
            Op::Div => x.iter().map(|p| p / y[0]).collect(),
            Op::Pow => vec![x[0].powf(y[0])],
            Op::Lt => truth(x[0] < y[0]),
            Op::Le => truth(x[0] <= y[0]),
            Op::Gt => truth(x[0] > y[0]),
            Op::Ge => truth(x[0] >= y[0]),
            Op::Eq => truth(x == y),
            Op::Ne => truth(x != y),
            _ => return Err(format!("it multiplies tensors, {BEYOND}")),
        })
    }

    fn call(&mut self, f: Builtin, args: &[Expr]) -> Result<Vec<f64>, String> {
        let a: Vec<Vec<f64>> = args.iter().map(|x| self.value(x)).collect::<Result<_, _>>()?;
        let scalar = |g: fn(f64) -> f64| vec![g(a[0][0])];
        // A symtensor or skewtensor stores each off-diagonal pair once; a vec and a full tensor store
        // every component.
        let weights = |e: &Expr| -> Vec<f64> {
            let halved = matches!(e.ty.shape, Shape::SymTensor | Shape::SkewTensor);
            let indices = ir::component_indices(e.ty.shape, self.dim);
            indices.iter().map(|(r, c)| if halved && r != c { 2.0 } else { 1.0 }).collect()
        };
        Ok(match f {
            Builtin::Sqrt => scalar(f64::sqrt),
            Builtin::Exp => scalar(f64::exp),
            Builtin::Ln => scalar(f64::ln),
            Builtin::Elementary(e) => scalar(e.row().f64),
            Builtin::Abs => a[0].iter().map(|x| x.abs()).collect(),
            Builtin::Min => a[1..].iter().fold(a[0].clone(), |m, x| m.iter().zip(x).map(|(p, q)| p.min(*q)).collect()),
            Builtin::Max => a[1..].iter().fold(a[0].clone(), |m, x| m.iter().zip(x).map(|(p, q)| p.max(*q)).collect()),
            Builtin::Dot => vec![a[0].iter().zip(&a[1]).map(|(x, y)| x * y).sum()],
            // A vec's length; a tensor's Frobenius norm over all its components.
            Builtin::Norm => vec![a[0].iter().zip(weights(&args[0])).map(|(x, w)| w * x * x).sum::<f64>().sqrt()],
            Builtin::Trace => {
                let diagonal = ir::component_indices(args[0].ty.shape, self.dim);
                vec![a[0].iter().zip(diagonal).filter(|(_, (r, c))| r == c).map(|(x, _)| x).sum()]
            }
            Builtin::Vector => (0..self.dim).map(|k| a.get(k).map_or(0.0, |c| c[0])).collect(),
            _ => return Err(format!("it calls `{}`, {BEYOND}", f.name())),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::{constant, eval, Leaves};
    use crate::ir::{Builtin, Expr, ExprKind, FieldId, Global, ParamId, Reduce, Shape, Side, Type};
    use crate::units::Unit;

    #[test]
    fn a_constant_folds_its_arithmetic_and_functions_and_refuses_a_global_or_a_vec() {
        let one = Type::scalar(Unit::ONE);
        let c = |v: f64| Expr::constant(v, one);
        let call =
            |name: &str, args: Vec<Expr>| Expr::new(ExprKind::Call(Builtin::by_name(name).expect(name).0, args), one);
        let e = call("sqrt", vec![c(2.0)]).scaled_by(c(3.0)).minus(call("acos", vec![c(0.5)]));
        assert_eq!(constant(&e), Some(2f64.sqrt() * 3.0 - 0.5f64.acos()));
        assert_eq!(constant(&call("min", vec![c(2.0), c(-1.0)])), Some(-1.0));
        let dim = Expr::new(ExprKind::Global(Global::Dim), one);
        assert_eq!(constant(&c(1.0).plus(dim)), None, "the dimension is no constant of the checker's");
        let v = call("vec", vec![c(1.0), c(2.0)]);
        let v = Expr { ty: Type::new(Shape::Vec, Unit::ONE), ..v };
        assert_eq!(constant(&call("norm", vec![v])), None, "a vec's length depends on the dimension");
    }

    /// `norm` of a field of each shape, in 2D and 3D, with the stored components 1, 2, 3, …: the
    /// length, or the Frobenius norm, of the whole vec or tensor those components stand for.
    #[test]
    fn norm_is_the_length_of_a_vec_and_the_frobenius_norm_of_each_kind_of_tensor() {
        struct Counting(usize);
        impl Leaves for Counting {
            fn field(&mut self, _: FieldId) -> Result<Vec<f64>, String> {
                Ok((1..=self.0).map(|k| k as f64).collect())
            }
            fn param(&mut self, _: ParamId) -> Result<Vec<f64>, String> {
                Err("no parameter".into())
            }
            fn global(&mut self, _: Global) -> Result<f64, String> {
                Err("no global".into())
            }
            fn reduction(&mut self, _: Reduce, _: &Expr) -> Result<f64, String> {
                Err("no reduction".into())
            }
        }
        for dim in [2, 3] {
            for shape in [Shape::Vec, Shape::SymTensor, Shape::SkewTensor, Shape::Tensor] {
                let ty = Type::new(shape, Unit::ONE);
                let field = Expr::new(ExprKind::Field(FieldId(0), Side::I), ty);
                let norm = Expr::new(ExprKind::Call(Builtin::Norm, vec![field]), Type::scalar(Unit::ONE));
                let n = crate::ir::components(shape, dim);
                let got = eval(&norm, dim, &mut Counting(n)).unwrap()[0];
                // The whole matrix (a vec as its one column), entry by entry from the stored ones.
                let mut squares = 0.0;
                for (k, (r, c)) in crate::ir::component_indices(shape, dim).into_iter().enumerate() {
                    let stored = (k + 1) as f64;
                    let mirrored = matches!(shape, Shape::SymTensor | Shape::SkewTensor) && r != c;
                    squares += stored * stored * if mirrored { 2.0 } else { 1.0 };
                }
                assert_eq!(got, squares.sqrt(), "norm of a {shape:?} in {dim}D");
                if shape == Shape::Vec {
                    let length = (1..=dim).map(|k| (k * k) as f64).sum::<f64>().sqrt();
                    assert_eq!(got, length, "the length of a vec in {dim}D");
                }
            }
        }
    }
}
