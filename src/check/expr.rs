//! Checking expressions: names, sides (i/j), shapes and units, helper inlining.

use super::types::{self, builtin_by_name, TypeError};
use super::Checker;
use crate::diag::{closest, Diagnostic, Span};
use crate::ir::{Builtin, Expr, ExprKind, FieldId, Global, LocalId, Op, PairValue, Reduce, Type};
use crate::syntax::ast::{self, BinOp, ExprKind as A, Shape, Side, UnOp};
use crate::units::{Ratio, Unit};

/// Where an expression stands, which decides what it may read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Where {
    /// Constants: literals and other constants only.
    Const,
    /// A parameter's default: constants and the same material's other parameters.
    Material,
    /// A kernel's `w(R)` and `dw(R)`.
    Kernel,
    /// One particle i: particle equations, `init`/`finally` of pair sums, rates, initial values.
    Particle,
    /// The neighbour loop of a pair sum: i and j.
    Loop,
    /// A timestep: reductions over particles, constants.
    Global,
}

pub struct Cx {
    pub at: Where,
    /// What is being checked, for messages ("pairsum `continuity`").
    pub what: String,
    /// This equation's outputs: readable as their current value outside the loop.
    pub outputs: Vec<FieldId>,
    /// Accumulators being summed: not readable inside the loop.
    pub summing: Vec<FieldId>,
    pub kernel_arg: Option<LocalId>,
}

impl Cx {
    pub fn new(at: Where, what: impl Into<String>) -> Cx {
        Cx { at, what: what.into(), outputs: vec![], summing: vec![], kernel_arg: None }
    }
    pub fn constant(what: &str) -> Cx {
        Cx::new(Where::Const, what)
    }
    pub fn particle(what: &str) -> Cx {
        Cx::new(Where::Particle, what)
    }
    fn with_at(&self, at: Where) -> Cx {
        Cx {
            at,
            what: self.what.clone(),
            outputs: self.outputs.clone(),
            summing: self.summing.clone(),
            kernel_arg: self.kernel_arg,
        }
    }
}

/// How a type error names two operands of an operator, and two arguments of a call.
const OPERANDS: [&str; 2] = ["left", "right"];
const ARGUMENTS: [&str; 2] = ["first argument", "second argument"];

const PAIR_NAMES: [&str; 6] = ["x_ij", "r_ij", "v_ij", "h_ij", "W_ij", "gradW_ij"];

/// A literal `0` or `inf` (without a unit) fits any unit, and `0` any shape.
pub fn is_free(e: &ast::Expr) -> bool {
    match &e.kind {
        A::Number(v, None) => *v == 0.0,
        A::Name(n) => n.name == "inf",
        A::Unary(UnOp::Neg, a) => is_free(a),
        _ => false,
    }
}

fn fit_free(e: &mut Expr, src: &ast::Expr, to: &Type) {
    if is_free(src) && e.ty.shape == Shape::Scalar {
        e.ty.unit = to.unit;
        if matches!(e.kind, ExprKind::Const(v) if v == 0.0) && to.shape != Shape::Bool {
            e.ty.shape = to.shape;
        }
    }
}

/// The deepest an expression may nest in the checker and in the IR it builds (the parser's limit
/// on the text is [`crate::syntax::MAX_DEPTH`]): every later stage recurses over it.
pub const MAX_DEPTH: usize = 256;

/// The most expressions the checker checks in one model, inlined helpers counted each time:
/// helpers that call another twice double at each level. The stdlib's largest model takes
/// about 2,000.
pub const MAX_WORK: usize = 250_000;

/// How deep an expression nests (a leaf is 1), without recursion.
pub fn ir_depth(e: &Expr) -> usize {
    let mut deepest = 0;
    let mut stack = vec![(e, 1usize)];
    while let Some((e, d)) = stack.pop() {
        deepest = deepest.max(d);
        match &e.kind {
            ExprKind::Unary(_, a)
            | ExprKind::ToTensor(a)
            | ExprKind::Component(a, _, _)
            | ExprKind::Reduction(_, a) => stack.push((a, d + 1)),
            ExprKind::Binary(_, a, b) | ExprKind::Let(_, a, b) => {
                stack.push((a, d + 1));
                stack.push((b, d + 1));
            }
            ExprKind::Select(a, b, c) => {
                stack.extend([(&**a, d + 1), (&**b, d + 1), (&**c, d + 1)]);
            }
            ExprKind::Call(_, args) => stack.extend(args.iter().map(|a| (a, d + 1))),
            ExprKind::Const(_)
            | ExprKind::Field(..)
            | ExprKind::Param(..)
            | ExprKind::Local(_)
            | ExprKind::Pair(_)
            | ExprKind::Global(_)
            | ExprKind::Identity
            | ExprKind::InGroup(..) => {}
        }
    }
    deepest
}

fn mk(kind: ExprKind, ty: Type, span: Span) -> Expr {
    Expr { kind, ty, span }
}

impl Checker {
    /// Reports a type error; where two operands' units differ, labels each with its unit, named
    /// after `sides` (`left`/`right` of an operator, the arguments of a call).
    fn type_error(&mut self, e: TypeError, span: Span, operands: &[&Expr], sides: [&str; 2]) {
        let code = e.code;
        let mut d = Diagnostic::error(code, e.message).at(span, e.label);
        if code == "E0201" && operands.len() == 2 && operands[0].ty.unit != operands[1].ty.unit {
            for (o, side) in operands.iter().zip(sides) {
                d = d.also(o.span, format!("{side}: {}", o.ty.unit));
            }
        }
        if let Some(h) = e.help {
            d = d.help(h);
        }
        self.error(d);
    }

    /// Checks an expression and makes it fit `ty` (shape and unit), explaining any mismatch.
    pub(crate) fn expr_as(&mut self, e: &ast::Expr, cx: &Cx, ty: Type, what: &str) -> Option<Expr> {
        let mut x = self.expr(e, cx)?;
        fit_free(&mut x, e, &ty);
        if x.ty.shape != ty.shape {
            let widen = ty.shape == Shape::Tensor && types::is_tensor_like(x.ty.shape);
            if !widen {
                let mut d = Diagnostic::error(
                    "E0202",
                    format!("shape mismatch: {what} must be a {}, found a {}", ty.shape.name(), x.ty.shape.name()),
                )
                .at(e.span, format!("this is a {}", x.ty.shape.name()));
                if ty.shape == Shape::SymTensor && x.ty.shape == Shape::Tensor {
                    d = d.help("take the symmetric part with `sym(...)`");
                } else if ty.shape == Shape::Scalar && x.ty.shape == Shape::Vec {
                    d = d.help("a vec's length is `norm(v)`; its components are `v.x`, `v.y`, `v.z`");
                }
                self.error(d);
                return None;
            }
            x = types::to_tensor(x);
        }
        if x.ty.unit != ty.unit && ty.shape != Shape::Bool {
            let mut d = Diagnostic::error(
                "E0201",
                format!("unit mismatch: {what} must be in {}, found {}", ty.unit, x.ty.unit),
            )
            .at(e.span, format!("this is {}", x.ty.unit))
            .note(format!("expected {}", ty.unit));
            if let Some(r) = x.ty.unit.div(&ty.unit) {
                d = d.note(format!("found / expected = {r}"));
            }
            self.error(d);
            return None;
        }
        Some(x)
    }

    /// Checks an expression. The checker recurses through the expression, the helpers it inlines
    /// and the constants it reads, so it counts its own depth (E0217 beyond [`MAX_DEPTH`]), the
    /// depth of what it builds (inlined helpers wrap their bodies in `let`s; E0217 beyond
    /// [`MAX_DEPTH`] at the outermost call) and its work on the whole model (E0217 beyond
    /// [`MAX_WORK`]: helpers that call others twice double at each level when inlined).
    pub(crate) fn expr(&mut self, e: &ast::Expr, cx: &Cx) -> Option<Expr> {
        if self.depth >= MAX_DEPTH || self.work >= MAX_WORK {
            self.too_deep(e.span);
            return None;
        }
        self.depth += 1;
        self.work += 1;
        let out = self.expr_inner(e, cx);
        self.depth -= 1;
        if self.depth == 0 {
            let out = out?;
            let deepest = ir_depth(&out);
            if deepest > MAX_DEPTH {
                let d = Diagnostic::error(
                    "E0217",
                    format!(
                        "with its helpers inlined, this expression nests {deepest} levels deep, more than {MAX_DEPTH}"
                    ),
                )
                .at(e.span, "too deep")
                .help("split it with `let` values in the equation, or use fewer nested helpers");
                self.error(d);
                return None;
            }
            return Some(out);
        }
        out
    }

    /// E0217, once per model, where the checker's recursion or work went past its bound.
    fn too_deep(&mut self, span: Span) {
        if self.too_deep_reported {
            return;
        }
        self.too_deep_reported = true;
        let msg = if self.work >= MAX_WORK {
            format!(
                "the model is too large to check: with its helpers inlined, its expressions exceed {MAX_WORK} nodes"
            )
        } else {
            format!(
                "nested too deeply: with the helpers and constants it uses, this expression nests more than {MAX_DEPTH} levels"
            )
        };
        let d = Diagnostic::error("E0217", msg)
            .at(span, "here")
            .help("split it with `let` values in the equation, or use fewer nested helpers and constants");
        self.error(d);
    }

    fn expr_inner(&mut self, e: &ast::Expr, cx: &Cx) -> Option<Expr> {
        let span = e.span;
        match &e.kind {
            A::Number(v, unit) => {
                let u = match unit {
                    Some(u) => self.unit(u)?,
                    None => Unit::ONE,
                };
                Some(mk(ExprKind::Const(*v), Type::scalar(u), span))
            }
            A::Bool(b) => Some(mk(ExprKind::Const(f64::from(u8::from(*b))), Type::BOOL, span)),
            A::Name(n) => self.name(n, cx),
            A::Index(base, side, side_span) => self.index(base, *side, *side_span, span, cx),
            A::Member(base, m) => self.member(base, m, span, cx),
            A::Call(f, args) => self.call(f, args, span, cx),
            A::InGroup(side, groups) => {
                if *side == Side::J && cx.at != Where::Loop {
                    self.not_here_j(span, cx);
                    return None;
                }
                if matches!(cx.at, Where::Const | Where::Material | Where::Kernel | Where::Global) {
                    self.error(
                        Diagnostic::error("E0203", format!("a group test needs a particle, and {} has none", cx.what))
                            .at(span, "no particle here"),
                    );
                    return None;
                }
                let set = self.groups(Some(groups));
                Some(mk(ExprKind::InGroup(*side, set), Type::BOOL, span))
            }
            A::Unary(op, a) => {
                let x = self.expr(a, cx)?;
                match op {
                    UnOp::Neg if types::is_numeric(x.ty.shape) => {
                        let ty = x.ty;
                        if let ExprKind::Const(v) = x.kind {
                            return Some(mk(ExprKind::Const(-v), ty, span));
                        }
                        Some(mk(ExprKind::Unary(Op::Neg, Box::new(x)), ty, span))
                    }
                    UnOp::Not if x.ty.shape == Shape::Bool => {
                        Some(mk(ExprKind::Unary(Op::Not, Box::new(x)), Type::BOOL, span))
                    }
                    _ => {
                        let (sym, want) = if *op == UnOp::Neg { ("-", "a number") } else { ("!", "a bool") };
                        self.error(
                            Diagnostic::error("E0202", format!("`{sym}` needs {want}, found a {}", x.ty.shape.name()))
                                .at(span, "here"),
                        );
                        None
                    }
                }
            }
            A::Binary(op, a, b) => {
                let mut x = self.expr(a, cx);
                let mut y = self.expr(b, cx);
                let (xa, ya) = (x.as_mut()?, y.as_mut()?);
                if matches!(
                    op,
                    BinOp::Add | BinOp::Sub | BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge | BinOp::Eq | BinOp::Ne
                ) {
                    let (tx, ty) = (xa.ty, ya.ty);
                    fit_free(xa, a, &ty);
                    fit_free(ya, b, &tx);
                }
                let (x, y) = (x?, y?);
                let (sx, sy) = (x.clone(), y.clone());
                match types::binary_op(*op, x, y, span) {
                    Ok(r) => Some(r),
                    Err(te) => {
                        self.type_error(te, span, &[&sx, &sy], OPERANDS);
                        None
                    }
                }
            }
        }
    }

    fn not_here_j(&mut self, span: Span, cx: &Cx) {
        self.error(
            Diagnostic::error("E0204", format!("{} reads neighbour j, but it has no neighbours", cx.what))
                .at(span, "j exists only in a pair sum's neighbour loop")
                .help("move this into a `pairsum`, or read particle i with `[i]`"),
        );
    }

    fn field_read(&mut self, f: FieldId, side: Side, span: Span, cx: &Cx) -> Option<Expr> {
        let mut fld = self.model.field(f).clone();
        // `acc` temporaries are stored as `sum.name`; messages use the name as written.
        fld.name = fld.name.rsplit('.').next().unwrap_or(&fld.name).to_string();
        match cx.at {
            Where::Const | Where::Material | Where::Kernel => {
                self.error(
                    Diagnostic::error("E0205", format!("field `{}` cannot appear in {}", fld.name, cx.what))
                        .at(span, "a per-particle value"),
                );
                return None;
            }
            Where::Global => {
                self.error(
                    Diagnostic::error(
                        "E0205",
                        format!("field `{}` is read outside a reduction in {}", fld.name, cx.what),
                    )
                    .at(span, "which particle's value?")
                    .help("reduce it over the particles: `min_over(...)`, `max_over(...)` or `sum_over(...)`"),
                );
                return None;
            }
            Where::Particle if side == Side::J => {
                self.not_here_j(span, cx);
                return None;
            }
            _ => {}
        }
        if cx.at == Where::Loop && cx.summing.contains(&f) {
            self.error(
                Diagnostic::error("E0206", format!("accumulator `{}` is read while it is being summed", fld.name))
                    .at(span, "its value is partial inside the neighbour loop")
                    .help("read it in the `finally` block"),
            );
            return None;
        }
        Some(mk(ExprKind::Field(f, side), fld.ty, span))
    }

    fn name(&mut self, n: &ast::Ident, cx: &Cx) -> Option<Expr> {
        let span = n.span;
        let name = n.name.as_str();
        if let Some((_, id)) = self.scope.iter().rev().find(|(s, _)| s == name) {
            if *id == super::POISONED {
                return None; // its definition had an error, already reported
            }
            let ty = self.model.locals[id.index()].ty;
            return Some(mk(ExprKind::Local(*id), ty, span));
        }
        if let (Some(arg), "R") = (cx.kernel_arg, name) {
            return Some(mk(ExprKind::Local(arg), Type::scalar(Unit::ONE), span));
        }
        if let Some(f) = self.lookup_field(name) {
            if cx.at == Where::Loop {
                let fld = self.model.field(f).name.clone();
                if cx.summing.contains(&f) {
                    return self.field_read(f, Side::I, span, cx);
                }
                self.error(
                    Diagnostic::error("E0207", format!("in a neighbour loop, say which particle's `{fld}` this is"))
                        .at(span, "i or j?")
                        .help(format!("write `{fld}[i]` or `{fld}[j]`")),
                );
                return None;
            }
            return self.field_read(f, Side::I, span, cx);
        }
        if let Some(p) = self.model.param_id(name) {
            return self.param_read(p, Side::I, span, cx);
        }
        if self.has_const(name) {
            let (v, u) = self.const_value(name)?;
            return Some(mk(ExprKind::Const(v), Type::scalar(u), span));
        }
        let global = |g| {
            Some(mk(
                ExprKind::Global(g),
                Type::scalar(match g {
                    Global::Time | Global::Dt => Unit::S,
                    Global::Dim => Unit::ONE,
                }),
                span,
            ))
        };
        match name {
            "pi" => return Some(mk(ExprKind::Const(std::f64::consts::PI), Type::scalar(Unit::ONE), span)),
            "inf" => return Some(mk(ExprKind::Const(f64::INFINITY), Type::scalar(Unit::ONE), span)),
            "I" => return Some(mk(ExprKind::Identity, Type::new(Shape::SymTensor, Unit::ONE), span)),
            "dim" if !matches!(cx.at, Where::Const | Where::Material) => return global(Global::Dim),
            "t" | "dt" if !matches!(cx.at, Where::Const | Where::Material | Where::Kernel) => {
                return global(if name == "t" { Global::Time } else { Global::Dt });
            }
            _ => {}
        }
        if PAIR_NAMES.contains(&name) {
            if cx.at != Where::Loop {
                self.error(
                    Diagnostic::error(
                        "E0204",
                        format!("`{name}` is a pair quantity, but {} has no neighbours", cx.what),
                    )
                    .at(span, "exists only in a pair sum's neighbour loop"),
                );
                return None;
            }
            return self.pair_value(name, span, cx);
        }
        let mut d = Diagnostic::error("E0208", format!("unknown name `{name}`")).at(span, "not declared");
        let mut known: Vec<String> = self.model.fields.iter().map(|f| f.name.clone()).collect();
        known.extend(self.model.params.iter().map(|p| p.name.clone()));
        known.extend(self.scope.iter().map(|(s, _)| s.clone()));
        known.extend(self.const_names());
        known.extend(PAIR_NAMES.iter().map(|s| s.to_string()));
        known.extend(["pi", "inf", "I", "dim", "t", "dt"].iter().map(|s| s.to_string()));
        if let Some(b) = closest(name, known.iter().map(String::as_str)) {
            d = d.help(format!("did you mean `{b}`?"));
        } else {
            d = d.help(format!("declare it: `field {name}: scalar [...]`, `param {name}: ...` or `let {name} = ...`"));
        }
        self.error(d);
        None
    }

    fn pair_value(&mut self, name: &str, span: Span, cx: &Cx) -> Option<Expr> {
        let m = Unit::M;
        let (kind, ty) = match name {
            "x_ij" => (ExprKind::Pair(PairValue::Xij), Type::new(Shape::Vec, m)),
            "r_ij" => (ExprKind::Pair(PairValue::Rij), Type::scalar(m)),
            "h_ij" => (ExprKind::Pair(PairValue::Hij), Type::scalar(m)),
            "W_ij" => (ExprKind::Pair(PairValue::W), Type::scalar(m.powr(Ratio::int(-3))?)),
            "gradW_ij" => (ExprKind::Pair(PairValue::GradW), Type::new(Shape::Vec, m.powr(Ratio::int(-4))?)),
            _ => {
                // v_ij = v[i] - v[j]
                let Some(v) = self.model.field_id("v") else {
                    self.error(
                        Diagnostic::error("E0208", "`v_ij` needs the velocity field `v`").at(span, "no field `v`"),
                    );
                    return None;
                };
                let vi = self.field_read(v, Side::I, span, cx)?;
                let vj = self.field_read(v, Side::J, span, cx)?;
                let ty = vi.ty;
                return Some(mk(ExprKind::Binary(Op::Sub, Box::new(vi), Box::new(vj)), ty, span));
            }
        };
        Some(mk(kind, ty, span))
    }

    fn param_read(&mut self, p: crate::ir::ParamId, side: Side, span: Span, cx: &Cx) -> Option<Expr> {
        let par = self.model.params[p.index()].clone();
        match cx.at {
            Where::Const | Where::Kernel | Where::Global => {
                let mut d =
                    Diagnostic::error("E0209", format!("parameter `{}` cannot appear in {}", par.name, cx.what))
                        .at(span, "parameters belong to a particle's material");
                if cx.at == Where::Global {
                    d = d.help(format!(
                        "read it inside a reduction, where each particle has its material: e.g. `min_over({} * h)`",
                        par.name
                    ));
                }
                self.error(d);
                return None;
            }
            Where::Particle | Where::Material if side == Side::J => {
                self.not_here_j(span, cx);
                return None;
            }
            _ => {}
        }
        Some(mk(ExprKind::Param(p, side), par.ty, span))
    }

    fn index(&mut self, base: &ast::Expr, side: Side, side_span: Span, span: Span, cx: &Cx) -> Option<Expr> {
        let A::Name(n) = &base.kind else {
            self.error(
                Diagnostic::error("E0210", "only a field or a parameter can be read at a particle")
                    .at(span, "`[i]`/`[j]` applies to a name")
                    .help("index the field, then compute: `norm(v[j])`, not `norm(v)[j]`"),
            );
            return None;
        };
        if side == Side::J && cx.at == Where::Particle {
            self.not_here_j(side_span, cx);
            return None;
        }
        if let Some(f) = self.lookup_field(&n.name) {
            if self.model.field(f).storage == crate::ir::Storage::Temp {
                self.error(
                    Diagnostic::error(
                        "E0210",
                        format!(
                            "`{}` is an `acc` of this pair sum, not a field: it has no `[{}]`",
                            n.name,
                            side.letter()
                        ),
                    )
                    .at(span, "local to this pair sum")
                    .help(format!("write `{}`", n.name)),
                );
                return None;
            }
            return self.field_read(f, side, span, cx);
        }
        if let Some(p) = self.model.param_id(&n.name) {
            return self.param_read(p, side, span, cx);
        }
        if self.scope.iter().any(|(s, _)| s == &n.name) {
            self.error(
                Diagnostic::error(
                    "E0210",
                    format!("`{}` is a local value, not a field: it has no `[{}]`", n.name, side.letter()),
                )
                .at(span, "local values belong to the pair or particle being computed")
                .help(format!("write `{}`", n.name)),
            );
            return None;
        }
        self.name(n, cx)?;
        self.error(
            Diagnostic::error("E0210", format!("`{}` is not a field or a parameter and cannot be indexed", n.name))
                .at(span, "here"),
        );
        None
    }

    fn member(&mut self, base: &ast::Expr, m: &ast::Ident, span: Span, cx: &Cx) -> Option<Expr> {
        let x = self.expr(base, cx)?;
        let axis = |c: char| "xyz".find(c);
        let chars: Vec<char> = m.name.chars().collect();
        let comp = match (x.ty.shape, chars.as_slice()) {
            (Shape::Vec, [a]) => axis(*a).map(|a| (a, 0)),
            (s, [a, b]) if types::is_tensor_like(s) => axis(*a).zip(axis(*b)),
            _ => None,
        };
        let Some((r, c)) = comp else {
            let expect = match x.ty.shape {
                Shape::Vec => "`.x`, `.y` or `.z`",
                s if types::is_tensor_like(s) => "two axes such as `.xy`",
                _ => "no components",
            };
            self.error(
                Diagnostic::error("E0211", format!("a {} has no component `.{}`", x.ty.shape.name(), m.name))
                    .at(m.span, format!("a {} has {expect}", x.ty.shape.name())),
            );
            return None;
        };
        let ty = Type::scalar(x.ty.unit);
        Some(mk(ExprKind::Component(Box::new(x), r as u8, c as u8), ty, span))
    }

    fn arity(&mut self, f: &ast::Ident, args: &[ast::Expr], want: usize, span: Span) -> bool {
        if args.len() == want {
            return true;
        }
        let s = if want == 1 { "" } else { "s" };
        self.error(
            Diagnostic::error("E0212", format!("`{}` takes {want} argument{s}, found {}", f.name, args.len()))
                .at(span, format!("{} given", args.len())),
        );
        false
    }

    fn call(&mut self, f: &ast::Ident, args: &[ast::Expr], span: Span, cx: &Cx) -> Option<Expr> {
        if let Some(def) = self.helper(&f.name) {
            return self.inline(def, f, args, span, cx);
        }
        match f.name.as_str() {
            "pow" => {
                if !self.arity(f, args, 2, span) {
                    return None;
                }
                let (a, b) = (self.expr(&args[0], cx), self.expr(&args[1], cx));
                let (a, b) = (a?, b?);
                let (sa, sb) = (a.clone(), b.clone());
                return types::binary_op(BinOp::Pow, a, b, span)
                    .map_err(|e| self.type_error(e, span, &[&sa, &sb], OPERANDS))
                    .ok();
            }
            "select" => return self.select(f, args, span, cx),
            "avg" => return self.avg(f, args, span, cx),
            "min_over" | "max_over" | "sum_over" => return self.reduction(f, args, span, cx),
            _ => {}
        }
        let Some((b, arity)) = builtin_by_name(&f.name) else {
            let mut d = Diagnostic::error("E0213", format!("unknown function `{}`", f.name))
                .at(f.span, "no builtin or helper of this name");
            let mut names: Vec<String> = types::callable().map(String::from).collect();
            names.extend(self.helper_names());
            if let Some(ours) = name_elsewhere(&f.name) {
                d = d.help(format!("this language writes it `{ours}`"));
            } else if let Some(best) = closest(&f.name, names.iter().map(String::as_str)) {
                d = d.help(format!("did you mean `{best}`?"));
            } else {
                d = d.help("define it with `fn name(...) -> type { ... }`");
            }
            self.error(d);
            return None;
        };
        match arity {
            Some(n) if !self.arity(f, args, n, span) => return None,
            Some(_) => {}
            None if args.len() < 2 => {
                self.error(
                    Diagnostic::error(
                        "E0212",
                        format!("`{}` takes two or more arguments, found {}", f.name, args.len()),
                    )
                    .at(span, "here"),
                );
                return None;
            }
            None => {}
        }
        let mut typed = vec![];
        let mut ok = true;
        for a in args {
            match self.expr(a, cx) {
                Some(x) => typed.push(x),
                None => ok = false,
            }
        }
        if !ok {
            return None;
        }
        if matches!(b, Builtin::Min | Builtin::Max | Builtin::Vector) {
            // Free zeros and infinities take the unit of the other arguments.
            if let Some(anchor) = typed.iter().zip(args).find(|(_, a)| !is_free(a)).map(|(t, _)| t.ty) {
                for (t, a) in typed.iter_mut().zip(args) {
                    fit_free(t, a, &anchor);
                }
            }
        }
        if let Some(expected) = types::fixed_arguments(b) {
            // A free zero or infinity takes the argument's own type: `W_at(0, h)`.
            for ((t, a), to) in typed.iter_mut().zip(args).zip(expected) {
                fit_free(t, a, &to);
            }
        }
        if matches!(b, Builtin::KernelAt | Builtin::KernelGradAt) && cx.at == Where::Kernel {
            let msg = format!("a kernel cannot be defined in terms of `{}`", b.name());
            self.error(Diagnostic::error("E0214", msg).at(span, "here"));
            return None;
        }
        let shown: Vec<Expr> = typed.clone();
        match types::builtin(b, typed, span) {
            Ok(e) => Some(e),
            Err(te) => {
                let refs: Vec<&Expr> = shown.iter().collect();
                self.type_error(te, span, if refs.len() == 2 { &refs } else { &[] }, ARGUMENTS);
                None
            }
        }
    }

    fn select(&mut self, f: &ast::Ident, args: &[ast::Expr], span: Span, cx: &Cx) -> Option<Expr> {
        if !self.arity(f, args, 3, span) {
            return None;
        }
        let c = self.expr(&args[0], cx);
        let a = self.expr(&args[1], cx);
        let b = self.expr(&args[2], cx);
        let (c, mut a, mut b) = (c?, a?, b?);
        if c.ty.shape != Shape::Bool {
            self.error(
                Diagnostic::error(
                    "E0202",
                    format!("the condition of `select` must be a bool, found a {}", c.ty.shape.name()),
                )
                .at(args[0].span, "not a condition")
                .help("compare something: `select(x > 0, a, b)`"),
            );
            return None;
        }
        let (ta, tb) = (a.ty, b.ty);
        fit_free(&mut a, &args[1], &tb);
        fit_free(&mut b, &args[2], &ta);
        if let Err(te) = types::same_unit(&a.ty, &b.ty, "the branches of `select`") {
            self.type_error(te, span, &[&a, &b], OPERANDS);
            return None;
        }
        let (sa, sb) = (a.clone(), b.clone());
        match types::unify_shapes(a, b, "the branches of `select`") {
            Ok((a, b)) => {
                let ty = a.ty;
                Some(mk(ExprKind::Select(Box::new(c), Box::new(a), Box::new(b)), ty, span))
            }
            Err(te) => {
                self.type_error(te, span, &[&sa, &sb], OPERANDS);
                None
            }
        }
    }

    fn avg(&mut self, f: &ast::Ident, args: &[ast::Expr], span: Span, cx: &Cx) -> Option<Expr> {
        if !self.arity(f, args, 1, span) {
            return None;
        }
        if cx.at != Where::Loop {
            self.error(
                Diagnostic::error("E0204", format!("`avg` averages over i and j, but {} has no neighbours", cx.what))
                    .at(span, "only in a neighbour loop"),
            );
            return None;
        }
        let A::Name(n) = &args[0].kind else {
            self.error(
                Diagnostic::error(
                    "E0210",
                    "`avg` takes the name of a field or parameter: `avg(c)` is (c[i] + c[j]) / 2",
                )
                .at(args[0].span, "not a name"),
            );
            return None;
        };
        let base = ast::Expr { kind: A::Name(n.clone()), span: n.span };
        let i = self.index(&base, Side::I, n.span, n.span, cx)?;
        let j = self.index(&base, Side::J, n.span, n.span, cx)?;
        if !types::is_numeric(i.ty.shape) {
            self.error(Diagnostic::error("E0202", "`avg` of a bool").at(span, "here"));
            return None;
        }
        let ty = i.ty;
        let sum = mk(ExprKind::Binary(Op::Add, Box::new(i), Box::new(j)), ty, span);
        let half = mk(ExprKind::Const(0.5), Type::scalar(Unit::ONE), span);
        Some(mk(ExprKind::Binary(Op::Scale, Box::new(half), Box::new(sum)), ty, span))
    }

    fn reduction(&mut self, f: &ast::Ident, args: &[ast::Expr], span: Span, cx: &Cx) -> Option<Expr> {
        if !self.arity(f, args, 1, span) {
            return None;
        }
        if cx.at != Where::Global {
            self.error(
                Diagnostic::error(
                    "E0215",
                    format!("`{}` reduces over all particles and belongs in a timestep, not in {}", f.name, cx.what),
                )
                .at(span, "not allowed here"),
            );
            return None;
        }
        let inner = cx.with_at(Where::Particle);
        let x = self.expr(&args[0], &inner)?;
        if x.ty.shape != Shape::Scalar {
            self.error(
                Diagnostic::error("E0202", format!("`{}` reduces scalars, found a {}", f.name, x.ty.shape.name()))
                    .at(args[0].span, "not a scalar"),
            );
            return None;
        }
        let r = match f.name.as_str() {
            "min_over" => Reduce::Min,
            "max_over" => Reduce::Max,
            _ => Reduce::Sum,
        };
        let ty = x.ty;
        Some(mk(ExprKind::Reduction(r, Box::new(x)), ty, span))
    }

    /// Inlines a helper: its arguments and `let`s become local bindings around its body.
    fn inline(
        &mut self,
        def: std::rc::Rc<ast::FnDef>,
        f: &ast::Ident,
        args: &[ast::Expr],
        span: Span,
        cx: &Cx,
    ) -> Option<Expr> {
        if !self.arity(f, args, def.params.len(), span) {
            return None;
        }
        if self.fn_stack.iter().any(|(n, _)| n == &def.name.name) {
            self.error(
                Diagnostic::error(
                    "E0216",
                    format!("helper `{}` calls itself; helpers are inlined and cannot recurse", def.name.name),
                )
                .at(span, "recursive call"),
            );
            return None;
        }
        let mut bindings: Vec<(LocalId, Expr)> = vec![];
        let mut ok = true;
        for (p, a) in def.params.iter().zip(args) {
            let x = match &p.ty {
                Some(t) => match self.type_spec(t) {
                    Some(ty) => self.expr_as(a, cx, ty, &format!("argument `{}` of `{}`", p.name.name, def.name.name)),
                    None => None,
                },
                None => self.expr(a, cx),
            };
            match x {
                Some(x) => {
                    let id = self.new_local(&p.name.name, x.ty);
                    bindings.push((id, x));
                }
                None => ok = false,
            }
        }
        if !ok {
            return None;
        }
        let mark = self.scope.len();
        for ((id, _), p) in bindings.iter().zip(&def.params) {
            self.scope.push((p.name.name.clone(), *id));
        }
        self.fn_stack.push((def.name.name.clone(), span));
        let before = self.diags.len();
        let mut body = self.helper_body(&def, cx, &mut bindings);
        self.fn_stack.pop();
        self.scope.truncate(mark);
        for d in &mut self.diags[before..] {
            if d.secondary.iter().all(|(s, _)| *s != span) {
                d.secondary.push((span, format!("in this call of `{}`", def.name.name)));
            }
        }
        let b = body.take()?;
        let mut out = b;
        for (id, value) in bindings.into_iter().rev() {
            let ty = out.ty;
            out = mk(ExprKind::Let(id, Box::new(value), Box::new(out)), ty, span);
        }
        Some(out)
    }

    fn helper_body(&mut self, def: &ast::FnDef, cx: &Cx, bindings: &mut Vec<(LocalId, Expr)>) -> Option<Expr> {
        for s in &def.lets {
            let ast::Stmt::Let { name, ty, value, .. } = s else {
                continue;
            };
            let x = match ty {
                Some(t) => self.type_spec(t).and_then(|t| self.expr_as(value, cx, t, &format!("`{}`", name.name))),
                None => self.expr(value, cx),
            };
            let Some(x) = x else {
                self.scope.push((name.name.clone(), super::POISONED));
                continue;
            };
            let id = self.new_local(&name.name, x.ty);
            self.scope.push((name.name.clone(), id));
            bindings.push((id, x));
        }
        match &def.ret {
            Some(t) => {
                let t = self.type_spec(t)?;
                self.expr_as(&def.body, cx, t, &format!("the result of `{}`", def.name.name))
            }
            None => self.expr(&def.body, cx),
        }
    }

    pub(crate) fn new_local(&mut self, name: &str, ty: Type) -> LocalId {
        self.model.locals.push(crate::ir::Local { name: name.to_string(), ty });
        LocalId(self.model.locals.len() as u32 - 1)
    }

    /// Helpers whose parameters are all typed are checked once on their own, so that a mistake in
    /// a helper nobody calls yet is still found.
    pub(crate) fn check_unchecked_helpers(&mut self) {
        let mut names = self.helper_names();
        names.sort();
        for n in names {
            let Some(def) = self.helper(&n) else { continue };
            if def.params.iter().any(|p| p.ty.is_none()) {
                continue;
            }
            let mark = self.scope.len();
            let mut ok = true;
            for p in &def.params {
                let Some(t) = p.ty.as_ref().and_then(|t| self.type_spec(t)) else {
                    ok = false;
                    continue;
                };
                let id = self.new_local(&p.name.name, t);
                self.scope.push((p.name.name.clone(), id));
            }
            if ok {
                // A helper may be meant for a neighbour loop or for one particle: it is fine if
                // it checks in either.
                let before = self.diags.len();
                let mut best: Option<Vec<Diagnostic>> = None;
                for at in [Where::Particle, Where::Loop] {
                    let cx = Cx::new(at, format!("helper `{n}`"));
                    self.fn_stack.push((n.clone(), def.span));
                    let mut bindings = vec![];
                    let _ = self.helper_body(&def, &cx, &mut bindings);
                    self.fn_stack.pop();
                    let found: Vec<Diagnostic> = self.diags.drain(before..).collect();
                    if best.as_ref().is_none_or(|b| found.len() < b.len()) {
                        best = Some(found);
                    }
                }
                self.diags.extend(best.unwrap_or_default());
            }
            self.scope.truncate(mark);
        }
    }
}

/// What this language calls a function that WGSL, GLSL, C or NumPy name otherwise (`length` is
/// `norm`), for E0213's help.
fn name_elsewhere(name: &str) -> Option<&'static str> {
    Some(match name {
        "length" | "magnitude" | "mag" => "norm",
        "normalize" | "normalise" => "v / norm(v)",
        "log" => "ln",
        "determinant" => "det",
        "inverse" => "inv",
        "clamp" => "min(max(x, lo), hi)",
        _ => return None,
    })
}
