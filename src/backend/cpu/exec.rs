//! Running compiled programs over the particle store: chunks of particles in parallel (rayon),
//! each particle gathering its neighbours in batches from the cell list (gather only: a chunk
//! writes the rows of its own particles and nothing else).

use super::lists::{beyond_reach, shifts, transformed, INDEX_MASK, TRANSFORM_SHIFT};
use super::program::{ColView, Ctx, Program, LANES};
use super::{Mirror, PairRegs, Variant};
use crate::grid::{Level, SizeLevels};
use crate::ir::Reduce;
use crate::particles::{Real, Store};

/// Lanes past a batch's last that native code may read or write: up to one iteration of the C
/// code's loop, at most four vectors of the fold period (the most lanes are f32's).
pub const OVERRUN: usize = 4 * super::jit::FOLD_BYTES / std::mem::size_of::<f32>();

/// A chunk of consecutive particles of one group.
#[derive(Clone, Copy, Debug)]
pub struct Chunk {
    pub group: usize,
    pub start: usize,
    pub len: usize,
}

pub fn chunks<T>(store: &Store<T>) -> Vec<Chunk> {
    let mut out = vec![];
    for (g, r) in &store.ranges {
        let mut s = r.start;
        while s < r.end {
            let len = (r.end - s).min(LANES);
            out.push(Chunk { group: g.index(), start: s, len });
            s += len;
        }
    }
    out
}

/// Raw views of every stored column.
pub fn views<T: Real>(store: &mut Store<T>) -> Vec<Option<ColView<T>>> {
    let ranges = store.ranges.len();
    store
        .columns
        .iter_mut()
        .map(|c| {
            c.as_mut().map(|c| {
                let present: Vec<isize> = c.base.iter().copied().filter(|b| *b != crate::particles::ABSENT).collect();
                let shared = present.first().copied().filter(|b| present.iter().all(|x| x == b));
                let uniform = shared.filter(|_| present.len() == ranges);
                ColView { ptr: c.data.as_mut_ptr(), comps: c.comps, base: c.base.clone(), uniform, shared }
            })
        })
        .collect()
}

/// Per-thread working memory.
#[derive(Default)]
pub struct Scratch<T> {
    pub a: Vec<T>,
    pub b: Vec<T>,
    pub c: Vec<T>,
    pub j: Vec<u32>,
    pub sign: Vec<T>,
    pub slots: Vec<T>,
    /// Kahan compensation of each slot.
    pub comp: Vec<T>,
    pub temps: Vec<Vec<T>>,
    pub ranges: Vec<(u32, u32)>,
}

fn frame<'a, T: Real>(buf: &'a mut Vec<T>, p: &Program<T>) -> &'a mut [T] {
    // Native code runs whole vectors from a particle's first lane, so it may touch up to
    // `OVERRUN` lanes past the last: frames, neighbour and sign lanes carry that padding.
    let len = p.n_regs.max(1) * LANES + OVERRUN;
    if buf.len() < len {
        buf.resize(len, T::zero());
    }
    p.fill_consts(&mut buf[..len]);
    &mut buf[..len]
}

/// Writes a program's stores for the lanes of a chunk.
pub fn write_stores<T: Real>(
    p: &Program<T>,
    regs: &[T],
    cols: &[Option<ColView<T>>],
    temps: &[Option<ColView<T>>],
    chunk: Chunk,
) {
    for s in &p.stores {
        let view = if s.temp { &temps[s.field.index()] } else { &cols[s.field.index()] };
        let Some(c) = view else { continue };
        let values = &regs[s.reg * LANES..s.reg * LANES + chunk.len];
        if s.temp {
            for (k, v) in values.iter().enumerate() {
                // SAFETY: the chunk's temp buffer has LANES rows.
                unsafe { *c.ptr.add(k * c.comps + s.comp) = *v };
            }
            continue;
        }
        let base = c.base[chunk.group];
        if base == crate::particles::ABSENT {
            continue;
        }
        let start = (chunk.start as isize + base) as usize;
        for (k, v) in values.iter().enumerate() {
            // SAFETY: rows of this chunk's particles; no other chunk writes them.
            unsafe { *c.ptr.add((start + k) * c.comps + s.comp) = *v };
        }
    }
}

pub struct Shared<'a, T> {
    pub cols: &'a [Option<ColView<T>>],
    /// Bit g: group g has particles in the store (a pass that sums over all of them skips the
    /// group test).
    pub groups_present: u64,
    pub params: &'a [T],
    pub param_stride: usize,
    pub param_offset: &'a [usize],
    pub group: &'a [u32],
    pub material: &'a [u32],
    pub time: T,
    pub dt: T,
}

impl<'a, T: Real> Shared<'a, T> {
    /// What the programs over `store` read besides their lanes, at the clock `g`; `cols` are the
    /// store's column views.
    pub fn of(store: &'a Store<T>, cols: &'a [Option<ColView<T>>], g: crate::backend::Globals) -> Shared<'a, T> {
        Shared {
            groups_present: store.ranges.iter().fold(0, |m, (g, _)| m | 1 << g.index()),
            cols,
            params: &store.params.values,
            param_stride: store.params.stride,
            param_offset: &store.params.offset,
            group: &store.group,
            material: &store.material,
            time: T::from_f64(g.time),
            dt: T::from_f64(g.dt),
        }
    }

    pub fn ctx(
        &self,
        temps: &'a [Option<ColView<T>>],
        chunk: Chunk,
        j: &'a [u32],
        sign: &'a [T],
        n: usize,
    ) -> Ctx<'a, T> {
        Ctx {
            cols: self.cols,
            temps,
            params: self.params,
            param_stride: self.param_stride,
            param_offset: self.param_offset,
            group: self.group,
            material: self.material,
            time: self.time,
            dt: self.dt,
            i0: chunk.start,
            g: chunk.group,
            j,
            sign,
            n,
        }
    }
}

/// Runs a particle program (an update, a tail) over one chunk and writes its stores.
pub fn run_particle<T: Real>(p: &Program<T>, sh: &Shared<T>, scratch: &mut Scratch<T>, chunk: Chunk) {
    let no_temps: Vec<Option<ColView<T>>> = vec![];
    let regs = frame(&mut scratch.a, p);
    let ctx = sh.ctx(&no_temps, chunk, &[], &[], chunk.len);
    p.run(regs, &ctx);
    write_stores(p, regs, sh.cols, &no_temps, chunk);
}

/// Runs a particle program's reductions over one chunk.
pub fn run_reduction<T: Real>(p: &Program<T>, sh: &Shared<T>, scratch: &mut Scratch<T>, chunk: Chunk, acc: &mut [f64]) {
    let regs = frame(&mut scratch.a, p);
    let ctx = sh.ctx(&[], chunk, &[], &[], chunk.len);
    p.run(regs, &ctx);
    for (index, reduce, reg) in &p.reduces {
        for v in &regs[reg * LANES..reg * LANES + chunk.len] {
            acc[*index] = fold(*reduce, acc[*index], v.to_f64());
        }
    }
}

fn fold(r: Reduce, a: f64, b: f64) -> f64 {
    match r {
        Reduce::Sum => a + b,
        Reduce::Min => a.min(b),
        Reduce::Max => a.max(b),
    }
}

/// Kahan summation: `sum` carries the total, `c` the low-order part lost so far.
#[inline(always)]
fn kahan<T: Real>(sum: &mut T, c: &mut T, lanes: &[T]) {
    for x in lanes {
        let y = *x - *c;
        let t = *sum + y;
        *c = (t - *sum) - y;
        *sum = t;
    }
}

/// What the neighbour batches of one pass need.
pub struct Neighbours<'a, T> {
    pub x: &'a [T],
    pub h: &'a [T],
    pub dim: usize,
    pub support: T,
    /// Per particle, an upper bound on the smoothing length of every particle within the largest
    /// cut-off of it (`Grid::nearby_max`): its search reaches support · (h_i + h_near_i)/2. Empty
    /// when the walk follows kept lists.
    pub h_near: &'a [f64],
    /// The largest smoothing length: what bounds the neighbours of an image across a periodic
    /// side.
    pub h_max: f64,
    pub mirrors: &'a [Mirror],
    pub walk: Walk<'a>,
    /// The walk in C, where a C compiler answers (else the scalar walk).
    pub c_walk: Option<super::cwalk::WalkFn<T>>,
}

/// Where a pass finds the candidates of a particle.
#[derive(Clone, Copy)]
pub enum Walk<'a> {
    /// The cells its cut-off reaches, in the grid of each particle size near it.
    Cells(&'a SizeLevels),
    /// Its kept list.
    Lists(&'a [Vec<u32>]),
}

/// One pass variant over one chunk: accumulator initial values and particle-i values, the
/// neighbour loop of every particle in batches, then the tail.
pub fn run_pass_chunk<T: Real>(
    v: &Variant<T>,
    sh: &Shared<T>,
    nb: &Neighbours<T>,
    scratch: &mut Scratch<T>,
    chunk: Chunk,
) {
    // Temp accumulators live in chunk-local buffers.
    scratch.temps.resize(v.temps.len(), vec![]);
    let mut temp_views: Vec<Option<ColView<T>>> = vec![None; sh.cols.len()];
    for (k, (f, comps)) in v.temps.iter().enumerate() {
        let buf = &mut scratch.temps[k];
        buf.resize(LANES * comps, T::zero());
        temp_views[f.index()] =
            Some(ColView { ptr: buf.as_mut_ptr(), comps: *comps, base: vec![], uniform: None, shared: None });
    }
    let Scratch { a, b, c, j, sign, slots, comp, ranges, .. } = scratch;
    let init_regs: &mut [T] = match &v.init {
        Some(p) => {
            let regs = frame(a, p);
            p.run(regs, &sh.ctx(&temp_views, chunk, &[], &[], chunk.len));
            regs
        }
        None => &mut [],
    };
    let dest = frame(b, &v.dest);
    v.dest.run(dest, &sh.ctx(&temp_views, chunk, &[], &[], chunk.len));
    let pair = frame(c, &v.pair);
    j.resize(LANES + OVERRUN, 0);
    let with_sign = !nb.mirrors.is_empty();
    sign.resize(if with_sign { 3 * LANES + OVERRUN } else { 0 }, T::one());
    let ns = v.slots.len();
    slots.resize(ns * chunk.len, T::zero());
    comp.clear();
    comp.resize(ns * chunk.len, T::zero());
    for k in 0..chunk.len {
        for (s, slot) in v.slots.iter().enumerate() {
            slots[k * ns + s] = match slot.init_reg {
                Some(r) => init_regs[r * LANES + k],
                None => T::from_f64(slot.reduce.identity()),
            };
        }
    }
    // Lanes hold the neighbours of several particles of the chunk one after another, so that the
    // cost of running an operation is shared by more pairs; `segs` marks whose lanes are whose.
    let all_sources = sh.groups_present & !v.sources == 0;
    let jit_cols = v.jit.as_ref().and_then(|jit| gathered_columns(&jit.gathers, sh.cols));
    let mut w = Writer {
        jit_cols: jit_cols.as_deref(),
        v,
        sh,
        temps: &temp_views,
        chunk,
        pair,
        dest,
        j,
        sign,
        with_sign,
        slots,
        comp,
        n: 0,
        segs: vec![],
        k: 0,
    };
    for k in 0..chunk.len {
        w.k = k;
        w.segs.push((k, w.n));
        let i = chunk.start + k;
        match (nb.dim, nb.walk) {
            (1, Walk::Lists(l)) => listed_neighbours_of::<T, 1>(&mut w, nb, i, &l[i], !all_sources),
            (2, Walk::Lists(l)) => listed_neighbours_of::<T, 2>(&mut w, nb, i, &l[i], !all_sources),
            (_, Walk::Lists(l)) => listed_neighbours_of::<T, 3>(&mut w, nb, i, &l[i], !all_sources),
            (1, Walk::Cells(g)) => neighbours_of::<T, 1>(&mut w, nb, g, i, ranges, !all_sources),
            (2, Walk::Cells(g)) => neighbours_of::<T, 2>(&mut w, nb, g, i, ranges, !all_sources),
            (_, Walk::Cells(g)) => neighbours_of::<T, 3>(&mut w, nb, g, i, ranges, !all_sources),
        }
    }
    if w.n > 0 {
        w.flush();
    }
    let slots = w.slots;
    // Accumulators to their rows (stored fields) or the chunk's temp rows.
    for k in 0..chunk.len {
        let i = chunk.start + k;
        for (s, slot) in v.slots.iter().enumerate() {
            let view = if slot.temp { &temp_views[slot.field.index()] } else { &sh.cols[slot.field.index()] };
            let Some(col) = view else { continue };
            let row = if slot.temp {
                k
            } else {
                let base = col.base[chunk.group];
                if base == crate::particles::ABSENT {
                    continue;
                }
                (i as isize + base) as usize
            };
            // SAFETY: particle i's row (or the chunk's temp row k): written only by this chunk.
            unsafe { *col.ptr.add(row * col.comps + slot.comp) = slots[k * ns + s] };
        }
    }
    if let Some(tail) = &v.tail {
        let regs = frame(a, tail);
        tail.run(regs, &sh.ctx(&temp_views, chunk, &[], &[], chunk.len));
        write_stores(tail, regs, sh.cols, &temp_views, chunk);
    }
}

/// Fills the lanes of a batch with neighbours and runs the pair program when it is full.
struct Writer<'a, 'b, T> {
    v: &'a Variant<T>,
    sh: &'a Shared<'b, T>,
    temps: &'a [Option<ColView<T>>],
    chunk: Chunk,
    pair: &'a mut [T],
    dest: &'a [T],
    j: &'a mut Vec<u32>,
    sign: &'a mut Vec<T>,
    with_sign: bool,
    /// Row 0 of each column the native pair program gathers (None: run the closures).
    jit_cols: Option<&'a [*const T]>,
    slots: &'a mut Vec<T>,
    comp: &'a mut Vec<T>,
    /// Lanes filled, and where each particle's lanes start: (particle in chunk, first lane).
    n: usize,
    segs: Vec<(usize, usize)>,
    /// The particle whose neighbours are being added.
    k: usize,
}

impl<T: Real> Writer<'_, '_, T> {
    /// Writes a candidate (j, or with `flip` an image of j) into the next lane and keeps it only
    /// if `keep`: a branch-free push, since whether a candidate is a neighbour is too random to
    /// predict (about half are rejected).
    #[inline(always)]
    fn offer<const D: usize>(&mut self, j: u32, dx: [T; 3], r2: T, h: T, flip: [bool; 3], keep: bool) {
        let n = self.n;
        let PairRegs { x, r: rr, h: hr } = self.v.pair_regs;
        for (c, v) in dx.iter().enumerate().take(D) {
            self.pair[(x + c) * LANES + n] = *v;
        }
        self.pair[rr * LANES + n] = r2.sqrt();
        self.pair[hr * LANES + n] = h;
        self.j[n] = j;
        if self.with_sign {
            // Every lane gets its signs: it may hold an earlier image's.
            for (c, f) in flip.iter().enumerate() {
                self.sign[c * LANES + n] = if *f { -T::one() } else { T::one() };
            }
        }
        self.n += keep as usize;
        if self.n == LANES {
            self.flush();
            self.segs.push((self.k, 0));
        }
    }

    /// Adds the candidates `list` names (of one image transform: `yi` and `flip`) by the walk in
    /// C, flushing the batch whenever it is full, as [`offer`](Self::offer) does.
    #[allow(clippy::too_many_arguments)]
    fn walk_in_c(
        &mut self,
        walk: super::cwalk::WalkFn<T>,
        nb: &Neighbours<T>,
        list: &[u32],
        yi: [T; 3],
        flip: [bool; 3],
        hi: T,
        sources: u64,
    ) {
        let PairRegs { x, r, h } = self.v.pair_regs;
        let flip = flip.map(|f| if f { -T::one() } else { T::one() });
        let sign = if self.with_sign { self.sign.as_mut_ptr() } else { std::ptr::null_mut() };
        let mut at = 0;
        while at < list.len() {
            let mut n = self.n;
            // SAFETY: the walk reads the candidates list[at..], the rows of x and h they name
            // (particles of the store, as `nb.x`, `nb.h` and `group` hold), yi and flip (three
            // each), and writes lanes n.. of the batch below LANES only: registers x..x + D, r and h
            // of the pair frame (each LANES lanes of it), j (LANES + OVERRUN long) and, with
            // mirrors, the three sign registers.
            let taken = unsafe {
                walk(
                    list[at..].as_ptr(),
                    list.len() - at,
                    nb.x.as_ptr(),
                    nb.h.as_ptr(),
                    self.sh.group.as_ptr(),
                    sources,
                    yi.as_ptr(),
                    flip.as_ptr(),
                    hi,
                    nb.support,
                    self.pair.as_mut_ptr(),
                    x,
                    r,
                    h,
                    self.j.as_mut_ptr(),
                    sign,
                    &mut n,
                )
            };
            (self.n, at) = (n, at + taken);
            if self.n == LANES {
                self.flush();
                self.segs.push((self.k, 0));
            }
        }
    }

    /// Runs the pair program over the batch and folds every particle's lanes into its
    /// accumulators: natively, one call per particle (which loads the particle's own values and
    /// folds its sums itself), or by closures over the whole batch, each particle's own values
    /// broadcast over its lanes first.
    fn flush(&mut self) {
        let (n, v) = (self.n, self.v);
        let ns = v.slots.len();
        let segs = std::mem::take(&mut self.segs);
        let seg_end = |q: usize| segs.get(q + 1).map(|s| s.1).unwrap_or(n);
        let sign: &[T] = if self.with_sign { self.sign } else { &[] };
        let native = match (&v.jit, self.jit_cols) {
            (Some(jit), Some(cols)) => {
                let sh = self.sh;
                let world = super::jit::World {
                    group: sh.group,
                    material: sh.material,
                    params: sh.params,
                    time: sh.time,
                    dt: sh.dt,
                };
                // The last vector may read up to OVERRUN lanes past the batch, where an earlier
                // pass may have left a particle of a group that does not store a gathered
                // column (or the 0 they start with): its row would lie outside the column. The
                // batch's last neighbour is a row of every column the pass gathers.
                let last = self.j[n - 1];
                self.j[n..n + OVERRUN].fill(last);
                debug_assert!(
                    self.j[..n + OVERRUN].iter().all(|&j| v.sources >> sh.group[j as usize] & 1 == 1),
                    "a lane the native code reads holds a particle the pass does not sum over"
                );
                for (q, &(k, start)) in segs.iter().enumerate() {
                    let end = seg_end(q);
                    if end > start {
                        let slots = &mut self.slots[k * ns..(k + 1) * ns];
                        let dest = self.dest[k..].as_ptr();
                        // SAFETY: the frame is the pair program's (padded for whole vectors); j
                        // holds LANES + padding rows of every gathered column (the lanes past the
                        // batch repeat its last neighbour); the sign lanes exist whenever the case has
                        // mirrors, which is when the program reads them; `dest` is lane k of the
                        // dest frame, which holds every broadcast register; `slots` are k's.
                        unsafe { jit.run(self.pair, self.j, cols, start..end, sign.as_ptr(), &world, dest, slots) }
                    }
                }
                true
            }
            _ => {
                for (u, r) in &v.exports {
                    for (q, &(k, start)) in segs.iter().enumerate() {
                        self.pair[r * LANES + start..r * LANES + seg_end(q)].fill(self.dest[u * LANES + k]);
                    }
                }
                let ctx = self.sh.ctx(self.temps, self.chunk, self.j, sign, n);
                v.pair.run(self.pair, &ctx);
                false
            }
        };
        for (a, s) in v.pair.accums.iter().zip(&v.accum_slot) {
            let compensated = v.slots[*s].compensated;
            if native && !compensated {
                continue; // folded by the native code
            }
            for (q, &(k, start)) in segs.iter().enumerate() {
                let end = seg_end(q);
                if end > start {
                    let lanes = &self.pair[a.reg * LANES + start..a.reg * LANES + end];
                    let slot = &mut self.slots[k * ns + s];
                    if compensated {
                        kahan(slot, &mut self.comp[k * ns + s], lanes);
                    } else {
                        *slot = super::jit::fold_partials(a.reduce, *slot, lanes);
                    }
                }
            }
        }
        self.n = 0;
        self.segs = segs;
        self.segs.clear();
    }
}

/// Row 0 of each gathered column, when every one is stored with one base on all the groups that
/// store it (the native code reads zeros for a neighbour of another group).
pub fn gathered_columns<T>(fields: &[crate::ir::FieldId], cols: &[Option<ColView<T>>]) -> Option<Vec<*const T>> {
    fields
        .iter()
        .map(|f| {
            let c = cols[f.index()].as_ref()?;
            Some(c.ptr.wrapping_offset(c.shared? * c.comps as isize) as *const T)
        })
        .collect()
}

/// Adds the neighbours of particle i (and of its mirror images) to the batch: x_ij, r_ij, h_ij.
#[inline(always)]
fn neighbours_of<T: Real, const D: usize>(
    w: &mut Writer<T>,
    nb: &Neighbours<T>,
    levels: &SizeLevels,
    i: usize,
    ranges: &mut Vec<(u32, u32)>,
    filter: bool,
) {
    let mut xi = [T::zero(); 3];
    xi[..D].copy_from_slice(&nb.x[i * D..i * D + D]);
    let hi = nb.h[i];
    let group = w.sh.group;
    let sources = w.v.sources;
    // No neighbour of i, nor of its images (a reflection only moves i away from the particles on
    // the planes' positive side), has a smoothing length above h_near.
    for t in 0..1u32 << nb.mirrors.len() {
        // Across a periodic side the neighbours are not near i: any h may be among them.
        let h_near = if shifts(t, nb.mirrors) { nb.h_max } else { nb.h_near[i] };
        // Transform t reflects or moves particle i across the planes whose bit is set.
        if beyond_reach(xi, t, nb.mirrors, nb.support.to_f64() * h_near) {
            continue;
        }
        let (yi, flip) = transformed(xi, t, nb.mirrors);
        let mut p = [0.0; 3];
        for c in 0..D {
            p[c] = yi[c].to_f64();
        }
        // h_ij ≤ (h_i + min(h_hi, h_near))/2: no neighbour lies beyond support · that.
        let reach = |level: &Level| level.reach(nb.support.to_f64(), hi.to_f64(), h_near, 0.0);
        if let Some(walk) = nb.c_walk {
            // Particle i itself is at distance 0: the walk never keeps it.
            let sources = if filter { sources } else { u64::MAX };
            levels.for_each_candidate_run(p, reach, ranges, |run| w.walk_in_c(walk, nb, run, yi, flip, hi, sources));
            continue;
        }
        levels.for_each_candidate(p, reach, ranges, |jj| {
            let jj = jj as usize;
            if (t != 0 || jj != i) && (!filter || (sources >> group[jj]) & 1 != 0) {
                offer_candidate::<T, D>(w, nb, yi, flip, hi, jj);
            }
        });
    }
}

/// Adds the neighbours of particle i from its kept list: the entries within the current cut-off.
#[inline(always)]
fn listed_neighbours_of<T: Real, const D: usize>(
    w: &mut Writer<T>,
    nb: &Neighbours<T>,
    i: usize,
    list: &[u32],
    filter: bool,
) {
    let mut xi = [T::zero(); 3];
    xi[..D].copy_from_slice(&nb.x[i * D..i * D + D]);
    let hi = nb.h[i];
    let group = w.sh.group;
    let sources = w.v.sources;
    if let Some(walk) = nb.c_walk {
        let sources = if filter { sources } else { u64::MAX };
        let mut at = 0;
        while at < list.len() {
            // Entries come grouped by transform: one run of each.
            let t = list[at] >> TRANSFORM_SHIFT;
            let run = list[at..].iter().position(|e| e >> TRANSFORM_SHIFT != t).unwrap_or(list.len() - at);
            let (yi, flip) = transformed(xi, t, nb.mirrors);
            w.walk_in_c(walk, nb, &list[at..at + run], yi, flip, hi, sources);
            at += run;
        }
        return;
    }
    let (mut t, (mut yi, mut flip)) = (0u32, (xi, [false; 3]));
    for &e in list {
        let jj = (e & INDEX_MASK) as usize;
        if e >> TRANSFORM_SHIFT != t {
            // Entries come grouped by transform: this changes a few times per list at most.
            t = e >> TRANSFORM_SHIFT;
            (yi, flip) = transformed(xi, t, nb.mirrors);
        }
        if filter && (sources >> group[jj]) & 1 == 0 {
            continue;
        }
        offer_candidate::<T, D>(w, nb, yi, flip, hi, jj);
    }
}

/// Offers neighbour j (or its image, with `flip`) of the point `yi` (particle i or its reflection)
/// to the batch: x_ij, r_ij, h_ij, kept when within the cut-off.
#[inline(always)]
fn offer_candidate<T: Real, const D: usize>(
    w: &mut Writer<T>,
    nb: &Neighbours<T>,
    yi: [T; 3],
    flip: [bool; 3],
    hi: T,
    jj: usize,
) {
    let xj = &nb.x[jj * D..jj * D + D];
    let mut r2 = T::zero();
    let mut dx = [T::zero(); 3];
    for c in 0..D {
        let diff = yi[c] - xj[c];
        // x_ij = x_i − (image of x_j): the reflection of (y_i − x_j) on the flipped axes.
        dx[c] = if flip[c] { -diff } else { diff };
        r2 = r2 + diff * diff;
    }
    let hij = (hi + nb.h[jj]) * T::from_f64(0.5);
    let rc = nb.support * hij;
    let inside = r2 < rc * rc && r2 != T::zero();
    w.offer::<D>(jj as u32, dx, r2, hij, flip, inside);
}
