//! The WGSL writer: IR statements and expressions as WGSL with vector and matrix types, field
//! and parameter accessors named after what they read, a comment per equation with its source.

use super::names::{Namer, Names};
use super::{globals as gl, prelude, validate, Binding, Kernel, KernelKind, Layout};
use crate::ir::{
    self, Builtin, EqId, EquationKind, Expr, ExprKind, FieldId, Global, GroupId, GroupSet, LocalId, Op, PairValue,
    ParamId, Reduce, Shape, Side, Stmt, Storage,
};
use crate::schedule::{Block, PassVariant, Plan, TailItem};
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::fmt::Write;

/// Workgroup size of every per-particle kernel.
pub const WORKGROUP: u32 = 64;

/// Entry point arguments of per-particle kernels, and their linear invocation index: the runtime
/// dispatches a 2D grid of workgroups when one dimension would exceed the device's limit.
const ENTRY_ARGS: &str =
    "@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) li: u32";
const LINEAR: &str = "(wg.x + wg.y * nwg.x) * 64u + li";

pub fn generate(plan: &Plan, cell_helpers: &str) -> Result<Vec<Kernel>, String> {
    if plan.model.groups.len() > 32 {
        return Err("the GPU backend handles at most 32 particle groups".into());
    }
    let lay = Layout::new(plan);
    let mut out = vec![];
    for (k, pass) in plan.passes.iter().enumerate() {
        for v in &pass.variants {
            out.push(pass_kernel(plan, &lay, k, v, cell_helpers));
        }
    }
    for (s, stage) in plan.stages.iter().enumerate() {
        let mut blocks = stage.updates.clone();
        blocks.extend(eq_blocks(plan, &stage.corrections));
        blocks.extend(eq_blocks(plan, &stage.derived));
        for g in plan.groups.iter(plan.model.groups.len()) {
            if blocks.iter().any(|b| b.dest.contains(g)) {
                let name = format!("update{}_{}", s + 1, group_name(plan, g));
                let title = format!("integrator stage {} ({})", s + 1, stage.name);
                out.push(particle_kernel(
                    plan,
                    &lay,
                    &name,
                    KernelKind::Update { stage: s, group: g },
                    g,
                    &blocks,
                    &title,
                ));
            }
        }
    }
    if !plan.saved.is_empty() {
        let stmts: Vec<Stmt> =
            plan.saved.iter().map(|(f, s)| Stmt::Set(*s, Expr::field(*f, plan.model.field(*f).ty))).collect();
        let block = Block { name: "save the state at the start of the step".into(), dest: plan.groups, stmts };
        for g in plan.groups.iter(plan.model.groups.len()) {
            let name = format!("save_{}", group_name(plan, g));
            out.push(particle_kernel(
                plan,
                &lay,
                &name,
                KernelKind::Save { group: g },
                g,
                std::slice::from_ref(&block),
                "save",
            ));
        }
    }
    let derived = eq_blocks(plan, &plan.derived);
    for g in plan.groups.iter(plan.model.groups.len()) {
        if derived.iter().any(|b| b.dest.contains(g)) {
            let name = format!("initialise_{}", group_name(plan, g));
            out.push(particle_kernel(
                plan,
                &lay,
                &name,
                KernelKind::Initialise { group: g },
                g,
                &derived,
                "state-only equations",
            ));
        }
    }
    out.push(reduction_kernel(plan, &lay));
    out.extend(watch_kernel(plan, &lay));
    out.push(timestep_kernel(plan));
    out.push(advance_kernel());
    // A test seam: `PAIRSUM_WGSL_FAULT` breaks the first kernel, so that the path of a module
    // naga rejects can be exercised end to end.
    if crate::config::env().wgsl_fault {
        if let Some(k) = out.first_mut() {
            k.wgsl.push_str("fn broken() -> f32 { return undefined_name; }\n");
        }
    }
    for k in &out {
        validate(&k.name, &k.wgsl).map_err(|e| format!("compiler bug: {e}\n--- {}.wgsl ---\n{}", k.name, k.wgsl))?;
    }
    Ok(out)
}

fn group_name(plan: &Plan, g: GroupId) -> String {
    sanitize(&plan.model.groups[g.index()].name)
}

fn sanitize(s: &str) -> String {
    s.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' { c } else { '_' }).collect()
}

fn eq_blocks(plan: &Plan, eqs: &[EqId]) -> Vec<Block> {
    plan.tail_blocks(&eqs.iter().map(|e| TailItem::Particle(*e)).collect::<Vec<_>>())
}

/// The WGSL type of a shape in `dim` dimensions.
fn ty(shape: Shape, dim: usize) -> String {
    match (shape, dim) {
        (Shape::Bool, _) => "bool".into(),
        (Shape::Scalar, _) | (_, 1) => "f32".into(),
        (Shape::Vec, d) => format!("vec{d}<f32>"),
        (_, d) => format!("mat{d}x{d}<f32>"),
    }
}

fn is_mat(shape: Shape, dim: usize) -> bool {
    dim > 1 && matches!(shape, Shape::SymTensor | Shape::SkewTensor | Shape::Tensor)
}

/// A WGSL float literal (f32 precision; infinities through helpers, never as constants).
fn lit(v: f64) -> String {
    let f = v as f32;
    if f.is_nan() {
        return "nan()".into();
    }
    if f.is_infinite() {
        return if f > 0.0 { "pinf()".into() } else { "(-pinf())".into() };
    }
    let s = format!("{f:?}");
    if s.contains('.') || s.contains('e') {
        s
    } else {
        format!("{s}.0")
    }
}

/// A value filled into every component of a shape.
fn fill(v: f64, shape: Shape, dim: usize) -> String {
    if shape == Shape::Bool {
        return if v != 0.0 { "true".into() } else { "false".into() };
    }
    let x = lit(v);
    match (shape, dim) {
        (Shape::Scalar, _) | (_, 1) => x,
        (Shape::Vec, d) => format!("vec{d}<f32>({x})"),
        (_, d) if v == 0.0 => format!("mat{d}x{d}<f32>()"),
        (_, d) => format!("mat{d}x{d}<f32>({})", vec![x; d * d].join(", ")),
    }
}

/// What a kernel writer knows about where it is.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Mode {
    /// Particle i of the kernel's group `G`.
    Group,
    /// Particle i of any group (the group read per particle).
    Any,
    /// No particle (the time-step kernel).
    None,
}

struct Writer<'a> {
    plan: &'a Plan,
    lay: &'a Layout,
    dim: usize,
    mode: Mode,
    out: String,
    indent: usize,
    local_names: HashMap<LocalId, String>,
    /// The identifiers of fields and parameters (the same in every kernel of a plan).
    names: Names,
    /// Gives out the kernel's local names.
    namer: Namer,
    /// The variable holding each field's current value for particle i (set, or accumulated).
    current: BTreeMap<FieldId, String>,
    /// The variables holding particle i's parameters, loaded once before a neighbour loop.
    params_i: BTreeMap<ParamId, String>,
    /// Accessors the kernel needs: (field, side), (param, side).
    fields: BTreeSet<(FieldId, Side)>,
    params: BTreeSet<(ParamId, Side)>,
    stores: BTreeSet<FieldId>,
    /// Kahan compensation variables of compensated sums.
    compensation: BTreeMap<FieldId, String>,
    /// Whether the pair loop reads `W_ij` or `gradW_ij`, which it then computes once per pair
    /// (`W_at` and `gradW_at` call the kernel functions themselves).
    reads_pair_kernel: bool,
    reductions: usize,
    tmp: usize,
    /// The groups particle i and its neighbours j can be in (a pass kernel's destination group
    /// and sources): `i in S` and `j in S` these settle are written as `true` or `false`, so a
    /// term selected away on the group is dead code the shader compiler drops.
    groups: (GroupSet, GroupSet),
}

impl<'a> Writer<'a> {
    fn new(plan: &'a Plan, lay: &'a Layout, mode: Mode) -> Writer<'a> {
        let names = Names::new(&plan.model);
        let namer = names.locals();
        Writer {
            plan,
            lay,
            dim: plan.dim,
            mode,
            out: String::new(),
            indent: 1,
            local_names: HashMap::new(),
            names,
            namer,
            current: BTreeMap::new(),
            params_i: BTreeMap::new(),
            fields: BTreeSet::new(),
            params: BTreeSet::new(),
            stores: BTreeSet::new(),
            compensation: BTreeMap::new(),
            reads_pair_kernel: false,
            reductions: 0,
            tmp: 0,
            groups: (GroupSet::ALL, GroupSet::ALL),
        }
    }

    fn line(&mut self, s: impl AsRef<str>) {
        for _ in 0..self.indent {
            self.out.push_str("    ");
        }
        self.out.push_str(s.as_ref());
        self.out.push('\n');
    }

    fn fresh(&mut self, base: &str) -> String {
        self.namer.call(base)
    }

    fn local(&mut self, id: LocalId) -> String {
        if let Some(n) = self.local_names.get(&id) {
            return n.clone();
        }
        let base = self.plan.model.locals.get(id.index()).map(|l| l.name.clone()).unwrap_or_else(|| "v".into());
        let n = self.fresh(&base);
        self.local_names.insert(id, n.clone());
        n
    }

    fn field_name(&self, f: FieldId) -> String {
        self.names.field(f).to_string()
    }

    fn shape_of(&self, f: FieldId) -> Shape {
        self.plan.model.field(f).ty.shape
    }

    /// The location of a source span, for comments.
    fn comment_for(&self, name: &str, kind: &str) -> String {
        format!("// {kind} {name}")
    }

    fn expr(&mut self, e: &Expr) -> String {
        let d = self.dim;
        let shape = e.ty.shape;
        match &e.kind {
            ExprKind::Const(v) => fill(*v, shape, d),
            ExprKind::Field(f, side) => {
                if *side == Side::I {
                    if let Some(v) = self.current.get(f) {
                        return v.clone();
                    }
                    self.fields.insert((*f, Side::I));
                    format!("ld_{}(i)", self.field_name(*f))
                } else {
                    self.fields.insert((*f, Side::J));
                    format!("ldj_{}(j, sgn)", self.field_name(*f))
                }
            }
            ExprKind::Param(p, side) => {
                self.params.insert((*p, *side));
                let name = self.names.param(*p);
                if *side == Side::I {
                    if let Some(v) = self.params_i.get(p) {
                        return v.clone();
                    }
                    format!("prm_{name}(i)")
                } else {
                    format!("prm_{name}(j)")
                }
            }
            ExprKind::Local(id) => self.local(*id),
            ExprKind::Pair(p) => {
                if matches!(p, PairValue::W | PairValue::GradW) {
                    self.reads_pair_kernel = true;
                }
                match p {
                    PairValue::Xij => "x_ij",
                    PairValue::Rij => "r_ij",
                    PairValue::Hij => "h_ij",
                    PairValue::W => "W_ij",
                    PairValue::GradW => "gradW_ij",
                }
                .into()
            }
            ExprKind::Global(g) => match g {
                Global::Time => "t".into(),
                Global::Dt => "dt".into(),
                Global::Dim => lit(d as f64),
            },
            ExprKind::Identity => {
                if d == 1 {
                    "1.0".into()
                } else {
                    "eye()".into()
                }
            }
            ExprKind::InGroup(side, set) => {
                let (who, possible) = if *side == Side::I { ("i", self.groups.0) } else { ("j", self.groups.1) };
                match set.decides(possible) {
                    Some(known) => known.to_string(),
                    None => format!("in_groups({}u, ints[{who}])", set.0 as u32),
                }
            }
            ExprKind::Unary(op, a) => {
                let x = self.expr(a);
                match op {
                    Op::Not => format!("(!{x})"),
                    _ if is_mat(shape, d) => format!("neg_m({x})"),
                    _ => format!("(-{x})"),
                }
            }
            ExprKind::Binary(op, a, b) => self.binary(*op, a, b, shape),
            ExprKind::Call(f, args) => self.call(*f, args, shape),
            ExprKind::Select(c, a, b) => {
                let (c, a, b) = (self.expr(c), self.expr(a), self.expr(b));
                if is_mat(shape, d) {
                    format!("sel_m({b}, {a}, {c})")
                } else {
                    format!("select({b}, {a}, {c})")
                }
            }
            ExprKind::ToTensor(a) => self.expr(a),
            ExprKind::Component(a, r, c) => {
                let x = self.expr(a);
                match (a.ty.shape, d) {
                    (_, 1) => x,
                    (Shape::Vec, _) => format!("{x}[{r}]"),
                    _ => format!("{x}[{c}][{r}]"),
                }
            }
            ExprKind::Let(id, value, body) => {
                let v = self.expr(value);
                let name = self.local(*id);
                self.line(format!("let {name} = {v};"));
                self.expr(body)
            }
            ExprKind::Reduction(..) => {
                let k = self.reductions;
                self.reductions += 1;
                format!("globals[{}u]", gl::REDUCTIONS + k)
            }
        }
    }

    /// A value used more than once in what is emitted: bound to a `let` first.
    fn bind(&mut self, x: String) -> String {
        if x.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return x;
        }
        self.tmp += 1;
        let name = self.fresh(&format!("p{}", self.tmp));
        self.line(format!("let {name} = {x};"));
        name
    }

    fn binary(&mut self, op: Op, a: &Expr, b: &Expr, shape: Shape) -> String {
        let d = self.dim;
        if op == Op::Pow {
            return self.power(a, b);
        }
        let (x, y) = (self.expr(a), self.expr(b));
        let sym = match op {
            Op::Add => "+",
            Op::Sub => "-",
            Op::Scale | Op::MatVec | Op::MatMul => "*",
            Op::Div if is_mat(shape, d) => return format!("div_m({x}, {y})"),
            Op::Div => "/",
            Op::Lt => "<",
            Op::Le => "<=",
            Op::Gt => ">",
            Op::Ge => ">=",
            Op::Eq => "==",
            Op::Ne => "!=",
            Op::And => "&&",
            Op::Or => "||",
            Op::Neg | Op::Not | Op::Pow => unreachable!("unary or handled"),
        };
        format!("({x} {sym} {y})")
    }

    /// Integer and half-integer powers by multiplication (WGSL's `pow` is undefined for a
    /// negative base); others by `pow`.
    fn power(&mut self, a: &Expr, b: &Expr) -> String {
        let base = self.expr(a);
        let exp = crate::check::types::const_value(b);
        match exp {
            Some(n) if n.fract() == 0.0 && n.abs() <= 8.0 => {
                if n == 0.0 {
                    return "1.0".into();
                }
                let x = self.bind(base);
                let prod = vec![x; n.unsigned_abs_f()].join(" * ");
                if n < 0.0 {
                    format!("(1.0 / ({prod}))")
                } else {
                    format!("({prod})")
                }
            }
            Some(h) if (h * 2.0).fract() == 0.0 && h.abs() <= 8.0 => {
                let x = self.bind(base);
                let k = (h.abs() - 0.5) as usize;
                let mut terms = vec![x.clone(); k];
                terms.push(format!("sqrt({x})"));
                let prod = terms.join(" * ");
                if h < 0.0 {
                    format!("(1.0 / ({prod}))")
                } else {
                    format!("({prod})")
                }
            }
            _ => {
                let e = self.expr(b);
                format!("pow({base}, {e})")
            }
        }
    }

    fn call(&mut self, f: Builtin, args: &[Expr], shape: Shape) -> String {
        let d = self.dim;
        let a: Vec<String> = args.iter().map(|x| self.expr(x)).collect();
        let arg_mat = args.first().is_some_and(|x| is_mat(x.ty.shape, d));
        let one_d = d == 1;
        match f {
            Builtin::Dot | Builtin::DDot | Builtin::Outer if one_d => format!("({} * {})", a[0], a[1]),
            Builtin::Dot => format!("dot({}, {})", a[0], a[1]),
            Builtin::DDot => format!("ddot({}, {})", a[0], a[1]),
            Builtin::Outer => format!("outer({}, {})", a[0], a[1]),
            Builtin::Sym | Builtin::Transpose | Builtin::Trace | Builtin::Diag if one_d => a[0].clone(),
            Builtin::Skew if one_d => "0.0".into(),
            Builtin::Dev if one_d => format!("({} * (2.0 / 3.0))", a[0]),
            Builtin::Sym => format!("sym({})", a[0]),
            Builtin::Skew => format!("skew({})", a[0]),
            Builtin::Dev => format!("dev({})", a[0]),
            Builtin::Trace => format!("trace({})", a[0]),
            Builtin::Transpose => format!("transpose({})", a[0]),
            Builtin::Diag => format!("diag({})", a[0]),
            Builtin::Norm if one_d => format!("abs({})", a[0]),
            Builtin::Norm if arg_mat => format!("frob({})", a[0]),
            Builtin::Norm => format!("length({})", a[0]),
            Builtin::Inv if one_d => format!("(1.0 / {})", a[0]),
            Builtin::Inv => format!("inv({})", a[0]),
            Builtin::Det if one_d => a[0].clone(),
            Builtin::Det => format!("determinant({})", a[0]),
            Builtin::Sqrt => format!("sqrt({})", a[0]),
            Builtin::Exp => format!("exp({})", a[0]),
            Builtin::Ln => format!("log({})", a[0]),
            Builtin::Elementary(e) => format!("{}({})", e.name(), a[0]),
            Builtin::Abs if is_mat(shape, d) => format!("abs_m({})", a[0]),
            Builtin::Abs => format!("abs({})", a[0]),
            Builtin::Min if is_mat(shape, d) => format!("min_m({}, {})", a[0], a[1]),
            Builtin::Max if is_mat(shape, d) => format!("max_m({}, {})", a[0], a[1]),
            Builtin::Min => format!("min({}, {})", a[0], a[1]),
            Builtin::Max => format!("max({}, {})", a[0], a[1]),
            Builtin::KernelAt => format!("kernel_w_at({}, {})", a[0], a[1]),
            Builtin::KernelGradAt => format!("kernel_grad_at({}, {})", a[0], a[1]),
            Builtin::Vector if one_d => a[0].clone(),
            Builtin::Vector => {
                let c: Vec<String> = (0..d).map(|k| a.get(k).cloned().unwrap_or_else(|| "0.0".into())).collect();
                format!("vec{d}<f32>({})", c.join(", "))
            }
        }
    }

    fn stmts(&mut self, stmts: &[Stmt]) {
        for s in stmts {
            match s {
                Stmt::Let(id, e) => {
                    let v = self.expr(e);
                    let name = self.local(*id);
                    self.line(format!("let {name} = {v};"));
                }
                Stmt::Set(f, e) => {
                    let v = self.expr(e);
                    let var = self.current.get(f).cloned().expect("every set field has a variable");
                    self.line(format!("{var} = {v};"));
                    self.stores.insert(*f);
                }
                Stmt::Accum(f, r, e) => {
                    let v = self.expr(e);
                    let var = self.current.get(f).cloned().expect("every accumulator has a variable");
                    let m = is_mat(self.shape_of(*f), self.dim);
                    if let (Reduce::Sum, Some(c)) = (r, self.compensation.get(f).cloned()) {
                        // Kahan: c carries the low-order part the sum has lost so far. Shader
                        // compilers may reassociate floating point and fold (t − s) − y to 0, so
                        // t and s pass through `opaque` (XOR with a run-time zero) first.
                        let op = match ty(self.shape_of(*f), self.dim).as_str() {
                            "f32" => "opaque_s",
                            t if t.starts_with("vec") => "opaque_v",
                            _ => "opaque_m",
                        };
                        self.line(format!(
                            "{{ let y_ = {v} - {c}; let t_ = {var} + y_; {c} = ({op}(t_, z_) - {op}({var}, z_)) - y_; {var} = t_; }}"
                        ));
                        continue;
                    }
                    let line = match (r, m) {
                        (Reduce::Sum, _) => format!("{var} = {var} + {v};"),
                        (Reduce::Min, false) => format!("{var} = min({var}, {v});"),
                        (Reduce::Max, false) => format!("{var} = max({var}, {v});"),
                        (Reduce::Min, true) => format!("{var} = min_m({var}, {v});"),
                        (Reduce::Max, true) => format!("{var} = max_m({var}, {v});"),
                    };
                    self.line(line);
                }
                Stmt::If(c, a, b) => {
                    let c = self.expr(c);
                    self.line(format!("if ({c}) {{"));
                    self.indent += 1;
                    self.stmts(a);
                    self.indent -= 1;
                    if b.is_empty() {
                        self.line("}");
                    } else {
                        self.line("} else {");
                        self.indent += 1;
                        self.stmts(b);
                        self.indent -= 1;
                        self.line("}");
                    }
                }
            }
        }
    }

    /// Declares a variable for every field the statements set, holding its current value.
    fn declare_sets(&mut self, stmts: &[Stmt], group: Option<GroupId>) {
        let mut set = BTreeSet::new();
        crate::ir::set_targets(stmts, &mut set);
        for f in set {
            if self.current.contains_key(&f) {
                continue;
            }
            let name = self.fresh(&format!("{}_i", self.field_name(f)));
            let shape = self.shape_of(f);
            let init = if self.stored_on(f, group) {
                self.fields.insert((f, Side::I));
                format!("ld_{}(i)", self.field_name(f))
            } else {
                fill(0.0, shape, self.dim)
            };
            self.line(format!("var {name}: {} = {init};", ty(shape, self.dim)));
            self.current.insert(f, name);
        }
    }

    fn stored_on(&self, f: FieldId, group: Option<GroupId>) -> bool {
        match (self.plan.field_layout(f), group) {
            (Some(l), Some(g)) => l.groups.contains(g),
            (Some(_), None) => true,
            _ => false,
        }
    }

    /// Stores every set field that is stored on the group.
    fn write_stores(&mut self, group: Option<GroupId>) {
        let stores: Vec<FieldId> = self.stores.iter().copied().collect();
        for f in stores {
            if self.plan.model.field(f).storage == Storage::Temp || !self.stored_on(f, group) {
                continue;
            }
            let var = self.current[&f].clone();
            self.fields.insert((f, Side::I));
            self.line(format!("st_{}(i, {var});", self.field_name(f)));
        }
    }

    /// Accessor functions for the fields and parameters used, and the kernel functions.
    fn accessors(&self) -> String {
        let mut s = String::new();
        let d = self.dim;
        for &(f, side) in &self.fields {
            let Some(slot) = self.lay.slot(f) else { continue };
            let name = self.field_name(f);
            let shape = self.shape_of(f);
            let comps = ir::components(shape, d);
            let t = ty(shape, d);
            let base_expr = |group: &str| format!("info[{} + {group}]", self.lay.base_index(slot, 0));
            match side {
                Side::I => {
                    let g = if self.mode == Mode::Group { "G" } else { "ints[i]" };
                    let _ = writeln!(s, "fn ld_{name}(i: u32) -> {t} {{");
                    let _ = writeln!(s, "    let b = u32({} + i32(i) * {comps});", base_expr(g));
                    let _ = writeln!(s, "    return {};", construct(shape, d, "b"));
                    let _ = writeln!(s, "}}");
                    let _ = writeln!(s, "fn st_{name}(i: u32, v: {t}) {{");
                    let _ = writeln!(s, "    let b = u32({} + i32(i) * {comps});", base_expr(g));
                    for line in destruct(shape, d, "b", "v") {
                        let _ = writeln!(s, "    {line}");
                    }
                    let _ = writeln!(s, "}}");
                }
                Side::J => {
                    let _ = writeln!(s, "fn ldj_{name}(j: u32, sgn: vec3<f32>) -> {t} {{");
                    let _ = writeln!(s, "    let base = {};", self.lay.base_of(slot, "j"));
                    if !self.lay.everywhere[slot] {
                        let _ = writeln!(s, "    if (base == {}) {{ return {}; }}", super::ABSENT, fill(0.0, shape, d));
                    }
                    let _ = writeln!(s, "    let b = u32(base + i32(j) * {comps});");
                    let _ = writeln!(s, "    return {};", flip(shape, d, &construct(shape, d, "b")));
                    let _ = writeln!(s, "}}");
                }
            }
        }
        for &(p, side) in &self.params {
            let par = &self.plan.model.params[p.index()];
            let name = self.names.param(p);
            let shape = par.ty.shape;
            let t = ty(shape, d);
            let who = if side == Side::I { "i" } else { "j" };
            // One accessor serves both sides: it reads the parameters of the particle it is given.
            if s.contains(&format!("fn prm_{name}(")) {
                continue;
            }
            let _ = writeln!(s, "fn prm_{name}({who}: u32) -> {t} {{");
            let _ = writeln!(
                s,
                "    let b = ints[arrayLength(&ints) / 2u + {who}] * {}u + {}u;",
                self.lay.param_stride,
                self.lay.param_offset[p.index()]
            );
            let _ = writeln!(s, "    return {};", construct(shape, d, "b").replace("data[", "params["));
            let _ = writeln!(s, "}}");
        }
        s
    }
}

/// A WGSL value of `shape` from its stored components at `data[b + k]`.
fn construct(shape: Shape, d: usize, b: &str) -> String {
    let at = |k: usize| if k == 0 { format!("data[{b}]") } else { format!("data[{b} + {k}u]") };
    if d == 1 || shape == Shape::Scalar {
        return if shape == Shape::SkewTensor { "0.0".into() } else { at(0) };
    }
    let idx = ir::component_indices(shape, d);
    match shape {
        Shape::Vec => format!("vec{d}<f32>({})", (0..d).map(at).collect::<Vec<_>>().join(", ")),
        _ => {
            // column c holds rows 0..d: element (r, c)
            let mut cols = vec![];
            for c in 0..d {
                let mut rows = vec![];
                for r in 0..d {
                    let v = match shape {
                        Shape::Tensor => at(r * d + c),
                        Shape::SymTensor => {
                            at(idx.iter().position(|&(a, b)| (a, b) == (r.min(c), r.max(c))).expect("upper triangle"))
                        }
                        _ => {
                            if r == c {
                                "0.0".into()
                            } else {
                                let k = idx
                                    .iter()
                                    .position(|&(a, b)| (a, b) == (r.min(c), r.max(c)))
                                    .expect("upper triangle");
                                if r < c {
                                    at(k)
                                } else {
                                    format!("-{}", at(k))
                                }
                            }
                        }
                    };
                    rows.push(v);
                }
                cols.push(format!("vec{d}<f32>({})", rows.join(", ")));
            }
            format!("mat{d}x{d}<f32>({})", cols.join(", "))
        }
    }
}

/// Statements storing `v`'s stored components at `data[b + k]`.
fn destruct(shape: Shape, d: usize, b: &str, v: &str) -> Vec<String> {
    let at = |k: usize| if k == 0 { format!("data[{b}]") } else { format!("data[{b} + {k}u]") };
    if d == 1 || shape == Shape::Scalar {
        return if shape == Shape::SkewTensor { vec![] } else { vec![format!("{} = {v};", at(0))] };
    }
    match shape {
        Shape::Vec => (0..d).map(|k| format!("{} = {v}[{k}];", at(k))).collect(),
        _ => ir::component_indices(shape, d)
            .iter()
            .enumerate()
            .map(|(k, &(r, c))| format!("{} = {v}[{c}][{r}];", at(k)))
            .collect(),
    }
}

/// A neighbour's value seen through a mirror: vec components and tensor (r, c) components
/// change sign with their axes.
fn flip(shape: Shape, d: usize, value: &str) -> String {
    match (shape, d) {
        (Shape::Scalar | Shape::Bool, _) => value.into(),
        (Shape::Vec, 1) => format!("({value} * sgn.x)"),
        (Shape::Vec, 2) => format!("({value} * sgn.xy)"),
        (Shape::Vec, _) => format!("({value} * sgn)"),
        (_, 1) => value.into(),
        (_, 2) => format!("flip_m({value}, sgn.xy)"),
        _ => format!("flip_m({value}, sgn)"),
    }
}

trait AbsF {
    fn unsigned_abs_f(self) -> usize;
}
impl AbsF for f64 {
    fn unsigned_abs_f(self) -> usize {
        self.abs() as usize
    }
}

/// Common text of every kernel: bindings, constants, helpers.
fn header(plan: &Plan, title: &str, group: Option<GroupId>, bindings: &[Binding]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "// Generated by pairsum from the model's IR: {title}. Do not edit.");
    let _ = writeln!(s, "// {}D, f32, kernel {}.", plan.dim, plan.model.kernels[plan.kernel.index()].name);
    for b in bindings {
        let _ = writeln!(s, "{}", b.declaration());
    }
    if let Some(g) = group {
        let _ = writeln!(s, "const G: i32 = {}; // group {}", g.0, plan.model.groups[g.index()].name);
    }
    let _ = writeln!(s, "fn pinf() -> f32 {{ return bitcast<f32>(0x7f800000u); }}");
    let _ = writeln!(s, "fn nan() -> f32 {{ return bitcast<f32>(0x7fc00000u); }}");
    let _ = writeln!(s, "fn in_groups(mask: u32, g: u32) -> bool {{ return ((mask >> g) & 1u) == 1u; }}");
    let compensated = |e: &crate::ir::Equation| matches!(e.kind, EquationKind::PairSum { compensated: true, .. });
    if plan.model.equations.iter().any(compensated) {
        s.push_str(&opaque_fns(plan.dim));
    }
    s.push_str(&prelude::helpers(plan.dim));
    s
}

/// `opaque_s/v/m(x, z)`: x unchanged (z is 0 at run time), but no longer provably equal to x.
fn opaque_fns(d: usize) -> String {
    let mut s = String::from("fn opaque_s(x: f32, z: u32) -> f32 { return bitcast<f32>(bitcast<u32>(x) ^ z); }\n");
    if d > 1 {
        let _ = writeln!(
            s,
            "fn opaque_v(x: vec{d}<f32>, z: u32) -> vec{d}<f32> {{ return bitcast<vec{d}<f32>>(bitcast<vec{d}<u32>>(x) ^ vec{d}<u32>(z)); }}"
        );
        let cols: Vec<String> = (0..d).map(|c| format!("opaque_v(x[{c}], z)")).collect();
        let _ = writeln!(
            s,
            "fn opaque_m(x: mat{d}x{d}<f32>, z: u32) -> mat{d}x{d}<f32> {{ return mat{d}x{d}<f32>({}); }}",
            cols.join(", ")
        );
    }
    s
}

/// `kernel_w(r, h)`, `kernel_w_at(r, h)` and `kernel_grad(r, h)` (the factor of x_ij), and
/// `kernel_grad_at(x, h)` where `body` calls it.
fn kernel_functions(plan: &Plan, lay: &Layout, body: &str) -> String {
    let k = &plan.model.kernels[plan.kernel.index()];
    let d = plan.dim;
    let mut w = Writer::new(plan, lay, Mode::None);
    w.indent = 1;
    w.local_names.insert(k.arg, "R".into());
    let wv = w.expr(&k.w);
    let w_lets = std::mem::take(&mut w.out);
    let dwv = w.expr(&k.dw);
    let dw_lets = std::mem::take(&mut w.out);
    let norm = lit(k.norm[d - 1]);
    let hd = vec!["h"; d].join(" * ");
    format!(
        "// kernel {name}: W = norm / h^d · w(r/h), ∇W = norm / h^(d+1) · dw(r/h) · x_ij / r
fn kernel_shape(R: f32) -> f32 {{
{w_lets}    return {wv};
}}
fn kernel_slope(R: f32) -> f32 {{
{dw_lets}    return {dwv};
}}
fn kernel_w(r: f32, h: f32) -> f32 {{ return {norm} / ({hd}) * kernel_shape(r / h); }}
fn kernel_w_at(r: f32, h: f32) -> f32 {{ return select(0.0, kernel_w(r, h), r / h < {support}); }}
fn kernel_grad(r: f32, h: f32) -> f32 {{ return {norm} / ({hd} * h) * kernel_slope(r / h) / r; }}
{grad_at}",
        name = k.name,
        support = lit(k.support),
        grad_at = if body.contains("kernel_grad_at(") { kernel_grad_at_fn(plan, k.support) } else { String::new() }
    )
}

/// `kernel_grad_at(x, h)`: ∇W at the separation x, 0 at x = 0 and from the support on.
fn kernel_grad_at_fn(plan: &Plan, support: f64) -> String {
    let vt = ty(Shape::Vec, plan.dim);
    let len = if plan.dim == 1 { "abs(x)" } else { "length(x)" };
    let support = lit(support);
    format!(
        "fn kernel_grad_at(x: {vt}, h: f32) -> {vt} {{
    let r = {len};
    return select({vt}(0.0), kernel_grad(r, h) * x, r > 0.0 && r / h < {support});
}}
"
    )
}

/// Positions of any particle as a vec3 (unused components 0), for the cell list.
fn position_fn(plan: &Plan, lay: &Layout) -> String {
    let d = plan.dim;
    let x = plan.model.field_id("x").expect("x");
    let slot = lay.slot(x).expect("x is stored");
    let base = lay.base_of(slot, "p");
    let comps: Vec<String> = (0..3).map(|c| if c < d { format!("data[b + {c}u]") } else { "0.0".into() }).collect();
    format!(
        "fn pos3(p: u32) -> vec3<f32> {{\n    let b = u32({base} + i32(p) * {d});\n    return vec3<f32>({});\n}}\n",
        comps.join(", ")
    )
}

fn h_fn(plan: &Plan, lay: &Layout) -> String {
    let h = plan.model.field_id("h").expect("h");
    let slot = lay.slot(h).expect("h is stored");
    format!("fn h_of(p: u32) -> f32 {{ return data[u32({} + i32(p))]; }}\n", lay.base_of(slot, "p"))
}

fn pass_kernel(plan: &Plan, lay: &Layout, pass: usize, v: &PassVariant, cell_helpers: &str) -> Kernel {
    let g = v.group;
    let d = plan.dim;
    let model = &plan.model;
    let mut w = Writer::new(plan, lay, Mode::Group);
    w.groups = (GroupSet::default().with(g), v.sources.intersect(plan.groups));
    let support = lit(model.kernels[plan.kernel.index()].support);
    w.line("let first = u32(info[1 + 2 * G]);");
    w.line("let count = u32(info[2 + 2 * G]);");
    w.line("if (k >= count) { return; }");
    w.line("let i = first + k;");
    w.line(format!("let t = globals[{}u];", gl::TIME));
    w.line(format!("let dt = globals[{}u];", gl::DT_PREV));
    // Accumulators, their identities and `init` blocks.
    let mut inits = vec![];
    for e in &v.pair_sums {
        let eq = plan.equation(*e);
        let EquationKind::PairSum { accumulators, init, compensated, .. } = &eq.kind else { continue };
        w.line(format!("// pairsum {}: accumulators", eq.name));
        for a in accumulators {
            let shape = w.shape_of(a.field);
            let name = w.fresh(&w.field_name(a.field));
            let value = match a.reduce {
                Reduce::Sum => fill(0.0, shape, d),
                Reduce::Min => fill(f64::INFINITY, shape, d).replace("(-pinf())", "pinf()"),
                Reduce::Max => fill(f64::NEG_INFINITY, shape, d),
            };
            let value = if a.reduce == Reduce::Min && is_mat(shape, d) {
                format!("pinf() * mat{d}x{d}<f32>({})", vec!["1.0"; d * d].join(", "))
            } else {
                value
            };
            w.line(format!("var {name}: {} = {value};", ty(shape, d)));
            if *compensated && a.reduce == Reduce::Sum {
                if w.compensation.is_empty() {
                    w.line(format!("let z_ = bitcast<u32>(globals[{}u]);", gl::ZERO));
                }
                let c = w.fresh(&format!("{name}_lost"));
                w.line(format!("var {c}: {} = {};", ty(shape, d), fill(0.0, shape, d)));
                w.compensation.insert(a.field, c);
            }
            w.current.insert(a.field, name);
            w.stores.insert(a.field);
        }
        inits.push(init.clone());
    }
    for init in &inits {
        w.stmts(init);
    }
    // Values of particle i that the neighbour loop reads, fields and parameters: loaded once.
    let mut read_i = BTreeSet::new();
    let mut params_i = BTreeSet::new();
    for e in &v.pair_sums {
        if let EquationKind::PairSum { body, .. } = &plan.equation(*e).kind {
            ir::walk_stmts(body, &mut |x| match x.kind {
                ExprKind::Field(f, Side::I) => {
                    read_i.insert(f);
                }
                ExprKind::Param(p, Side::I) => {
                    params_i.insert(p);
                }
                _ => {}
            });
        }
    }
    for p in params_i {
        let name = w.names.param(p).to_string();
        let var = w.fresh(&format!("{name}_i"));
        w.params.insert((p, Side::I));
        w.line(format!("let {var} = prm_{name}(i);"));
        w.params_i.insert(p, var);
    }
    for f in read_i {
        if w.current.contains_key(&f) || plan.model.field(f).storage == Storage::Temp {
            continue;
        }
        let name = w.fresh(&format!("{}_i", w.field_name(f)));
        w.fields.insert((f, Side::I));
        w.line(format!("let {name} = ld_{}(i);", w.field_name(f)));
        w.current.insert(f, name);
    }
    w.line("let xi = pos3(i);");
    w.line("let hi = h_of(i);");
    w.line(format!("let mirrors = u32(globals[{}u]);", gl::PLANES));
    let lists = plan.search.keeps_lists();
    let close = if lists { list_walk(&mut w) } else { cell_walk(&mut w, &support) };
    let all_present = v.sources == plan.groups;
    if !all_present {
        w.line(format!("if (!in_groups({}u, ints[j])) {{ continue; }}", v.sources.0 as u32));
    }
    w.line("let dxv = yi - pos3(j);");
    w.line("let r2 = dot(dxv, dxv);");
    w.line("let h_ij = 0.5 * (hi + h_of(j));");
    w.line(format!("let rc = {support} * h_ij;"));
    w.line("if (r2 >= rc * rc || r2 == 0.0) { continue; }");
    let xij = match d {
        1 => "(dxv * sgn).x",
        2 => "(dxv * sgn).xy",
        _ => "(dxv * sgn)",
    };
    w.line(format!("let x_ij = {xij};"));
    w.line("let r_ij = sqrt(r2);");
    let body_start = w.out.len();
    for e in &v.pair_sums {
        let eq = plan.equation(*e);
        let sources = &eq.sources_for(v.group);
        let EquationKind::PairSum { body, .. } = &eq.kind else { continue };
        w.line(format!("// pairsum {} ({})", eq.name, eq.location));
        let masked = sources.intersect(plan.groups) != v.sources;
        if masked {
            w.line(format!("if (in_groups({}u, ints[j])) {{", sources.0 as u32));
            w.indent += 1;
        }
        w.stmts(body);
        if masked {
            w.indent -= 1;
            w.line("}");
        }
    }
    if w.reads_pair_kernel {
        // W and its gradient, computed only when a sum reads them.
        let pre = format!(
            "{ind}let W_ij = kernel_w(r_ij, h_ij);\n{ind}let gradW_ij = kernel_grad(r_ij, h_ij) * x_ij;\n",
            ind = "    ".repeat(w.indent)
        );
        w.out.insert_str(body_start, &pre);
    }
    for (outdent, line) in close {
        w.indent -= outdent;
        w.line(line);
    }
    // The tail: `finally` blocks and particle equations, in order. Preloaded values of fields the
    // tail sets give way to variables.
    for b in plan.tail_blocks(&v.tail) {
        let mut set = BTreeSet::new();
        crate::ir::set_targets(&b.stmts, &mut set);
        for f in set {
            if !w.stores.contains(&f) {
                w.current.remove(&f);
            }
        }
        w.line(w.comment_for(&b.name, "then"));
        w.declare_sets(&b.stmts, Some(g));
        w.stmts(&b.stmts);
    }
    w.write_stores(Some(g));
    let name = format!("pass{}_{}", pass + 1, group_name(plan, g));
    let eqs: Vec<&str> = v.pair_sums.iter().map(|e| plan.equation(*e).name.as_str()).collect();
    let title = format!("pass {} on {}: {}", pass + 1, model.groups[g.index()].name, eqs.join(", "));
    let walk = if lists { vec![Binding::Lists] } else { vec![Binding::Grid, Binding::Cells] };
    let mut bindings = vec![Binding::Data, Binding::Ints, Binding::Params, Binding::Meta];
    bindings.extend(walk);
    bindings.push(Binding::Globals);
    let mut wgsl = header(plan, &title, Some(g), &bindings);
    if !lists {
        wgsl.push_str(cell_helpers);
    }
    wgsl.push_str(&kernel_functions(plan, lay, &w.out));
    wgsl.push_str(&position_fn(plan, lay));
    wgsl.push_str(&h_fn(plan, lay));
    wgsl.push_str(&w.accessors());
    let _ = writeln!(
        wgsl,
        "@compute @workgroup_size({WORKGROUP})\nfn main({ENTRY_ARGS}) {{\n    let k = {LINEAR};\n{}}}",
        w.out
    );
    Kernel { name, kind: KernelKind::Pass { pass, group: g }, wgsl, bindings }
}

/// Opens the neighbour loop over the cells around particle i (and around its mirror images) that
/// may hold a particle within the cut-off (`walk_cells`, `walk_skips` of `backend::gpu::cells`):
/// `j`, `yi` (i or its image) and `sgn` are in scope inside. Returns the lines that close it, each
/// with how far it is outdented.
fn cell_walk(w: &mut Writer, support: &str) -> Vec<(usize, &'static str)> {
    w.line("let h_max = bitcast<f32>(grid[9]);");
    w.line("for (var tr = 0u; tr < (1u << mirrors); tr++) {");
    w.indent += 1;
    reflect(w, Some(&format!("abs(xi[axis] - at) >= {support} * h_max")));
    w.line(format!("let wk = walk_cells(yi, {support} * h_max);"));
    w.line("for (var z = wk.lo.z; z <= wk.hi.z; z++) {");
    w.line("for (var y = wk.lo.y; y <= wk.hi.y; y++) {");
    w.line("for (var x = wk.lo.x; x <= wk.hi.x; x++) {");
    w.line("if (walk_skips(wk, vec3<u32>(x, y, z))) { continue; }");
    w.line("let cell = cell_index(vec3<u32>(x, y, z));");
    w.line("for (var s = cell_start(cell); s < cell_start(cell + 1u); s++) {");
    w.indent += 1;
    w.line("let j = sorted_particle(s);");
    w.line("if (tr == 0u && j == i) { continue; }");
    vec![(1, "}"), (0, "}}}"), (1, "}")]
}

/// Opens the neighbour loop over particle i's kept list (`backend::gpu::lists`): each entry a
/// neighbour and the mirrors its image reflects across. Returns the line that closes it.
fn list_walk(w: &mut Writer) -> Vec<(usize, &'static str)> {
    use crate::backend::gpu::lists as l;
    w.line("let n_all = u32(info[0]);");
    w.line(format!("let list_start = {}u + 3u * n_all + lists[{}u + n_all + i];", l::HEADER, l::HEADER));
    w.line(format!("for (var k_list = list_start; k_list < list_start + lists[{}u + i]; k_list++) {{", l::HEADER));
    w.indent += 1;
    w.line("let entry = lists[k_list];");
    w.line(format!("let j = entry & {:#x}u;", l::INDEX_MASK));
    w.line(format!("let tr = entry >> {}u;", l::TRANSFORM_SHIFT));
    reflect(w, None);
    vec![(1, "}")]
}

/// `yi` and `sgn`: particle i reflected across the symmetry planes and moved across the periodic
/// sides whose bit is set in transform `tr`, and the axes that flips. With `too_far` (a condition
/// on `axis` and `at`), the transform is skipped when it holds for one of its planes, or when it
/// takes both sides of a periodic axis (which moves i nowhere).
fn reflect(w: &mut Writer, too_far: Option<&str>) {
    w.line("var yi = xi;");
    w.line("var sgn = vec3<f32>(1.0);");
    if too_far.is_some() {
        w.line("var skip = false;");
        w.line("var shifted = vec3<u32>(0u);");
    }
    w.line("for (var m = 0u; m < mirrors; m++) {");
    w.line("    if (((tr >> m) & 1u) == 1u) {");
    w.line(format!("        let axis = u32(globals[{}u + 3u * m]);", gl::PLANES + 1));
    w.line(format!("        let at = globals[{}u + 3u * m];", gl::PLANES + 2));
    w.line(format!("        let shift = globals[{}u + 3u * m];", gl::PLANES + 3));
    if let Some(cond) = too_far {
        w.line(format!("        if ({cond}) {{ skip = true; }}"));
    }
    w.line("        if (shift == 0.0) {");
    w.line("            yi[axis] = 2.0 * at - xi[axis];");
    w.line("            sgn[axis] = -sgn[axis];");
    w.line("        } else {");
    w.line("            yi[axis] = xi[axis] + shift;");
    if too_far.is_some() {
        w.line("            shifted[axis] += 1u;");
    }
    w.line("        }");
    w.line("    }");
    w.line("}");
    if too_far.is_some() {
        w.line("if (skip || any(shifted > vec3<u32>(1u))) { continue; }");
    }
}

fn particle_kernel(
    plan: &Plan,
    lay: &Layout,
    name: &str,
    kind: KernelKind,
    g: GroupId,
    blocks: &[Block],
    title: &str,
) -> Kernel {
    // Updates run at time t + fraction × dt of the step; other particle kernels at t.
    let frac = match kind {
        KernelKind::Update { stage, .. } => plan
            .actions
            .iter()
            .find_map(|a| match a {
                crate::schedule::Action::Update { stage: s, time_fraction } if *s == stage => Some(*time_fraction),
                _ => None,
            })
            .unwrap_or(1.0),
        _ => 0.0,
    };
    let dt_slot = if matches!(kind, KernelKind::Update { .. }) { gl::DT } else { gl::DT_PREV };
    let mut w = Writer::new(plan, lay, Mode::Group);
    w.line("let first = u32(info[1 + 2 * G]);");
    w.line("let count = u32(info[2 + 2 * G]);");
    w.line("if (k >= count) { return; }");
    w.line("let i = first + k;");
    w.line(format!("let dt = globals[{dt_slot}u];"));
    w.line(format!("let t = globals[{}u] + {} * dt;", gl::TIME, lit(frac)));
    for b in blocks.iter().filter(|b| b.dest.contains(g)) {
        w.line(format!("// {}", b.name));
        w.declare_sets(&b.stmts, Some(g));
        w.stmts(&b.stmts);
    }
    w.write_stores(Some(g));
    let body = std::mem::take(&mut w.out);
    let bindings = vec![Binding::Data, Binding::Ints, Binding::Params, Binding::Meta, Binding::Globals];
    let mut wgsl = header(plan, title, Some(g), &bindings);
    if body.contains("kernel_w") || body.contains("kernel_grad_at(") {
        wgsl.push_str(&kernel_functions(plan, lay, &body));
    }
    wgsl.push_str(&w.accessors());
    let _ = writeln!(
        wgsl,
        "@compute @workgroup_size({WORKGROUP})\nfn main({ENTRY_ARGS}) {{\n    let k = {LINEAR};\n{body}}}"
    );
    Kernel { name: name.to_string(), kind, wgsl, bindings }
}

/// Per-particle values of every time-step reduction, into scratch: reduction k of particle i at
/// `data[info[len - 1] + k * n + i]` (the last `meta` word is the scratch offset).
fn reduction_kernel(plan: &Plan, lay: &Layout) -> Kernel {
    let reds = crate::backend::timestep::reductions(&plan.model, &plan.timesteps);
    let mut w = Writer::new(plan, lay, Mode::Any);
    w.line("let n = u32(info[0]);");
    w.line("let i = k;");
    w.line("if (i >= n) { return; }");
    w.line(format!("let t = globals[{}u];", gl::TIME));
    w.line(format!("let dt = globals[{}u];", gl::DT_PREV));
    w.line(format!("let scratch = u32(info[{}]);", lay.meta_len()));
    for (k, (_, e)) in reds.iter().enumerate() {
        let v = w.expr(e);
        w.line(format!("data[scratch + {k}u * n + i] = {v};"));
    }
    let bindings = vec![Binding::Data, Binding::Ints, Binding::Params, Binding::Meta, Binding::Globals];
    let mut wgsl = header(plan, "the per-particle values of the time-step reductions", None, &bindings);
    wgsl.push_str(&w.accessors());
    let _ = writeln!(
        wgsl,
        "@compute @workgroup_size({WORKGROUP})\nfn main({ENTRY_ARGS}) {{\n    let k = {LINEAR};\n{}}}",
        w.out
    );
    Kernel { name: "timestep_values".into(), kind: KernelKind::ReductionValues, wgsl, bindings }
}

/// Per-particle values of the watchdog's reductions (see [`gl::WATCH`]), into scratch after the
/// time step's: `|v|²`, the energy `m (½|v|² + e − g·x)` (with `e` where the group stores a
/// scalar `e`, and the scene's gravity `g`), its magnitude and `½ m |v|²`, on the groups that store `x` and
/// `v` (the energy where they store `m` too); 0 elsewhere. None when the plan stores no `x` or `v`.
fn watch_kernel(plan: &Plan, lay: &Layout) -> Option<Kernel> {
    let model = &plan.model;
    // Fields the plan stores (a model that never reads `m` stores none: its energy is left 0, as
    // the watchdog then has no energy bound).
    let field =
        |name: &str| model.field_id(name).filter(|f| lay.slot(*f).is_some()).map(|f| Expr::field(f, model.field(f).ty));
    let (x, v) = (field("x")?, field("v")?);
    let m = field("m");
    let e = field("e").filter(|e| e.ty.shape == Shape::Scalar);
    // The groups that store a field, as `in_groups` masks (as `i in S` is written).
    let mask = |f: Option<&Expr>| -> u32 {
        let Some(ExprKind::Field(f, _)) = f.map(|f| &f.kind) else { return 0 };
        plan.field_layout(*f).map_or(0, |l| l.groups.0 as u32)
    };
    let moving = mask(Some(&x)) & mask(Some(&v));
    let weighed = moving & mask(m.as_ref());
    let heated = weighed & mask(e.as_ref());
    let gravity = plan
        .scene_params
        .iter()
        .find(|p| p.role == crate::schedule::SceneRole::Gravity)
        .map_or(vec![0.0; plan.dim], |p| p.value.clone());
    let reductions = crate::backend::timestep::reductions(&plan.model, &plan.timesteps).len();
    let mut w = Writer::new(plan, lay, Mode::Any);
    w.line("let n = u32(info[0]);");
    w.line("let i = k;");
    w.line("if (i >= n) { return; }");
    w.line(format!("let scratch = u32(info[{}]) + {reductions}u * n;", lay.meta_len()));
    w.line("var speed2 = 0.0;");
    w.line("var energy = 0.0;");
    w.line("var kinetic = 0.0;");
    w.line(format!("if (in_groups({moving}u, ints[i])) {{"));
    let (xs, vs) = (w.expr(&x), w.expr(&v));
    let dot = |a: &str, b: &str| if plan.dim == 1 { format!("({a} * {b})") } else { format!("dot({a}, {b})") };
    let g = match plan.dim {
        1 => lit(gravity[0]),
        d => format!("vec{d}<f32>({})", gravity.iter().map(|c| lit(*c)).collect::<Vec<_>>().join(", ")),
    };
    w.line(format!("    let v = {vs};"));
    w.line(format!("    speed2 = {};", dot("v", "v")));
    if let Some(m) = &m {
        let ms = w.expr(m);
        // In an axisymmetric case each mass is its ring's (watchdog.rs).
        let ms =
            if plan.axisymmetric() { format!("({ms} * {} * {xs}.x)", lit(crate::schedule::ring(1.0))) } else { ms };
        w.line(format!("    if (in_groups({weighed}u, ints[i])) {{"));
        w.line(format!("        kinetic = 0.5 * {ms} * speed2;"));
        w.line(format!("        energy = {ms} * (0.5 * speed2 - {});", dot(&g, &xs)));
        if let Some(e) = &e {
            let es = w.expr(e);
            w.line(format!("        if (in_groups({heated}u, ints[i])) {{ energy = energy + {ms} * {es}; }}"));
        }
        w.line("    }");
    }
    w.line("}");
    w.line("data[scratch + i] = speed2;");
    w.line("data[scratch + n + i] = energy;");
    w.line("data[scratch + 2u * n + i] = abs(energy);");
    w.line("data[scratch + 3u * n + i] = kinetic;");
    let bindings = vec![Binding::Data, Binding::Ints, Binding::Meta];
    let mut wgsl = header(plan, "the per-particle values of the watchdog's reductions", None, &bindings);
    wgsl.push_str(&w.accessors());
    let _ = writeln!(
        wgsl,
        "@compute @workgroup_size({WORKGROUP})\nfn main({ENTRY_ARGS}) {{\n    let k = {LINEAR};\n{}}}",
        w.out
    );
    Some(Kernel { name: "watch_values".into(), kind: KernelKind::WatchValues, wgsl, bindings })
}

/// The time step from the reductions: the least positive finite limit, then dt_max and the end.
fn timestep_kernel(plan: &Plan) -> Kernel {
    let lay = Layout::new(plan);
    let mut w = Writer::new(plan, &lay, Mode::None);
    w.line(format!("let t = globals[{}u];", gl::TIME));
    w.line(format!("let dt = globals[{}u];", gl::DT_PREV));
    w.line(format!("var best = globals[{}u];", gl::DT_MAX));
    for ts in &plan.timesteps {
        let e = &plan.model.timesteps[*ts];
        w.line(format!("// timestep {}", e.name));
        let v = w.expr(&e.value);
        let name = w.fresh(&format!("limit_{}", e.name));
        w.line(format!("let {name} = {v};"));
        w.line(format!("if ({name} > 0.0 && {name} < pinf()) {{ best = min(best, {name}); }}"));
    }
    w.line(format!("let remaining = globals[{}u] - t;", gl::END_TIME));
    w.line("if (remaining > 0.0 && remaining < best * 1.000001) { best = remaining; }");
    w.line(format!("globals[{}u] = best;", gl::DT));
    let bindings = vec![Binding::Globals];
    let mut wgsl = header(plan, "the time step", None, &bindings);
    let _ = writeln!(wgsl, "@compute @workgroup_size(1)\nfn main() {{\n{}}}", w.out);
    Kernel { name: "timestep".into(), kind: KernelKind::Timestep, wgsl, bindings }
}

fn advance_kernel() -> Kernel {
    let wgsl = format!(
        "// Generated by pairsum: advances the clock after a step. Do not edit.
@group(0) @binding(6) var<storage, read_write> globals: array<f32>;
@compute @workgroup_size(1)
fn main() {{
    let dt = globals[{dt}u];
    globals[{time}u] = globals[{time}u] + dt;
    globals[{prev}u] = dt;
    globals[{step}u] = globals[{step}u] + 1.0;
}}
",
        dt = gl::DT,
        time = gl::TIME,
        prev = gl::DT_PREV,
        step = gl::STEP
    );
    Kernel { name: "advance".into(), kind: KernelKind::Advance, wgsl, bindings: vec![Binding::Globals] }
}
