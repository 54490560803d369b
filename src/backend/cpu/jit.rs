//! Native code for the neighbour loop's pair program, generated with Cranelift.
//!
//! The closure programs (`program.rs`) pay for each operation with a call and a round trip of its
//! lanes through memory. The JIT compiles the same scalar SSA graph into one function that runs
//! the whole program on SIMD vectors of neighbours (2 f64 or 4 f32) with every intermediate in a
//! register. It is called once per particle with that particle's lanes of the batch, loads the
//! particle's own values itself and folds its sums into the particle's accumulators
//! ([`fold_partials`], which the closures use too); compensated sums are written per lane for Rust
//! to fold (Kahan). It emits the same operations in the same order as the closures (no fused
//! multiply–adds; min/max, exp, ln and pow as `program.rs` computes them), hence bit-identical
//! results — `tests/jit.rs` checks that on every bundled case.
//!
//! A program that calls an elementary function (`ir::ELEMENTARY`: `sin`, `acos`, `tanh`, …),
//! which the JIT does not emit, is left to the C code ([`super::ccode`], which calls libm on each
//! lane) or the closures; so does a pass whose gathered columns are not stored with one base on every
//! group that stores them. A neighbour whose group does not store a gathered field (the
//! projectile's, for the plate's damage) reads zeros there, as with the closures.
//! `PAIRSUM_NO_JIT=1` turns the JIT off.

use super::lower::{Bin, Graph, Id, Node, Un};
use super::math::{ExpConsts, LnConsts};
use super::program::LANES;
use super::program::{lane_max, lane_min, sign_axes};
use crate::ir::{FieldId, Global, GroupSet, Model, Reduce, Side};
use crate::particles::Real;
use cranelift_codegen::ir::condcodes::FloatCC;
use cranelift_codegen::ir::condcodes::IntCC;
use cranelift_codegen::ir::{types, AbiParam, InstBuilder, MachMemFlags as MemFlags, Type, UserFuncName, Value};
use cranelift_codegen::settings::{self, Configurable};
use cranelift_frontend::Variable;
use cranelift_frontend::{FunctionBuilder, FunctionBuilderContext};
use cranelift_jit::{JITBuilder, JITModule};
use cranelift_module::{default_libcall_names, Linkage, Module};
use std::collections::HashMap;

/// `fn(frame, j, columns, start, end, sign, group, material, params, dest, slots, time, dt)`: runs
/// the pair program on lanes `start..end` of the frame — the neighbours of one particle —, with
/// that particle's own values at `dest` (its lane of the dest program's frame) and its
/// accumulators at `slots`.
pub(super) type PairFn<T> = unsafe extern "C" fn(
    *mut T,
    *const u32,
    *const *const T,
    usize,
    usize,
    *const T,
    *const u32,
    *const u32,
    *const T,
    *const T,
    *mut T,
    T,
    T,
);

/// The JIT's vectors: 128 bits (Cranelift's x86 backend has no wider ones).
pub const VECTOR_BYTES: usize = 16;

/// The period of a batch's partial sums, in bytes of lanes: 256 bits, the widest vectors the
/// native code runs on (the C path's on AVX2). Every path folds with this period, so the
/// closures, Cranelift's 128-bit code and the C path's 256-bit code stay bit-identical.
pub const FOLD_BYTES: usize = 32;

/// Lanes of the JIT's vectors for reals of type T.
pub fn width<T: Real>() -> usize {
    VECTOR_BYTES / T::BYTES
}

/// The partial sums of a batch for reals of type T (4 f64, 8 f32): lane k of a particle's
/// neighbours goes into partial k mod this (see [`fold_partials`]).
pub fn fold_lanes<T: Real>() -> usize {
    FOLD_BYTES / T::BYTES
}

/// `op(a, b)` of a reduction, as every path computes it.
#[inline]
pub fn reduce_op<T: Real>(reduce: Reduce, a: T, b: T) -> T {
    match reduce {
        Reduce::Sum => a + b,
        Reduce::Min => lane_min(a, b),
        Reduce::Max => lane_max(a, b),
    }
}

/// Combines partials pairwise with `op`, neighbours first: ((p0 p1) (p2 p3)) ((p4 p5) (p6 p7)).
/// Every path's fold takes this order: on values, on Cranelift's values, on C expressions.
pub fn pairwise<V: Clone>(p: &[V], op: &mut impl FnMut(V, V) -> V) -> V {
    if p.len() == 1 {
        return p[0].clone();
    }
    let half = p.len() / 2;
    let (a, b) = (pairwise(&p[..half], op), pairwise(&p[half..], op));
    op(a, b)
}

/// [`pairwise`] with a reduction's operation.
#[inline]
pub fn fold_tree<T: Real>(reduce: Reduce, p: &[T]) -> T {
    pairwise(p, &mut |a, b| reduce_op(reduce, a, b))
}

/// Folds lanes into `slot` as the native code does: [`fold_lanes`] interleaved partial results
/// (lane k into partial k mod that, padded with the identity to whole periods), combined
/// pairwise ([`fold_tree`]), then into the slot. The closures fold with it too, so every path
/// stays bit-identical.
#[inline]
pub fn fold_partials<T: Real>(reduce: Reduce, slot: T, lanes: &[T]) -> T {
    let w = fold_lanes::<T>();
    let id = T::from_f64(reduce.identity());
    let mut p = [id; 8];
    let whole = lanes.len().div_ceil(w) * w;
    for k in 0..whole {
        let x = if k < lanes.len() { lanes[k] } else { id };
        p[k % w] = reduce_op(reduce, p[k % w], x);
    }
    reduce_op(reduce, slot, fold_tree(reduce, &p[..w]))
}

/// Which code generator made a pair program.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum NativeKind {
    /// Cranelift, 128-bit vectors (this module).
    Cranelift,
    /// The machine's C compiler, 256-bit vectors ([`super::ccode`]).
    C,
}

/// A compiled pair program.
pub struct JitPair<T> {
    func: PairFn<T>,
    /// The fields it gathers at j, in the order of the column pointers it expects.
    pub gathers: Vec<FieldId>,
    pub kind: NativeKind,
    _code: Code,
}

/// What owns the generated code; freed with the program.
enum Code {
    Cranelift(Option<Box<JITModule>>),
    Library(#[allow(dead_code)] libloading::Library),
}

// SAFETY: the module is only touched on drop; the code it owns is immutable and re-entrant.
unsafe impl Send for Code {}
unsafe impl Sync for Code {}

impl Drop for Code {
    fn drop(&mut self) {
        if let Code::Cranelift(m) = self {
            if let Some(m) = m.take() {
                // SAFETY: the function pointer into this memory is dropped with the JitPair.
                unsafe { m.free_memory() };
            }
        }
    }
}

impl<T: Real> JitPair<T> {
    /// A program whose code is `func` in the shared library `lib`.
    pub(super) fn from_library(
        func: PairFn<T>,
        gathers: Vec<FieldId>,
        lib: libloading::Library,
        kind: NativeKind,
    ) -> Self {
        JitPair { func, gathers, kind, _code: Code::Library(lib) }
    }

    /// Runs the program on lanes `lanes` of the frame, the neighbours of one particle, and folds
    /// them into its accumulators. `cols[k]` points at row 0 of `gathers[k]`'s column; `sign`
    /// holds the per-axis mirror signs (3 × LANES) when the program was compiled with them;
    /// `dest` is the particle's lane of the dest program's frame; `slots` its accumulators.
    ///
    /// # Safety
    /// `frame` is the program's frame (`n_regs × LANES`, plus `width − 1` lanes of padding: the
    /// last vector may run past `lanes.end`), `j[..LANES + width − 1]` are rows of every gathered
    /// column and particles of `group`/`material`, `params` is the parameter table the program was
    /// compiled for, `sign` is valid when the program uses it, `dest` reaches every broadcast
    /// register and `slots` every folded slot.
    #[allow(clippy::too_many_arguments)]
    pub unsafe fn run(
        &self,
        frame: &mut [T],
        j: &[u32],
        cols: &[*const T],
        lanes: std::ops::Range<usize>,
        sign: *const T,
        world: &World<T>,
        dest: *const T,
        slots: &mut [T],
    ) {
        let pad = width::<T>() - 1;
        debug_assert!(cols.len() == self.gathers.len() && lanes.end <= LANES);
        debug_assert!(j.len() >= LANES + pad && frame.len() % LANES >= pad, "no padding for whole vectors");
        let f = self.func;
        let (g, m, p) = (world.group.as_ptr(), world.material.as_ptr(), world.params.as_ptr());
        let (fr, jp, cp, sl) = (frame.as_mut_ptr(), j.as_ptr(), cols.as_ptr(), slots.as_mut_ptr());
        unsafe { f(fr, jp, cp, lanes.start, lanes.end, sign, g, m, p, dest, sl, world.time, world.dt) }
    }
}

/// What a pair program reads besides the frame and the gathered columns.
pub struct World<'a, T> {
    pub group: &'a [u32],
    pub material: &'a [u32],
    pub params: &'a [T],
    pub time: T,
    pub dt: T,
}

/// What the JIT needs to know of the program: its graph and nodes in order, where the caller
/// puts the preset values, and where the accumulated values must end up.
pub struct PairSpec<'a> {
    pub model: &'a Model,
    pub dim: usize,
    pub graph: &'a Graph,
    pub nodes: &'a [Id],
    pub preset: &'a [(Id, usize)],
    /// Values of particle i: (id, register of the dest program), loaded once per call.
    pub broadcast: &'a [(Id, usize)],
    /// Values written per lane into the frame (id, register): compensated sums, which Rust folds.
    pub outputs: &'a [(Id, usize)],
    /// Values folded into the particle's accumulators: (id, slot, reduction).
    pub folded: &'a [(Id, usize, Reduce)],
    /// Whether lanes carry mirror signs (the case has symmetry planes).
    pub signs: bool,
    /// The parameter table's layout: a parameter component is at `material × stride + offset`.
    pub param_stride: usize,
    pub param_offset: &'a [usize],
    /// Fields gathered at j that some source group does not store, with the set of groups that
    /// do: a neighbour of another group reads 0 there, as the closures give.
    pub partial: &'a [(FieldId, GroupSet)],
}

/// Zeros that a neighbour reads for a field its group does not store: the rows of the widest
/// field (a 3 × 3 tensor) at most.
pub(super) static ZERO_ROW: [u64; 9] = [0; 9];

/// Whether the JIT is on (it is unless `PAIRSUM_NO_JIT` is set or the host has no backend).
pub fn enabled() -> bool {
    !crate::config::env().no_jit && cranelift_native::builder().is_ok()
}

/// Whether native code can run the program: every node is one it emits, and every partly stored
/// column fits the zero row.
pub(super) fn check(spec: &PairSpec) -> Result<(), String> {
    for (f, _) in spec.partial {
        if crate::ir::components(spec.model.field(*f).ty.shape, spec.dim) > ZERO_ROW.len() {
            return Err(format!("`{}` is wider than the zero row", spec.model.field(*f).name));
        }
    }
    for id in spec.nodes {
        supported(&spec.graph.nodes[*id as usize])?;
    }
    Ok(())
}

/// Compiles the pair program, or says why not.
pub fn compile_pair<T: Real>(spec: &PairSpec) -> Result<JitPair<T>, String> {
    check(spec)?;
    let elementary = |id: &Id| match spec.graph.nodes[*id as usize] {
        Node::Un(Un::Elementary(e), _) => Some(e),
        _ => None,
    };
    if let Some(e) = spec.nodes.iter().find_map(elementary) {
        return Err(format!("`{}`: Cranelift's code has no elementary functions (the C code has)", e.name()));
    }
    let mut flags = settings::builder();
    flags.set("opt_level", "speed").map_err(|e| e.to_string())?;
    flags.set("use_colocated_libcalls", "false").map_err(|e| e.to_string())?;
    flags.set("is_pic", "false").map_err(|e| e.to_string())?;
    let isa = cranelift_native::builder()?.finish(settings::Flags::new(flags)).map_err(|e| e.to_string())?;
    let mut module = JITModule::new(JITBuilder::with_isa(isa, default_libcall_names()));
    let ptr = module.target_config().pointer_type();
    let real = if T::BYTES == 8 { types::F64 } else { types::F32 };
    let mut ctx = module.make_context();
    for t in [ptr, ptr, ptr, ptr, ptr, ptr, ptr, ptr, ptr, ptr, ptr, real, real] {
        ctx.func.signature.params.push(AbiParam::new(t));
    }
    let id = module.declare_function("pair", Linkage::Local, &ctx.func.signature).map_err(|e| e.to_string())?;
    ctx.func.name = UserFuncName::user(0, id.as_u32());
    let mut fctx = FunctionBuilderContext::new();
    let config = module.target_config();
    let gathers = {
        let b = FunctionBuilder::new(&mut ctx.func, &mut fctx);
        Emitter::<T>::new(b, spec, ptr).emit(config)
    };
    let debug = crate::config::env().debug >= 2;
    ctx.set_disasm(debug);
    module.define_function(id, &mut ctx).map_err(|e| format!("{e:?}"))?;
    if debug {
        if let Some(code) = ctx.compiled_code().and_then(|c| c.vcode.as_ref()) {
            eprintln!("native pair program:\n{code}");
        }
    }
    module.clear_context(&mut ctx);
    module.finalize_definitions().map_err(|e| e.to_string())?;
    let code = module.get_finalized_function(id);
    // SAFETY: the function was declared with exactly this signature (C calling convention).
    let func = unsafe { std::mem::transmute::<*const u8, PairFn<T>>(code) };
    Ok(JitPair { func, gathers, kind: NativeKind::Cranelift, _code: Code::Cranelift(Some(Box::new(module))) })
}

/// The fields the program reads at j, in the order of the column pointers native code takes.
pub(super) fn gathered_fields(spec: &PairSpec) -> Vec<FieldId> {
    let mut gathers: Vec<FieldId> = vec![];
    for id in spec.nodes {
        if let Node::Load { field, side: Side::J, .. } = spec.graph.nodes[*id as usize] {
            if !gathers.contains(&field) {
                gathers.push(field);
            }
        }
    }
    gathers
}

/// The nodes in the order the outputs demand them (a depth-first post-order from each output,
/// operands before their users, the deeper operand first), so that a value is computed just
/// before it is used and the registers hold few values at a time.
pub(super) fn demand_order(spec: &PairSpec) -> Vec<Id> {
    let g = spec.graph;
    // Register need of each subtree (Sethi–Ullman), to visit the hungrier operand first.
    let mut need: HashMap<Id, u32> = HashMap::new();
    for id in spec.nodes {
        let ops = g.nodes[*id as usize].operands();
        let mut ns: Vec<u32> = ops.iter().map(|o| need.get(o).copied().unwrap_or(1)).collect();
        ns.sort_unstable_by(|a, b| b.cmp(a));
        let n = ns.iter().enumerate().map(|(k, n)| n + k as u32).max().unwrap_or(1);
        need.insert(*id, n);
    }
    let mut done: std::collections::HashSet<Id> = std::collections::HashSet::new();
    let mut order = vec![];
    let roots = spec.outputs.iter().map(|(id, _)| *id).chain(spec.folded.iter().map(|(id, _, _)| *id));
    for root in roots {
        let mut stack = vec![(root, false)];
        while let Some((id, expanded)) = stack.pop() {
            if done.contains(&id) {
                continue;
            }
            if expanded {
                done.insert(id);
                order.push(id);
                continue;
            }
            stack.push((id, true));
            if spec.preset.iter().any(|(p, _)| *p == id) {
                continue; // computed by the caller: its operands are not the program's
            }
            let mut ops = g.nodes[id as usize].operands();
            // Pushed last = visited first: the operand that needs the most registers.
            ops.sort_by_key(|o| need.get(o).copied().unwrap_or(1));
            for o in ops {
                if !done.contains(&o) {
                    stack.push((o, false));
                }
            }
        }
    }
    order
}

fn supported(node: &Node) -> Result<(), String> {
    match node {
        Node::Load { side: Side::I, .. } | Node::Param { side: Side::I, .. } => {
            Err("a value of particle i read per lane".into())
        }
        _ => Ok(()),
    }
}

struct Emitter<'a, 'b, T> {
    b: FunctionBuilder<'b>,
    spec: &'a PairSpec<'a>,
    ptr: Type,
    real: Type,
    vec: Type,
    int: Type,
    width: usize,
    consts: HashMap<u64, Value>,
    int_consts: HashMap<i64, Value>,
    _t: std::marker::PhantomData<T>,
}

impl<'a, 'b, T: Real> Emitter<'a, 'b, T> {
    fn new(b: FunctionBuilder<'b>, spec: &'a PairSpec<'a>, ptr: Type) -> Self {
        let (real, vec, int) = if T::BYTES == 8 {
            (types::F64, types::F64X2, types::I64X2)
        } else {
            (types::F32, types::F32X4, types::I32X4)
        };
        Emitter {
            b,
            spec,
            ptr,
            real,
            vec,
            int,
            width: width::<T>(),
            consts: HashMap::new(),
            int_consts: HashMap::new(),
            _t: std::marker::PhantomData,
        }
    }

    fn mem() -> MemFlags {
        MemFlags::new().with_notrap()
    }

    /// A vector of the constant `v` (rounded to T), made once where first asked for: the entry
    /// block, or the loop body for constants only the body uses.
    fn splat(&mut self, v: f64) -> Value {
        let t = T::from_f64(v);
        let bits = t.to_f64().to_bits();
        if let Some(x) = self.consts.get(&bits) {
            return *x;
        }
        let s =
            if T::BYTES == 8 { self.b.ins().f64const(t.to_f64()) } else { self.b.ins().f32const(t.to_f64() as f32) };
        let x = self.b.ins().splat(self.vec, s);
        self.consts.insert(bits, x);
        x
    }

    fn splat_int(&mut self, v: i64) -> Value {
        if let Some(x) = self.int_consts.get(&v) {
            return *x;
        }
        let lane = self.int.lane_type();
        let s = self.b.ins().iconst(lane, if T::BYTES == 8 { v } else { v as i32 as i64 });
        let x = self.b.ins().splat(self.int, s);
        self.int_consts.insert(v, x);
        x
    }

    /// A vector of the bit pattern of `v` rounded to T, as integers.
    fn splat_bits_of(&mut self, v: f64) -> Value {
        let bits = if T::BYTES == 8 { v.to_bits() as i64 } else { (v as f32).to_bits() as i64 };
        self.splat_int(bits)
    }

    fn mask_as_float(&mut self, mask: Value) -> Value {
        self.b.ins().bitcast(self.vec, MemFlags::new(), mask)
    }

    fn bits_as_int(&mut self, x: Value) -> Value {
        self.b.ins().bitcast(self.int, MemFlags::new(), x)
    }

    /// 1 where the mask is set, else 0.
    fn truth(&mut self, mask: Value, one: Value, zero: Value) -> Value {
        let m = self.mask_as_float(mask);
        self.b.ins().bitselect(m, one, zero)
    }

    fn select(&mut self, mask: Value, a: Value, b: Value) -> Value {
        let m = self.mask_as_float(mask);
        self.b.ins().bitselect(m, a, b)
    }

    /// Emits the function; returns the gathered fields in column-pointer order.
    fn emit(mut self, config: cranelift_codegen::isa::TargetFrontendConfig) -> Vec<FieldId> {
        let spec = self.spec;
        let entry = self.b.create_block();
        self.b.append_block_params_for_function_params(entry);
        self.b.switch_to_block(entry);
        let p = self.b.block_params(entry).to_vec();
        let (frame, jptr, cols, start, end, sign) = (p[0], p[1], p[2], p[3], p[4], p[5]);
        let (group, material, params, dest, slots, time, dt) = (p[6], p[7], p[8], p[9], p[10], p[11], p[12]);
        // Loop-invariant values: constants, globals, column pointers.
        let one = self.splat(1.0);
        let zero = self.splat(0.0);
        let time = self.b.ins().splat(self.vec, time);
        let dt = self.b.ins().splat(self.vec, dt);
        let gathers = gathered_fields(spec);
        let col_ptrs: Vec<Value> = (0..gathers.len())
            .map(|k| self.b.ins().load(self.ptr, Self::mem(), cols, (k * self.ptr.bytes() as usize) as i32))
            .collect();
        let mut vals: HashMap<Id, Value> = HashMap::new();
        for (id, u) in spec.broadcast {
            let x = self.b.ins().load(self.real, Self::mem(), dest, (u * LANES * T::BYTES) as i32);
            let v = self.b.ins().splat(self.vec, x);
            vals.insert(*id, v);
        }
        // The accumulators: per folded value, one vector for each set of the fold's partials
        // (`fold_lanes` / `width`), starting at the identity. An iteration folds into the first
        // and rotates them, so iteration i's lanes land in set i mod sets, as `fold_partials`.
        let sets = fold_lanes::<T>() / self.width;
        let accs: Vec<Vec<Variable>> = spec
            .folded
            .iter()
            .map(|(_, _, r)| {
                (0..sets)
                    .map(|_| {
                        let var = self.b.declare_var(self.vec);
                        let id = self.splat(r.identity());
                        self.b.def_var(var, id);
                        var
                    })
                    .collect()
            })
            .collect();
        // Lane k of a vector is lane base + k of the frame; iota = (0, 1, …).
        let lane_ty = self.int.lane_type();
        let mut iota = {
            let z = self.b.ins().iconst(lane_ty, 0);
            self.b.ins().scalar_to_vector(self.int, z)
        };
        for k in 1..self.width {
            let c = self.b.ins().iconst(lane_ty, k as i64);
            iota = self.b.ins().insertlane(iota, c, k as u8);
        }
        let end_lane = if lane_ty == self.ptr { end } else { self.b.ins().ireduce(lane_ty, end) };
        let end_vec = self.b.ins().splat(self.int, end_lane);
        for id in spec.nodes {
            if let Node::Const(bits) = spec.graph.nodes[*id as usize] {
                let v = self.splat(f64::from_bits(bits));
                vals.insert(*id, v);
            }
        }
        let head = self.b.create_block();
        let body = self.b.create_block();
        let exit = self.b.create_block();
        self.b.ins().jump(head, &[start.into()]);

        self.b.switch_to_block(head);
        let base = self.b.append_block_param(head, self.ptr);
        let more = self.b.ins().icmp(IntCC::UnsignedLessThan, base, end);
        self.b.ins().brif(more, body, &[], exit, &[]);

        self.b.switch_to_block(body);
        let bytes = T::BYTES as i64;
        // Byte offset of lane `base` within a register.
        let lane_off = self.b.ins().imul_imm_s(base, bytes);
        let lane_addr = self.b.ins().iadd(frame, lane_off);
        let reg_addr = |r: usize| (r * LANES * T::BYTES) as i32;
        // Preset values are loaded where first used, not all at the top (where they would only
        // be spilled).
        let preset: HashMap<Id, usize> = spec.preset.iter().copied().collect();
        // The neighbour index of each lane, widened to a pointer.
        let j_off = self.b.ins().imul_imm_s(base, 4);
        let j_addr = self.b.ins().iadd(jptr, j_off);
        let js: Vec<Value> = (0..self.width)
            .map(|k| {
                let j = self.b.ins().uload32(Self::mem(), j_addr, (4 * k) as i32);
                if self.ptr == types::I32 {
                    self.b.ins().ireduce(types::I32, j)
                } else {
                    j
                }
            })
            .collect();
        let mut rows: HashMap<FieldId, Vec<Value>> = HashMap::new();
        let sign_addr = if spec.signs {
            let off = self.b.ins().imul_imm_s(base, bytes);
            Some(self.b.ins().iadd(sign, off))
        } else {
            None
        };
        for id in &demand_order(spec) {
            if vals.contains_key(id) {
                continue;
            }
            let node = spec.graph.nodes[*id as usize];
            for o in node.operands() {
                if let (None, Some(r)) = (vals.get(&o), preset.get(&o)) {
                    let v = self.b.ins().load(self.vec, Self::mem(), lane_addr, reg_addr(*r));
                    vals.insert(o, v);
                }
            }
            if let Some(r) = preset.get(id) {
                let v = self.b.ins().load(self.vec, Self::mem(), lane_addr, reg_addr(*r));
                vals.insert(*id, v);
                continue;
            }
            let v = match node {
                Node::Const(_) | Node::PairX(_) | Node::PairR | Node::PairH => {
                    unreachable!("constants and pair values are preset")
                }
                Node::Global(g) => match g {
                    Global::Time => time,
                    Global::Dt => dt,
                    Global::Dim => self.splat(spec.dim as f64),
                },
                Node::Load { field, comp, side: Side::J } => {
                    let comps = crate::ir::components(spec.model.field(field).ty.shape, spec.dim);
                    let slot = gathers.iter().position(|f| *f == field).expect("gathered field");
                    let row = match rows.get(&field) {
                        Some(r) => r.clone(),
                        None => {
                            let stride = (comps * T::BYTES) as i64;
                            let stored_on = spec.partial.iter().find(|(f, _)| *f == field).map(|(_, set)| *set);
                            let r: Vec<Value> = js
                                .iter()
                                .map(|j| {
                                    let off = self.b.ins().imul_imm_s(*j, stride);
                                    let row = self.b.ins().iadd(col_ptrs[slot], off);
                                    match stored_on {
                                        Some(set) => self.row_if_stored(set, group, *j, row),
                                        None => row,
                                    }
                                })
                                .collect();
                            rows.insert(field, r.clone());
                            r
                        }
                    };
                    let off = (comp as usize * T::BYTES) as i32;
                    let first = self.b.ins().load(self.real, Self::mem(), row[0], off);
                    let mut v = self.b.ins().scalar_to_vector(self.vec, first);
                    for (k, addr) in row.iter().enumerate().skip(1) {
                        let x = self.b.ins().load(self.real, Self::mem(), *addr, off);
                        v = self.b.ins().insertlane(v, x, k as u8);
                    }
                    if let Some(sa) = sign_addr {
                        for a in sign_axes(spec.model.field(field).ty.shape, spec.dim, comp as usize) {
                            let s = self.b.ins().load(self.vec, Self::mem(), sa, (a * LANES * T::BYTES) as i32);
                            v = self.b.ins().fmul(v, s);
                        }
                    }
                    v
                }
                Node::Un(op, a) => {
                    let a = vals[&a];
                    match op {
                        Un::Neg => self.b.ins().fneg(a),
                        Un::Abs => self.b.ins().fabs(a),
                        Un::Sqrt => self.b.ins().sqrt(a),
                        Un::Not => {
                            let m = self.b.ins().fcmp(FloatCC::Equal, a, zero);
                            self.truth(m, one, zero)
                        }
                        Un::Exp => self.exp(a, T::EXP),
                        Un::Ln => self.ln(a, T::LN),
                        Un::Elementary(_) => unreachable!("checked by `compile_pair`"),
                    }
                }
                Node::Bin(op, a, c) => {
                    let (a, c) = (vals[&a], vals[&c]);
                    self.bin(op, a, c, one, zero)
                }
                Node::Select(c, a, e) => {
                    let m = self.b.ins().fcmp(FloatCC::NotEqual, vals[&c], zero);
                    self.select(m, vals[&a], vals[&e])
                }
                Node::Param { param, comp, side: Side::J } => {
                    let off = (spec.param_offset[param.index()] + comp as usize) * T::BYTES;
                    let stride = (spec.param_stride * T::BYTES) as i64;
                    self.per_lane(&js, |e, j| {
                        let m = e.lane_u32(material, j);
                        let row = e.b.ins().imul_imm_s(m, stride);
                        let addr = e.b.ins().iadd(params, row);
                        e.b.ins().load(e.real, Self::mem(), addr, off as i32)
                    })
                }
                Node::InGroup(Side::J, set) => self.per_lane(&js, |e, j| {
                    // (set >> group[j]) & 1, as a real 0 or 1.
                    let g = e.lane_u32(group, j);
                    let bits = e.b.ins().iconst(types::I64, set as i64);
                    let bit = e.b.ins().ushr(bits, g);
                    let bit = e.b.ins().band_imm_s(bit, 1);
                    e.b.ins().fcvt_from_uint(e.real, bit)
                }),
                Node::Load { .. } | Node::Param { .. } | Node::InGroup(..) => unreachable!("checked by `supported`"),
            };
            vals.insert(*id, v);
        }
        // Lanes of this vector before `end`.
        let base_lane = if lane_ty == self.ptr { base } else { self.b.ins().ireduce(lane_ty, base) };
        let base_vec = self.b.ins().splat(self.int, base_lane);
        let idx = self.b.ins().iadd(base_vec, iota);
        let live = self.b.ins().icmp(IntCC::UnsignedLessThan, idx, end_vec);
        for (id, r) in spec.outputs {
            let v = match (vals.get(id), preset.get(id)) {
                (Some(v), _) => *v,
                (None, Some(p)) => self.b.ins().load(self.vec, Self::mem(), lane_addr, reg_addr(*p)),
                (None, None) => unreachable!("every output is computed or preset"),
            };
            // Lanes from `end` on keep what they hold: past a full batch they are the next
            // register's first lanes, another particle's outputs.
            let old = self.b.ins().load(self.vec, Self::mem(), lane_addr, reg_addr(*r));
            let v = self.select(live, v, old);
            self.b.ins().store(Self::mem(), v, lane_addr, reg_addr(*r));
        }
        if !spec.folded.is_empty() {
            // Lanes at or past `end` contribute the identity (as `fold_partials` pads).
            for ((id, _, r), var) in spec.folded.iter().zip(&accs) {
                let v = match (vals.get(id), preset.get(id)) {
                    (Some(v), _) => *v,
                    (None, Some(p)) => self.b.ins().load(self.vec, Self::mem(), lane_addr, reg_addr(*p)),
                    (None, None) => unreachable!("every folded value is computed or preset"),
                };
                let identity = self.splat(r.identity());
                let v = self.select(live, v, identity);
                let acc = self.b.use_var(var[0]);
                let acc = self.combine(*r, acc, v);
                for k in 1..sets {
                    let next = self.b.use_var(var[k]);
                    self.b.def_var(var[k - 1], next);
                }
                self.b.def_var(var[sets - 1], acc);
            }
        }
        let next = self.b.ins().iadd_imm_s(base, self.width as i64);
        self.b.ins().jump(head, &[next.into()]);

        self.b.switch_to_block(exit);
        // After n iterations, variable k holds set (k + n) mod sets (sets is 1 or 2).
        assert!(sets <= 2, "the fold rotates at most two sets");
        let n = self.b.ins().isub(end, start);
        let n = self.b.ins().iadd_imm_s(n, self.width as i64 - 1);
        let n = self.b.ins().ushr_imm_u(n, self.width.trailing_zeros() as i64);
        let odd = self.b.ins().band_imm_s(n, 1);
        for ((_, slot, r), var) in spec.folded.iter().zip(&accs) {
            let vars: Vec<Value> = var.iter().map(|v| self.b.use_var(*v)).collect();
            let ordered: Vec<Value> = if sets == 2 {
                vec![self.b.ins().select(odd, vars[1], vars[0]), self.b.ins().select(odd, vars[0], vars[1])]
            } else {
                vars
            };
            let mut lanes: Vec<Value> = vec![];
            for acc in ordered {
                lanes.extend((0..self.width).map(|k| self.b.ins().extractlane(acc, k as u8)));
            }
            let h = pairwise(&lanes, &mut |a, b| self.combine(*r, a, b));
            let off = (slot * T::BYTES) as i32;
            let old = self.b.ins().load(self.real, Self::mem(), slots, off);
            let new = self.combine(*r, old, h);
            self.b.ins().store(Self::mem(), new, slots, off);
        }
        self.b.ins().return_(&[]);
        self.b.seal_all_blocks();
        self.b.finalize(config);
        gathers
    }

    /// `op(a, b)` of a reduction, as `fold_partials` computes it (scalars or vectors alike).
    fn combine(&mut self, r: Reduce, a: Value, b: Value) -> Value {
        match r {
            Reduce::Sum => self.b.ins().fadd(a, b),
            Reduce::Min | Reduce::Max => {
                // lane_min / lane_max: b when a is NaN or b is beyond a, else a.
                let nan = self.b.ins().fcmp(FloatCC::Unordered, a, a);
                let cc = if r == Reduce::Min { FloatCC::LessThan } else { FloatCC::GreaterThan };
                let beyond = self.b.ins().fcmp(cc, b, a);
                let m = self.b.ins().bor(nan, beyond);
                if self.b.func.dfg.value_type(a).is_vector() {
                    self.select(m, b, a)
                } else {
                    self.b.ins().select(m, b, a)
                }
            }
        }
    }

    /// `row` when j's group is in `set`, else the address of [`ZERO_ROW`] (never j's row: a
    /// column not stored on j's group has no row for it).
    fn row_if_stored(&mut self, set: GroupSet, group: Value, j: Value, row: Value) -> Value {
        let g = self.lane_u32(group, j);
        let bits = self.b.ins().iconst(types::I64, set.0 as i64);
        let bit = self.b.ins().ushr(bits, g);
        let bit = self.b.ins().band_imm_s(bit, 1);
        let zeros = self.b.ins().iconst(self.ptr, ZERO_ROW.as_ptr() as i64);
        self.b.ins().select(bit, row, zeros)
    }

    /// `array[j]` of a `u32` array, widened to 64 bits.
    fn lane_u32(&mut self, array: Value, j: Value) -> Value {
        let off = self.b.ins().imul_imm_s(j, 4);
        let addr = self.b.ins().iadd(array, off);
        let v = self.b.ins().uload32(Self::mem(), addr, 0);
        if self.ptr == types::I32 {
            self.b.ins().ireduce(types::I32, v)
        } else {
            v
        }
    }

    /// A vector whose lane k is `scalar(j_k)`.
    fn per_lane(&mut self, js: &[Value], mut scalar: impl FnMut(&mut Self, Value) -> Value) -> Value {
        let first = scalar(self, js[0]);
        let mut v = self.b.ins().scalar_to_vector(self.vec, first);
        for (k, j) in js.iter().enumerate().skip(1) {
            let x = scalar(self, *j);
            v = self.b.ins().insertlane(v, x, k as u8);
        }
        v
    }

    fn bin(&mut self, op: Bin, a: Value, c: Value, one: Value, zero: Value) -> Value {
        let cmp = |e: &mut Self, cc: FloatCC| {
            let m = e.b.ins().fcmp(cc, a, c);
            e.truth(m, one, zero)
        };
        match op {
            Bin::Add => self.b.ins().fadd(a, c),
            Bin::Sub => self.b.ins().fsub(a, c),
            Bin::Mul => self.b.ins().fmul(a, c),
            Bin::Div => self.b.ins().fdiv(a, c),
            Bin::Lt => cmp(self, FloatCC::LessThan),
            Bin::Le => cmp(self, FloatCC::LessThanOrEqual),
            Bin::Gt => cmp(self, FloatCC::GreaterThan),
            Bin::Ge => cmp(self, FloatCC::GreaterThanOrEqual),
            Bin::Eq => cmp(self, FloatCC::Equal),
            Bin::Ne => cmp(self, FloatCC::NotEqual),
            Bin::And | Bin::Or => {
                let x = self.b.ins().fcmp(FloatCC::NotEqual, a, zero);
                let y = self.b.ins().fcmp(FloatCC::NotEqual, c, zero);
                let m = if op == Bin::And { self.b.ins().band(x, y) } else { self.b.ins().bor(x, y) };
                self.truth(m, one, zero)
            }
            // program::lane_min / lane_max: y when x is NaN or y is beyond x, else x.
            Bin::Min | Bin::Max => {
                let nan = self.b.ins().fcmp(FloatCC::Unordered, a, a);
                let cc = if op == Bin::Min { FloatCC::LessThan } else { FloatCC::GreaterThan };
                let beyond = self.b.ins().fcmp(cc, c, a);
                let m = self.b.ins().bor(nan, beyond);
                self.select(m, c, a)
            }
            Bin::Pow => self.pow(a, c, one, zero),
        }
    }

    /// `math::ln_f64` / `ln_f32`, operation for operation (k to a real by the magic constant:
    /// exact, as the recipe's conversion).
    fn ln(&mut self, x: Value, k: &LnConsts) -> Value {
        let min_normal = self.splat(k.min_normal);
        let tiny = self.b.ins().fcmp(FloatCC::LessThan, x, min_normal);
        let up = self.splat(2f64.powi(k.scale as i32));
        let scaled = self.b.ins().fmul(x, up);
        let xs = self.select(tiny, scaled, x);
        let bits = self.bits_as_int(xs);
        let e = self.b.ins().ushr_imm_u(bits, k.mantissa as i64);
        let mant_mask = self.splat_int((1i64 << k.mantissa) - 1);
        let mant = self.b.ins().band(bits, mant_mask);
        let sqrt2 = self.splat_int(k.sqrt2_mantissa);
        let big = self.b.ins().icmp(IntCC::SignedGreaterThan, mant, sqrt2);
        let (one_int, zero_int) = (self.splat_int(1), self.splat_int(0));
        let big = self.b.ins().bitselect(big, one_int, zero_int);
        let bias = self.splat_int(k.bias);
        let zexp = self.b.ins().isub(bias, big);
        let zexp = self.b.ins().ishl_imm_u(zexp, k.mantissa as i64);
        let zbits = self.b.ins().bor(mant, zexp);
        let z = self.mask_as_float(zbits);
        let n = self.b.ins().isub(e, bias);
        let n = self.b.ins().iadd(n, big);
        let scale = self.splat_int(k.scale);
        let adjust = self.b.ins().bitselect(tiny, scale, zero_int);
        let n = self.b.ins().isub(n, adjust);
        let (one, two, half) = (self.splat(1.0), self.splat(2.0), self.splat(0.5));
        let f = self.b.ins().fsub(z, one);
        let d = self.b.ins().fadd(two, f);
        let s = self.b.ins().fdiv(f, d);
        let w = self.b.ins().fmul(s, s);
        let lg = k.lg;
        let mut r = self.splat(lg[lg.len() - 1]);
        for c in lg[..lg.len() - 1].iter().rev() {
            let c = self.splat(*c);
            r = self.b.ins().fmul(r, w);
            r = self.b.ins().fadd(r, c);
        }
        let r = self.b.ins().fmul(r, w);
        let hf = self.b.ins().fmul(half, f);
        let hfsq = self.b.ins().fmul(hf, f);
        let magic = T::EXP.magic;
        let magic_int = self.splat_bits_of(magic);
        let nb = self.b.ins().iadd(n, magic_int);
        let nb = self.mask_as_float(nb);
        let magic = self.splat(magic);
        let nf = self.b.ins().fsub(nb, magic);
        let (ln2_hi, ln2_lo) = (self.splat(k.ln2_hi), self.splat(k.ln2_lo));
        // nf·ln2_hi − ((hfsq − (s·(hfsq + r) + nf·ln2_lo)) − f)
        let a = self.b.ins().fadd(hfsq, r);
        let a = self.b.ins().fmul(s, a);
        let lo = self.b.ins().fmul(nf, ln2_lo);
        let a = self.b.ins().fadd(a, lo);
        let a = self.b.ins().fsub(hfsq, a);
        let a = self.b.ins().fsub(a, f);
        let hi = self.b.ins().fmul(nf, ln2_hi);
        let y = self.b.ins().fsub(hi, a);
        let zero = self.splat(0.0);
        let is_zero = self.b.ins().fcmp(FloatCC::Equal, x, zero);
        let minus_inf = self.splat(f64::NEG_INFINITY);
        let y = self.select(is_zero, minus_inf, y);
        let inf = self.splat(f64::INFINITY);
        let is_inf = self.b.ins().fcmp(FloatCC::Equal, x, inf);
        let y = self.select(is_inf, inf, y);
        let negative = self.b.ins().fcmp(FloatCC::LessThan, x, zero);
        let nan = self.b.ins().fcmp(FloatCC::Unordered, x, x);
        let undefined = self.b.ins().bor(negative, nan);
        let nan = self.splat(f64::NAN);
        self.select(undefined, nan, y)
    }

    /// `math::pow_f64` / `pow_f32`: exp(y · ln x), 1 where y = 0 or x = 1.
    fn pow(&mut self, x: Value, y: Value, one: Value, zero: Value) -> Value {
        let l = self.ln(x, T::LN);
        let a = self.b.ins().fmul(y, l);
        let p = self.exp(a, T::EXP);
        let y0 = self.b.ins().fcmp(FloatCC::Equal, y, zero);
        let x1 = self.b.ins().fcmp(FloatCC::Equal, x, one);
        let m = self.b.ins().bor(y0, x1);
        self.select(m, one, p)
    }

    /// `math::exp_f64` / `exp_f32`, operation for operation.
    fn exp(&mut self, x: Value, k: &ExpConsts) -> Value {
        let lo = self.splat(k.lo);
        let hi = self.splat(k.hi);
        let below = self.b.ins().fcmp(FloatCC::LessThan, x, lo);
        let above = self.b.ins().fcmp(FloatCC::GreaterThan, x, hi);
        let x = self.select(above, hi, x);
        let x = self.select(below, lo, x);
        let magic = self.splat(k.magic);
        let log2e = self.splat(k.log2e);
        let t = self.b.ins().fmul(x, log2e);
        let t = self.b.ins().fadd(t, magic);
        let nf = self.b.ins().fsub(t, magic);
        let (ln2_hi, ln2_lo) = (self.splat(k.ln2_hi), self.splat(k.ln2_lo));
        let a = self.b.ins().fmul(nf, ln2_hi);
        let r = self.b.ins().fsub(x, a);
        let a = self.b.ins().fmul(nf, ln2_lo);
        let r = self.b.ins().fsub(r, a);
        let c = k.coeffs;
        let mut p = self.splat(c[c.len() - 1]);
        for ci in c[..c.len() - 1].iter().rev() {
            let ci = self.splat(*ci);
            p = self.b.ins().fmul(p, r);
            p = self.b.ins().fadd(p, ci);
        }
        let magic_int = self.splat_bits_of(k.magic);
        let t_int = self.bits_as_int(t);
        let n = self.b.ins().isub(t_int, magic_int);
        let zero = self.splat(0.0);
        let negative = self.b.ins().fcmp(FloatCC::LessThan, x, zero);
        let (up, down) = (self.splat_int(k.margin), self.splat_int(-k.margin));
        let m = self.b.ins().bitselect(negative, up, down);
        let bias = self.splat_int(k.bias);
        let e1 = self.b.ins().iadd(n, m);
        let e1 = self.b.ins().iadd(e1, bias);
        let e1 = self.b.ins().ishl_imm_u(e1, k.mantissa as i64);
        let e2 = self.b.ins().isub(bias, m);
        let e2 = self.b.ins().ishl_imm_u(e2, k.mantissa as i64);
        let s1 = self.mask_as_float(e1);
        let s2 = self.mask_as_float(e2);
        let y = self.b.ins().fmul(p, s1);
        self.b.ins().fmul(y, s2)
    }
}
