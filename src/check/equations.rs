//! Checking equations (pair sums and particle equations), their statements and the i/j
//! discipline, and the `integrate`, `timestep` and `kernel` items.

use super::expr::{Cx, Where};
use super::types;
use super::Checker;
use crate::diag::{closest, Diagnostic, Span};
use crate::ir::{self, Accumulator, Equation, EquationKind, Expr, ExprKind, FieldId, Op, Reduce, Type};
use crate::syntax::ast::{self, AccumOp, Item, Shape, Side, Storage};
use crate::units::Unit;
use std::collections::{BTreeSet, HashMap};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Block {
    Init,
    Loop,
    Finally,
    Particle,
}

/// What the statements of one equation may write.
struct EqState {
    what: String,
    outputs: Vec<FieldId>,
    is_pair: bool,
    reduce: HashMap<FieldId, (Reduce, Span)>,
}

impl Checker {
    /// A field's name as the user wrote it (`acc` temporaries are stored as `sum.name`).
    fn display_name(&self, f: FieldId) -> String {
        let name = &self.model.field(f).name;
        name.rsplit('.').next().unwrap_or(name).to_string()
    }

    /// Output declarations (`-> drho: scalar [...]`) declare fields before any body is checked, so
    /// that equations may read each other's results in any file order.
    pub(crate) fn declare_outputs(&mut self, items: &[&Item]) {
        for it in items {
            let outputs = match it {
                Item::PairSum(p) => &p.outputs,
                Item::Particle(p) => &p.outputs,
                _ => continue,
            };
            for o in outputs {
                let Some(t) = &o.ty else { continue };
                if self.reserved_name(&o.name) {
                    continue;
                }
                if let Some(ty) = self.type_spec(t) {
                    self.add_field(&o.name, ty, Storage::Field, o.name.span);
                }
            }
        }
    }

    fn reserved_name(&mut self, n: &ast::Ident) -> bool {
        if super::RESERVED.contains(&n.name.as_str()) || types::builtin_by_name(&n.name).is_some() {
            self.error(
                Diagnostic::error("E0106", format!("`{}` is a name of the language and cannot name a field", n.name))
                    .at(n.span, "reserved name"),
            );
            return true;
        }
        false
    }

    fn unknown_field(&mut self, n: &ast::Ident, what: &str) {
        let names: Vec<String> = self.model.fields.iter().map(|f| f.name.clone()).collect();
        let mut d = Diagnostic::error("E0208", format!("unknown field `{}`", n.name))
            .at(n.span, format!("{what} names no declared field"));
        if let Some(b) = closest(&n.name, names.iter().map(String::as_str)) {
            d = d.help(format!("did you mean `{b}`?"));
        } else {
            d = d.help(format!("give it a type to declare it here: `{}: scalar [...]`", n.name));
        }
        self.error(d);
    }

    fn resolve_outputs(&mut self, outputs: &[ast::Output], what: &str) -> Option<Vec<FieldId>> {
        let mut ids = vec![];
        let mut ok = true;
        for o in outputs {
            let Some(id) = self.model.field_id(&o.name.name) else {
                if o.ty.is_none() {
                    self.unknown_field(&o.name, "this output");
                }
                ok = false;
                continue;
            };
            if ids.contains(&id) {
                self.error(
                    Diagnostic::error(
                        "E0307",
                        format!("`{}` is listed twice among the outputs of {what}", o.name.name),
                    )
                    .at(o.name.span, "again"),
                );
                ok = false;
                continue;
            }
            ids.push(id);
        }
        ok.then_some(ids)
    }

    pub(crate) fn pairsum(&mut self, p: &ast::PairSumDef) {
        let what = format!("pairsum `{}`", p.name.name);
        let dest = self.scoped_groups(p.on.as_ref(), p.name.span, &what);
        let (sources, narrowed) = self.scoped_sources(p.from.as_ref(), dest, p.name.span, &what);
        let Some(stored) = self.resolve_outputs(&p.outputs, &what) else {
            return;
        };
        for f in &stored {
            self.accumulator_of.entry(*f).or_insert_with(|| p.name.name.clone());
        }
        let mut outputs = stored.clone();
        self.temps.clear();
        for t in &p.temps {
            let Some(ty) = t.ty.as_ref().and_then(|ty| self.type_spec(ty)) else {
                continue;
            };
            if self.temps.iter().any(|(n, _)| *n == t.name.name)
                || stored.iter().any(|f| self.model.field(*f).name == t.name.name)
            {
                self.error(
                    Diagnostic::error("E0307", format!("`{}` is declared twice in {what}", t.name.name))
                        .at(t.name.span, "again"),
                );
                continue;
            }
            self.model.fields.push(ir::Field {
                saved_of: None,
                name: format!("{}.{}", p.name.name, t.name.name),
                ty,
                storage: Storage::Temp,
                init: None,
                span: t.name.span,
            });
            let id = FieldId(self.model.fields.len() as u32 - 1);
            self.temps.push((t.name.name.clone(), id));
            outputs.push(id);
        }
        let mut st = EqState { what: what.clone(), outputs: outputs.clone(), is_pair: true, reduce: HashMap::new() };
        let mut cx = Cx::new(Where::Particle, format!("the `init` of {what}"));
        cx.outputs = outputs.clone();
        let init = self.stmts(&p.init, Block::Init, &cx, &mut st);
        let mut cx = Cx::new(Where::Loop, what.clone());
        cx.outputs = outputs.clone();
        cx.summing = outputs.clone();
        let body = self.stmts(&p.body, Block::Loop, &cx, &mut st);
        let mut cx = Cx::new(Where::Particle, format!("the `finally` of {what}"));
        cx.outputs = outputs.clone();
        let finally = self.stmts(&p.finally, Block::Finally, &cx, &mut st);
        let accumulators = outputs
            .iter()
            .map(|f| Accumulator { field: *f, reduce: st.reduce.get(f).map(|r| r.0).unwrap_or(Reduce::Sum) })
            .collect();
        self.temps.clear();
        let own = p.own || self.module_scope.own_group;
        let body = if p.own_body || self.module_scope.own_body { self.within_own_body(body) } else { body };
        let kind = EquationKind::PairSum {
            sources,
            narrowed,
            own,
            accumulators,
            init,
            body,
            finally,
            compensated: p.compensated,
        };
        self.push_equation(&p.name.name, kind, dest, stored, p.span);
    }

    /// A pair loop's statements run only for neighbours of particle i's own body (`from own body`):
    /// `if body[i] == body[j] { … }`.
    fn within_own_body(&self, stmts: Vec<ir::Stmt>) -> Vec<ir::Stmt> {
        let Some(f) = self.model.field_id("body") else { return stmts };
        let ty = self.model.field(f).ty;
        let side = |s| ir::Expr::new(ir::ExprKind::Field(f, s), ty);
        let same = ir::Expr::binary(ir::Op::Eq, side(ir::Side::I), side(ir::Side::J), ir::Type::BOOL);
        vec![ir::Stmt::If(same, stmts, vec![])]
    }

    pub(crate) fn particle(&mut self, p: &ast::ParticleDef) {
        let what = format!("particle equation `{}`", p.name.name);
        let dest = self.scoped_groups(p.on.as_ref(), p.name.span, &what);
        let Some(outputs) = self.resolve_outputs(&p.outputs, &what) else {
            return;
        };
        let mut st = EqState { what: what.clone(), outputs: outputs.clone(), is_pair: false, reduce: HashMap::new() };
        let mut cx = Cx::new(Where::Particle, what);
        cx.outputs = outputs.clone();
        let body = self.stmts(&p.body, Block::Particle, &cx, &mut st);
        self.push_equation(&p.name.name, EquationKind::Particle { body }, dest, outputs, p.span);
    }

    fn push_equation(&mut self, name: &str, kind: EquationKind, dest: ir::GroupSet, writes: Vec<FieldId>, span: Span) {
        // Two modules may each have an equation of one name (`continuity::fourtakas` on a fluid,
        // `continuity::plain` on a solid): equations are told apart by their module. One file
        // may not define a name twice; two writers of one field on a group are E0305.
        if let Some(other) = self.model.equations.iter().find(|e| e.name == name && e.span.file == span.file) {
            let other_span = other.span;
            self.error(
                Diagnostic::error("E0101", format!("equation `{name}` is defined twice"))
                    .at(span, "second definition")
                    .also(other_span, "first definition"),
            );
            return;
        }
        let (reads, params) = {
            let stmts: Vec<&[ir::Stmt]> = match &kind {
                EquationKind::PairSum { init, body, finally, .. } => vec![init, body, finally],
                EquationKind::Particle { body } => vec![body],
            };
            let mut reads = BTreeSet::new();
            let mut params = BTreeSet::new();
            for s in stmts {
                ir::walk_stmts(s, &mut |e| match &e.kind {
                    ExprKind::Field(f, side)
                        if !writes.contains(f) && self.model.field(*f).storage != Storage::Temp =>
                    {
                        reads.insert((*f, *side));
                    }
                    ExprKind::Param(p, side) => {
                        params.insert((*p, *side));
                    }
                    _ => {}
                });
            }
            (reads, params)
        };
        self.model.equations.push(Equation {
            name: name.to_string(),
            kind,
            dest,
            writes,
            reads,
            params,
            span,
            location: String::new(),
            builds_on: self.builds_on.get(&span.file).cloned().unwrap_or_default(),
        });
    }

    fn stmts(&mut self, stmts: &[ast::Stmt], bk: Block, cx: &Cx, st: &mut EqState) -> Vec<ir::Stmt> {
        let mark = self.scope.len();
        let mut out = vec![];
        for s in stmts {
            if let Some(x) = self.stmt(s, bk, cx, st) {
                out.push(x);
            }
        }
        self.scope.truncate(mark);
        out
    }

    fn stmt(&mut self, s: &ast::Stmt, bk: Block, cx: &Cx, st: &mut EqState) -> Option<ir::Stmt> {
        match s {
            ast::Stmt::Let { name, ty, value, .. } => {
                if self.model.field_id(&name.name).is_some() || self.model.param_id(&name.name).is_some() {
                    self.error(
                        Diagnostic::error(
                            "E0308",
                            format!("`let {}` hides the field or parameter of the same name", name.name),
                        )
                        .at(name.span, "choose another name"),
                    );
                    return None;
                }
                let x = match ty {
                    Some(t) => self.type_spec(t).and_then(|t| self.expr_as(value, cx, t, &format!("`{}`", name.name))),
                    None => self.expr(value, cx),
                };
                let Some(x) = x else {
                    self.scope.push((name.name.clone(), super::POISONED));
                    return None;
                };
                let id = self.new_local(&name.name, x.ty);
                self.scope.push((name.name.clone(), id));
                Some(ir::Stmt::Let(id, x))
            }
            ast::Stmt::Assign { target, value, span } => {
                let f = self.target(target, st)?;
                if bk == Block::Loop {
                    let fname = self.display_name(f);
                    self.error(
                        Diagnostic::error(
                            "E0304",
                            format!("`{fname} = ...` inside the neighbour loop would keep only the last neighbour"),
                        )
                        .at(*span, "assignment in the neighbour loop")
                        .help(format!(
                            "fold each neighbour in with `{fname} += ...` (or `min=`/`max=`), or assign in `finally`"
                        )),
                    );
                    return None;
                }
                if bk == Block::Init && st.is_pair && !st.outputs.contains(&f) {
                    return None;
                }
                let ty = self.model.field(f).ty;
                let fname = self.display_name(f);
                let x = self.expr_as(value, cx, ty, &format!("the value of `{fname}`"))?;
                Some(ir::Stmt::Set(f, x))
            }
            ast::Stmt::Accum { target, op, value, span } => {
                if bk != Block::Loop {
                    let where_ = if st.is_pair { "the neighbour loop" } else { "a pair sum's neighbour loop" };
                    self.error(
                        Diagnostic::error(
                            "E0309",
                            format!("`{}` folds neighbours together and belongs in {where_}", op.text()),
                        )
                        .at(*span, "no neighbours here")
                        .help(format!("assign with `{} = ...`", target.name.name)),
                    );
                    return None;
                }
                let f = self.target(target, st)?;
                let reduce = match op {
                    AccumOp::Add | AccumOp::Sub => Reduce::Sum,
                    AccumOp::Min => Reduce::Min,
                    AccumOp::Max => Reduce::Max,
                };
                if let Some((prev, prev_span)) = st.reduce.get(&f) {
                    if *prev != reduce {
                        let fname = self.display_name(f);
                        self.error(
                            Diagnostic::error(
                                "E0310",
                                format!("accumulator `{fname}` is both a {} and a {}", prev.name(), reduce.name()),
                            )
                            .at(*span, format!("{} here", reduce.name()))
                            .also(*prev_span, format!("{} here", prev.name())),
                        );
                        return None;
                    }
                } else {
                    st.reduce.insert(f, (reduce, *span));
                }
                let ty = self.model.field(f).ty;
                let fname = self.display_name(f);
                let mut x = self.expr_as(value, cx, ty, &format!("what is added to `{fname}`"))?;
                if *op == AccumOp::Sub {
                    let (t, sp) = (x.ty, x.span);
                    x = Expr { kind: ExprKind::Unary(Op::Neg, Box::new(x)), ty: t, span: sp };
                }
                Some(ir::Stmt::Accum(f, reduce, x))
            }
            ast::Stmt::If { cond, then, otherwise, .. } => {
                let c = self.expr(cond, cx)?;
                if c.ty.shape != Shape::Bool {
                    self.error(
                        Diagnostic::error("E0202", format!("an `if` needs a condition, found a {}", c.ty.shape.name()))
                            .at(cond.span, "not a bool")
                            .help("compare something: `if r_ij > 0 [m] { ... }`"),
                    );
                    return None;
                }
                let a = self.stmts(then, bk, cx, st);
                let b = self.stmts(otherwise, bk, cx, st);
                Some(ir::Stmt::If(c, a, b))
            }
        }
    }

    /// The field a statement writes, if this equation may write it.
    fn target(&mut self, t: &ast::LValue, st: &EqState) -> Option<FieldId> {
        let name = &t.name.name;
        if let Some(f) = self.temps.iter().find(|(n, _)| n == name).map(|(_, f)| *f) {
            if t.side.is_none() {
                return Some(f);
            }
        }
        if let Some((Side::J, side_span)) = t.side {
            self.error(
                Diagnostic::error("E0301", format!("{} writes neighbour j's `{name}`", st.what))
                    .at(t.name.span.to(side_span), "a neighbour's value")
                    .note("each particle computes only its own values (gather, never scatter), so neighbour loops run in parallel without conflicts")
                    .help(format!("sum the contribution into particle i instead: `{name} += ...` for i, and let j compute its own")),
            );
            return None;
        }
        let Some(f) = self.model.field_id(name) else {
            if self.scope.iter().any(|(s, _)| s == name) {
                self.error(
                    Diagnostic::error("E0311", format!("`{name}` is a `let` value and cannot be changed"))
                        .at(t.name.span, "immutable")
                        .help("bind a new name with `let`"),
                );
            } else {
                self.unknown_field(&t.name, "this assignment");
            }
            return None;
        };
        if st.outputs.contains(&f) {
            return Some(f);
        }
        if let Some(owner) = self.accumulator_of.get(&f) {
            self.error(
                Diagnostic::error(
                    "E0303",
                    format!("`{name}` is the accumulator of pairsum `{owner}`; {} cannot write it", st.what),
                )
                .at(t.name.span, format!("belongs to `{owner}`"))
                .help("an equation writes only the outputs listed after its `->`"),
            );
            return None;
        }
        self.error(
            Diagnostic::error("E0302", format!("`{name}` is not an output of {}", st.what))
                .at(t.name.span, "not listed after `->`")
                .help(format!("add `{name}` to the outputs after `->`")),
        );
        None
    }

    pub(crate) fn integrate(&mut self, def: &ast::IntegrateDef) {
        let dest = self.scoped_groups(def.on.as_ref(), def.span, "this `integrate` block");
        for r in &def.rates {
            let Some(f) = self.model.field_id(&r.state.name) else {
                self.unknown_field(&r.state, "this rate");
                continue;
            };
            let field = self.model.field(f).clone();
            if field.storage != Storage::State {
                self.error(
                    Diagnostic::error(
                        "E0312",
                        format!("`{}` is recomputed every step; only state fields are integrated", field.name),
                    )
                    .at(r.state.span, "not a state field")
                    .also(field.span, "declared here")
                    .help(format!("declare it `state {}: ...`", field.name)),
                );
                continue;
            }
            let Some(unit) = field.ty.unit.div(&Unit::S) else {
                continue;
            };
            let cx = Cx::new(Where::Particle, format!("the rate of `{}`", field.name));
            let Some(rate) =
                self.expr_as(&r.rate, &cx, Type::new(field.ty.shape, unit), &format!("the rate of `{}`", field.name))
            else {
                continue;
            };
            let mut reads = BTreeSet::new();
            ir::walk_expr(&rate, &mut |e| {
                if let ExprKind::Field(f, _) = e.kind {
                    reads.insert(f);
                }
            });
            if let Some(other) = self.model.rates.iter().find(|o| o.state == f && !o.dest.intersect(dest).is_empty()) {
                let span = other.span;
                self.error(
                    Diagnostic::error("E0305", format!("`{}` is integrated twice", field.name))
                        .at(r.span, "second rate")
                        .also(span, "first rate"),
                );
                continue;
            }
            self.model.rates.push(ir::Rate { state: f, rate, dest, reads, span: r.span });
        }
    }

    pub(crate) fn timestep(&mut self, def: &ast::TimestepDef) {
        let cx = Cx::new(Where::Global, format!("timestep `{}`", def.name.name));
        let Some(mut value) = self.expr_as(&def.value, &cx, Type::scalar(Unit::S), "a time step") else {
            return;
        };
        let dest = self.scoped_groups(None, def.name.span, &format!("timestep `{}`", def.name.name));
        if dest.0 & self.model.all_groups().0 != self.model.all_groups().0 {
            reduce_only_on(&mut value, dest);
        }
        let mut reads = BTreeSet::new();
        ir::walk_expr(&value, &mut |e| {
            if let ExprKind::Field(f, _) = e.kind {
                reads.insert(f);
            }
        });
        self.model.timesteps.push(ir::Timestep { name: def.name.name.clone(), dest, value, reads, span: def.span });
    }

    pub(crate) fn requirement(&mut self, def: &ast::RequireDef) {
        let cx = Cx::new(Where::Material, "a requirement");
        let Some(cond) = self.expr_as(&def.cond, &cx, Type::BOOL, "a requirement") else {
            return;
        };
        let groups = self.scoped_groups(None, def.span, "a requirement");
        self.model.requirements.push(ir::Requirement { cond, why: def.why.clone(), groups, span: def.span });
    }

    pub(crate) fn kernel(&mut self, k: &ast::KernelDef) {
        if self.model.kernel_id(&k.name.name).is_some() {
            self.error(
                Diagnostic::error("E0101", format!("kernel `{}` is defined twice", k.name.name))
                    .at(k.name.span, "second definition"),
            );
            return;
        }
        let arg = self.new_local("R", Type::scalar(Unit::ONE));
        let mut support = None;
        let mut norm = [None; 3];
        let mut w = None;
        let mut dw = None;
        for e in &k.entries {
            let takes_arg = matches!(e.key.as_str(), "w" | "dw");
            if takes_arg != e.arg.is_some() {
                let msg =
                    if takes_arg { format!("write `{}(R) = ...`", e.key) } else { format!("write `{} = ...`", e.key) };
                self.error(
                    Diagnostic::error("E0313", format!("kernel entry `{}` has the wrong form", e.key))
                        .at(e.key_span, msg),
                );
                continue;
            }
            if let Some(a) = &e.arg {
                if a.name != "R" {
                    self.error(
                        Diagnostic::error("E0313", "a kernel's argument is `R`, the distance over h")
                            .at(a.span, "write `R`"),
                    );
                    continue;
                }
            }
            let one = Type::scalar(Unit::ONE);
            if takes_arg {
                let mut cx = Cx::new(Where::Kernel, format!("kernel `{}`", k.name.name));
                cx.kernel_arg = Some(arg);
                let x = self.expr_as(&e.value, &cx, one, &format!("`{}(R)`", e.key));
                if e.key == "w" {
                    w = x;
                } else {
                    dw = x;
                }
            } else {
                let cx = Cx::constant(&format!("kernel `{}`", k.name.name));
                let Some(x) = self.expr_as(&e.value, &cx, one, &format!("`{}`", e.key)) else {
                    continue;
                };
                let Some(v) = types::const_value(&x) else {
                    self.error(
                        Diagnostic::error("E0109", format!("`{}` must be a constant", e.key))
                            .at(e.value.span, "not constant"),
                    );
                    continue;
                };
                match e.key.as_str() {
                    "support" => support = Some(v),
                    "norm1" => norm[0] = Some(v),
                    "norm2" => norm[1] = Some(v),
                    _ => norm[2] = Some(v),
                }
            }
        }
        let missing: Vec<&str> = [
            ("support", support.is_none()),
            ("norm1", norm[0].is_none()),
            ("norm2", norm[1].is_none()),
            ("norm3", norm[2].is_none()),
            ("w(R)", w.is_none()),
            ("dw(R)", dw.is_none()),
        ]
        .iter()
        .filter(|(_, m)| *m)
        .map(|(n, _)| *n)
        .collect();
        if !missing.is_empty() {
            if !self.diags.iter().any(|d| {
                d.is_error()
                    && d.primary
                        .as_ref()
                        .is_some_and(|p| p.0.file == k.span.file && p.0.start >= k.span.start && p.0.end <= k.span.end)
            }) {
                self.error(
                    Diagnostic::error("E0314", format!("kernel `{}` lacks {}", k.name.name, missing.join(", ")))
                        .at(k.name.span, "incomplete kernel"),
                );
            }
            return;
        }
        self.model.kernels.push(ir::Kernel {
            name: k.name.name.clone(),
            support: support.unwrap_or(2.0),
            norm: [norm[0].unwrap_or(0.0), norm[1].unwrap_or(0.0), norm[2].unwrap_or(0.0)],
            arg,
            w: w.expect("checked above"),
            dw: dw.expect("checked above"),
            span: k.span,
        });
    }

    /// A field is written by at most one equation on any group. Each equation that writes a field
    /// some earlier equation writes on a common group is reported once per field, against the
    /// first such equation: comparing every pair made a model of n equations writing one field
    /// n²/2 errors (a 100,000-equation file never finished checking).
    pub(crate) fn check_writers(&mut self) {
        let eqs = self.model.equations.clone();
        // Per field: per group, the first equation that writes it there.
        let mut first: HashMap<FieldId, [Option<usize>; 64]> = HashMap::new();
        for (b, eb) in eqs.iter().enumerate() {
            for f in &eb.writes {
                let by_group = first.entry(*f).or_insert([None; 64]);
                let mut earlier = None;
                for (g, writer) in by_group.iter_mut().enumerate() {
                    if eb.dest.0 & (1 << g) == 0 {
                        continue;
                    }
                    match *writer {
                        Some(a) => earlier = Some(earlier.map_or(a, |e: usize| e.min(a))),
                        None => *writer = Some(b),
                    }
                }
                let Some(a) = earlier.filter(|a| *a != b) else { continue };
                let ea = &eqs[a];
                let name = self.model.field(*f).name.clone();
                let groups = self.model.group_names(ea.dest.intersect(eb.dest));
                self.error(
                    Diagnostic::error(
                        "E0305",
                        format!("`{name}` is written by both `{}` and `{}` on {}", ea.name, eb.name, groups),
                    )
                    .at(eb.span, format!("`{}` writes `{name}`", eb.name))
                    .also(ea.span, format!("`{}` writes `{name}` too", ea.name))
                    .help("restrict them to different groups with `on`, or remove one"),
                );
            }
        }
    }
}

/// A time step restricted to groups (`use timestep::x on G`) reduces over their particles only:
/// every other particle gives the reduction its identity (+∞ to a min, −∞ to a max, 0 to a sum).
fn reduce_only_on(value: &mut ir::Expr, dest: ir::GroupSet) {
    ir::walk_expr_mut(value, &mut |e| {
        if let ExprKind::Reduction(reduce, inner) = &mut e.kind {
            let identity = match reduce {
                ir::Reduce::Min => f64::INFINITY,
                ir::Reduce::Max => f64::NEG_INFINITY,
                ir::Reduce::Sum => 0.0,
            };
            let ty = inner.ty;
            let member = ir::Expr::new(ExprKind::InGroup(ir::Side::I, dest), Type::BOOL);
            let body = std::mem::replace(&mut **inner, ir::Expr::constant(identity, ty));
            **inner = ir::Expr::new(
                ExprKind::Select(Box::new(member), Box::new(body), Box::new(ir::Expr::constant(identity, ty))),
                ty,
            );
        }
    });
}
