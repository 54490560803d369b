//! Checks that need the whole model (files that `integrate` something): every field read is
//! provided on the groups that read it, equations form no cycle within a step, initial values can
//! be computed in some order, and nothing computed or declared goes unused.

use super::Checker;
use crate::diag::{Diagnostic, Span};
use crate::ir::{self, Equation, ExprKind, FieldId, GroupSet, Side, Storage};
use std::collections::BTreeSet;

impl Checker {
    pub(crate) fn model_checks(&mut self) {
        self.check_provided();
        self.check_summed_state();
        self.check_cycles();
        self.check_initial_values();
        self.warn_unused();
    }

    fn is_state(&self, f: FieldId) -> bool {
        self.model.field(f).storage == Storage::State
    }

    /// Groups on which some equation writes `f` (all groups for state).
    fn provided_on(&self, f: FieldId) -> GroupSet {
        if self.is_state(f) {
            return self.model.all_groups();
        }
        self.model
            .equations
            .iter()
            .filter(|e| e.writes.contains(&f))
            .fold(GroupSet::default(), |acc, e| acc.union(e.dest))
    }

    /// A state is obtained one way on each group: integrated from a rate, or computed by a pair
    /// sum in each evaluation (summation density), never both.
    fn check_summed_state(&mut self) {
        let mut errors = vec![];
        for e in self.model.equations.iter().filter(|e| e.is_pair()) {
            for f in e.writes.iter().filter(|f| self.is_state(**f)) {
                for r in self.model.rates.iter().filter(|r| r.state == *f && !r.dest.intersect(e.dest).is_empty()) {
                    let name = &self.model.field(*f).name;
                    let groups = self.model.group_names(r.dest.intersect(e.dest));
                    errors.push(
                        Diagnostic::error(
                            "E0306",
                            format!("`{name}` is both integrated and summed by `{}` on {groups}", e.name),
                        )
                        .at(e.span, format!("`{}` computes `{name}` in every evaluation", e.name))
                        .also(r.span, format!("and this rate integrates `{name}`"))
                        .help("a state is either integrated from a rate or computed by a pair sum on a group: restrict one of them with `on`, or drop one"),
                    );
                }
            }
        }
        self.diags.extend(errors);
    }

    fn first_read_span(stmts: &[&[ir::Stmt]], f: FieldId, side: Side) -> Option<Span> {
        let mut found = None;
        for s in stmts {
            ir::walk_stmts(s, &mut |e| {
                if let ExprKind::Field(g, sd) = e.kind {
                    if g == f && sd == side && found.is_none() {
                        found = Some(e.span);
                    }
                }
            });
        }
        found
    }

    fn check_provided(&mut self) {
        let all = self.model.all_groups();
        let mut errors = vec![];
        for e in &self.model.equations {
            let mut reported = BTreeSet::new();
            for &(f, side) in &e.reads {
                let need = if side == Side::I { e.dest } else { e.sources() };
                let missing = GroupSet(need.0 & !self.provided_on(f).0 & all.0);
                if missing.is_empty() || !reported.insert(f) {
                    continue;
                }
                let span = Self::first_read_span(&stmts_of(e), f, side).unwrap_or(e.span);
                errors.push(self.not_provided(f, missing, span, &format!("`{}`", e.name)));
            }
        }
        for r in &self.model.rates {
            for &f in &r.reads {
                let missing = GroupSet(r.dest.0 & !self.provided_on(f).0 & all.0);
                if !missing.is_empty() {
                    errors.push(self.not_provided(f, missing, r.span, "this rate"));
                }
            }
        }
        for t in &self.model.timesteps {
            for &f in &t.reads {
                let missing = GroupSet(t.dest.0 & !self.provided_on(f).0 & all.0);
                if !missing.is_empty() {
                    errors.push(self.not_provided(f, missing, t.span, &format!("timestep `{}`", t.name)));
                }
            }
        }
        self.diags.extend(errors);
    }

    fn not_provided(&self, f: FieldId, missing: GroupSet, span: Span, reader: &str) -> Diagnostic {
        let field = self.model.field(f);
        let writers: Vec<&Equation> = self.model.equations.iter().filter(|e| e.writes.contains(&f)).collect();
        let groups = self.model.group_names(missing);
        let mut d = Diagnostic::error(
            "E0401",
            format!("field `{}` is read by {reader} before anything provides it", field.name),
        )
        .at(span, format!("read here on {groups}"));
        if writers.is_empty() {
            d = d
                .also(field.span, "declared here")
                .note(format!("no equation writes `{}`, and it is not `state`", field.name))
                .help(format!(
                    "add an equation that computes `{}`, or declare it `state` if the scene sets it",
                    field.name
                ));
        } else {
            for w in writers {
                d = d.also(w.span, format!("`{}` writes it only on {}", w.name, self.model.group_names(w.dest)));
            }
            d = d.help("widen the writer's `on` clause, or restrict the reader to the groups where the field exists");
        }
        d
    }

    /// Evaluation equations (those that write no state) must be orderable within a step; so must
    /// corrections (those that update state after each integration stage).
    fn check_cycles(&mut self) {
        let n = self.model.equations.len();
        let writes_state: Vec<bool> = self.model.equations.iter().map(|e| self.model.is_correction(e)).collect();
        let summed: BTreeSet<FieldId> =
            self.model.equations.iter().filter(|e| e.is_pair()).flat_map(|e| e.writes.iter().copied()).collect();
        let mut edges: Vec<Vec<(usize, FieldId)>> = vec![vec![]; n];
        // What `ew` writes that `er` reads on groups where both run, among fields of its class:
        // state for corrections; for the evaluation, fields and the state pair sums compute.
        let link = |ew: &ir::Equation, er: &ir::Equation, state: bool| -> Option<FieldId> {
            er.reads.iter().find_map(|&(f, side)| {
                let reader_groups = if side == Side::I { er.dest } else { er.sources() };
                let relevant = if state { self.is_state(f) } else { !self.is_state(f) || summed.contains(&f) };
                (relevant && ew.writes.contains(&f) && !ew.dest.intersect(reader_groups).is_empty()).then_some(f)
            })
        };
        for (w, ew) in self.model.equations.iter().enumerate() {
            for (r, er) in self.model.equations.iter().enumerate() {
                if w == r || writes_state[w] != writes_state[r] {
                    continue;
                }
                let Some(f) = link(ew, er, writes_state[w]).or_else(|| link(er, ew, writes_state[w])) else { continue };
                let before = if writes_state[w] {
                    let (we, re) = (ir::EqId(w as u32), ir::EqId(r as u32));
                    self.model.correction_before(we, re, |a, b| link(a, b, true).is_some())
                } else {
                    link(ew, er, false).is_some()
                };
                if before {
                    edges[w].push((r, f));
                }
            }
        }
        if let Some(cycle) = find_cycle(&edges) {
            let names: Vec<String> = cycle.iter().map(|(e, _)| self.model.equations[*e].name.clone()).collect();
            let first = cycle[0].0;
            let mut d = Diagnostic::error(
                "E0402",
                format!("equations form a cycle within one step: {} → {}", names.join(" → "), names[0]),
            )
            .at(self.model.equations[first].span, "this equation depends on its own result");
            for (k, (e, f)) in cycle.iter().enumerate() {
                let next = cycle[(k + 1) % cycle.len()].0;
                d = d.note(format!(
                    "`{}` reads `{}`, which `{}` writes",
                    self.model.equations[next].name,
                    self.model.field(*f).name,
                    self.model.equations[*e].name
                ));
                if k > 0 {
                    d = d.also(self.model.equations[*e].span, format!("`{}`", self.model.equations[*e].name));
                }
            }
            d = d.help("break the cycle: make one of these fields `state` (carried from the previous step), or merge the equations");
            self.error(d);
        }
    }

    fn check_initial_values(&mut self) {
        let n = self.model.fields.len();
        let mut edges: Vec<Vec<(usize, FieldId)>> = vec![vec![]; n];
        let mut errors = vec![];
        for (k, f) in self.model.fields.iter().enumerate() {
            let Some(init) = &f.init else { continue };
            ir::walk_expr(init, &mut |e| {
                if let ExprKind::Field(g, _) = e.kind {
                    if self.model.field(g).storage != Storage::State {
                        errors.push(
                            Diagnostic::error(
                                "E0403",
                                format!(
                                    "the initial value of `{}` reads `{}`, which is computed during the step",
                                    f.name,
                                    self.model.field(g).name
                                ),
                            )
                            .at(e.span, "not available before the first step")
                            .help("initial values read only state fields and parameters"),
                        );
                    } else {
                        edges[g.index()].push((k, g));
                    }
                }
            });
        }
        self.diags.extend(errors);
        if let Some(cycle) = find_cycle(&edges) {
            let names: Vec<String> = cycle.iter().map(|(f, _)| self.model.fields[*f].name.clone()).collect();
            let span = self.model.fields[cycle[0].0].span;
            self.error(
                Diagnostic::error(
                    "E0403",
                    format!("initial values depend on each other: {} → {}", names.join(" → "), names[0]),
                )
                .at(span, "in this cycle"),
            );
        }
    }

    fn warn_unused(&mut self) {
        let mut read: BTreeSet<FieldId> = BTreeSet::new();
        let mut params: BTreeSet<ir::ParamId> = BTreeSet::new();
        let mut note = |e: &ir::Expr| match e.kind {
            ExprKind::Field(f, _) => {
                read.insert(f);
            }
            ExprKind::Param(p, _) => {
                params.insert(p);
            }
            _ => {}
        };
        for e in &self.model.equations {
            for s in stmts_of(e) {
                ir::walk_stmts(s, &mut note);
            }
        }
        for r in &self.model.rates {
            ir::walk_expr(&r.rate, &mut note);
        }
        for t in &self.model.timesteps {
            ir::walk_expr(&t.value, &mut note);
        }
        for f in &self.model.fields {
            if let Some(i) = &f.init {
                ir::walk_expr(i, &mut note);
            }
        }
        for p in &self.model.params {
            if let Some(d) = &p.default {
                ir::walk_expr(d, &mut note);
            }
        }
        read.extend(self.model.rates.iter().map(|r| r.state));
        let mut warnings = vec![];
        for e in &self.model.equations {
            for f in &e.writes {
                if !read.contains(f) && !self.is_state(*f) {
                    let name = &self.model.field(*f).name;
                    warnings.push(
                        Diagnostic::warning(
                            "W0501",
                            format!("`{name}` is computed by `{}` but nothing reads it", e.name),
                        )
                        .at(e.span, format!("writes `{name}`"))
                        .note("it is computed only if a case outputs it"),
                    );
                }
            }
        }
        for (k, p) in self.model.params.iter().enumerate() {
            // The prelude's `gravity` and `axisymmetric` are the scene's: the integrator reads
            // gravity whether or not a model does, and a planar model need not read either.
            if !params.contains(&ir::ParamId(k as u32)) && p.name != ir::GRAVITY && p.name != ir::AXISYMMETRIC {
                warnings.push(
                    Diagnostic::warning("W0502", format!("parameter `{}` is declared but never used", p.name))
                        .at(p.span, "unused"),
                );
            }
        }
        self.diags.extend(warnings);
    }
}

pub(crate) fn stmts_of(e: &Equation) -> Vec<&[ir::Stmt]> {
    match &e.kind {
        ir::EquationKind::PairSum { init, body, finally, .. } => vec![init, body, finally],
        ir::EquationKind::Particle { body } => vec![body],
    }
}

/// A cycle in a graph given by edge lists (node → (node, label)), as the (node, label) path.
fn find_cycle(edges: &[Vec<(usize, FieldId)>]) -> Option<Vec<(usize, FieldId)>> {
    #[derive(Clone, Copy, PartialEq)]
    enum Mark {
        New,
        Active,
        Done,
    }
    fn visit(
        v: usize,
        edges: &[Vec<(usize, FieldId)>],
        mark: &mut [Mark],
        path: &mut Vec<(usize, FieldId)>,
    ) -> Option<Vec<(usize, FieldId)>> {
        mark[v] = Mark::Active;
        for &(w, f) in &edges[v] {
            path.push((v, f));
            if mark[w] == Mark::Active {
                let start = path.iter().position(|(n, _)| *n == w).unwrap_or(0);
                return Some(path[start..].to_vec());
            }
            if mark[w] == Mark::New {
                if let Some(c) = visit(w, edges, mark, path) {
                    return Some(c);
                }
            }
            path.pop();
        }
        mark[v] = Mark::Done;
        None
    }
    let mut mark = vec![Mark::New; edges.len()];
    for v in 0..edges.len() {
        if mark[v] == Mark::New {
            let mut path = vec![];
            if let Some(c) = visit(v, edges, &mut mark, &mut path) {
                return Some(c);
            }
        }
    }
    None
}
