//! The checker: resolves names, infers and checks shapes and physical units, enforces the i/j
//! discipline, and produces the typed IR (`ir::Model`) with each equation's read and write sets.
//!
//! Order of work: collect groups, constants, fields, parameters, helpers and kernels from every
//! module; declare equation outputs; check every body; then, for a complete model (one with an
//! `integrate` block), the model-wide checks in `model.rs`.

mod equations;
mod expr;
pub mod load;
mod model;
pub mod types;

use crate::diag::{closest, Diagnostic, Diagnostics, Sources, Span};
use crate::ir::{self, FieldId, GroupSet, Model, Type};
use crate::syntax::ast::{self, Item, Shape, Storage};
use crate::units::{Ratio, Unit};
use std::collections::{BTreeSet, HashMap};
use std::path::Path;
use std::rc::Rc;

pub use load::{Loader, Stdlib};

/// What `check` gives back: the model (complete as far as it could be checked) and every diagnostic.
pub struct Checked {
    pub model: Model,
    pub diags: Vec<Diagnostic>,
    /// Whether the modules form a whole model (they integrate something) rather than a library.
    pub is_model: bool,
}

impl Checked {
    pub fn has_errors(&self) -> bool {
        self.diags.iter().any(|d| d.is_error())
    }
    pub fn into_result(self) -> Result<(Model, Vec<Diagnostic>), Diagnostics> {
        if self.has_errors() {
            Err(Diagnostics(self.diags))
        } else {
            Ok((self.model, self.diags))
        }
    }
}

/// Loads the given files (and what they `use`) and checks them as one model.
pub fn check_paths(sources: &mut Sources, paths: &[&Path], stdlib: Stdlib) -> Checked {
    let mut loader = Loader::new(sources, stdlib);
    for p in paths {
        loader.load_path(p);
    }
    finish(loader)
}

/// Checks source text (tests, fuzzing, models embedded in case files).
pub fn check_text(sources: &mut Sources, name: &str, text: &str, stdlib: Stdlib) -> Checked {
    let mut loader = Loader::new(sources, stdlib);
    loader.load_text(name, text, None);
    finish(loader)
}

/// Checks stdlib modules by their relative paths.
pub fn check_stdlib_modules(sources: &mut Sources, modules: &[&str], stdlib: Stdlib) -> Checked {
    let mut loader = Loader::new(sources, stdlib);
    for m in modules {
        let _ = loader.load_stdlib_module(m, None, true);
    }
    finish(loader)
}

fn finish(loader: Loader<'_>) -> Checked {
    let Loader { sources, modules, diags, .. } = loader;
    let mut checker = Checker::new();
    checker.diags = diags;
    if checker.diags.iter().any(|d| d.is_error()) {
        // A module that does not parse leaves names undefined; checking the rest would only
        // pile consequences on the real error.
        return Checked { model: checker.model, diags: checker.diags, is_model: false };
    }
    let is_model = modules.iter().any(|m| m.ast.items.iter().any(|i| matches!(i, Item::Integrate(_))));
    checker.builds_on = modules_used(&modules);
    checker.run(&modules, is_model);
    let mut diags = checker.diags;
    dedup(&mut diags);
    let mut model = checker.model;
    for e in &mut model.equations {
        let (line, _) = sources.line_col(e.span);
        e.location = format!("{}:{line}", sources.name(e.span.file));
    }
    for p in &mut model.params {
        // The comment of the first declaration that has one, and where it is.
        let described = std::iter::once(p.span).chain(p.also_declared.iter().copied()).map(|span| {
            let (line, _) = sources.line_col(span);
            let (declared, doc) = declaration_and_doc(sources.text(span.file), line);
            (declared, doc, format!("{}:{line}", sources.name(span.file)))
        });
        let all: Vec<_> = described.collect();
        let (_, doc, location) = all.iter().find(|(_, doc, _)| !doc.is_empty()).unwrap_or(&all[0]).clone();
        // The declaration that gives the default, where one does.
        let with_default = all.iter().find(|(declared, ..)| declared.contains('='));
        p.declared = with_default.filter(|_| p.default.is_some()).unwrap_or(&all[0]).0.clone();
        (p.doc, p.location) = (doc, location);
    }
    Checked { model, diags, is_model }
}

/// A parameter's declaration on line `line` (1-based) of `text`, without `param` and its
/// comment, and its comment: the one after it on the line, else the first sentence of the
/// comment block just above it.
fn declaration_and_doc(text: &str, line: usize) -> (String, String) {
    let lines: Vec<&str> = text.lines().collect();
    let Some(decl) = line.checked_sub(1).and_then(|k| lines.get(k)) else { return Default::default() };
    let (code, after) = decl.split_once("//").unwrap_or((decl, ""));
    let declared = code.trim().trim_start_matches("param").trim().to_string();
    if !after.trim().is_empty() {
        return (declared, after.trim().to_string());
    }
    let above: Vec<&str> =
        lines[..line - 1].iter().rev().take_while(|l| l.trim_start().starts_with("//")).copied().collect();
    let block: Vec<&str> = above.iter().rev().map(|l| l.trim_start().trim_start_matches('/').trim()).collect();
    (declared, first_sentence(&block.join(" ")))
}

/// Up to the first full stop, at most about 120 characters.
fn first_sentence(text: &str) -> String {
    let sentence = text.split_once(". ").map_or(text, |(first, _)| first).trim_end_matches('.');
    match sentence.char_indices().nth(120) {
        Some((cut, _)) => format!("{}…", &sentence[..cut]),
        None => sentence.to_string(),
    }
}

/// For each module's source file, the files of every module it uses, directly or not.
fn modules_used(modules: &[load::Module]) -> HashMap<u32, BTreeSet<u32>> {
    fn reach(modules: &[load::Module], k: usize, out: &mut BTreeSet<u32>) {
        for u in &modules[k].uses {
            if out.insert(modules[u.target].file) {
                reach(modules, u.target, out);
            }
        }
    }
    (0..modules.len())
        .map(|k| {
            let mut used = BTreeSet::new();
            reach(modules, k, &mut used);
            (modules[k].file, used)
        })
        .collect()
}

/// Checks an expression written outside the model (a case file's initial value of `field`, or a
/// probe's expression when `field` is `None`: the text standing at byte `offset` of source `file`)
/// against the checked model: names, shapes and units as in an `init` of the model, and the
/// field's type.
pub fn case_expression(
    model: &Model,
    file: u32,
    offset: usize,
    text: &str,
    field: Option<FieldId>,
) -> Result<ir::Expr, Vec<Diagnostic>> {
    let ast = crate::syntax::parse_expr(file, offset, text).map_err(|d| vec![*d])?;
    let mut checker = Checker::new();
    checker.model = model.clone();
    let value = match field {
        Some(f) => {
            checker.expr_as(&ast, &expr::Cx::particle("an initial value"), model.field(f).ty, "the initial value")
        }
        None => checker.expr(&ast, &expr::Cx::particle("a probe's expression")),
    };
    match value {
        Some(v) if !checker.diags.iter().any(|d| d.is_error()) => Ok(v),
        _ => Err(checker.diags),
    }
}

fn dedup(diags: &mut Vec<Diagnostic>) {
    let mut seen = std::collections::HashSet::new();
    diags.retain(|d| seen.insert((d.message.clone(), d.primary.as_ref().map(|p| p.0))));
}

/// Names no declaration may take: the language's own.
pub const RESERVED: [&str; 15] =
    ["t", "dt", "dim", "I", "pi", "inf", "x_ij", "r_ij", "v_ij", "h_ij", "W_ij", "gradW_ij", "true", "false", "R"];

/// A module's scope, from the `use … on G from S` clauses that reach it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Scope {
    /// The groups its equations run on.
    pub on: GroupSet,
    /// For each group its equations run on (by index), the groups its pair sums see there: each
    /// `use … on G from S` pairs S with G.
    pub from: [GroupSet; 64],
    /// Its pair sums see only particle i's own group (`from own`).
    pub own_group: bool,
    /// Its pair sums see only particle i's own body (`from own body`).
    pub own_body: bool,
}

impl Scope {
    /// Every group, no restriction.
    const ALL: Scope = Scope { on: GroupSet::ALL, from: [GroupSet::ALL; 64], own_group: false, own_body: false };

    /// The groups its pair sums see on group `g`.
    pub fn sources_on(&self, g: ir::GroupId) -> GroupSet {
        self.from[g.0 as usize]
    }
}

/// The binding of a `let` whose value had an error: later uses stay quiet instead of reporting an
/// unknown name.
pub(crate) const POISONED: ir::LocalId = ir::LocalId(u32::MAX);

pub(crate) struct ConstVal {
    value: f64,
    unit: Unit,
}

pub(crate) struct Checker {
    pub(crate) model: Model,
    pub(crate) diags: Vec<Diagnostic>,
    consts: HashMap<String, ConstVal>,
    const_defs: HashMap<String, ast::ConstDecl>,
    const_busy: Vec<String>,
    fns: HashMap<String, Rc<ast::FnDef>>,
    /// Which equation declared each accumulator (for "writes another equation's accumulator").
    accumulator_of: HashMap<FieldId, String>,
    /// For each module's source file, the files of every module it uses, directly or not.
    pub(crate) builds_on: HashMap<u32, BTreeSet<u32>>,
    /// Active `let` and helper-parameter bindings, innermost last.
    scope: Vec<(String, ir::LocalId)>,
    /// The `acc` temporaries of the pair sum being checked, by their short name.
    temps: Vec<(String, FieldId)>,
    /// Helpers being inlined (to catch recursion and to say "called from").
    fn_stack: Vec<(String, Span)>,
    /// How deep `expr` has recursed, and how many expressions it has checked (`expr::MAX_DEPTH`,
    /// `expr::MAX_WORK`); whether E0217 has been reported.
    depth: usize,
    work: usize,
    too_deep_reported: bool,
    /// The groups the module being checked may run on and see as neighbours (`use m on G from S`),
    /// and whether its pair sums see only the destination's own group (`from own`).
    module_scope: Scope,
}

impl Checker {
    fn new() -> Checker {
        Checker {
            model: Model::default(),
            diags: vec![],
            consts: HashMap::new(),
            const_defs: HashMap::new(),
            const_busy: vec![],
            fns: HashMap::new(),
            accumulator_of: HashMap::new(),
            builds_on: HashMap::new(),
            scope: vec![],
            temps: vec![],
            fn_stack: vec![],
            depth: 0,
            work: 0,
            too_deep_reported: false,
            module_scope: Scope::ALL,
        }
    }

    pub(crate) fn error(&mut self, d: Diagnostic) {
        self.diags.push(d);
    }

    fn run(&mut self, modules: &[load::Module], is_model: bool) {
        let items: Vec<&Item> = modules.iter().flat_map(|m| m.ast.items.iter()).collect();
        let owner: Vec<usize> =
            modules.iter().enumerate().flat_map(|(k, m)| m.ast.items.iter().map(move |_| k)).collect();
        self.collect_groups(&items);
        let scopes = self.module_scopes(modules);
        for it in &items {
            if let Item::Const(c) = it {
                if self.const_defs.insert(c.name.name.clone(), c.clone()).is_some() {
                    self.error(
                        Diagnostic::error("E0101", format!("constant `{}` is defined twice", c.name.name))
                            .at(c.name.span, "second definition"),
                    );
                }
            }
        }
        for it in &items {
            match it {
                Item::Field(f) => self.declare_field(f),
                Item::Param(p) => self.declare_param(p),
                Item::Fn(f) if self.fns.insert(f.name.name.clone(), Rc::new(f.clone())).is_some() => {
                    self.error(
                        Diagnostic::error("E0101", format!("helper `{}` is defined twice", f.name.name))
                            .at(f.name.span, "second definition"),
                    );
                }
                _ => {}
            }
        }
        let mut names: Vec<String> = self.const_defs.keys().cloned().collect();
        names.sort();
        for n in names {
            self.const_value(&n);
        }
        for it in &items {
            if let Item::Kernel(k) = it {
                self.kernel(k);
            }
        }
        self.declare_outputs(&items);
        self.check_declaration_values(&items);
        for (it, k) in items.iter().zip(&owner) {
            self.module_scope = scopes[*k];
            match it {
                Item::PairSum(p) => self.pairsum(p),
                Item::Particle(p) => self.particle(p),
                Item::Integrate(i) => self.integrate(i),
                Item::Timestep(t) => self.timestep(t),
                Item::Require(r) => self.requirement(r),
                Item::KernelSelect(k) => match self.model.kernel_id(&k.name) {
                    Some(id) => self.model.kernel = Some(id),
                    None => {
                        let names: Vec<&str> = self.model.kernels.iter().map(|k| k.name.as_str()).collect();
                        let mut d = Diagnostic::error("E0102", format!("unknown kernel `{}`", k.name))
                            .at(k.span, "no kernel of this name");
                        if let Some(b) = closest(&k.name, names.iter().copied()) {
                            d = d.help(format!("did you mean `{b}`?"));
                        } else {
                            d = d.help("define it with `kernel name { ... }` or `use kernels`");
                        }
                        self.error(d);
                    }
                },
                _ => {}
            }
        }
        self.module_scope = Scope::ALL;
        self.check_unchecked_helpers();
        self.check_writers();
        if is_model && !self.diags.iter().any(|d| d.is_error()) {
            self.model_checks();
        }
    }

    /// The groups each module's equations may run on and see, from the `use … on G from S` along
    /// every path from a module the user named: the union over paths of the intersection along
    /// each. Restrictions reach the modules a restricted module uses, unless another path frees them.
    /// `from own` (and `from own body`) holds for a module when it holds on every path (some `use` on
    /// each says it).
    fn module_scopes(&mut self, modules: &[load::Module]) -> Vec<Scope> {
        let all = self.model.all_groups();
        let none = Scope { on: GroupSet::default(), from: [GroupSet::default(); 64], own_group: true, own_body: true };
        let root = Scope { on: all, from: [all; 64], own_group: false, own_body: false };
        let mut scopes: Vec<Scope> =
            modules.iter().enumerate().map(|(k, m)| if m.root || k == 0 { root } else { none }).collect();
        let mut edges = vec![];
        for (k, m) in modules.iter().enumerate() {
            for e in &m.uses {
                let on = self.groups(e.on.as_ref());
                let from = self.groups(e.from.as_ref());
                edges.push((k, e.target, on, from, e.own, e.own_body));
            }
        }
        loop {
            let mut changed = false;
            for &(a, b, on, from, own, own_body) in &edges {
                let (sa, sb) = (scopes[a], scopes[b]);
                if sa.on.intersect(on).is_empty() {
                    continue;
                }
                let mut reach = Scope {
                    on: sb.on.union(sa.on.intersect(on)),
                    from: sb.from,
                    own_group: sb.own_group && (sa.own_group || own),
                    own_body: sb.own_body && (sa.own_body || own_body),
                };
                for g in sa.on.intersect(on).iter(64) {
                    reach.from[g.0 as usize] = sb.sources_on(g).union(sa.sources_on(g).intersect(from));
                }
                if reach != sb {
                    scopes[b] = reach;
                    changed = true;
                }
            }
            if !changed {
                self.warn_own_undone(modules, &scopes);
                return scopes;
            }
        }
    }

    /// W0503: a `use … from own` (or `from own body`) that another path undoes. `from own` holds
    /// for a module only when every path to it says so, so a plain `use` of the same module
    /// anywhere else (a library module that only wanted its fields) silently widens its sums to
    /// every neighbour: the model's restriction is not what runs.
    fn warn_own_undone(&mut self, modules: &[load::Module], scopes: &[Scope]) {
        let reached = |k: usize| !scopes[k].on.is_empty();
        let edges: Vec<(usize, &load::UseEdge)> =
            modules.iter().enumerate().flat_map(|(k, m)| m.uses.iter().map(move |e| (k, e))).collect();
        for &(a, asked) in &edges {
            let target = &scopes[asked.target];
            let group = asked.own && !target.own_group;
            if !(group || asked.own_body && !target.own_body) || !reached(a) {
                continue;
            }
            let clause = if group { "from own" } else { "from own body" };
            let keeps = |k: usize, e: &load::UseEdge| {
                if group {
                    e.own || scopes[k].own_group
                } else {
                    e.own_body || scopes[k].own_body
                }
            };
            let Some((_, freeing)) =
                edges.iter().find(|&&(k, e)| e.target == asked.target && reached(k) && !keeps(k, e))
            else {
                continue;
            };
            self.diags.push(
                Diagnostic::warning(
                    "W0503",
                    format!("this `{clause}` does not hold: another `use` of the module has none"),
                )
                .at(asked.span, format!("`{clause}` asked here"))
                .also(freeing.span, "used here without it")
                .note(format!(
                    "`{clause}` holds for a module only when every `use` that reaches it says so; here the module's \
                         pair sums see every neighbour"
                ))
                .help(format!("add `{clause}` to the other `use`, or drop it if that module only needs the fields")),
            );
        }
    }

    /// An equation's groups (`on`, default all) within the module's scope.
    pub(crate) fn scoped_groups(&mut self, list: Option<&Vec<ast::Ident>>, span: Span, what: &str) -> GroupSet {
        let scope = self.module_scope.on;
        let set = self.groups(list).intersect(scope);
        self.check_left_some(set, scope, false, span, what);
        set
    }

    /// A pair sum's neighbour groups (`from`, default all) on each of its groups `dest`, within the
    /// module's scope: their union, and the groups of `dest` that see fewer (each with its own).
    pub(crate) fn scoped_sources(
        &mut self,
        list: Option<&Vec<ast::Ident>>,
        dest: GroupSet,
        span: Span,
        what: &str,
    ) -> (GroupSet, Vec<(ir::GroupId, GroupSet)>) {
        let from = self.groups(list);
        let n = self.model.groups.len();
        let on_each: Vec<_> = dest.iter(n).map(|g| (g, from.intersect(self.module_scope.sources_on(g)))).collect();
        for &(g, s) in &on_each {
            let on_g = format!("{what} on `{}`", self.model.groups[g.0 as usize].name);
            self.check_left_some(s, self.module_scope.sources_on(g), true, span, &on_g);
        }
        let union = on_each.iter().fold(GroupSet::default(), |a, (_, s)| a.union(*s));
        (union, on_each.into_iter().filter(|(_, s)| *s != union).collect())
    }

    /// E0110: the `use … on`/`from` clauses that reach an equation's module leave it no group.
    fn check_left_some(&mut self, set: GroupSet, scope: GroupSet, sources: bool, span: Span, what: &str) {
        if set.is_empty() && scope != GroupSet::ALL && scope != self.model.all_groups() {
            let word = if sources { "neighbour" } else { "particle" };
            self.error(
                Diagnostic::error("E0110", format!("{what} is left no {word} group to run on"))
                    .at(span, "defined here")
                    .note(format!(
                        "the `use … {}` clauses that reach its module allow only: {}",
                        if sources { "from" } else { "on" },
                        self.model.group_names(scope)
                    )),
            );
        }
    }

    fn collect_groups(&mut self, items: &[&Item]) {
        for it in items {
            if let Item::Groups(gs) = it {
                for g in gs {
                    if self.model.group_id(&g.name).is_none() {
                        self.model.groups.push(ir::Group { name: g.name.clone(), span: g.span });
                    }
                }
            }
        }
        if self.model.groups.is_empty() {
            // A model that declares no group has one: every particle belongs to `all`.
            self.model.groups.push(ir::Group { name: "all".into(), span: Span::default() });
        }
        if self.model.groups.len() > 64 {
            let span = self.model.groups[64].span;
            self.error(Diagnostic::error("E0103", "a model has at most 64 particle groups").at(span, "the 65th"));
            self.model.groups.truncate(64);
        }
    }

    pub(crate) fn groups(&mut self, list: Option<&Vec<ast::Ident>>) -> GroupSet {
        let Some(list) = list else {
            return self.model.all_groups();
        };
        let mut set = GroupSet::default();
        for g in list {
            match self.model.group_id(&g.name) {
                Some(id) => set = set.with(id),
                None => {
                    let names: Vec<String> = self.model.groups.iter().map(|g| g.name.clone()).collect();
                    let mut d = Diagnostic::error("E0104", format!("unknown particle group `{}`", g.name))
                        .at(g.span, "no group of this name");
                    if let Some(b) = closest(&g.name, names.iter().map(String::as_str)) {
                        d = d.help(format!("did you mean `{b}`?"));
                    } else if names.is_empty() {
                        d = d.help(format!("declare it: `group {}`", g.name));
                    } else {
                        d = d.note(format!("the groups are: {}", names.join(", ")));
                    }
                    self.error(d);
                }
            }
        }
        set
    }

    pub(crate) fn unit(&mut self, u: &ast::UnitAnnot) -> Option<Unit> {
        self.unit_expr(&u.expr)
    }

    fn unit_expr(&mut self, u: &ast::UnitExpr) -> Option<Unit> {
        match u {
            ast::UnitExpr::One => Some(Unit::ONE),
            ast::UnitExpr::Name(n) => match Unit::named(&n.name) {
                Some(u) => Some(u),
                None => {
                    let mut d = Diagnostic::error("E0105", format!("unknown unit `{}`", n.name))
                        .at(n.span, "not a unit the language knows");
                    let prefixed = ["k", "M", "G", "m", "u", "n", "c", "m"]
                        .iter()
                        .any(|p| n.name.strip_prefix(p).is_some_and(|rest| Unit::named(rest).is_some()));
                    if prefixed {
                        d = d.help("units in the language are SI without prefixes; write the base unit (values in case files may use prefixes)");
                    } else if let Some(b) = closest(&n.name, Unit::KNOWN.iter().copied()) {
                        d = d.help(format!("did you mean `{b}`?"));
                    } else {
                        d = d.note(format!("known units: {}", Unit::KNOWN.join(", ")));
                    }
                    self.error(d);
                    None
                }
            },
            ast::UnitExpr::Mul(a, b) => {
                let (a, b) = (self.unit_expr(a)?, self.unit_expr(b)?);
                a.mul(&b)
            }
            ast::UnitExpr::Div(a, b) => {
                let (a, b) = (self.unit_expr(a)?, self.unit_expr(b)?);
                a.div(&b)
            }
            ast::UnitExpr::Pow(a, n, d, span) => {
                let base = self.unit_expr(a)?;
                match Ratio::new(*n, *d) {
                    Some(r) => base.powr(r),
                    None => {
                        self.error(
                            Diagnostic::error("E0105", "a unit exponent with a zero denominator").at(*span, "here"),
                        );
                        None
                    }
                }
            }
        }
    }

    pub(crate) fn type_spec(&mut self, t: &ast::TypeSpec) -> Option<Type> {
        let unit = match &t.unit {
            Some(u) => self.unit(u)?,
            None => Unit::ONE,
        };
        Some(Type::new(t.shape, unit))
    }

    fn reserved(&mut self, name: &ast::Ident, what: &str) -> bool {
        if RESERVED.contains(&name.name.as_str()) || types::builtin_by_name(&name.name).is_some() {
            self.error(
                Diagnostic::error(
                    "E0106",
                    format!("`{}` is a name of the language and cannot name a {what}", name.name),
                )
                .at(name.span, "reserved name"),
            );
            return true;
        }
        false
    }

    fn declare_field(&mut self, f: &ast::FieldDecl) {
        if self.reserved(&f.name, "field") {
            return;
        }
        let Some(ty) = self.type_spec(&f.ty) else {
            return;
        };
        self.add_field(&f.name, ty, f.storage, f.name.span);
    }

    /// Declares a field, or accepts an identical redeclaration.
    pub(crate) fn add_field(&mut self, name: &ast::Ident, ty: Type, storage: Storage, span: Span) -> Option<FieldId> {
        if let Some(id) = self.model.field_id(&name.name) {
            let old = self.model.field(id).clone();
            if old.ty != ty || old.storage != storage {
                let word = |s: Storage| {
                    if s == Storage::State {
                        "state"
                    } else {
                        "field"
                    }
                };
                self.error(
                    Diagnostic::error("E0107", format!("conflicting declarations of field `{}`", name.name))
                        .at(name.span, format!("declared here as {} {}", word(storage), ty))
                        .also(old.span, format!("and here as {} {}", word(old.storage), old.ty)),
                );
                return None;
            }
            return Some(id);
        }
        if self.model.param_id(&name.name).is_some() {
            self.error(
                Diagnostic::error("E0107", format!("`{}` is already a parameter", name.name))
                    .at(name.span, "also declared as a field"),
            );
            return None;
        }
        self.model.fields.push(ir::Field { name: name.name.clone(), ty, storage, init: None, span, saved_of: None });
        Some(FieldId(self.model.fields.len() as u32 - 1))
    }

    fn declare_param(&mut self, p: &ast::ParamDecl) {
        if self.reserved(&p.name, "parameter") {
            return;
        }
        let Some(ty) = self.type_spec(&p.ty) else {
            return;
        };
        if let Some(id) = self.model.param_id(&p.name.name) {
            let old = self.model.params[id.index()].clone();
            if old.ty != ty {
                self.error(
                    Diagnostic::error("E0107", format!("conflicting declarations of parameter `{}`", p.name.name))
                        .at(p.name.span, format!("declared here as {ty}"))
                        .also(old.span, format!("and here as {}", old.ty)),
                );
            }
            self.model.params[id.index()].also_declared.push(p.name.span);
            return;
        }
        if self.model.field_id(&p.name.name).is_some() {
            self.error(
                Diagnostic::error("E0107", format!("`{}` is already a field", p.name.name))
                    .at(p.name.span, "also declared as a parameter"),
            );
            return;
        }
        self.model.params.push(ir::Param {
            name: p.name.name.clone(),
            ty,
            default: None,
            span: p.name.span,
            declared: String::new(),
            doc: String::new(),
            location: String::new(),
            also_declared: vec![],
        });
    }

    /// Field initial values and parameter defaults, once every name is known.
    fn check_declaration_values(&mut self, items: &[&Item]) {
        for it in items {
            match it {
                Item::Field(f) => {
                    let Some(init) = &f.init else { continue };
                    let Some(id) = self.model.field_id(&f.name.name) else {
                        continue;
                    };
                    if f.storage != Storage::State {
                        self.error(
                            Diagnostic::error(
                                "E0108",
                                format!(
                                    "only state fields have initial values; `{}` is recomputed every step",
                                    f.name.name
                                ),
                            )
                            .at(init.span, "initial value of a non-state field")
                            .help(format!(
                                "declare it `state {}: ...` if it carries over from step to step",
                                f.name.name
                            )),
                        );
                        continue;
                    }
                    let ty = self.model.field(id).ty;
                    let cx = expr::Cx::particle("the initial value of a field");
                    if let Some(e) = self.expr_as(init, &cx, ty, "the initial value") {
                        self.model.fields[id.index()].init = Some(e);
                    }
                }
                Item::Param(p) => {
                    let Some(default) = &p.default else { continue };
                    let Some(id) = self.model.param_id(&p.name.name) else {
                        continue;
                    };
                    let ty = self.model.params[id.index()].ty;
                    let cx = expr::Cx::new(expr::Where::Material, "a parameter's default");
                    if let Some(first) = &self.model.params[id.index()].default {
                        let first = crate::host_eval::constant(first);
                        let second =
                            self.expr_as(default, &cx, ty, "the default").as_ref().and_then(crate::host_eval::constant);
                        if first.is_some() && first == second {
                            continue; // two modules that agree on a constant default
                        }
                        self.error(
                            Diagnostic::error("E0107", format!("parameter `{}` has two defaults", p.name.name))
                                .at(default.span, "second default")
                                .help("keep one, or give both the same constant; a material can always bind its own value"),
                        );
                        continue;
                    }
                    if let Some(e) = self.expr_as(default, &cx, ty, "the default") {
                        self.model.params[id.index()].default = Some(e);
                    }
                }
                _ => {}
            }
        }
    }

    /// Evaluates a constant (on first use), detecting cycles.
    pub(crate) fn const_value(&mut self, name: &str) -> Option<(f64, Unit)> {
        if let Some(c) = self.consts.get(name) {
            return Some((c.value, c.unit));
        }
        let def = self.const_defs.get(name)?.clone();
        if self.const_busy.iter().any(|n| n == name) {
            self.error(
                Diagnostic::error("E0109", format!("constant `{name}` is defined in terms of itself"))
                    .at(def.name.span, "cycle"),
            );
            return None;
        }
        self.const_busy.push(name.to_string());
        let cx = expr::Cx::constant("a constant");
        let result = self.expr(&def.value, &cx);
        self.const_busy.pop();
        let e = result?;
        if e.ty.shape != Shape::Scalar {
            self.error(
                Diagnostic::error("E0109", "constants are scalars")
                    .at(def.value.span, format!("this is a {}", e.ty.shape.name())),
            );
            return None;
        }
        let Some(v) = types::const_value(&e) else {
            self.error(
                Diagnostic::error("E0109", format!("`{name}` is not a constant expression"))
                    .at(def.value.span, "cannot be computed before the run"),
            );
            return None;
        };
        self.consts.insert(name.to_string(), ConstVal { value: v, unit: e.ty.unit });
        Some((v, e.ty.unit))
    }

    pub(crate) fn has_const(&self, name: &str) -> bool {
        self.const_defs.contains_key(name)
    }

    /// A field by name, the current pair sum's `acc` temporaries first.
    pub(crate) fn lookup_field(&self, name: &str) -> Option<FieldId> {
        self.temps.iter().find(|(n, _)| n == name).map(|(_, f)| *f).or_else(|| self.model.field_id(name))
    }

    pub(crate) fn helper(&self, name: &str) -> Option<Rc<ast::FnDef>> {
        self.fns.get(name).cloned()
    }

    pub(crate) fn helper_names(&self) -> Vec<String> {
        self.fns.keys().cloned().collect()
    }

    pub(crate) fn const_names(&self) -> Vec<String> {
        self.const_defs.keys().cloned().collect()
    }
}
