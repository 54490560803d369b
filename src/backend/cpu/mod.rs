//! The CPU backend: every block of the plan lowered to scalar SSA (`lower`), compiled to closures
//! over batches of lanes (`program`), and run over the particle store in parallel chunks with the
//! cell list as the neighbour iterator (`exec`).

pub mod ccode;
mod cwalk;
mod exec;
pub mod jit;
pub mod lists;
pub mod lower;
pub mod math;
pub mod program;

use super::{timestep, Backend, BackendError, Globals, Mirror, Snapshot};
use crate::grid::{morton_permutation, Grid, SizeLevels};
use crate::ir::{FieldId, GroupId, GroupSet, Reduce, Side, Storage};
use crate::particles::{Real, Store};
use crate::schedule::{Block, Plan};
use exec::{chunks, views, Chunk, Neighbours, Scratch, Shared, Walk};
use lower::{Effect, Graph, Id, Known, Lowerer, Mode, Node};
use program::{compile, live_nodes, Pinned, Program, LANES};
use rayon::prelude::*;

/// Registers of the pair program that the neighbour batch fills: x_ij components, r_ij, h_ij.
#[derive(Clone, Copy, Debug)]
pub struct PairRegs {
    pub x: usize,
    pub r: usize,
    pub h: usize,
}

/// An accumulator component of a pass variant.
pub struct Slot {
    pub field: FieldId,
    pub comp: usize,
    pub reduce: Reduce,
    pub temp: bool,
    /// Register of its `init` value in the init program, if `init` sets it.
    pub init_reg: Option<usize>,
    /// Summed with Kahan compensation (`compensated` pair sums).
    pub compensated: bool,
}

/// A pass compiled for one destination group.
pub struct Variant<T> {
    pub group: usize,
    pub sources: u64,
    pub init: Option<Program<T>>,
    /// Values of particle i that the neighbour loop reads (computed once per particle).
    pub dest: Program<T>,
    /// (register in `dest`, register in `pair`) of every value broadcast to the neighbour lanes.
    pub exports: Vec<(usize, usize)>,
    pub pair: Program<T>,
    /// The pair program as native code (`jit.rs`), when it compiled.
    pub jit: Option<jit::JitPair<T>>,
    pub pair_regs: PairRegs,
    pub slots: Vec<Slot>,
    /// For each of `pair.accums`, its slot.
    pub accum_slot: Vec<usize>,
    pub tail: Option<Program<T>>,
    /// Temp accumulators (`acc`) and their component counts.
    pub temps: Vec<(FieldId, usize)>,
}

pub struct CpuBackend<T: Real> {
    pub plan: Plan,
    pub store: Store<T>,
    passes: Vec<Vec<Variant<T>>>,
    /// Per stage, per group: the fused update program.
    stages: Vec<Vec<Option<Program<T>>>>,
    derived: Vec<Option<Program<T>>>,
    reductions: Vec<Option<Program<T>>>,
    n_reductions: usize,
    mirrors: Vec<Mirror>,
    chunks: Vec<Chunk>,
    pub support: f64,
    x: FieldId,
    h: FieldId,
    /// Neighbour lists kept across evaluations, when the plan's search keeps them.
    pub(crate) lists: lists::Lists<T>,
    /// The largest smoothing length over every rank of a run split into domains, where the lists
    /// must reach as far as in the run in one piece (their skin is a fraction of it).
    pub(crate) lists_h_max: Option<f64>,
    /// The neighbour walk in C (`cwalk`), where a C compiler answers; else the scalar walk.
    c_walk: Option<cwalk::WalkFn<T>>,
    /// The state last kept as good ([`Backend::keep`]): the columns in the store's precision,
    /// the ids and the materials, copied into buffers reused from one keep to the next.
    kept: Option<Kept<T>>,
    /// Per model group, the nanoseconds its particles spent in neighbour passes since the last
    /// [`take_pass_time`](Self::take_pass_time), when asked to measure it.
    pass_time: Option<Vec<std::sync::atomic::AtomicU64>>,
}

/// What the passes of one evaluation search ([`CpuBackend::search`]).
pub struct Search<T> {
    x: Vec<T>,
    h: Vec<T>,
    grid: Option<SizeLevels>,
    h_near: Vec<f64>,
    h_max: f64,
}

#[derive(Default)]
struct Kept<T> {
    columns: Vec<Option<Vec<T>>>,
    id: Vec<u32>,
    material: Vec<u32>,
}

fn is_stored(plan: &Plan, g: usize) -> impl Fn(FieldId) -> bool + '_ {
    move |f| plan.field_layout(f).is_some_and(|l| l.groups.contains(GroupId(g as u32)))
}

/// A particle program for group `g` from blocks run in order.
fn particle_program<T: Real>(plan: &Plan, known: &Known, g: usize, blocks: &[Block]) -> Option<Program<T>> {
    let kernel = &plan.model.kernels[plan.kernel.index()];
    let mut lw = Lowerer::new(&plan.model, known, kernel, plan.dim, Mode::Particle, Box::new(is_stored(plan, g)));
    let mut any = false;
    for b in blocks.iter().filter(|b| b.dest.contains(GroupId(g as u32))) {
        lw.block(&b.stmts, None);
        any = true;
    }
    if !any {
        return None;
    }
    lw.finish_stores();
    lw.optimise();
    let roots: Vec<Id> = lw.effects.iter().map(effect_value).collect();
    let nodes = live_nodes(&lw.g, roots);
    Some(compile(&plan.model, plan.dim, &lw.g, &nodes, &lw.effects, &Pinned { preset: vec![], exports: vec![] }))
}

/// The parameters and fields that are constants of the run (see [`lower::Known`]).
/// The values the programs fold: the parameters every material of `store` binds alike, and the
/// fields nothing writes that every particle of `store` holds alike.
pub fn known<T: Real>(plan: &Plan, store: &Store<T>) -> lower::Known {
    lower::Known { params: known_params(&plan.model, store), fields: known_fields(plan, store) }
}

/// Fields nothing writes during a run and every particle holds with one value.
fn known_fields<T: Real>(plan: &Plan, store: &Store<T>) -> Vec<Option<Vec<f64>>> {
    let model = &plan.model;
    let mut written = vec![false; model.fields.len()];
    for eq in &model.equations {
        eq.writes.iter().for_each(|f| written[f.index()] = true);
    }
    model.rates.iter().for_each(|r| written[r.state.index()] = true);
    for (a, b) in &plan.saved {
        written[a.index()] = true;
        written[b.index()] = true;
    }
    fn targets(stmts: &[crate::ir::Stmt], written: &mut [bool]) {
        for s in stmts {
            match s {
                crate::ir::Stmt::Set(f, _) | crate::ir::Stmt::Accum(f, _, _) => written[f.index()] = true,
                crate::ir::Stmt::If(_, a, b) => {
                    targets(a, written);
                    targets(b, written);
                }
                crate::ir::Stmt::Let(..) => {}
            }
        }
    }
    for st in &plan.stages {
        st.updates.iter().for_each(|b| targets(&b.stmts, &mut written));
    }
    (0..model.fields.len())
        .map(|f| {
            let field = &model.fields[f];
            if written[f] || field.storage == Storage::Temp || field.saved_of.is_some() || store.n == 0 {
                return None;
            }
            let col = store.columns[f].as_ref()?;
            if store.ranges.iter().any(|(g, _)| col.base[g.index()] == crate::particles::ABSENT) {
                return None;
            }
            let first: Vec<T> = col.data[..col.comps].to_vec();
            col.data
                .chunks_exact(col.comps)
                .take(store.n)
                .all(|row| row == first.as_slice())
                .then(|| first.iter().map(|v| v.to_f64()).collect())
        })
        .collect()
}

/// The parameters every material with particles binds to the same value.
fn known_params<T: Real>(model: &crate::ir::Model, store: &Store<T>) -> Vec<Option<Vec<f64>>> {
    let mut materials: Vec<u32> = store.material.clone();
    materials.sort_unstable();
    materials.dedup();
    let table = &store.params;
    (0..model.params.len())
        .map(|p| {
            let p = crate::ir::ParamId(p as u32);
            let values = |m: u32| -> Vec<f64> {
                (0..table.comps[p.index()]).map(|c| table.get(m as usize, p, c).to_f64()).collect()
            };
            let first = values(*materials.first()?);
            materials.iter().all(|m| values(*m) == first).then_some(first)
        })
        .collect()
}

fn effect_value(e: &Effect) -> Id {
    match *e {
        Effect::Store { value, .. } | Effect::Accum { value, .. } | Effect::Reduce { value, .. } => value,
    }
}

fn eq_blocks(plan: &Plan, eqs: &[crate::ir::EqId]) -> Vec<Block> {
    eqs.iter()
        .map(|e| {
            let eq = plan.equation(*e);
            let stmts = match &eq.kind {
                crate::ir::EquationKind::Particle { body } => body.clone(),
                crate::ir::EquationKind::PairSum { finally, .. } => finally.clone(),
            };
            Block { name: eq.name.clone(), dest: eq.dest, stmts }
        })
        .collect()
}

fn varying(node: &Node, flags: &[bool]) -> bool {
    match *node {
        Node::Load { side, .. } | Node::Param { side, .. } | Node::InGroup(side, _) => side == crate::ir::Side::J,
        Node::PairX(_) | Node::PairR | Node::PairH => true,
        _ => node.operands().iter().any(|o| flags[*o as usize]),
    }
}

/// The fields the pair program gathers at j that not every source group with particles stores,
/// with the groups that do.
fn partly_stored(plan: &Plan, graph: &Graph, nodes: &[Id], sources: GroupSet) -> Vec<(FieldId, GroupSet)> {
    let mut out: Vec<(FieldId, GroupSet)> = vec![];
    for id in nodes {
        if let Node::Load { field, side: Side::J, .. } = graph.nodes[*id as usize] {
            let stored_on = plan.field_layout(field).map_or(GroupSet(0), |l| l.groups);
            if sources.0 & plan.groups.0 & !stored_on.0 != 0 && !out.iter().any(|(f, _)| *f == field) {
                out.push((field, stored_on));
            }
        }
    }
    out
}

fn compile_variant<T: Real>(
    plan: &Plan,
    known: &Known,
    params: &crate::particles::ParamTable<T>,
    signs: bool,
    v: &crate::schedule::PassVariant,
) -> Variant<T> {
    let g = v.group.index();
    let model = &plan.model;
    let kernel = &model.kernels[plan.kernel.index()];
    let dim = plan.dim;
    // The neighbour loops of every pair sum of the pass, one graph.
    let mut lw = Lowerer::new(model, known, kernel, dim, Mode::Pair, Box::new(|_| true))
        .in_groups(GroupSet::default().with(v.group), v.sources.intersect(plan.groups));
    let mut init_blocks = vec![];
    let mut slots: Vec<Slot> = vec![];
    let mut temps = vec![];
    for e in &v.pair_sums {
        let eq = plan.equation(*e);
        let sources = &eq.sources_for(v.group);
        let crate::ir::EquationKind::PairSum { accumulators, init, body, compensated, .. } = &eq.kind else {
            continue;
        };
        let mask = (sources.intersect(plan.groups) != v.sources).then(|| lw.sources_mask(*sources));
        lw.block(body, mask);
        init_blocks.push(Block { name: eq.name.clone(), dest: eq.dest, stmts: init.clone() });
        for a in accumulators {
            let f = model.field(a.field);
            let temp = f.storage == Storage::Temp;
            let comps = crate::ir::components(f.ty.shape, dim);
            if temp {
                temps.push((a.field, comps));
            } else if !is_stored(plan, g)(a.field) {
                continue;
            }
            for c in 0..comps {
                let compensated = *compensated && a.reduce == Reduce::Sum;
                slots.push(Slot { field: a.field, comp: c, reduce: a.reduce, temp, init_reg: None, compensated });
            }
        }
    }
    // Initial accumulator values (`init` blocks), as a particle program whose stores are read.
    let init = if init_blocks.iter().any(|b| !b.stmts.is_empty()) {
        let mut il = Lowerer::new(model, known, kernel, dim, Mode::Particle, Box::new(|_| true));
        for b in &init_blocks {
            il.block(&b.stmts, None);
        }
        il.finish_stores();
        let roots: Vec<Id> = il.effects.iter().map(effect_value).collect();
        let nodes = live_nodes(&il.g, roots);
        let p: Program<T> =
            compile(model, dim, &il.g, &nodes, &il.effects, &Pinned { preset: vec![], exports: vec![] });
        for st in &p.stores {
            if let Some(s) = slots.iter_mut().find(|s| s.field == st.field && s.comp == st.comp) {
                s.init_reg = Some(st.reg);
            }
        }
        Some(p)
    } else {
        None
    };
    // Split: values of particle i alone (computed once per particle) and per-neighbour values.
    lw.optimise();
    let graph = &lw.g;
    let mut flags = vec![false; graph.nodes.len()];
    for (k, n) in graph.nodes.iter().enumerate() {
        flags[k] = varying(n, &flags);
    }
    let accum_effects: Vec<Effect> = lw
        .effects
        .iter()
        .filter(|e| match e {
            Effect::Accum { field, comp, .. } => slots.iter().any(|s| s.field == *field && s.comp == *comp as usize),
            _ => false,
        })
        .cloned()
        .collect();
    let roots: Vec<Id> = accum_effects.iter().map(effect_value).collect();
    let all = live_nodes(graph, roots.iter().copied());
    let is_const = |id: Id| matches!(graph.nodes[id as usize], Node::Const(_));
    let pair_nodes: Vec<Id> = all.iter().copied().filter(|id| flags[*id as usize] || is_const(*id)).collect();
    // Uniform values the pair program reads: operands of varying nodes, and uniform accum values.
    let mut exports: Vec<Id> = vec![];
    for id in &pair_nodes {
        for o in graph.nodes[*id as usize].operands() {
            if !flags[o as usize] && !is_const(o) && !exports.contains(&o) {
                exports.push(o);
            }
        }
    }
    for r in &roots {
        if !flags[*r as usize] && !is_const(*r) && !exports.contains(r) {
            exports.push(*r);
        }
    }
    let dest_nodes = live_nodes(graph, exports.iter().copied());
    let dest_nodes: Vec<Id> = dest_nodes.into_iter().filter(|id| !flags[*id as usize]).collect();
    let dest: Program<T> =
        compile(model, dim, graph, &dest_nodes, &[], &Pinned { preset: vec![], exports: exports.clone() });
    // Pair program registers: x_ij (dim), r_ij, h_ij, then the broadcast uniforms.
    let pair_regs = PairRegs { x: 0, r: dim, h: dim + 1 };
    let mut preset: Vec<(Id, usize)> = vec![];
    for (k, n) in graph.nodes.iter().enumerate() {
        match n {
            Node::PairX(c) => preset.push((k as Id, *c as usize)),
            Node::PairR => preset.push((k as Id, dim)),
            Node::PairH => preset.push((k as Id, dim + 1)),
            _ => {}
        }
    }
    let mut bcast = vec![];
    for (k, u) in exports.iter().enumerate() {
        preset.push((*u, dim + 2 + k));
        bcast.push((dest.reg_of[u], dim + 2 + k));
    }
    let mut preset_regs = preset.clone();
    if preset_regs.iter().all(|(_, r)| *r != dim + 1) {
        // Keep the fixed registers reserved even when no node reads them.
        preset_regs.push((Id::MAX, dim + 1));
    }
    if crate::config::env().debug >= 2 {
        for id in &pair_nodes {
            eprintln!("  v{id} = {:?}", graph.nodes[*id as usize]);
        }
        for e in &accum_effects {
            eprintln!("  {e:?}");
        }
    }
    let pair: Program<T> = compile(
        model,
        dim,
        graph,
        &pair_nodes,
        &accum_effects,
        &Pinned { preset: preset_regs.clone(), exports: vec![] },
    );
    let accum_slot: Vec<usize> = pair
        .accums
        .iter()
        .map(|a| slots.iter().position(|s| s.field == a.field && s.comp == a.comp).expect("slot of every accum"))
        .collect();
    let jit = jit::enabled()
        .then(|| {
            let mut outputs: Vec<(Id, usize)> = vec![];
            let mut folded: Vec<(Id, usize, Reduce)> = vec![];
            for ((e, a), s) in accum_effects.iter().zip(&pair.accums).zip(&accum_slot) {
                if slots[*s].compensated {
                    outputs.push((effect_value(e), a.reg));
                } else {
                    folded.push((effect_value(e), *s, a.reduce));
                }
            }
            let broadcast: Vec<(Id, usize)> = exports.iter().map(|u| (*u, dest.reg_of[u])).collect();
            let partial = partly_stored(plan, graph, &pair_nodes, v.sources);
            let spec = jit::PairSpec {
                model,
                dim,
                graph,
                nodes: &pair_nodes,
                preset: &preset_regs,
                broadcast: &broadcast,
                outputs: &outputs,
                folded: &folded,
                signs,
                param_stride: params.stride,
                param_offset: &params.offset,
                partial: &partial,
            };
            let debug = crate::config::env().debug >= 1;
            let c = if ccode::enabled() {
                ccode::compile_pair::<T>(&spec)
                    .map_err(|why| {
                        // A compiler that answers but fails is worth a word once: the run is slower.
                        static TOLD: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
                        if debug {
                            eprintln!("pass on group {g}: Cranelift, not C ({why})");
                        } else if !TOLD.swap(true, std::sync::atomic::Ordering::Relaxed) {
                            let first = why.lines().next().unwrap_or_default();
                            eprintln!(
                                "warning: the C compiler failed on a pair program ({first}); Cranelift's code runs \
                                 instead (PAIRSUM_DEBUG=1 says more, PAIRSUM_NATIVE=cranelift keeps it quiet)"
                            );
                        }
                    })
                    .ok()
            } else {
                None
            };
            c.or_else(|| {
                jit::compile_pair::<T>(&spec)
                    .map_err(|why| {
                        if debug {
                            eprintln!("pass on group {g}: closures, not native code ({why})");
                        }
                    })
                    .ok()
            })
        })
        .flatten();
    let tail = particle_program(plan, known, g, &plan.tail_blocks(&v.tail));
    Variant {
        group: g,
        sources: v.sources.0,
        init,
        dest,
        exports: bcast,
        pair,
        jit,
        pair_regs,
        slots,
        accum_slot,
        tail,
        temps,
    }
}

impl<T: Real> CpuBackend<T> {
    /// The same backend with every neighbour loop run by closures (the reference the JIT's
    /// native code is tested against, and `PAIRSUM_NO_JIT`'s behaviour).
    pub fn without_jit(mut self) -> Self {
        for v in self.passes.iter_mut().flatten() {
            v.jit = None;
        }
        self.c_walk = None;
        self
    }

    /// Whether the neighbours are walked in C (`cwalk`).
    pub fn walks_in_c(&self) -> bool {
        self.c_walk.is_some()
    }

    /// How many pass variants run as native code, of how many.
    pub fn native_passes(&self) -> (usize, usize) {
        let all = self.passes.iter().flatten();
        (all.clone().filter(|v| v.jit.is_some()).count(), all.count())
    }

    /// How many pass variants run as native code made by `kind`.
    pub fn passes_made_by(&self, kind: jit::NativeKind) -> usize {
        self.passes.iter().flatten().filter(|v| v.jit.as_ref().is_some_and(|j| j.kind == kind)).count()
    }

    /// What runs the neighbour loops: "C pair code", or the count of each where they differ.
    fn pair_code(&self) -> String {
        let (native, all) = self.native_passes();
        let kinds = [
            (self.passes_made_by(jit::NativeKind::C), "C"),
            (self.passes_made_by(jit::NativeKind::Cranelift), "Cranelift"),
            (all - native, "closures"),
        ];
        let used: Vec<_> = kinds.iter().filter(|(n, _)| *n > 0).collect();
        match used.as_slice() {
            [(_, name)] => format!("{name} pair code"),
            _ => format!("pair code: {}", used.iter().map(|(n, k)| format!("{n} {k}")).collect::<Vec<_>>().join(", ")),
        }
    }

    /// Compiles every block of the plan for every group present. The store must hold the
    /// particles (sorted group-major) with the scene's fields and the material parameters set.
    pub fn new(plan: Plan, store: Store<T>, mirrors: Vec<Mirror>) -> Result<CpuBackend<T>, BackendError> {
        let known = known(&plan, &store);
        Self::with_known(plan, store, mirrors, known)
    }

    /// As [`new`](Self::new), with the values the programs fold given (a rank of a split run
    /// holds a share of the particles and folds only what every rank's share agrees on).
    pub fn with_known(
        plan: Plan,
        mut store: Store<T>,
        mirrors: Vec<Mirror>,
        known: Known,
    ) -> Result<CpuBackend<T>, BackendError> {
        let x = plan.model.field_id("x").ok_or_else(|| BackendError("the model has no position field `x`".into()))?;
        let h = plan.model.field_id("h").ok_or_else(|| BackendError("the model has no smoothing length `h`".into()))?;
        let n_groups = plan.model.groups.len();
        let present: Vec<usize> = plan.groups.iter(n_groups).map(|g| g.index()).collect();
        let per_group = |f: &dyn Fn(usize) -> Option<Program<T>>| -> Vec<Option<Program<T>>> {
            (0..n_groups).map(|g| if present.contains(&g) { f(g) } else { None }).collect()
        };
        let mut passes: Vec<Vec<Variant<T>>> = plan
            .passes
            .iter()
            .map(|p| {
                p.variants
                    .iter()
                    .map(|v| compile_variant(&plan, &known, &store.params, !mirrors.is_empty(), v))
                    .collect()
            })
            .collect();
        // Native code gathers a column from one base (the store's layout is fixed from here on).
        let cols = views(&mut store);
        for v in passes.iter_mut().flatten() {
            if v.jit.as_ref().is_some_and(|jit| exec::gathered_columns(&jit.gathers, &cols).is_none()) {
                if crate::config::env().debug >= 1 {
                    eprintln!("pass on group {}: closures, a gathered column has no single base", v.group);
                }
                v.jit = None;
            }
        }
        drop(cols);
        let mut stages = vec![];
        for st in &plan.stages {
            let mut blocks = st.updates.clone();
            blocks.extend(eq_blocks(&plan, &st.corrections));
            blocks.extend(eq_blocks(&plan, &st.derived));
            stages.push(per_group(&|g| particle_program(&plan, &known, g, &blocks)));
        }
        let derived = per_group(&|g| particle_program(&plan, &known, g, &eq_blocks(&plan, &plan.derived)));
        let reds = timestep::reductions(&plan.model, &plan.timesteps);
        let kernel = &plan.model.kernels[plan.kernel.index()];
        let reductions = per_group(&|_| {
            if reds.is_empty() {
                return None;
            }
            let mut lw = Lowerer::new(&plan.model, &known, kernel, plan.dim, Mode::Particle, Box::new(|_| true));
            for (k, (r, e)) in reds.iter().enumerate() {
                lw.reduction(k, *r, e);
            }
            let roots: Vec<Id> = lw.effects.iter().map(effect_value).collect();
            let nodes = live_nodes(&lw.g, roots);
            Some(compile(
                &plan.model,
                plan.dim,
                &lw.g,
                &nodes,
                &lw.effects,
                &Pinned { preset: vec![], exports: vec![] },
            ))
        });
        let support = kernel.support;
        let chunks = chunks(&store);
        if crate::config::env().debug >= 1 {
            for (k, p) in passes.iter().enumerate() {
                for v in p {
                    let v: &Variant<T> = v;
                    eprintln!(
                        "pass {k} group {}: dest {} instrs/{} regs, pair {} instrs/{} regs, {} exports, tail {}",
                        v.group,
                        v.dest.instrs.len(),
                        v.dest.n_regs,
                        v.pair.instrs.len(),
                        v.pair.n_regs,
                        v.exports.len(),
                        v.tail.as_ref().map(|t| t.instrs.len()).unwrap_or(0)
                    );
                }
            }
        }
        let c_walk = cwalk::walker::<T>(plan.dim);
        Ok(CpuBackend {
            c_walk,
            passes,
            stages,
            derived,
            reductions,
            n_reductions: reds.len(),
            mirrors,
            chunks,
            support,
            x,
            h,
            plan,
            store,
            lists: lists::Lists::default(),
            lists_h_max: None,
            kept: None,
            pass_time: None,
        })
    }

    /// Measures from now on the time each group's particles spend in neighbour passes.
    pub fn measure_pass_time(&mut self) {
        let groups = self.plan.model.groups.len();
        self.pass_time = Some((0..groups).map(|_| std::sync::atomic::AtomicU64::new(0)).collect());
    }

    /// Per model group, the seconds spent in neighbour passes since the last call (zeros when
    /// not measured).
    pub fn take_pass_time(&mut self) -> Vec<f64> {
        let groups = self.plan.model.groups.len();
        match &self.pass_time {
            Some(t) => t.iter().map(|a| a.swap(0, std::sync::atomic::Ordering::Relaxed) as f64 * 1e-9).collect(),
            None => vec![0.0; groups],
        }
    }

    /// Replaces the particles (same plan and layout, sorted group-major) while keeping the
    /// compiled programs, and runs the particle programs only on the first `active[k]` particles
    /// of the store's k-th group range: the others (a domain's halo) are read as neighbours only.
    /// The programs fold the fields that were constant over the store they were compiled for, so
    /// `store` must be a subset of that one's particles (or hold the same constant values).
    pub fn replace_particles(&mut self, mut store: Store<T>, active: &[usize]) {
        let cols = views(&mut store);
        for v in self.passes.iter_mut().flatten() {
            if v.jit.as_ref().is_some_and(|jit| exec::gathered_columns(&jit.gathers, &cols).is_none()) {
                v.jit = None;
            }
        }
        drop(cols);
        self.chunks = chunks(&store)
            .into_iter()
            .filter_map(|c| {
                let k = store.ranges.iter().position(|(g, _)| g.index() == c.group)?;
                let end = store.ranges[k].1.start + active[k];
                (c.start < end).then(|| Chunk { len: c.len.min(end - c.start), ..c })
            })
            .collect();
        self.store = store;
        self.lists.invalidate();
        self.kept = None;
    }

    /// The neighbour search of one evaluation: the positions and smoothing lengths it searches,
    /// and either a grid per particle size or the kept lists brought up to date.
    pub fn search(&mut self) -> Result<Search<T>, BackendError> {
        let dim = self.plan.dim;
        let h_max = self.h_max();
        if h_max <= 0.0 || !h_max.is_finite() {
            return Err(BackendError(format!(
                "the largest smoothing length is {h_max}: no neighbour search is possible"
            )));
        }
        super::check_periods(&self.mirrors, self.support, h_max)?;
        let x: Vec<T> = self.positions().to_vec();
        let h: Vec<T> = self.store.column(self.h).expect("h is stored").data.clone();
        // Kept lists, brought up to date as the plan's search says; or a grid per particle size
        // (`SizeLevels`), of cells of half its largest cut-off: the search visits only the cells
        // the cut-off sphere reaches (`Grid::cell_ranges_within`), fewer candidates than the
        // 3^dim cells of a cut-off's size.
        let grid = if self.plan.search.keeps_lists() {
            let h_max = crate::compare::largest_number(h_max, self.lists_h_max);
            let sources = lists::sources_per_group(&self.plan);
            let inp = lists::BuildInput {
                x: &x,
                h: &h,
                dim,
                support: self.support,
                h_max,
                mirrors: &self.mirrors,
                sources: Some((&self.store.group, &sources)),
            };
            let store = &self.store;
            let field = |f| store.read_f64(f).map(|(_, v)| v).unwrap_or_else(|| vec![f64::NAN; store.n]);
            self.lists.prepare(&self.plan.search, &inp, field);
            None
        } else {
            Some(SizeLevels::build(&x, dim, &h, self.support, 0.0))
        };
        // With graded spacing a fine particle far from the coarse ones need not search as far as
        // the coarsest cut-off.
        let h_near = match grid {
            Some(_) => Grid::nearby_max(&x, dim, &h, self.support * h_max),
            None => vec![],
        };
        Ok(Search { x, h, grid, h_near, h_max })
    }

    /// Pass `k` of an evaluation over every active particle, with the neighbours of `search`.
    pub fn run_pass(&mut self, k: usize, g: Globals, search: &Search<T>) {
        let walk = match &search.grid {
            Some(grid) => Walk::Cells(grid),
            None => Walk::Lists(&self.lists.of),
        };
        let cols = views(&mut self.store);
        let sh = Shared::of(&self.store, &cols, g);
        let nb = Neighbours {
            walk,
            x: &search.x,
            h: &search.h,
            dim: self.plan.dim,
            support: T::from_f64(self.support),
            h_near: &search.h_near,
            h_max: search.h_max,
            mirrors: &self.mirrors,
            c_walk: self.c_walk,
        };
        let pass = &self.passes[k];
        let timed = self.pass_time.as_deref();
        self.chunks.par_iter().for_each_init(Scratch::default, |scratch, chunk| {
            if let Some(v) = pass.iter().find(|v| v.group == chunk.group) {
                let started = timed.map(|_| std::time::Instant::now());
                exec::run_pass_chunk(v, &sh, &nb, scratch, *chunk);
                if let (Some(t), Some(s)) = (timed, started) {
                    t[chunk.group].fetch_add(s.elapsed().as_nanos() as u64, std::sync::atomic::Ordering::Relaxed);
                }
            }
        });
    }

    /// Runs a per-group particle program over every chunk in parallel.
    fn run_programs(&mut self, programs: &[Option<Program<T>>], g: Globals) {
        let cols = views(&mut self.store);
        let sh = Shared::of(&self.store, &cols, g);
        self.chunks.par_iter().for_each_init(Scratch::default, |scratch, chunk| {
            if let Some(p) = &programs[chunk.group] {
                exec::run_particle(p, &sh, scratch, *chunk);
            }
        });
    }

    /// The largest smoothing length that is a number: it sizes the search, and a NaN h is left
    /// to the watchdog, which names its particle.
    fn h_max(&self) -> f64 {
        let Some(c) = self.store.column(self.h) else { return 0.0 };
        c.data.par_iter().map(|v| v.to_f64()).reduce(|| 0.0, |a, b| crate::compare::largest_number(a, [b]))
    }

    fn positions(&self) -> &[T] {
        &self.store.column(self.x).expect("x is stored on every group").data
    }
}

impl<T: Real> Backend for CpuBackend<T> {
    fn describe(&self) -> String {
        format!("cpu ({}, {} threads, {})", T::NAME, rayon::current_num_threads(), self.pair_code())
    }

    fn plan(&self) -> &Plan {
        &self.plan
    }

    fn particles(&self) -> usize {
        self.store.n
    }

    fn initialise(&mut self) -> Result<(), BackendError> {
        let derived = std::mem::take(&mut self.derived);
        self.run_programs(&derived, Globals::default());
        self.derived = derived;
        Ok(())
    }

    fn save(&mut self) -> Result<(), BackendError> {
        for (f, s) in self.plan.saved.clone() {
            let (Some(src), Some(_)) = (self.store.column(f).cloned(), self.store.column(s)) else { continue };
            let n = self.store.n;
            let group = self.store.group.clone();
            let dst = self.store.column_mut(s).expect("checked");
            for (i, g) in group.iter().enumerate().take(n) {
                let g = *g as usize;
                if !src.has(g) || !dst.has(g) {
                    continue;
                }
                let (a, b) = (src.row(i, g), dst.row(i, g));
                dst.data[b * dst.comps..(b + 1) * dst.comps]
                    .copy_from_slice(&src.data[a * src.comps..(a + 1) * src.comps]);
            }
        }
        Ok(())
    }

    fn evaluate(&mut self, g: Globals) -> Result<(), BackendError> {
        let search = self.search()?;
        for k in 0..self.passes.len() {
            self.run_pass(k, g, &search);
        }
        Ok(())
    }

    fn reductions(&mut self, g: Globals) -> Result<Vec<f64>, BackendError> {
        let n = self.n_reductions;
        if n == 0 {
            return Ok(vec![]);
        }
        let reds = timestep::reductions(&self.plan.model, &self.plan.timesteps);
        let identity: Vec<f64> = reds.iter().map(|(r, _)| r.identity()).collect();
        let cols = views(&mut self.store);
        let sh = Shared::of(&self.store, &cols, g);
        let programs = &self.reductions;
        // Per chunk partial results, combined in chunk order: the same on any thread count.
        let partials: Vec<Vec<f64>> = self
            .chunks
            .par_iter()
            .map_init(Scratch::default, |scratch, chunk| {
                let mut acc = identity.clone();
                if let Some(p) = &programs[chunk.group] {
                    exec::run_reduction(p, &sh, scratch, *chunk, &mut acc);
                }
                acc
            })
            .collect();
        let mut out = identity.clone();
        for p in partials {
            for (k, (r, _)) in reds.iter().enumerate() {
                out[k] = match r {
                    Reduce::Sum => out[k] + p[k],
                    Reduce::Min => out[k].min(p[k]),
                    Reduce::Max => out[k].max(p[k]),
                };
            }
        }
        Ok(out)
    }

    fn update(&mut self, stage: usize, g: Globals) -> Result<(), BackendError> {
        let programs = std::mem::take(&mut self.stages[stage]);
        self.run_programs(&programs, g);
        self.stages[stage] = programs;
        Ok(())
    }

    fn reorder(&mut self) -> Result<(), BackendError> {
        let dim = self.plan.dim;
        let h_max = self.h_max();
        if h_max <= 0.0 {
            return Ok(());
        }
        let cell = self.support * h_max;
        let mut perm: Vec<u32> = Vec::with_capacity(self.store.n);
        for (_, r) in self.store.ranges.clone() {
            let x = &self.positions()[r.start * dim..r.end * dim];
            perm.extend(morton_permutation(x, dim, cell).into_iter().map(|p| p + r.start as u32));
        }
        self.store.permute(&perm);
        self.lists.permute(&perm);
        Ok(())
    }

    fn read(&self, f: FieldId) -> Result<Option<(usize, Vec<f64>)>, BackendError> {
        Ok(self.store.read_f64(f))
    }

    fn ids(&self) -> Result<Vec<u32>, BackendError> {
        Ok(self.store.id.clone())
    }

    fn groups(&self) -> Vec<u32> {
        self.store.group.clone()
    }

    fn snapshot(&self) -> Result<Snapshot, BackendError> {
        Ok(snapshot_of(&self.store))
    }

    fn restore(&mut self, s: &Snapshot) -> Result<(), BackendError> {
        for (c, d) in self.store.columns.iter_mut().zip(&s.columns) {
            if let (Some(c), Some(d)) = (c.as_mut(), d) {
                for (x, v) in c.data.iter_mut().zip(d) {
                    *x = T::from_f64(*v);
                }
            }
        }
        self.store.id = s.id.clone();
        self.store.material = s.material.clone();
        self.lists.invalidate();
        Ok(())
    }

    fn keep(&mut self) -> Result<(), BackendError> {
        let kept = self.kept.get_or_insert_with(Kept::default);
        kept.columns.resize(self.store.columns.len(), None);
        for (k, c) in kept.columns.iter_mut().zip(&self.store.columns) {
            match (k, c) {
                (Some(k), Some(c)) => k.clone_from(&c.data),
                (k, c) => *k = c.as_ref().map(|c| c.data.clone()),
            }
        }
        kept.id.clone_from(&self.store.id);
        kept.material.clone_from(&self.store.material);
        Ok(())
    }

    fn kept(&self) -> Result<Snapshot, BackendError> {
        let kept = self.kept.as_ref().ok_or_else(|| BackendError("no state was kept".into()))?;
        Ok(Snapshot {
            columns: kept.columns.iter().map(|c| c.as_ref().map(|c| c.iter().map(|v| v.to_f64()).collect())).collect(),
            id: kept.id.clone(),
            material: kept.material.clone(),
        })
    }

    fn restore_kept(&mut self) -> Result<(), BackendError> {
        let kept = self.kept.as_ref().ok_or_else(|| BackendError("no state was kept".into()))?;
        for (c, k) in self.store.columns.iter_mut().zip(&kept.columns) {
            if let (Some(c), Some(k)) = (c.as_mut(), k) {
                c.data.copy_from_slice(k);
            }
        }
        self.store.id.clone_from(&kept.id);
        self.store.material.clone_from(&kept.material);
        self.lists.invalidate();
        Ok(())
    }

    fn search_stats(&self) -> crate::schedule::SearchStats {
        self.lists.stats
    }

    fn first_non_finite(&mut self, fields: &[FieldId]) -> Result<Option<(usize, FieldId)>, BackendError> {
        Ok(first_non_finite_in(&self.store, fields))
    }
}

/// The store's columns, ids and materials as f64.
pub fn snapshot_of<T: Real>(store: &Store<T>) -> Snapshot {
    Snapshot {
        columns: store
            .columns
            .iter()
            .map(|c| c.as_ref().map(|c| c.data.iter().map(|v| v.to_f64()).collect()))
            .collect(),
        id: store.id.clone(),
        material: store.material.clone(),
    }
}

/// The first particle (in store order) with a non-finite value in one of `fields`, and that field.
pub fn first_non_finite_in<T: Real>(store: &Store<T>, fields: &[FieldId]) -> Option<(usize, FieldId)> {
    let mut best: Option<(usize, FieldId)> = None;
    for f in fields {
        let Some(c) = store.column(*f) else { continue };
        for i in 0..store.n {
            let g = store.group[i] as usize;
            if !c.has(g) {
                continue;
            }
            let row = c.row(i, g);
            if c.data[row * c.comps..(row + 1) * c.comps].iter().any(|v| !v.is_finite()) {
                if best.is_none_or(|(b, _)| i < b) {
                    best = Some((i, *f));
                }
                break;
            }
        }
    }
    best
}

/// Lanes per batch, for reports.
pub const BATCH_LANES: usize = LANES;
