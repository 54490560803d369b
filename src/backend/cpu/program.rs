//! Scalar SSA → closures over batches of lanes. Each SSA value gets a register of `LANES` reals;
//! each operation is one closure that loops over the lanes of its registers (a loop the compiler
//! vectorises), so the cost of dispatch is paid once per operation per batch, not per pair.
//! Registers are reused after their last use; an operation never writes a register it reads.

use super::lower::{Bin, Effect, Graph, Id, Node, Un};
use crate::ir::{FieldId, Global, Model, Reduce, Shape, Side, Storage};
use crate::particles::{Real, ABSENT};

/// Lanes per batch: neighbours of one particle, or particles of one chunk.
pub const LANES: usize = 64;

/// A raw view of a column, so that parallel chunks can write their own rows while others read
/// rows they never write (the scheduler guarantees a pass never reads at j what it writes).
#[derive(Clone)]
pub struct ColView<T> {
    pub ptr: *mut T,
    pub comps: usize,
    pub base: Vec<isize>,
    /// The base when every group that stores the column has the same one (rows are particle
    /// indices, the usual case): neighbour gathers then skip the per-particle group lookup.
    pub uniform: Option<isize>,
    /// The base shared by every group that stores the column, if they share one.
    pub shared: Option<isize>,
}

// SAFETY: a ColView is only dereferenced at rows the scheduler's invariants make race-free:
// each chunk writes the rows of its own particles; fields read at j are not written in that pass.
unsafe impl<T: Send> Send for ColView<T> {}
unsafe impl<T: Sync> Sync for ColView<T> {}

/// What a program reads besides its registers.
pub struct Ctx<'a, T> {
    pub cols: &'a [Option<ColView<T>>],
    /// Per-chunk accumulators of pair sums (`acc`), by field id; row = particle − i0.
    pub temps: &'a [Option<ColView<T>>],
    pub params: &'a [T],
    pub param_stride: usize,
    pub param_offset: &'a [usize],
    pub group: &'a [u32],
    pub material: &'a [u32],
    pub time: T,
    pub dt: T,
    /// Particle mode: the first particle of the chunk and its group.
    pub i0: usize,
    pub g: usize,
    /// Pair mode: the neighbour of each lane, and per-axis signs of mirror images (empty: none).
    pub j: &'a [u32],
    pub sign: &'a [T],
    pub n: usize,
}

pub type Instr<T> = Box<dyn Fn(&mut [T], &Ctx<T>) + Send + Sync>;

/// A compiled straight-line program.
pub struct Program<T> {
    pub instrs: Vec<Instr<T>>,
    pub n_regs: usize,
    pub consts: Vec<(usize, T)>,
    pub stores: Vec<Store>,
    pub accums: Vec<Accum>,
    pub reduces: Vec<(usize, Reduce, usize)>,
    /// Register of each value that outlives the program (exports, effects).
    pub reg_of: std::collections::HashMap<Id, usize>,
}

pub struct Store {
    pub field: FieldId,
    pub comp: usize,
    pub reg: usize,
    pub temp: bool,
}

pub struct Accum {
    pub field: FieldId,
    pub comp: usize,
    pub reduce: Reduce,
    pub reg: usize,
}

impl<T: Real> Program<T> {
    /// Registers with the program's constants filled in.
    pub fn frame(&self) -> Vec<T> {
        let mut regs = vec![T::zero(); self.n_regs.max(1) * LANES];
        self.fill_consts(&mut regs);
        regs
    }
    pub fn fill_consts(&self, regs: &mut [T]) {
        for (r, v) in &self.consts {
            regs[r * LANES..(r + 1) * LANES].fill(*v);
        }
    }
    pub fn run(&self, regs: &mut [T], ctx: &Ctx<T>) {
        for i in &self.instrs {
            i(regs, ctx);
        }
    }
}

/// Registers the program must leave in place: values read by later stages (exports) or preset by
/// the caller (pair quantities, broadcast uniforms).
pub struct Pinned {
    pub preset: Vec<(Id, usize)>,
    pub exports: Vec<Id>,
}

#[inline(always)]
fn reg<T>(p: *mut T, r: usize, n: usize) -> &'static [T] {
    // SAFETY: r < n_regs, so the range lies in the frame; distinct from every written register.
    unsafe { std::slice::from_raw_parts(p.add(r * LANES), n) }
}

#[inline(always)]
fn reg_mut<T>(p: *mut T, r: usize, n: usize) -> &'static mut [T] {
    // SAFETY: as `reg`; the allocator never gives an operation's output the register of an operand.
    unsafe { std::slice::from_raw_parts_mut(p.add(r * LANES), n) }
}

/// Whether the lane loops may use AVX2 (checked once at run time, so one binary runs everywhere
/// and uses the wider vectors where the CPU has them).
pub fn wide_simd() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        static WIDE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
        *WIDE.get_or_init(|| {
            !crate::config::env().no_wide_simd && is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")
        })
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Defines `$name(out, ins...)`: the lane loop of one operation, compiled twice — for the
/// baseline target and with AVX2 enabled — and dispatched on `wide`. The operation is inlined
/// into the loop (a function pointer per lane would cost a call per element and stop
/// vectorisation). Rust never contracts `a * b + c` into an FMA, so both give identical results.
macro_rules! lane_loop {
    ($name:ident, ($($arg:ident),*), |$($v:ident),*| $f:expr) => {
        #[inline(always)]
        fn $name<T: Real>(wide: bool, out: &mut [T], $($arg: &[T]),*) {
            #[inline(always)]
            fn body<T: Real>(out: &mut [T], $($arg: &[T]),*) {
                for k in 0..out.len() {
                    $(let $v = $arg[k];)*
                    out[k] = $f;
                }
            }
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2,fma")]
            unsafe fn body_wide<T: Real>(out: &mut [T], $($arg: &[T]),*) {
                body(out, $($arg),*)
            }
            #[cfg(target_arch = "x86_64")]
            if wide {
                // SAFETY: `wide` is true only when the CPU has AVX2 and FMA.
                return unsafe { body_wide(out, $($arg),*) };
            }
            let _ = wide;
            body(out, $($arg),*)
        }
    };
}

macro_rules! lanes1 {
    ($o:expr, $a:expr, |$x:ident| $f:expr) => {{
        lane_loop!(op, (a), |$x| $f);
        let (o, a, wide) = ($o, $a, wide_simd());
        Box::new(move |regs: &mut [T], ctx: &Ctx<T>| {
            let p = regs.as_mut_ptr();
            op(wide, reg_mut(p, o, ctx.n), reg(p, a, ctx.n))
        }) as Instr<T>
    }};
}

macro_rules! lanes2 {
    ($o:expr, $a:expr, $b:expr, |$x:ident, $y:ident| $f:expr) => {{
        lane_loop!(op, (a, b), |$x, $y| $f);
        let (o, a, b, wide) = ($o, $a, $b, wide_simd());
        Box::new(move |regs: &mut [T], ctx: &Ctx<T>| {
            let p = regs.as_mut_ptr();
            op(wide, reg_mut(p, o, ctx.n), reg(p, a, ctx.n), reg(p, b, ctx.n))
        }) as Instr<T>
    }};
}

macro_rules! lanes3 {
    ($o:expr, $a:expr, $b:expr, $c:expr, |$x:ident, $y:ident, $z:ident| $f:expr) => {{
        lane_loop!(op, (a, b, c), |$x, $y, $z| $f);
        let (o, a, b, c, wide) = ($o, $a, $b, $c, wide_simd());
        Box::new(move |regs: &mut [T], ctx: &Ctx<T>| {
            let p = regs.as_mut_ptr();
            op(wide, reg_mut(p, o, ctx.n), reg(p, a, ctx.n), reg(p, b, ctx.n), reg(p, c, ctx.n))
        }) as Instr<T>
    }};
}

fn truth<T: Real>(c: bool) -> T {
    if c {
        T::one()
    } else {
        T::zero()
    }
}

/// min and max as the JIT computes them: NaN loses to a number, as in `f64::min`; of two equal
/// values (±0) the first.
#[inline(always)]
#[allow(clippy::eq_op)] // x != x: x is NaN
pub fn lane_min<T: Real>(x: T, y: T) -> T {
    if x != x || y < x {
        y
    } else {
        x
    }
}

#[inline(always)]
#[allow(clippy::eq_op)] // x != x: x is NaN
pub fn lane_max<T: Real>(x: T, y: T) -> T {
    if x != x || y > x {
        y
    } else {
        x
    }
}

fn un_instr<T: Real>(op: Un, o: usize, a: usize) -> Instr<T> {
    match op {
        Un::Neg => lanes1!(o, a, |x| -x),
        Un::Not => lanes1!(o, a, |x| truth(x == T::zero())),
        Un::Sqrt => lanes1!(o, a, |x| x.sqrt()),
        Un::Exp => lanes1!(o, a, |x| x.lane_exp()),
        Un::Ln => lanes1!(o, a, |x| x.lane_ln()),
        Un::Elementary(e) => {
            let f = T::elementary(e);
            Box::new(move |regs: &mut [T], ctx: &Ctx<T>| {
                let p = regs.as_mut_ptr();
                let (out, a) = (reg_mut(p, o, ctx.n), reg(p, a, ctx.n));
                for k in 0..out.len() {
                    out[k] = f(a[k]);
                }
            })
        }
        Un::Abs => lanes1!(o, a, |x| x.abs()),
    }
}

fn bin_instr<T: Real>(op: Bin, o: usize, a: usize, b: usize) -> Instr<T> {
    match op {
        Bin::Add => lanes2!(o, a, b, |x, y| x + y),
        Bin::Sub => lanes2!(o, a, b, |x, y| x - y),
        Bin::Mul => lanes2!(o, a, b, |x, y| x * y),
        Bin::Div => lanes2!(o, a, b, |x, y| x / y),
        Bin::Pow => lanes2!(o, a, b, |x, y| x.lane_pow(y)),
        Bin::Min => lanes2!(o, a, b, |x, y| lane_min(x, y)),
        Bin::Max => lanes2!(o, a, b, |x, y| lane_max(x, y)),
        Bin::Lt => lanes2!(o, a, b, |x, y| truth(x < y)),
        Bin::Le => lanes2!(o, a, b, |x, y| truth(x <= y)),
        Bin::Gt => lanes2!(o, a, b, |x, y| truth(x > y)),
        Bin::Ge => lanes2!(o, a, b, |x, y| truth(x >= y)),
        Bin::Eq => lanes2!(o, a, b, |x, y| truth(x == y)),
        Bin::Ne => lanes2!(o, a, b, |x, y| truth(x != y)),
        Bin::And => lanes2!(o, a, b, |x, y| truth(x != T::zero() && y != T::zero())),
        Bin::Or => lanes2!(o, a, b, |x, y| truth(x != T::zero() || y != T::zero())),
    }
}

/// The axes whose mirror signs multiply a stored component (a vec's component flips with its axis,
/// a tensor's (a, b) with both).
pub(super) fn sign_axes(shape: Shape, dim: usize, comp: usize) -> Vec<usize> {
    match shape {
        Shape::Scalar | Shape::Bool => vec![],
        Shape::Vec => vec![comp],
        _ => {
            let (a, b) = crate::ir::component_indices(shape, dim)[comp];
            if a == b {
                vec![]
            } else {
                vec![a, b]
            }
        }
    }
}

fn load<T: Real>(model: &Model, dim: usize, o: usize, field: FieldId, comp: usize, side: Side) -> Instr<T> {
    let f = field.index();
    let temp = model.field(field).storage == Storage::Temp;
    if side == Side::I {
        return Box::new(move |regs: &mut [T], ctx: &Ctx<T>| {
            let out = reg_mut(regs.as_mut_ptr(), o, ctx.n);
            let view = if temp { &ctx.temps[f] } else { &ctx.cols[f] };
            match view {
                Some(c) if temp => {
                    for (k, x) in out.iter_mut().enumerate() {
                        // SAFETY: the chunk's temp buffer holds LANES rows.
                        *x = unsafe { *c.ptr.add(k * c.comps + comp) };
                    }
                }
                Some(c) if c.base[ctx.g] != ABSENT => {
                    let start = (ctx.i0 as isize + c.base[ctx.g]) as usize;
                    for (k, x) in out.iter_mut().enumerate() {
                        // SAFETY: rows of the chunk's particles exist in a column stored on its group.
                        *x = unsafe { *c.ptr.add((start + k) * c.comps + comp) };
                    }
                }
                _ => out.fill(T::from_f64(f64::NAN)),
            }
        });
    }
    let axes = sign_axes(model.field(field).ty.shape, dim, comp);
    Box::new(move |regs: &mut [T], ctx: &Ctx<T>| {
        let out = reg_mut(regs.as_mut_ptr(), o, ctx.n);
        let Some(c) = &ctx.cols[f] else {
            out.fill(T::from_f64(f64::NAN));
            return;
        };
        if let Some(base) = c.uniform {
            let ptr = c.ptr.wrapping_offset(base * c.comps as isize + comp as isize);
            for (x, &j) in out.iter_mut().zip(&ctx.j[..ctx.n]) {
                // SAFETY: every group stores this column with the same base: j's row exists.
                *x = unsafe { *ptr.add(j as usize * c.comps) };
            }
        } else {
            for (k, x) in out.iter_mut().enumerate() {
                let j = ctx.j[k] as usize;
                let base = c.base[ctx.group[j] as usize];
                *x = if base == ABSENT {
                    T::zero()
                } else {
                    // SAFETY: j's row exists because its group stores the column.
                    unsafe { *c.ptr.add((j as isize + base) as usize * c.comps + comp) }
                };
            }
        }
        if !ctx.sign.is_empty() {
            for a in &axes {
                let s = &ctx.sign[a * LANES..a * LANES + ctx.n];
                for (x, s) in out.iter_mut().zip(s) {
                    *x = *x * *s;
                }
            }
        }
    })
}

fn param<T: Real>(o: usize, param: usize, comp: usize, side: Side) -> Instr<T> {
    Box::new(move |regs: &mut [T], ctx: &Ctx<T>| {
        let out = reg_mut(regs.as_mut_ptr(), o, ctx.n);
        let off = ctx.param_offset[param] + comp;
        for (k, x) in out.iter_mut().enumerate() {
            let particle = if side == Side::I { ctx.i0 + k } else { ctx.j[k] as usize };
            *x = ctx.params[ctx.material[particle] as usize * ctx.param_stride + off];
        }
    })
}

fn node_instr<T: Real>(model: &Model, dim: usize, node: &Node, o: usize, r: &dyn Fn(Id) -> usize) -> Option<Instr<T>> {
    Some(match *node {
        Node::Const(_) | Node::PairX(_) | Node::PairR | Node::PairH => return None,
        Node::Load { field, comp, side } => load(model, dim, o, field, comp as usize, side),
        Node::Param { param: p, comp, side } => param(o, p.index(), comp as usize, side),
        Node::Global(g) => Box::new(move |regs: &mut [T], ctx: &Ctx<T>| {
            let v = match g {
                Global::Time => ctx.time,
                Global::Dt => ctx.dt,
                Global::Dim => T::from_f64(dim as f64),
            };
            reg_mut(regs.as_mut_ptr(), o, ctx.n).fill(v);
        }),
        Node::InGroup(side, set) => Box::new(move |regs: &mut [T], ctx: &Ctx<T>| {
            let out = reg_mut(regs.as_mut_ptr(), o, ctx.n);
            for (k, x) in out.iter_mut().enumerate() {
                let particle = if side == Side::I { ctx.i0 + k } else { ctx.j[k] as usize };
                *x = truth(set >> ctx.group[particle] & 1 == 1);
            }
        }),
        Node::Un(op, a) => un_instr(op, o, r(a)),
        Node::Bin(op, a, b) => bin_instr(op, o, r(a), r(b)),
        Node::Select(c, a, b) => lanes3!(o, r(c), r(a), r(b), |c, a, b| if c != T::zero() { a } else { b }),
    })
}

fn effect_value(e: &Effect) -> Id {
    match *e {
        Effect::Store { value, .. } | Effect::Accum { value, .. } | Effect::Reduce { value, .. } => value,
    }
}

/// Nodes the effects (and exports) need, in evaluation order.
pub fn live_nodes(g: &Graph, roots: impl IntoIterator<Item = Id>) -> Vec<Id> {
    let mut live = vec![false; g.nodes.len()];
    let mut stack: Vec<Id> = roots.into_iter().collect();
    while let Some(id) = stack.pop() {
        if std::mem::replace(&mut live[id as usize], true) {
            continue;
        }
        stack.extend(g.nodes[id as usize].operands());
    }
    (0..g.nodes.len() as Id).filter(|i| live[*i as usize]).collect()
}

/// Compiles the given nodes (in order) and effects. `pinned.preset` values already sit in
/// registers the caller fills; `pinned.exports` stay readable after the program.
pub fn compile<T: Real>(
    model: &Model,
    dim: usize,
    g: &Graph,
    nodes: &[Id],
    effects: &[Effect],
    pinned: &Pinned,
) -> Program<T> {
    use std::collections::HashMap;
    let mut reg_of: HashMap<Id, usize> = HashMap::new();
    let mut next = 0usize;
    let mut free: Vec<usize> = vec![];
    let mut consts = vec![];
    for (id, r) in &pinned.preset {
        reg_of.insert(*id, *r);
        next = next.max(r + 1);
    }
    // Multiply–add fusion: `c + x·y`, `c − x·y`, `x·y − c` become one operation when the product
    // is used only there, halving the register traffic of sums of products.
    let fused = fuse_multiply_adds(g, nodes, effects, pinned);
    let operands = |id: Id| -> Vec<Id> {
        match fused.get(&id) {
            Some(f) => vec![f.x, f.y, f.c],
            None => g.nodes[id as usize].operands(),
        }
    };
    let absorbed: std::collections::HashSet<Id> = fused.values().map(|f| f.product).collect();
    let order: Vec<Id> = nodes.iter().copied().filter(|id| !absorbed.contains(id)).collect();
    // Last use of each value: effects and exports keep theirs to the end.
    let mut last: HashMap<Id, usize> = HashMap::new();
    for (k, id) in order.iter().enumerate() {
        for o in operands(*id) {
            last.insert(o, k);
        }
    }
    for e in effects {
        last.insert(effect_value(e), usize::MAX);
    }
    for x in &pinned.exports {
        last.insert(*x, usize::MAX);
    }
    for id in &order {
        if let Node::Const(bits) = g.nodes[*id as usize] {
            if !reg_of.contains_key(id) {
                reg_of.insert(*id, next);
                consts.push((next, T::from_f64(f64::from_bits(bits))));
                next += 1;
            }
        }
    }
    let mut instrs = vec![];
    for (k, id) in order.iter().enumerate() {
        let node = g.nodes[*id as usize];
        if reg_of.contains_key(id) {
            continue;
        }
        let o = free.pop().unwrap_or_else(|| {
            next += 1;
            next - 1
        });
        reg_of.insert(*id, o);
        let lookup = |x: Id| reg_of[&x];
        let instr = match fused.get(id) {
            Some(f) => Some(fused_instr::<T>(f.kind, o, lookup(f.x), lookup(f.y), lookup(f.c))),
            None => node_instr::<T>(model, dim, &node, o, &lookup),
        };
        if let Some(i) = instr {
            instrs.push(i);
        }
        let mut ops = operands(*id);
        ops.sort_unstable();
        ops.dedup();
        for op in ops {
            let is_const = matches!(g.nodes[op as usize], Node::Const(_));
            let preset = pinned.preset.iter().any(|(p, _)| *p == op);
            if last.get(&op) == Some(&k) && !is_const && !preset {
                if let Some(r) = reg_of.get(&op) {
                    free.push(*r);
                }
            }
        }
    }
    let mut stores = vec![];
    let mut accums = vec![];
    let mut reduces = vec![];
    for e in effects {
        match *e {
            Effect::Store { field, comp, value } => stores.push(Store {
                field,
                comp: comp as usize,
                reg: reg_of[&value],
                temp: model.field(field).storage == Storage::Temp,
            }),
            Effect::Accum { field, comp, reduce, value } => {
                accums.push(Accum { field, comp: comp as usize, reduce, reg: reg_of[&value] })
            }
            Effect::Reduce { index, reduce, value } => reduces.push((index, reduce, reg_of[&value])),
        }
    }
    Program { instrs, n_regs: next, consts, stores, accums, reduces, reg_of }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum FusedKind {
    /// c + x·y
    MulAdd,
    /// c − x·y
    SubMul,
    /// x·y − c
    MulSub,
}

struct Fused {
    kind: FusedKind,
    product: Id,
    x: Id,
    y: Id,
    c: Id,
}

/// Sums and differences whose one side is a product used nowhere else.
fn fuse_multiply_adds(
    g: &Graph,
    nodes: &[Id],
    effects: &[Effect],
    pinned: &Pinned,
) -> std::collections::HashMap<Id, Fused> {
    use std::collections::HashMap;
    let mut uses: HashMap<Id, usize> = HashMap::new();
    for id in nodes {
        for o in g.nodes[*id as usize].operands() {
            *uses.entry(o).or_default() += 1;
        }
    }
    for e in effects {
        *uses.entry(effect_value(e)).or_default() += 2;
    }
    for x in pinned.exports.iter().chain(pinned.preset.iter().map(|(p, _)| p)) {
        *uses.entry(*x).or_default() += 2;
    }
    let in_set: std::collections::HashSet<Id> = nodes.iter().copied().collect();
    let product = |id: Id| -> Option<(Id, Id)> {
        match g.nodes[id as usize] {
            Node::Bin(Bin::Mul, x, y) if uses.get(&id) == Some(&1) && in_set.contains(&id) => Some((x, y)),
            _ => None,
        }
    };
    let mut out = HashMap::new();
    let mut taken = std::collections::HashSet::new();
    for id in nodes {
        let (kind, prod, c) = match g.nodes[*id as usize] {
            Node::Bin(Bin::Add, a, b) => match (product(b), product(a)) {
                (Some(_), _) if !taken.contains(&b) => (FusedKind::MulAdd, b, a),
                (_, Some(_)) if !taken.contains(&a) => (FusedKind::MulAdd, a, b),
                _ => continue,
            },
            Node::Bin(Bin::Sub, a, b) => match (product(b), product(a)) {
                (Some(_), _) if !taken.contains(&b) => (FusedKind::SubMul, b, a),
                (_, Some(_)) if !taken.contains(&a) => (FusedKind::MulSub, a, b),
                _ => continue,
            },
            _ => continue,
        };
        let Some((x, y)) = product(prod) else { continue };
        if prod == c {
            continue;
        }
        taken.insert(prod);
        out.insert(*id, Fused { kind, product: prod, x, y, c });
    }
    out
}

fn fused_instr<T: Real>(kind: FusedKind, o: usize, x: usize, y: usize, c: usize) -> Instr<T> {
    match kind {
        FusedKind::MulAdd => lanes3!(o, x, y, c, |a, b, d| d + a * b),
        FusedKind::SubMul => lanes3!(o, x, y, c, |a, b, d| d - a * b),
        FusedKind::MulSub => lanes3!(o, x, y, c, |a, b, d| a * b - d),
    }
}
