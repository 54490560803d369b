//! IR → scalar SSA: every vector and tensor operation becomes operations on components, shared
//! sub-expressions are computed once (hash-consing), constants fold (`p * I` touches only the
//! diagonal), and `if` becomes masked selects, so a program is a flat list of scalar operations
//! that the closure compiler runs over batches of lanes.

use crate::ir::{
    self, Builtin, Elementary, Expr, ExprKind, FieldId, Global, GroupSet, Kernel, LocalId, Model, Op, PairValue,
    ParamId, Reduce, Shape, Side, Stmt,
};
use std::collections::{BTreeMap, HashMap};

pub type Id = u32;

#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum Un {
    Neg,
    Not,
    Sqrt,
    Exp,
    Ln,
    /// A function from the table of elementary functions (`ir::ELEMENTARY`).
    Elementary(Elementary),
    Abs,
}

#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum Bin {
    Add,
    Sub,
    Mul,
    Div,
    Pow,
    Min,
    Max,
    Lt,
    Le,
    Gt,
    Ge,
    Eq,
    Ne,
    And,
    Or,
}

impl Bin {
    fn commutes(self) -> bool {
        matches!(self, Bin::Add | Bin::Mul | Bin::Min | Bin::Max | Bin::Eq | Bin::Ne | Bin::And | Bin::Or)
    }
}

/// One scalar value of a program.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum Node {
    /// A constant, by its f64 bits.
    Const(u64),
    /// Stored component `comp` of a field, of particle i or neighbour j.
    Load {
        field: FieldId,
        comp: u16,
        side: Side,
    },
    Param {
        param: ParamId,
        comp: u16,
        side: Side,
    },
    /// x_i − x_j, component c (provided by the neighbour batch).
    PairX(u8),
    PairR,
    PairH,
    Global(Global),
    InGroup(Side, u64),
    Un(Un, Id),
    Bin(Bin, Id, Id),
    Select(Id, Id, Id),
}

impl Node {
    pub fn operands(&self) -> Vec<Id> {
        match *self {
            Node::Un(_, a) => vec![a],
            Node::Bin(_, a, b) => vec![a, b],
            Node::Select(c, a, b) => vec![c, a, b],
            _ => vec![],
        }
    }
}

fn effect_value(e: &Effect) -> Id {
    match *e {
        Effect::Store { value, .. } | Effect::Accum { value, .. } | Effect::Reduce { value, .. } => value,
    }
}

/// What a program does with its values.
#[derive(Clone, Debug)]
pub enum Effect {
    /// Write stored component `comp` of a field of particle i.
    Store { field: FieldId, comp: u16, value: Id },
    /// Fold a neighbour's contribution into an accumulator component.
    Accum { field: FieldId, comp: u16, reduce: Reduce, value: Id },
    /// Fold a particle's value into reduction `index` (time steps).
    Reduce { index: usize, reduce: Reduce, value: Id },
}

#[derive(Default, Clone, Debug)]
pub struct Graph {
    pub nodes: Vec<Node>,
    map: HashMap<Node, Id>,
}

impl Graph {
    pub fn constant_of(&self, id: Id) -> Option<f64> {
        match self.nodes[id as usize] {
            Node::Const(b) => Some(f64::from_bits(b)),
            _ => None,
        }
    }

    fn intern(&mut self, n: Node) -> Id {
        if let Some(id) = self.map.get(&n) {
            return *id;
        }
        self.nodes.push(n);
        let id = self.nodes.len() as Id - 1;
        self.map.insert(n, id);
        id
    }

    pub fn c(&mut self, v: f64) -> Id {
        // -0.0 and 0.0 fold to one constant.
        let v = if v == 0.0 { 0.0 } else { v };
        self.intern(Node::Const(v.to_bits()))
    }

    pub fn un(&mut self, op: Un, a: Id) -> Id {
        if let Some(x) = self.constant_of(a) {
            let r = match op {
                Un::Neg => -x,
                Un::Not => f64::from(u8::from(x == 0.0)),
                Un::Sqrt => x.sqrt(),
                Un::Exp => x.exp(),
                Un::Ln => x.ln(),
                Un::Elementary(e) => e.eval(x),
                Un::Abs => x.abs(),
            };
            return self.c(r);
        }
        if let (Un::Neg, Node::Un(Un::Neg, inner)) = (op, self.nodes[a as usize]) {
            return inner;
        }
        self.intern(Node::Un(op, a))
    }

    // Comparisons with float constants read better as guards than as float patterns.
    #[allow(clippy::redundant_guards)]
    pub fn bin(&mut self, op: Bin, a: Id, b: Id) -> Id {
        let (ca, cb) = (self.constant_of(a), self.constant_of(b));
        if let (Some(x), Some(y)) = (ca, cb) {
            let t = |c: bool| f64::from(u8::from(c));
            let r = match op {
                Bin::Add => x + y,
                Bin::Sub => x - y,
                Bin::Mul => x * y,
                Bin::Div => x / y,
                Bin::Pow => x.powf(y),
                Bin::Min => x.min(y),
                Bin::Max => x.max(y),
                Bin::Lt => t(x < y),
                Bin::Le => t(x <= y),
                Bin::Gt => t(x > y),
                Bin::Ge => t(x >= y),
                Bin::Eq => t(x == y),
                Bin::Ne => t(x != y),
                Bin::And => t(x != 0.0 && y != 0.0),
                Bin::Or => t(x != 0.0 || y != 0.0),
            };
            return self.c(r);
        }
        match (op, ca, cb) {
            (Bin::Add, Some(z), _) if z == 0.0 => return b,
            (Bin::Add | Bin::Sub, _, Some(z)) if z == 0.0 => return a,
            (Bin::Sub, Some(z), _) if z == 0.0 => return self.un(Un::Neg, b),
            (Bin::Mul, Some(z), _) | (Bin::Mul, _, Some(z)) if z == 0.0 => return self.c(0.0),
            (Bin::Mul, Some(o), _) if o == 1.0 => return b,
            (Bin::Mul | Bin::Div, _, Some(o)) if o == 1.0 => return a,
            (Bin::Mul, Some(m), _) if m == -1.0 => return self.un(Un::Neg, b),
            (Bin::Mul, _, Some(m)) if m == -1.0 => return self.un(Un::Neg, a),
            (Bin::Div, Some(z), _) if z == 0.0 => return self.c(0.0),
            (Bin::And, Some(x), _) => return if x != 0.0 { b } else { self.c(0.0) },
            (Bin::And, _, Some(y)) => return if y != 0.0 { a } else { self.c(0.0) },
            (Bin::Or, Some(x), _) => return if x != 0.0 { self.c(1.0) } else { b },
            (Bin::Or, _, Some(y)) => return if y != 0.0 { self.c(1.0) } else { a },
            _ => {}
        }
        if op == Bin::Sub && a == b {
            return self.c(0.0);
        }
        // x / c → x · (1/c): a multiplication instead of a division in every lane.
        if let (Bin::Div, Some(c)) = (op, cb) {
            let r = self.c(1.0 / c);
            return self.bin(Bin::Mul, a, r);
        }
        if op == Bin::Add && a == b {
            let two = self.c(2.0);
            return self.bin(Bin::Mul, two, a);
        }
        // c₁ · (c₂ · x) → (c₁c₂) · x
        if op == Bin::Mul {
            let (k, x) = match (ca, cb) {
                (Some(k), None) => (k, b),
                (None, Some(k)) => (k, a),
                _ => (f64::NAN, a),
            };
            if !k.is_nan() {
                if let Node::Bin(Bin::Mul, p, q) = self.nodes[x as usize] {
                    let inner = match (self.constant_of(p), self.constant_of(q)) {
                        (Some(c), _) => Some((c, q)),
                        (_, Some(c)) => Some((c, p)),
                        _ => None,
                    };
                    if let Some((c, y)) = inner {
                        let kc = self.c(k * c);
                        return self.bin(Bin::Mul, kc, y);
                    }
                }
            }
        }
        // x + (−y) → x − y; keeps the graph small for sums of negated terms.
        if let (Bin::Add, Node::Un(Un::Neg, y)) = (op, self.nodes[b as usize]) {
            return self.bin(Bin::Sub, a, y);
        }
        let (a, b) = if op.commutes() && b < a { (b, a) } else { (a, b) };
        self.intern(Node::Bin(op, a, b))
    }

    /// A copy of the graph reachable from `roots` in which divisions by a value that divides
    /// more than once become multiplications by its reciprocal, computed once. Returns the new
    /// graph and the new id of every old one (`Id::MAX` where unreachable).
    pub fn share_reciprocals(&self, roots: &[Id]) -> (Graph, Vec<Id>) {
        let live = reachable(self, roots);
        let mut divisors: HashMap<Id, usize> = HashMap::new();
        for (k, n) in self.nodes.iter().enumerate() {
            if let (true, Node::Bin(Bin::Div, _, d)) = (live[k], n) {
                *divisors.entry(*d).or_default() += 1;
            }
        }
        let mut g = Graph::default();
        let mut map = vec![Id::MAX; self.nodes.len()];
        for (k, n) in self.nodes.iter().enumerate() {
            if !live[k] {
                continue;
            }
            let m = |x: Id| map[x as usize];
            map[k] = match *n {
                Node::Un(op, a) => g.un(op, m(a)),
                Node::Bin(Bin::Div, a, d) if divisors.get(&d).copied().unwrap_or(0) > 1 => {
                    let one = g.c(1.0);
                    let r = g.bin(Bin::Div, one, m(d));
                    g.bin(Bin::Mul, m(a), r)
                }
                Node::Bin(op, a, b) => g.bin(op, m(a), m(b)),
                Node::Select(c, a, b) => g.select(m(c), m(a), m(b)),
                leaf => g.intern(leaf),
            };
        }
        (g, map)
    }

    pub fn select(&mut self, c: Id, a: Id, b: Id) -> Id {
        if let Some(x) = self.constant_of(c) {
            return if x != 0.0 { a } else { b };
        }
        if a == b {
            return a;
        }
        self.intern(Node::Select(c, a, b))
    }

    fn add(&mut self, a: Id, b: Id) -> Id {
        self.bin(Bin::Add, a, b)
    }
    fn sub(&mut self, a: Id, b: Id) -> Id {
        self.bin(Bin::Sub, a, b)
    }
    fn mul(&mut self, a: Id, b: Id) -> Id {
        self.bin(Bin::Mul, a, b)
    }
    fn div(&mut self, a: Id, b: Id) -> Id {
        self.bin(Bin::Div, a, b)
    }
    fn sum(&mut self, ids: &[Id]) -> Id {
        let zero = self.c(0.0);
        ids.iter().fold(zero, |acc, x| self.add(acc, *x))
    }
    /// x^n for a small integer n by multiplication.
    pub fn powi(&mut self, x: Id, n: i32) -> Id {
        let mut r = self.c(1.0);
        for _ in 0..n.unsigned_abs() {
            r = self.mul(r, x);
        }
        if n < 0 {
            let one = self.c(1.0);
            r = self.div(one, r);
        }
        r
    }
}

/// Which nodes the roots depend on.
fn reachable(g: &Graph, roots: &[Id]) -> Vec<bool> {
    let mut live = vec![false; g.nodes.len()];
    let mut stack: Vec<Id> = roots.to_vec();
    while let Some(id) = stack.pop() {
        if !std::mem::replace(&mut live[id as usize], true) {
            stack.extend(g.nodes[id as usize].operands());
        }
    }
    live
}

/// A lowered value: a scalar, the d components of a vec, or the full d×d row-major matrix of any
/// tensor (symmetric and skew tensors included, so every operation has one form).
#[derive(Clone, Debug)]
pub struct Val {
    pub shape: Shape,
    pub c: Vec<Id>,
}

fn scalar(id: Id) -> Val {
    Val { shape: Shape::Scalar, c: vec![id] }
}

/// How particle i's values are read: per lane (particle programs) or once per destination.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// One particle per lane: particle equations, `finally`, updates, reductions.
    Particle,
    /// One neighbour per lane, for one particle i.
    Pair,
}

/// Values known when the programs are compiled, which fold like literals.
#[derive(Clone, Debug, Default)]
pub struct Known {
    /// By parameter id: `Some` when every material with particles binds the same value, so that
    /// the parameter is a constant of the run (`f^art_n` with `art_n = 4` becomes three
    /// multiplications).
    pub params: Vec<Option<Vec<f64>>>,
    /// By field id: `Some` when no equation, rate, constraint or saved copy writes the field and
    /// every particle holds the same value (a uniform `h`, `dx`: the kernel's normalisation and
    /// `W(Δp)` become constants).
    pub fields: Vec<Option<Vec<f64>>>,
}

impl Known {
    /// What every one of `parts` knows alike (the ranks of a split run, each over its share).
    pub fn agreed(parts: &[Known]) -> Known {
        let agree = |entries: &dyn Fn(&Known) -> &Vec<Option<Vec<f64>>>| {
            let first = parts.first().map(entries).cloned().unwrap_or_default();
            let same = |k: usize| parts.iter().all(|p| entries(p)[k] == first[k]);
            first.iter().enumerate().map(|(k, v)| v.clone().filter(|_| same(k))).collect()
        };
        Known { params: agree(&|k| &k.params), fields: agree(&|k| &k.fields) }
    }

    /// As numbers: per parameter, then per field, a count of values (−1 for unknown) and the
    /// values.
    pub fn encode(&self) -> Vec<f64> {
        let mut out = vec![self.params.len() as f64];
        for v in self.params.iter().chain(&self.fields) {
            match v {
                Some(v) => out.extend(std::iter::once(v.len() as f64).chain(v.iter().copied())),
                None => out.push(-1.0),
            }
        }
        out
    }

    /// What [`encode`](Self::encode) wrote.
    pub fn decode(numbers: &[f64]) -> Known {
        let params = numbers[0] as usize;
        let (mut at, mut all) = (1, vec![]);
        while at < numbers.len() {
            let len = numbers[at];
            at += 1;
            if len < 0.0 {
                all.push(None);
                continue;
            }
            all.push(Some(numbers[at..at + len as usize].to_vec()));
            at += len as usize;
        }
        let fields = all.split_off(params.min(all.len()));
        Known { params: all, fields }
    }
}

pub struct Lowerer<'a> {
    pub model: &'a Model,
    known: &'a Known,
    pub kernel: &'a Kernel,
    pub dim: usize,
    pub g: Graph,
    pub effects: Vec<Effect>,
    mode: Mode,
    locals: HashMap<LocalId, Val>,
    /// Values written so far (particle mode), so later statements read them without memory.
    current: BTreeMap<FieldId, Val>,
    /// Fields whose writes to keep (stored on the group being compiled).
    stored: Box<dyn Fn(FieldId) -> bool + 'a>,
    /// The groups particle i and its neighbours j can be in, where the program is compiled for
    /// them (a pass variant, a group's particle program): `i in S` and `j in S` fold to constants
    /// where these settle them, so a term selected away on a group is never computed there.
    groups: (GroupSet, GroupSet),
}

impl<'a> Lowerer<'a> {
    pub fn new(
        model: &'a Model,
        known: &'a Known,
        kernel: &'a Kernel,
        dim: usize,
        mode: Mode,
        stored: Box<dyn Fn(FieldId) -> bool + 'a>,
    ) -> Self {
        Lowerer {
            model,
            known,
            kernel,
            dim,
            g: Graph::default(),
            effects: vec![],
            mode,
            locals: HashMap::new(),
            current: BTreeMap::new(),
            stored,
            groups: (GroupSet::ALL, GroupSet::ALL),
        }
    }

    /// Particle i is in one of `i`, its neighbours in one of `j`: group tests these settle fold.
    pub fn in_groups(mut self, i: GroupSet, j: GroupSet) -> Self {
        self.groups = (i, j);
        self
    }

    fn full_len(&self, shape: Shape) -> usize {
        match shape {
            Shape::Scalar | Shape::Bool => 1,
            Shape::Vec => self.dim,
            _ => self.dim * self.dim,
        }
    }

    fn fill(&mut self, shape: Shape, v: f64) -> Val {
        let id = self.g.c(v);
        Val { shape, c: vec![id; self.full_len(shape)] }
    }

    fn identity(&mut self) -> Val {
        let d = self.dim;
        let (z, o) = (self.g.c(0.0), self.g.c(1.0));
        let c = (0..d * d).map(|k| if k / d == k % d { o } else { z }).collect();
        Val { shape: Shape::SymTensor, c }
    }

    /// The full form of a stored field's components (`load(comp)` gives a stored component).
    fn expand(&mut self, shape: Shape, mut load: impl FnMut(&mut Graph, usize) -> Id) -> Val {
        let d = self.dim;
        let idx = ir::component_indices(shape, d);
        let find = |a: usize, b: usize| idx.iter().position(|&(r, c)| r == a && c == b);
        let c = match shape {
            Shape::Scalar | Shape::Bool => vec![load(&mut self.g, 0)],
            Shape::Vec => (0..d).map(|k| load(&mut self.g, k)).collect(),
            Shape::Tensor => (0..d * d).map(|k| load(&mut self.g, k)).collect(),
            Shape::SymTensor => {
                let mut out = vec![0; d * d];
                for a in 0..d {
                    for b in 0..d {
                        let k = find(a.min(b), a.max(b)).expect("upper triangle");
                        out[a * d + b] = load(&mut self.g, k);
                    }
                }
                out
            }
            Shape::SkewTensor => {
                let mut out = vec![0; d * d];
                for a in 0..d {
                    for b in 0..d {
                        out[a * d + b] = if a == b {
                            self.g.c(0.0)
                        } else {
                            let k = find(a.min(b), a.max(b)).expect("upper triangle");
                            let v = load(&mut self.g, k);
                            if a < b {
                                v
                            } else {
                                self.g.un(Un::Neg, v)
                            }
                        };
                    }
                }
                out
            }
        };
        Val { shape, c }
    }

    /// The stored components of a full value (inverse of `expand`).
    pub fn stored_components(&self, v: &Val, shape: Shape) -> Vec<Id> {
        let d = self.dim;
        match shape {
            Shape::Scalar | Shape::Bool => vec![v.c[0]],
            Shape::Vec => v.c.clone(),
            _ => ir::component_indices(shape, d).iter().map(|&(a, b)| v.c[a * d + b]).collect(),
        }
    }

    /// h_ij: a constant when `h` is a known field (one value on every particle, never written).
    fn pair_h(&mut self) -> Id {
        let known = self.model.field_id("h").and_then(|h| self.known.fields.get(h.index())).and_then(|v| v.as_ref());
        match known {
            Some(h) => self.g.c(h[0]),
            None => self.g.intern(Node::PairH),
        }
    }

    fn field(&mut self, f: FieldId, side: Side) -> Val {
        if side == Side::I {
            if let Some(v) = self.current.get(&f) {
                return v.clone();
            }
        }
        let shape = self.model.field(f).ty.shape;
        // A neighbour's vec or tensor is gathered with the sign flips of a symmetry plane's image,
        // so only a scalar, or a field that is 0 everywhere, is the same constant on both sides.
        let same_on_images = side == Side::I || shape == Shape::Scalar || shape == Shape::Bool;
        if let Some(values) = self.known.fields.get(f.index()).and_then(|v| v.as_ref()) {
            if same_on_images || values.iter().all(|v| *v == 0.0) {
                return self.expand(shape, |g, k| g.c(values[k]));
            }
        }
        self.expand(shape, |g, k| g.intern(Node::Load { field: f, comp: k as u16, side }))
    }

    fn param(&mut self, p: ParamId, side: Side) -> Val {
        let shape = self.model.params[p.index()].ty.shape;
        if let Some(values) = self.known.params.get(p.index()).and_then(|v| v.as_ref()) {
            return self.expand(shape, |g, k| g.c(values[k]));
        }
        self.expand(shape, |g, k| g.intern(Node::Param { param: p, comp: k as u16, side }))
    }

    /// W(r, h): `norm_d / h^d · w(r/h)`, zero beyond the support when `cutoff`.
    pub fn kernel_w(&mut self, r: Id, h: Id, cutoff: bool) -> Id {
        let big_r = self.g.div(r, h);
        let w = self.kernel_fn(big_r, true);
        let norm = self.g.c(self.kernel.norm[self.dim - 1]);
        let hd = self.g.powi(h, self.dim as i32);
        let a = self.g.div(norm, hd);
        let value = self.g.mul(a, w);
        if cutoff {
            let support = self.g.c(self.kernel.support);
            let inside = self.g.bin(Bin::Lt, big_r, support);
            let zero = self.g.c(0.0);
            return self.g.select(inside, value, zero);
        }
        value
    }

    /// ∇_i W = norm_d / h^(d+1) · dw(R) · x_ij / r (pairs at r = 0 never reach a program).
    fn kernel_grad(&mut self) -> Val {
        let (r, h) = (self.g.intern(Node::PairR), self.pair_h());
        let big_r = self.g.div(r, h);
        let dw = self.kernel_fn(big_r, false);
        let norm = self.g.c(self.kernel.norm[self.dim - 1]);
        let hd = self.g.powi(h, self.dim as i32 + 1);
        let a = self.g.div(norm, hd);
        let f = self.g.mul(a, dw);
        let f_over_r = self.g.div(f, r);
        let c = (0..self.dim)
            .map(|k| {
                let x = self.g.intern(Node::PairX(k as u8));
                self.g.mul(f_over_r, x)
            })
            .collect();
        Val { shape: Shape::Vec, c }
    }

    fn kernel_fn(&mut self, big_r: Id, value: bool) -> Id {
        let k = self.kernel;
        self.locals.insert(k.arg, scalar(big_r));
        let e = if value { &k.w } else { &k.dw };
        self.expr(e).c[0]
    }

    pub fn expr(&mut self, e: &Expr) -> Val {
        match &e.kind {
            ExprKind::Const(v) => self.fill(e.ty.shape, *v),
            ExprKind::Field(f, side) => self.field(*f, *side),
            ExprKind::Param(p, side) => self.param(*p, *side),
            ExprKind::Local(id) => self.locals.get(id).cloned().unwrap_or_else(|| self.fill(e.ty.shape, f64::NAN)),
            ExprKind::Pair(p) => self.pair(*p),
            ExprKind::Global(g) => {
                if *g == Global::Dim {
                    let d = self.dim as f64;
                    return scalar(self.g.c(d));
                }
                let id = self.g.intern(Node::Global(*g));
                scalar(id)
            }
            ExprKind::Identity => self.identity(),
            ExprKind::InGroup(side, set) => {
                let possible = if *side == Side::I { self.groups.0 } else { self.groups.1 };
                let id = match set.decides(possible) {
                    Some(known) => self.g.c(if known { 1.0 } else { 0.0 }),
                    None => self.g.intern(Node::InGroup(*side, set.0)),
                };
                scalar(id)
            }
            ExprKind::Unary(op, a) => {
                let a = self.expr(a);
                let op = if *op == Op::Not { Un::Not } else { Un::Neg };
                let c = a.c.iter().map(|x| self.g.un(op, *x)).collect();
                Val { shape: e.ty.shape, c }
            }
            ExprKind::Binary(op, a, b) => {
                let (a, b) = (self.expr(a), self.expr(b));
                self.binary(*op, a, b, e.ty.shape)
            }
            ExprKind::Call(f, args) => {
                let args: Vec<Val> = args.iter().map(|a| self.expr(a)).collect();
                self.call(*f, args, e.ty.shape)
            }
            ExprKind::Select(c, a, b) => {
                let c = self.expr(c).c[0];
                let (a, b) = (self.expr(a), self.expr(b));
                let comps = a.c.iter().zip(&b.c).map(|(x, y)| self.g.select(c, *x, *y)).collect();
                Val { shape: e.ty.shape, c: comps }
            }
            ExprKind::ToTensor(a) => {
                let v = self.expr(a);
                Val { shape: Shape::Tensor, c: v.c }
            }
            ExprKind::Component(a, r, c) => {
                let v = self.expr(a);
                let k = if v.shape == Shape::Vec { *r as usize } else { *r as usize * self.dim + *c as usize };
                scalar(v.c[k])
            }
            ExprKind::Let(id, value, body) => {
                let v = self.expr(value);
                self.locals.insert(*id, v);
                self.expr(body)
            }
            ExprKind::Reduction(..) => self.fill(e.ty.shape, f64::NAN),
        }
    }

    fn pair(&mut self, p: PairValue) -> Val {
        match p {
            PairValue::Xij => {
                let c = (0..self.dim).map(|k| self.g.intern(Node::PairX(k as u8))).collect();
                Val { shape: Shape::Vec, c }
            }
            PairValue::Rij => scalar(self.g.intern(Node::PairR)),
            PairValue::Hij => scalar(self.pair_h()),
            PairValue::W => {
                let (r, h) = (self.g.intern(Node::PairR), self.pair_h());
                let w = self.kernel_w(r, h, false);
                scalar(w)
            }
            PairValue::GradW => self.kernel_grad(),
        }
    }

    fn binary(&mut self, op: Op, a: Val, b: Val, shape: Shape) -> Val {
        let d = self.dim;
        let bin = match op {
            Op::Add => Some(Bin::Add),
            Op::Sub => Some(Bin::Sub),
            Op::Lt => Some(Bin::Lt),
            Op::Le => Some(Bin::Le),
            Op::Gt => Some(Bin::Gt),
            Op::Ge => Some(Bin::Ge),
            Op::Eq => Some(Bin::Eq),
            Op::Ne => Some(Bin::Ne),
            Op::And => Some(Bin::And),
            Op::Or => Some(Bin::Or),
            _ => None,
        };
        if let Some(bop) = bin {
            let c = a.c.iter().zip(&b.c).map(|(x, y)| self.g.bin(bop, *x, *y)).collect();
            return Val { shape, c };
        }
        match op {
            Op::Scale => {
                let s = a.c[0];
                let c = b.c.iter().map(|x| self.g.mul(s, *x)).collect();
                Val { shape, c }
            }
            Op::Div => {
                let s = b.c[0];
                let c = a.c.iter().map(|x| self.g.div(*x, s)).collect();
                Val { shape, c }
            }
            Op::MatVec => {
                let c = (0..d)
                    .map(|r| {
                        let terms: Vec<Id> = (0..d).map(|k| self.g.mul(a.c[r * d + k], b.c[k])).collect();
                        self.g.sum(&terms)
                    })
                    .collect();
                Val { shape: Shape::Vec, c }
            }
            Op::MatMul => {
                let mut c = vec![0; d * d];
                for r in 0..d {
                    for col in 0..d {
                        let terms: Vec<Id> = (0..d).map(|k| self.g.mul(a.c[r * d + k], b.c[k * d + col])).collect();
                        c[r * d + col] = self.g.sum(&terms);
                    }
                }
                Val { shape: Shape::Tensor, c }
            }
            Op::Pow => {
                let p = self.power(a.c[0], b.c[0]);
                scalar(p)
            }
            _ => unreachable!("handled above"),
        }
    }

    fn power(&mut self, x: Id, e: Id) -> Id {
        match self.g.constant_of(e) {
            Some(n) if n.fract() == 0.0 && n.abs() <= 8.0 => self.g.powi(x, n as i32),
            Some(h) if (h * 2.0).fract() == 0.0 && h.abs() <= 8.0 => {
                // x^(k + 1/2) = x^k · √x
                let pos = {
                    let s = self.g.un(Un::Sqrt, x);
                    let p = self.g.powi(x, (h.abs() - 0.5) as i32);
                    self.g.mul(p, s)
                };
                if h < 0.0 {
                    let one = self.g.c(1.0);
                    return self.g.div(one, pos);
                }
                pos
            }
            _ => self.g.bin(Bin::Pow, x, e),
        }
    }

    fn call(&mut self, f: Builtin, args: Vec<Val>, shape: Shape) -> Val {
        let d = self.dim;
        let t = |v: &Val, r: usize, c: usize| v.c[r * d + c];
        match f {
            Builtin::Dot => {
                let terms: Vec<Id> = (0..d).map(|k| self.g.mul(args[0].c[k], args[1].c[k])).collect();
                scalar(self.g.sum(&terms))
            }
            Builtin::Outer => {
                let c = (0..d * d).map(|k| self.g.mul(args[0].c[k / d], args[1].c[k % d])).collect();
                Val { shape: Shape::Tensor, c }
            }
            Builtin::DDot => {
                let terms: Vec<Id> = (0..d * d).map(|k| self.g.mul(args[0].c[k], args[1].c[k])).collect();
                scalar(self.g.sum(&terms))
            }
            Builtin::Sym | Builtin::Skew => {
                let a = &args[0];
                let half = self.g.c(0.5);
                let op = if f == Builtin::Sym { Bin::Add } else { Bin::Sub };
                let c = (0..d * d)
                    .map(|k| {
                        let (r, col) = (k / d, k % d);
                        if f == Builtin::Skew && r == col {
                            return self.g.c(0.0);
                        }
                        let s = self.g.bin(op, t(a, r, col), t(a, col, r));
                        self.g.mul(half, s)
                    })
                    .collect();
                Val { shape, c }
            }
            Builtin::Dev => {
                let a = &args[0];
                let tr = self.trace(a);
                let third = self.g.c(1.0 / 3.0);
                let m = self.g.mul(third, tr);
                let c = (0..d * d).map(|k| if k / d == k % d { self.g.sub(a.c[k], m) } else { a.c[k] }).collect();
                Val { shape, c }
            }
            Builtin::Trace => {
                let tr = self.trace(&args[0]);
                scalar(tr)
            }
            Builtin::Transpose => {
                let a = &args[0];
                let c = (0..d * d).map(|k| t(a, k % d, k / d)).collect();
                Val { shape, c }
            }
            Builtin::Norm => {
                let terms: Vec<Id> = args[0].c.iter().map(|x| self.g.mul(*x, *x)).collect();
                let s = self.g.sum(&terms);
                scalar(self.g.un(Un::Sqrt, s))
            }
            Builtin::Inv => self.inverse(&args[0], shape),
            Builtin::Det => {
                let det = self.det(&args[0]);
                scalar(det)
            }
            Builtin::Sqrt | Builtin::Exp | Builtin::Ln | Builtin::Elementary(_) | Builtin::Abs => {
                let op = match f {
                    Builtin::Sqrt => Un::Sqrt,
                    Builtin::Exp => Un::Exp,
                    Builtin::Ln => Un::Ln,
                    Builtin::Elementary(e) => Un::Elementary(e),
                    _ => Un::Abs,
                };
                let c = args[0].c.iter().map(|x| self.g.un(op, *x)).collect();
                Val { shape, c }
            }
            Builtin::Min | Builtin::Max => {
                let op = if f == Builtin::Min { Bin::Min } else { Bin::Max };
                let c = args[0].c.iter().zip(&args[1].c).map(|(x, y)| self.g.bin(op, *x, *y)).collect();
                Val { shape, c }
            }
            Builtin::Diag => {
                let z = self.g.c(0.0);
                let c = (0..d * d).map(|k| if k / d == k % d { args[0].c[k / d] } else { z }).collect();
                Val { shape: Shape::SymTensor, c }
            }
            Builtin::KernelAt => {
                let w = self.kernel_w(args[0].c[0], args[1].c[0], true);
                scalar(w)
            }
            Builtin::KernelGradAt => self.kernel_grad_at(&args[0], args[1].c[0]),
            Builtin::Vector => {
                let c = (0..d).map(|k| args.get(k).map_or_else(|| self.g.c(0.0), |a| a.c[0])).collect();
                Val { shape: Shape::Vec, c }
            }
        }
    }

    /// ∇W at the separation `x` with smoothing length `h`: norm_d / h^(d+1) · dw(R) · x / r,
    /// 0 at r = 0 and from the support on.
    fn kernel_grad_at(&mut self, x: &Val, h: Id) -> Val {
        let squares: Vec<Id> = x.c.iter().map(|c| self.g.mul(*c, *c)).collect();
        let r2 = self.g.sum(&squares);
        let r = self.g.un(Un::Sqrt, r2);
        let big_r = self.g.div(r, h);
        let dw = self.kernel_fn(big_r, false);
        let norm = self.g.c(self.kernel.norm[self.dim - 1]);
        let hd = self.g.powi(h, self.dim as i32 + 1);
        let a = self.g.div(norm, hd);
        let f = self.g.mul(a, dw);
        let f_over_r = self.g.div(f, r);
        let (zero, support) = (self.g.c(0.0), self.g.c(self.kernel.support));
        let inside = self.g.bin(Bin::Lt, big_r, support);
        let apart = self.g.bin(Bin::Gt, r, zero);
        let counts = self.g.bin(Bin::And, inside, apart);
        let c =
            x.c.iter()
                .map(|xk| {
                    let g = self.g.mul(f_over_r, *xk);
                    self.g.select(counts, g, zero)
                })
                .collect();
        Val { shape: Shape::Vec, c }
    }

    fn trace(&mut self, a: &Val) -> Id {
        let d = self.dim;
        let diag: Vec<Id> = (0..d).map(|k| a.c[k * d + k]).collect();
        self.g.sum(&diag)
    }

    fn det(&mut self, a: &Val) -> Id {
        match self.dim {
            1 => a.c[0],
            2 => {
                let p = self.g.mul(a.c[0], a.c[3]);
                let q = self.g.mul(a.c[1], a.c[2]);
                self.g.sub(p, q)
            }
            _ => {
                let mut terms = vec![];
                for c in 0..3 {
                    let cof = self.cofactor(a, 0, c);
                    terms.push(self.g.mul(a.c[c], cof));
                }
                self.g.sum(&terms)
            }
        }
    }

    /// The (r, c) cofactor of a 3×3 matrix.
    fn cofactor(&mut self, a: &Val, r: usize, c: usize) -> Id {
        let (r1, r2) = ((r + 1) % 3, (r + 2) % 3);
        let (c1, c2) = ((c + 1) % 3, (c + 2) % 3);
        let p = self.g.mul(a.c[r1 * 3 + c1], a.c[r2 * 3 + c2]);
        let q = self.g.mul(a.c[r1 * 3 + c2], a.c[r2 * 3 + c1]);
        self.g.sub(p, q)
    }

    fn inverse(&mut self, a: &Val, shape: Shape) -> Val {
        let d = self.dim;
        let det = self.det(a);
        let one = self.g.c(1.0);
        let inv_det = self.g.div(one, det);
        let c = match d {
            1 => vec![inv_det],
            2 => {
                let n1 = self.g.un(Un::Neg, a.c[1]);
                let n2 = self.g.un(Un::Neg, a.c[2]);
                [a.c[3], n1, n2, a.c[0]].iter().map(|x| self.g.mul(*x, inv_det)).collect()
            }
            _ => {
                // inverse = adjugate / det, adjugate = transpose of the cofactor matrix
                let mut out = vec![0; 9];
                for r in 0..3 {
                    for c in 0..3 {
                        let cof = self.cofactor(a, c, r);
                        out[r * 3 + c] = self.g.mul(cof, inv_det);
                    }
                }
                out
            }
        };
        Val { shape, c }
    }

    /// Lowers statements under a mask (`None`: all lanes).
    pub fn block(&mut self, stmts: &[Stmt], mask: Option<Id>) {
        for s in stmts {
            match s {
                Stmt::Let(id, e) => {
                    let v = self.expr(e);
                    self.locals.insert(*id, v);
                }
                Stmt::Set(f, e) => {
                    let mut v = self.expr(e);
                    if let Some(m) = mask {
                        let old = self.field(*f, Side::I);
                        v.c = v.c.iter().zip(&old.c).map(|(n, o)| self.g.select(m, *n, *o)).collect();
                    }
                    v.shape = self.model.field(*f).ty.shape;
                    self.current.insert(*f, v);
                }
                Stmt::Accum(f, reduce, e) => {
                    let v = self.expr(e);
                    let shape = self.model.field(*f).ty.shape;
                    let comps = self.stored_components(&v, shape);
                    let identity = self.g.c(reduce.identity());
                    for (k, c) in comps.into_iter().enumerate() {
                        let value = match mask {
                            Some(m) => self.g.select(m, c, identity),
                            None => c,
                        };
                        self.effects.push(Effect::Accum { field: *f, comp: k as u16, reduce: *reduce, value });
                    }
                }
                Stmt::If(c, a, b) => {
                    let cond = self.expr(c).c[0];
                    let not = self.g.un(Un::Not, cond);
                    let (ma, mb) = match mask {
                        Some(m) => (self.g.bin(Bin::And, m, cond), self.g.bin(Bin::And, m, not)),
                        None => (cond, not),
                    };
                    self.block(a, Some(ma));
                    self.block(b, Some(mb));
                }
            }
        }
    }

    /// Ends a particle program: every field written becomes stores of its components (fields not
    /// stored on this group are dropped, and so is the work that only they needed).
    pub fn finish_stores(&mut self) {
        let written: Vec<(FieldId, Val)> = std::mem::take(&mut self.current).into_iter().collect();
        for (f, v) in written {
            if !(self.stored)(f) {
                continue;
            }
            let shape = self.model.field(f).ty.shape;
            for (k, c) in self.stored_components(&v, shape).into_iter().enumerate() {
                self.effects.push(Effect::Store { field: f, comp: k as u16, value: c });
            }
        }
    }

    /// A reduction over particles (time steps): `expr` per particle folded with `reduce`.
    pub fn reduction(&mut self, index: usize, reduce: Reduce, e: &Expr) {
        let v = self.expr(e).c[0];
        self.effects.push(Effect::Reduce { index, reduce, value: v });
    }

    /// A mask that restricts a pair sum to its own source groups within a fused pass.
    pub fn sources_mask(&mut self, sources: GroupSet) -> Id {
        self.g.intern(Node::InGroup(Side::J, sources.0))
    }

    /// Shares reciprocals of repeated divisors across the whole program (see `Graph::share_reciprocals`).
    pub fn optimise(&mut self) {
        let roots: Vec<Id> = self.effects.iter().map(effect_value).collect();
        let (g, map) = self.g.share_reciprocals(&roots);
        for e in &mut self.effects {
            match e {
                Effect::Store { value, .. } | Effect::Accum { value, .. } | Effect::Reduce { value, .. } => {
                    *value = map[*value as usize]
                }
            }
        }
        self.g = g;
    }

    pub fn mode(&self) -> Mode {
        self.mode
    }
}
