//! The typed intermediate representation: what `check` produces and every later stage reads.
//! Names are resolved to ids, every expression carries its shape and unit, helper functions are
//! inlined, and each equation knows what it reads (per side) and writes.

use crate::diag::Span;
pub use crate::syntax::ast::{Shape, Side, Storage};
use crate::units::Unit;
use std::collections::BTreeSet;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Type {
    pub shape: Shape,
    pub unit: Unit,
}

impl Type {
    pub const BOOL: Type = Type { shape: Shape::Bool, unit: Unit::ONE };
    pub fn new(shape: Shape, unit: Unit) -> Type {
        Type { shape, unit }
    }
    pub fn scalar(unit: Unit) -> Type {
        Type { shape: Shape::Scalar, unit }
    }
}

impl std::fmt::Display for Type {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.shape == Shape::Bool {
            write!(f, "bool")
        } else {
            write!(f, "{} [{}]", self.shape.name(), self.unit)
        }
    }
}

/// The prelude's parameter that the case's `gravity` binds for every material (the integrator adds
/// it to the rate of `v`; models may read it).
pub const GRAVITY: &str = "gravity";
/// The prelude's parameter that is 1 in an axisymmetric case, 0 otherwise: set by the scene.
pub const AXISYMMETRIC: &str = "axisymmetric";
/// The state fields the scene places with every particle (besides its velocity `v`).
pub const PLACED: [&str; 5] = ["x", "vol", "dx", "body", "part"];

/// Components a shape holds in `dim` dimensions. Symmetric and skew tensors keep their upper
/// triangle row by row (sym 3D: xx xy xz yy yz zz; skew 3D: xy xz yz); full tensors are row-major.
pub fn components(shape: Shape, dim: usize) -> usize {
    match shape {
        Shape::Scalar | Shape::Bool => 1,
        Shape::Vec => dim,
        Shape::SymTensor => dim * (dim + 1) / 2,
        Shape::SkewTensor => dim * (dim - 1) / 2,
        Shape::Tensor => dim * dim,
    }
}

/// The (row, column) of each stored component of a shape.
pub fn component_indices(shape: Shape, dim: usize) -> Vec<(usize, usize)> {
    match shape {
        Shape::Scalar | Shape::Bool => vec![(0, 0)],
        Shape::Vec => (0..dim).map(|a| (a, 0)).collect(),
        Shape::SymTensor => (0..dim).flat_map(|a| (a..dim).map(move |b| (a, b))).collect(),
        Shape::SkewTensor => (0..dim).flat_map(|a| (a + 1..dim).map(move |b| (a, b))).collect(),
        Shape::Tensor => (0..dim).flat_map(|a| (0..dim).map(move |b| (a, b))).collect(),
    }
}

/// The axes' names, by index.
pub const AXIS_NAMES: [&str; 3] = ["x", "y", "z"];

/// The names of the stored components of a shape (`""` for a scalar, `x`, `y` of a vec, `xx`,
/// `xy` of a tensor), in the order `component_indices` gives.
pub fn component_names(shape: Shape, dim: usize) -> Vec<String> {
    let axis = |a: usize| AXIS_NAMES[a];
    match shape {
        Shape::Scalar | Shape::Bool => vec![String::new()],
        Shape::Vec => (0..dim).map(|a| axis(a).to_string()).collect(),
        _ => component_indices(shape, dim).into_iter().map(|(a, b)| format!("{}{}", axis(a), axis(b))).collect(),
    }
}

macro_rules! id {
    ($name:ident) => {
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub struct $name(pub u32);
        impl $name {
            pub fn index(self) -> usize {
                self.0 as usize
            }
        }
    };
}
id!(FieldId);
id!(ParamId);
id!(GroupId);
id!(EqId);
id!(LocalId);
id!(KernelId);

/// A set of particle groups (at most 64 per model).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub struct GroupSet(pub u64);

impl GroupSet {
    pub const ALL: GroupSet = GroupSet(u64::MAX);
    pub fn contains(self, g: GroupId) -> bool {
        self.0 & (1 << g.0) != 0
    }
    pub fn with(self, g: GroupId) -> GroupSet {
        GroupSet(self.0 | (1 << g.0))
    }
    pub fn union(self, o: GroupSet) -> GroupSet {
        GroupSet(self.0 | o.0)
    }
    pub fn intersect(self, o: GroupSet) -> GroupSet {
        GroupSet(self.0 & o.0)
    }
    /// Whether `i in self` is settled for a particle known to be in one of `possible`: `Some(true)`
    /// when every group of `possible` is in the set, `Some(false)` when none is, `None` otherwise.
    pub fn decides(self, possible: GroupSet) -> Option<bool> {
        if possible.intersect(self) == possible {
            Some(true)
        } else if possible.intersect(self).is_empty() {
            Some(false)
        } else {
            None
        }
    }
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }
    pub fn iter(self, n_groups: usize) -> impl Iterator<Item = GroupId> {
        (0..n_groups as u32).map(GroupId).filter(move |g| self.contains(*g))
    }
}

#[derive(Clone, Debug)]
pub struct Field {
    pub name: String,
    pub ty: Type,
    pub storage: Storage,
    /// Initial value (per particle, i side only) for state fields the scene does not set.
    pub init: Option<Expr>,
    pub span: Span,
    /// For the integrator's copy of a state at the start of the step (named `x@0`): the state.
    pub saved_of: Option<FieldId>,
}

#[derive(Clone, Debug)]
pub struct Param {
    pub name: String,
    pub ty: Type,
    /// Used when a material does not bind the parameter (a constant expression).
    pub default: Option<Expr>,
    pub span: Span,
    /// Its declaration as written, without `param` and the comment (`p_spall: scalar [Pa] =
    /// 1e20 [Pa]`), its comment (the one after it on its line, else the first sentence of the
    /// comment just above it), and `file:line`: what `pairsum plan` lists.
    pub declared: String,
    pub doc: String,
    pub location: String,
    /// Where other modules declare it too (the same type).
    pub also_declared: Vec<Span>,
}

#[derive(Clone, Debug)]
pub struct Group {
    pub name: String,
    pub span: Span,
}

/// A smoothing kernel: `W = norm_d / h^d · w(R)`, `∇W = norm_d / h^(d+1) · dw(R) · x_ij / r`,
/// `R = r / h`, zero for `R ≥ support`. `w` and `dw` are expressions in the local `arg`.
#[derive(Clone, Debug)]
pub struct Kernel {
    pub name: String,
    pub support: f64,
    pub norm: [f64; 3],
    pub arg: LocalId,
    pub w: Expr,
    pub dw: Expr,
    pub span: Span,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Reduce {
    Sum,
    Min,
    Max,
}

impl Reduce {
    pub fn identity(self) -> f64 {
        match self {
            Reduce::Sum => 0.0,
            Reduce::Min => f64::INFINITY,
            Reduce::Max => f64::NEG_INFINITY,
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Reduce::Sum => "sum",
            Reduce::Min => "min",
            Reduce::Max => "max",
        }
    }
}

#[derive(Clone, Debug)]
pub struct Accumulator {
    pub field: FieldId,
    pub reduce: Reduce,
}

#[derive(Clone, Debug)]
pub enum EquationKind {
    /// Summed over the neighbours j (in `sources`) of each particle i: `init`, then `body` per
    /// neighbour, then `finally`.
    PairSum {
        /// Every group a neighbour may belong to, over all destination groups.
        sources: GroupSet,
        /// The destination groups whose neighbours are fewer than `sources` (`use m on A` beside
        /// `use m on B from S`), each with its own.
        narrowed: Vec<(GroupId, GroupSet)>,
        /// `from own`: of `sources`, only the destination particle's own group.
        own: bool,
        accumulators: Vec<Accumulator>,
        init: Vec<Stmt>,
        body: Vec<Stmt>,
        finally: Vec<Stmt>,
        /// Sums with Kahan compensation.
        compensated: bool,
    },
    /// Per particle, no neighbours.
    Particle { body: Vec<Stmt> },
}

#[derive(Clone, Debug)]
pub struct Equation {
    pub name: String,
    pub kind: EquationKind,
    /// Destination groups: the particles i this equation runs on.
    pub dest: GroupSet,
    pub writes: Vec<FieldId>,
    /// Fields read, with the side they are read on.
    pub reads: BTreeSet<(FieldId, Side)>,
    pub params: BTreeSet<(ParamId, Side)>,
    pub span: Span,
    /// `file:line` of the definition, for generated code's comments.
    pub location: String,
    /// The source files of the modules this equation's module uses, directly or not.
    pub builds_on: BTreeSet<u32>,
}

impl Equation {
    pub fn is_pair(&self) -> bool {
        matches!(self.kind, EquationKind::PairSum { .. })
    }
    /// Every group a neighbour j may belong to (over all destination groups).
    pub fn sources(&self) -> GroupSet {
        match &self.kind {
            EquationKind::PairSum { sources, own: false, .. } => *sources,
            EquationKind::PairSum { sources, own: true, .. } => sources.intersect(self.dest),
            EquationKind::Particle { .. } => GroupSet::default(),
        }
    }
    /// The groups a neighbour j may belong to when i is in group `g`.
    pub fn sources_for(&self, g: GroupId) -> GroupSet {
        match &self.kind {
            EquationKind::PairSum { sources, narrowed, own, .. } => {
                let on_g = narrowed.iter().find(|(n, _)| *n == g).map_or(*sources, |(_, s)| *s);
                if *own {
                    on_g.intersect(GroupSet::default().with(g))
                } else {
                    on_g
                }
            }
            EquationKind::Particle { .. } => GroupSet::default(),
        }
    }
    pub fn reads_field(&self, f: FieldId) -> bool {
        self.reads.contains(&(f, Side::I)) || self.reads.contains(&(f, Side::J))
    }
    /// Whether this equation's module uses (directly or not) the module that defines `other`.
    pub fn builds_on(&self, other: &Equation) -> bool {
        self.span.file != other.span.file && self.builds_on.contains(&other.span.file)
    }
}

/// `integrate on G { x' = rate }`
#[derive(Clone, Debug)]
pub struct Rate {
    pub state: FieldId,
    pub rate: Expr,
    pub dest: GroupSet,
    pub reads: BTreeSet<FieldId>,
    pub span: Span,
}

/// `timestep name = expr`: the step is the minimum over all of them.
#[derive(Clone, Debug)]
pub struct Timestep {
    pub name: String,
    /// Its reductions run over these groups' particles only (the `on` of the `use` that reached it).
    pub dest: GroupSet,
    pub value: Expr,
    pub reads: BTreeSet<FieldId>,
    pub span: Span,
}

/// `require cond else "why"`: a condition on a material's parameters, checked for every material
/// with particles on `groups` (the `on` of the `use` that reached it) when a case binds them.
#[derive(Clone, Debug)]
pub struct Requirement {
    pub cond: Expr,
    pub why: String,
    pub groups: GroupSet,
    pub span: Span,
}

#[derive(Clone, Debug)]
pub enum Stmt {
    Let(LocalId, Expr),
    /// Give an output (or, in `finally`, an accumulator) its value.
    Set(FieldId, Expr),
    /// In a pair loop: fold a value into an accumulator.
    Accum(FieldId, Reduce, Expr),
    If(Expr, Vec<Stmt>, Vec<Stmt>),
}

#[derive(Clone, Debug)]
pub struct Expr {
    pub kind: ExprKind,
    pub ty: Type,
    pub span: Span,
}

/// Quantities of the pair (i, j) that the neighbour iterator provides.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PairValue {
    /// x_i − x_j
    Xij,
    /// |x_i − x_j|
    Rij,
    /// (h_i + h_j) / 2
    Hij,
    /// W(r_ij, h_ij)
    W,
    /// ∇_i W(r_ij, h_ij)
    GradW,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Global {
    Time,
    Dt,
    Dim,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Op {
    Neg,
    Not,
    /// Same shape on both sides.
    Add,
    Sub,
    /// scalar × any
    Scale,
    /// any ÷ scalar
    Div,
    /// tensor-like × vec
    MatVec,
    /// tensor-like × tensor-like → tensor
    MatMul,
    /// scalar ^ scalar
    Pow,
    Lt,
    Le,
    Gt,
    Ge,
    Eq,
    Ne,
    And,
    Or,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Builtin {
    Dot,
    Outer,
    Sym,
    Skew,
    Dev,
    Trace,
    Transpose,
    Norm,
    DDot,
    Inv,
    Det,
    Sqrt,
    Exp,
    Ln,
    /// A function of one dimensionless scalar from the table of [`Elementary`] functions.
    Elementary(Elementary),
    Abs,
    Min,
    Max,
    /// The diagonal symtensor of a vec.
    Diag,
    /// W at a given distance and smoothing length: `W_at(r, h)`
    KernelAt,
    /// ∇W at a given separation vector and smoothing length: `gradW_at(r, h)` (0 at r = 0 and
    /// beyond the support), the kernel gradient of a pair in another configuration than the
    /// current one (the reference configuration of a total Lagrangian solid).
    KernelGradAt,
    /// A vec from scalars: `vec(a, b)` or `vec(a, b, c)`; components past the model's dimension
    /// are dropped, missing ones are 0.
    Vector,
}

/// Every builtin but the elementary functions, with its name in the language and its arity (None:
/// two or more).
const BUILTINS: [(Builtin, &str, Option<usize>); 21] = [
    (Builtin::Dot, "dot", Some(2)),
    (Builtin::Outer, "outer", Some(2)),
    (Builtin::DDot, "ddot", Some(2)),
    (Builtin::Sym, "sym", Some(1)),
    (Builtin::Skew, "skew", Some(1)),
    (Builtin::Dev, "dev", Some(1)),
    (Builtin::Trace, "trace", Some(1)),
    (Builtin::Transpose, "transpose", Some(1)),
    (Builtin::Norm, "norm", Some(1)),
    (Builtin::Inv, "inv", Some(1)),
    (Builtin::Det, "det", Some(1)),
    (Builtin::Sqrt, "sqrt", Some(1)),
    (Builtin::Exp, "exp", Some(1)),
    (Builtin::Ln, "ln", Some(1)),
    (Builtin::Abs, "abs", Some(1)),
    (Builtin::Min, "min", None),
    (Builtin::Max, "max", None),
    (Builtin::Diag, "diag", Some(1)),
    (Builtin::KernelAt, "W_at", Some(2)),
    (Builtin::KernelGradAt, "gradW_at", Some(2)),
    (Builtin::Vector, "vec", None),
];

impl Builtin {
    pub fn name(self) -> &'static str {
        match self {
            Builtin::Elementary(e) => e.name(),
            b => BUILTINS.iter().find(|(c, ..)| *c == b).map(|(_, name, _)| *name).expect("every builtin is listed"),
        }
    }

    /// The builtin called `name`, with its arity (None: two or more).
    pub fn by_name(name: &str) -> Option<(Builtin, Option<usize>)> {
        let listed = BUILTINS.iter().find(|(_, n, _)| *n == name).map(|(b, _, arity)| (*b, *arity));
        listed.or_else(|| Elementary::by_name(name).map(|e| (Builtin::Elementary(e), Some(1))))
    }

    /// Every builtin's name.
    pub fn names() -> impl Iterator<Item = &'static str> {
        BUILTINS.iter().map(|(_, name, _)| *name).chain(ELEMENTARY.iter().map(|e| e.name))
    }
}

/// An elementary function of one dimensionless scalar, with a dimensionless value (applied to a
/// vec or tensor, to each component): a row of [`ELEMENTARY`]. Adding one is adding its row:
/// the checker, the host's evaluator, the CPU's closures and C code and the WGSL take it from
/// there (Cranelift's pair code leaves a program that calls one to the C code or the closures).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Elementary(u8);

/// A row of the table of elementary functions: the name (the language's, WGSL's and C's, whose
/// f32 version appends `f`) and the Rust function for each precision, which the host and the
/// CPU's closures call and which are C's libm functions of the same name.
pub struct ElementaryFn {
    pub name: &'static str,
    pub f64: fn(f64) -> f64,
    pub f32: fn(f32) -> f32,
}

/// Angles are in radians; the inverse functions' domains are C's (`asin` and `acos` of a value in
/// [−1, 1]).
pub const ELEMENTARY: [ElementaryFn; 9] = [
    ElementaryFn { name: "sin", f64: f64::sin, f32: f32::sin },
    ElementaryFn { name: "cos", f64: f64::cos, f32: f32::cos },
    ElementaryFn { name: "tan", f64: f64::tan, f32: f32::tan },
    ElementaryFn { name: "asin", f64: f64::asin, f32: f32::asin },
    ElementaryFn { name: "acos", f64: f64::acos, f32: f32::acos },
    ElementaryFn { name: "atan", f64: f64::atan, f32: f32::atan },
    ElementaryFn { name: "sinh", f64: f64::sinh, f32: f32::sinh },
    ElementaryFn { name: "cosh", f64: f64::cosh, f32: f32::cosh },
    ElementaryFn { name: "tanh", f64: f64::tanh, f32: f32::tanh },
];

impl Elementary {
    pub fn by_name(name: &str) -> Option<Elementary> {
        ELEMENTARY.iter().position(|e| e.name == name).map(|k| Elementary(k as u8))
    }

    /// Its row of [`ELEMENTARY`].
    pub fn row(self) -> &'static ElementaryFn {
        &ELEMENTARY[self.0 as usize]
    }

    pub fn name(self) -> &'static str {
        self.row().name
    }

    pub fn eval(self, x: f64) -> f64 {
        (self.row().f64)(x)
    }
}

#[derive(Clone, Debug)]
pub enum ExprKind {
    /// A scalar constant (bool constants are 0/1 with type bool).
    Const(f64),
    Field(FieldId, Side),
    Param(ParamId, Side),
    Local(LocalId),
    Pair(PairValue),
    Global(Global),
    /// The identity tensor I (a symtensor).
    Identity,
    /// Whether particle i or j belongs to one of the groups.
    InGroup(Side, GroupSet),
    Unary(Op, Box<Expr>),
    Binary(Op, Box<Expr>, Box<Expr>),
    Call(Builtin, Vec<Expr>),
    /// `select(c, a, b)`
    Select(Box<Expr>, Box<Expr>, Box<Expr>),
    /// A symtensor or skewtensor widened to a full tensor.
    ToTensor(Box<Expr>),
    /// One component: a vec's `.x` is (0, 0); a tensor's `.xy` is (0, 1).
    Component(Box<Expr>, u8, u8),
    /// `let local = value in body` (from inlined helper functions).
    Let(LocalId, Box<Expr>, Box<Expr>),
    /// `min_over`, `max_over`, `sum_over` a per-particle expression (timesteps and reports).
    Reduction(Reduce, Box<Expr>),
}

/// Constructors for expressions that later stages synthesise (integrator updates, constraints).
impl Expr {
    pub fn new(kind: ExprKind, ty: Type) -> Expr {
        Expr { kind, ty, span: Span::default() }
    }
    pub fn constant(v: f64, ty: Type) -> Expr {
        Expr::new(ExprKind::Const(v), ty)
    }
    pub fn field(f: FieldId, ty: Type) -> Expr {
        Expr::new(ExprKind::Field(f, Side::I), ty)
    }
    pub fn param(p: ParamId, ty: Type) -> Expr {
        Expr::new(ExprKind::Param(p, Side::I), ty)
    }
    pub fn global(g: Global) -> Expr {
        let unit = match g {
            Global::Time | Global::Dt => Unit::S,
            Global::Dim => Unit::ONE,
        };
        Expr::new(ExprKind::Global(g), Type::scalar(unit))
    }
    pub fn binary(op: Op, a: Expr, b: Expr, ty: Type) -> Expr {
        Expr::new(ExprKind::Binary(op, Box::new(a), Box::new(b)), ty)
    }
    /// a + b (same type)
    pub fn plus(self, b: Expr) -> Expr {
        let ty = self.ty;
        Expr::binary(Op::Add, self, b, ty)
    }
    /// a − b (same type)
    pub fn minus(self, b: Expr) -> Expr {
        let ty = self.ty;
        Expr::binary(Op::Sub, self, b, ty)
    }
    /// s × a for a scalar s; the unit is the product.
    pub fn scaled_by(self, s: Expr) -> Expr {
        let unit = self.ty.unit.mul(&s.ty.unit).unwrap_or(self.ty.unit);
        let ty = Type::new(self.ty.shape, unit);
        Expr::binary(Op::Scale, s, self, ty)
    }
    /// a ÷ s for a scalar s.
    pub fn divided_by(self, s: Expr) -> Expr {
        let unit = self.ty.unit.div(&s.ty.unit).unwrap_or(self.ty.unit);
        let ty = Type::new(self.ty.shape, unit);
        Expr::binary(Op::Div, self, s, ty)
    }
    pub fn select(c: Expr, a: Expr, b: Expr) -> Expr {
        let ty = a.ty;
        Expr::new(ExprKind::Select(Box::new(c), Box::new(a), Box::new(b)), ty)
    }
}

#[derive(Clone, Debug)]
pub struct Local {
    pub name: String,
    pub ty: Type,
}

/// A checked model: everything the scheduler and the backends need.
#[derive(Clone, Debug, Default)]
pub struct Model {
    pub fields: Vec<Field>,
    pub params: Vec<Param>,
    pub groups: Vec<Group>,
    pub kernels: Vec<Kernel>,
    /// The kernel the model asks for (`kernel = name`); a case may override it.
    pub kernel: Option<KernelId>,
    pub equations: Vec<Equation>,
    pub rates: Vec<Rate>,
    pub timesteps: Vec<Timestep>,
    pub requirements: Vec<Requirement>,
    pub locals: Vec<Local>,
}

impl Model {
    /// Whether correction `w` must run before correction `r` within a stage. Corrections update
    /// state, whose old and new values are both well defined, so their order is a choice: a
    /// module that uses another runs its corrections after that module's (the heating by plastic
    /// work after the radial return that gives the plastic strain); otherwise `w` runs first when
    /// `r` reads state that `w` writes on `groups` (the groups where `r` reads it).
    pub fn correction_before(&self, w: EqId, r: EqId, writes_read: impl Fn(&Equation, &Equation) -> bool) -> bool {
        let (ew, er) = (&self.equations[w.index()], &self.equations[r.index()]);
        if ew.builds_on(er) {
            false
        } else if er.builds_on(ew) {
            writes_read(ew, er) || writes_read(er, ew)
        } else {
            writes_read(ew, er)
        }
    }

    pub fn field(&self, id: FieldId) -> &Field {
        &self.fields[id.index()]
    }

    /// A correction: a particle equation that writes state. It runs after each integration stage
    /// (radial return, damage), while every other equation runs in the evaluation of the rates.
    pub fn is_correction(&self, e: &Equation) -> bool {
        !e.is_pair() && e.writes.iter().any(|f| self.field(*f).storage == Storage::State)
    }
    pub fn field_id(&self, name: &str) -> Option<FieldId> {
        self.fields.iter().position(|f| f.name == name).map(|i| FieldId(i as u32))
    }
    pub fn param_id(&self, name: &str) -> Option<ParamId> {
        self.params.iter().position(|p| p.name == name).map(|i| ParamId(i as u32))
    }
    pub fn group_id(&self, name: &str) -> Option<GroupId> {
        self.groups.iter().position(|g| g.name == name).map(|i| GroupId(i as u32))
    }
    pub fn kernel_id(&self, name: &str) -> Option<KernelId> {
        self.kernels.iter().position(|k| k.name == name).map(|i| KernelId(i as u32))
    }
    pub fn all_groups(&self) -> GroupSet {
        GroupSet(if self.groups.len() >= 64 { u64::MAX } else { (1u64 << self.groups.len()) - 1 })
    }
    pub fn group_names(&self, set: GroupSet) -> String {
        let names: Vec<&str> = set.iter(self.groups.len()).map(|g| self.groups[g.index()].name.as_str()).collect();
        names.join("|")
    }
}

/// Visits every sub-expression (pre-order).
pub fn walk_expr<'a>(e: &'a Expr, f: &mut impl FnMut(&'a Expr)) {
    f(e);
    match &e.kind {
        ExprKind::Unary(_, a) | ExprKind::ToTensor(a) | ExprKind::Component(a, _, _) | ExprKind::Reduction(_, a) => {
            walk_expr(a, f)
        }
        ExprKind::Binary(_, a, b) | ExprKind::Let(_, a, b) => {
            walk_expr(a, f);
            walk_expr(b, f);
        }
        ExprKind::Select(c, a, b) => {
            walk_expr(c, f);
            walk_expr(a, f);
            walk_expr(b, f);
        }
        ExprKind::Call(_, args) => args.iter().for_each(|a| walk_expr(a, f)),
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

/// Visits every sub-expression mutably (post-order: children first, so `f` sees them rewritten).
pub fn walk_expr_mut(e: &mut Expr, f: &mut impl FnMut(&mut Expr)) {
    match &mut e.kind {
        ExprKind::Unary(_, a) | ExprKind::ToTensor(a) | ExprKind::Component(a, _, _) | ExprKind::Reduction(_, a) => {
            walk_expr_mut(a, f)
        }
        ExprKind::Binary(_, a, b) | ExprKind::Let(_, a, b) => {
            walk_expr_mut(a, f);
            walk_expr_mut(b, f);
        }
        ExprKind::Select(c, a, b) => {
            walk_expr_mut(c, f);
            walk_expr_mut(a, f);
            walk_expr_mut(b, f);
        }
        ExprKind::Call(_, args) => args.iter_mut().for_each(|a| walk_expr_mut(a, f)),
        ExprKind::Const(_)
        | ExprKind::Field(..)
        | ExprKind::Param(..)
        | ExprKind::Local(_)
        | ExprKind::Pair(_)
        | ExprKind::Global(_)
        | ExprKind::Identity
        | ExprKind::InGroup(..) => {}
    }
    f(e);
}

/// Adds to `out` every field a statement list gives a value (`Set`), in both branches of an `if`.
pub fn set_targets(stmts: &[Stmt], out: &mut BTreeSet<FieldId>) {
    for s in stmts {
        match s {
            Stmt::Set(f, _) => {
                out.insert(*f);
            }
            Stmt::If(_, a, b) => {
                set_targets(a, out);
                set_targets(b, out);
            }
            Stmt::Let(..) | Stmt::Accum(..) => {}
        }
    }
}

/// Visits every expression of a statement list.
pub fn walk_stmts<'a>(stmts: &'a [Stmt], f: &mut impl FnMut(&'a Expr)) {
    for s in stmts {
        match s {
            Stmt::Let(_, e) | Stmt::Set(_, e) | Stmt::Accum(_, _, e) => walk_expr(e, f),
            Stmt::If(c, a, b) => {
                walk_expr(c, f);
                walk_stmts(a, f);
                walk_stmts(b, f);
            }
        }
    }
}
