//! The abstract syntax tree: what the source says, with a span on every node. No meaning yet —
//! names are unresolved and nothing is typed; `check` turns this into the typed IR.

use crate::diag::Span;

#[derive(Clone, Debug, PartialEq)]
pub struct Ident {
    pub name: String,
    pub span: Span,
}

#[derive(Clone, Debug)]
pub struct File {
    pub items: Vec<Item>,
}

#[derive(Clone, Debug)]
pub enum Item {
    Use(Use),
    Groups(Vec<Ident>),
    Field(FieldDecl),
    Param(ParamDecl),
    Const(ConstDecl),
    KernelSelect(Ident),
    Kernel(KernelDef),
    Fn(FnDef),
    PairSum(PairSumDef),
    Particle(ParticleDef),
    Integrate(IntegrateDef),
    Timestep(TimestepDef),
    Require(RequireDef),
}

#[derive(Clone, Debug)]
pub enum UsePath {
    /// `use solid::jaumann` → `solid/jaumann.sph`
    Module(Vec<Ident>),
    /// `use "my/file.sph"`, relative to the using file
    File(String),
}

#[derive(Clone, Debug)]
pub struct Use {
    pub path: UsePath,
    /// `use m on G from S`: m's equations run only on G (pair sums see only neighbours in S).
    pub on: Option<Vec<Ident>>,
    pub from: Option<Vec<Ident>>,
    /// `from own`: m's pair sums see only neighbours of particle i's own group.
    pub own: bool,
    /// `from own body`: m's pair sums see only neighbours of particle i's own body.
    pub own_body: bool,
    pub span: Span,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Shape {
    Scalar,
    Vec,
    SymTensor,
    SkewTensor,
    Tensor,
    Bool,
}

impl Shape {
    pub fn name(self) -> &'static str {
        match self {
            Shape::Scalar => "scalar",
            Shape::Vec => "vec",
            Shape::SymTensor => "symtensor",
            Shape::SkewTensor => "skewtensor",
            Shape::Tensor => "tensor",
            Shape::Bool => "bool",
        }
    }
}

/// A unit as written: `[kg/m^3]`. Resolved to dimensions by `units`.
#[derive(Clone, Debug)]
pub enum UnitExpr {
    One,
    Name(Ident),
    Mul(Box<UnitExpr>, Box<UnitExpr>),
    Div(Box<UnitExpr>, Box<UnitExpr>),
    Pow(Box<UnitExpr>, i32, i32, Span),
}

#[derive(Clone, Debug)]
pub struct UnitAnnot {
    pub expr: UnitExpr,
    pub span: Span,
}

#[derive(Clone, Debug)]
pub struct TypeSpec {
    pub shape: Shape,
    pub unit: Option<UnitAnnot>,
    pub span: Span,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Storage {
    /// Recomputed every step by the equation that writes it.
    Field,
    /// Carried from step to step: integrated, corrected, or set by the scene.
    State,
    /// An accumulator local to one pair sum (`acc`): lives only while its pass runs.
    Temp,
}

#[derive(Clone, Debug)]
pub struct FieldDecl {
    pub storage: Storage,
    pub name: Ident,
    pub ty: TypeSpec,
    pub init: Option<Expr>,
    pub span: Span,
}

#[derive(Clone, Debug)]
pub struct ParamDecl {
    pub name: Ident,
    pub ty: TypeSpec,
    pub default: Option<Expr>,
    pub span: Span,
}

#[derive(Clone, Debug)]
pub struct ConstDecl {
    pub name: Ident,
    pub value: Expr,
    pub span: Span,
}

#[derive(Clone, Debug)]
pub struct KernelEntry {
    pub key: String,
    pub key_span: Span,
    pub arg: Option<Ident>,
    pub value: Expr,
}

#[derive(Clone, Debug)]
pub struct KernelDef {
    pub name: Ident,
    pub entries: Vec<KernelEntry>,
    pub span: Span,
}

#[derive(Clone, Debug)]
pub struct FnParam {
    pub name: Ident,
    pub ty: Option<TypeSpec>,
}

#[derive(Clone, Debug)]
pub struct FnDef {
    pub name: Ident,
    pub params: Vec<FnParam>,
    pub ret: Option<TypeSpec>,
    pub lets: Vec<Stmt>,
    pub body: Expr,
    pub span: Span,
}

#[derive(Clone, Debug)]
pub struct Output {
    pub name: Ident,
    /// `name: shape [unit]` declares a new field; a bare name writes an existing one.
    pub ty: Option<TypeSpec>,
}

#[derive(Clone, Debug)]
pub struct PairSumDef {
    pub name: Ident,
    pub on: Option<Vec<Ident>>,
    pub from: Option<Vec<Ident>>,
    /// `from own`: only neighbours of particle i's own group.
    pub own: bool,
    /// `from own body`: only neighbours of particle i's own body.
    pub own_body: bool,
    pub outputs: Vec<Output>,
    /// `acc name: type`: accumulators local to this pair sum (summed, read in `finally`, not stored).
    pub temps: Vec<Output>,
    /// `compensated`: sums use Kahan compensation.
    pub compensated: bool,
    pub init: Vec<Stmt>,
    pub body: Vec<Stmt>,
    pub finally: Vec<Stmt>,
    pub span: Span,
}

#[derive(Clone, Debug)]
pub struct ParticleDef {
    pub name: Ident,
    pub on: Option<Vec<Ident>>,
    pub outputs: Vec<Output>,
    pub body: Vec<Stmt>,
    pub span: Span,
}

#[derive(Clone, Debug)]
pub struct Rate {
    pub state: Ident,
    pub rate: Expr,
    pub span: Span,
}

#[derive(Clone, Debug)]
pub struct IntegrateDef {
    pub on: Option<Vec<Ident>>,
    pub rates: Vec<Rate>,
    pub span: Span,
}

#[derive(Clone, Debug)]
pub struct TimestepDef {
    pub name: Ident,
    pub value: Expr,
    pub span: Span,
}

/// `require cond else "why"`: a condition on a material's parameters.
#[derive(Clone, Debug)]
pub struct RequireDef {
    pub cond: Expr,
    pub why: String,
    pub span: Span,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Side {
    I,
    J,
}

impl Side {
    pub fn letter(self) -> char {
        match self {
            Side::I => 'i',
            Side::J => 'j',
        }
    }
}

#[derive(Clone, Debug)]
pub struct LValue {
    pub name: Ident,
    pub side: Option<(Side, Span)>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AccumOp {
    Add,
    Sub,
    Min,
    Max,
}

impl AccumOp {
    pub fn text(self) -> &'static str {
        match self {
            AccumOp::Add => "+=",
            AccumOp::Sub => "-=",
            AccumOp::Min => "min=",
            AccumOp::Max => "max=",
        }
    }
}

#[derive(Clone, Debug)]
pub enum Stmt {
    Let { name: Ident, ty: Option<TypeSpec>, value: Expr, span: Span },
    Assign { target: LValue, value: Expr, span: Span },
    Accum { target: LValue, op: AccumOp, value: Expr, span: Span },
    If { cond: Expr, then: Vec<Stmt>, otherwise: Vec<Stmt>, span: Span },
}

impl Stmt {
    pub fn span(&self) -> Span {
        match self {
            Stmt::Let { span, .. } | Stmt::Assign { span, .. } | Stmt::Accum { span, .. } | Stmt::If { span, .. } => {
                *span
            }
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BinOp {
    Or,
    And,
    Eq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
    Add,
    Sub,
    Mul,
    Div,
    Pow,
}

impl BinOp {
    pub fn text(self) -> &'static str {
        match self {
            BinOp::Or => "||",
            BinOp::And => "&&",
            BinOp::Eq => "==",
            BinOp::Ne => "!=",
            BinOp::Lt => "<",
            BinOp::Le => "<=",
            BinOp::Gt => ">",
            BinOp::Ge => ">=",
            BinOp::Add => "+",
            BinOp::Sub => "-",
            BinOp::Mul => "*",
            BinOp::Div => "/",
            BinOp::Pow => "^",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UnOp {
    Neg,
    Not,
}

#[derive(Clone, Debug)]
pub struct Expr {
    pub kind: ExprKind,
    pub span: Span,
}

#[derive(Clone, Debug)]
pub enum ExprKind {
    Number(f64, Option<UnitAnnot>),
    Bool(bool),
    Name(Ident),
    /// `rho[j]`
    Index(Box<Expr>, Side, Span),
    /// `v[i].x`, `s[i].xy`
    Member(Box<Expr>, Ident),
    Call(Ident, Vec<Expr>),
    /// `j in fluid | solid`
    InGroup(Side, Vec<Ident>),
    Unary(UnOp, Box<Expr>),
    Binary(BinOp, Box<Expr>, Box<Expr>),
}
