//! A run split into domains (issue 42): one rank's share of it. The particles are cut into boxes
//! by recursive coordinate bisection (`grid::decompose`); a rank runs a CPU backend over the
//! particles in its box (its own) and copies of the others' particles within reach of them (its
//! halo), its neighbour passes on its own GPU where it has one (`on_gpu`, `gpu::share`). Each
//! evaluation starts by sending every particle that left the box to the rank whose box it
//! entered, with its whole state (migration), and by rebuilding the halos, whose copies carry
//! only the fields some pass reads at j (the rest of a particle's state is never read there);
//! before each later
//! pass, a halo receives the fields that pass reads at j and an earlier pass of the evaluation
//! wrote (`Plan::fields_read_at_j`). The passes, updates and reductions run over a rank's own
//! particles only; the time step, the fields the engine and the runner read, the watchdog's
//! checks and the last good state are global, so every rank takes the same decisions.
//!
//! Every exchange goes through a [`Transport`] and is collective: every rank makes the same calls
//! in the same order. What travels is counted in [`Traffic`].

use super::cpu::lists::{half_period, KeptList, TRANSFORM_SHIFT};
use super::cpu::{first_non_finite_in, known, lower::Known, snapshot_of, CpuBackend};
use super::gpu::{device::Gpu, share::DevicePasses};
use super::transport::Transport;
use super::{padded, Backend, BackendError, Globals, Mirror, Nearby, Snapshot, WatchValues};
use crate::compare::largest_number;
use crate::engine::watchdog::{gravity, Motion};
use crate::grid::decompose::{bisect_with_cuts, Cuts};
use crate::ir::{FieldId, Reduce};
use crate::particles::{ParamTable, Real, Store};
use crate::scene::max_keeping_nan;
use crate::schedule::{search::Search as Lists, Plan};
use std::collections::{HashMap, HashSet};
use std::sync::Mutex;

/// What a rank sent to the others, in bytes of the run's precision.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Traffic {
    /// Whole particles that changed domain.
    pub migration: u64,
    /// Particles copied into halos when they were rebuilt (the fields some pass reads at j), and
    /// the ids the adaptive search's lists asked the other ranks for.
    pub halo_builds: u64,
    /// Fields sent to halos before a pass.
    pub halo_updates: u64,
    /// Rebuilds of the halos (with migration).
    pub rebuilds: u64,
    /// Particles in the halo at the last rebuild.
    pub halo_particles: usize,
    /// New cuts, where the ranks' measured work had drifted apart.
    pub rebalances: u64,
    /// The largest rank's neighbour-pass time over the ranks' mean, at the last check.
    pub imbalance: f64,
    /// The halo's skin at the last rebuild, as a fraction of the largest cut-off.
    pub skin: f64,
    /// Seconds this rank spent rebuilding and updating its halos.
    pub halo_secs: f64,
}

/// A particle: one in a store here, or one that travelled as its group, material and id, then
/// the fields it carries of those its group stores, in the plan's layout order: every one for a
/// particle that changed rank (`Sent`), those a pass reads at j for a halo's copy (`Halo`).
#[derive(Clone)]
enum Row<'a, T> {
    Here(&'a Store<T>, usize),
    Sent(&'a [f64]),
    Halo(&'a [f64]),
}

/// The adaptive search's lists of this rank's own particles, by id, while the particles move to
/// another store (the run in one piece keeps them from their last rebuild, so a split run must
/// carry them, not rebuild them, when particles change rank or the halo changes).
struct Carried {
    /// The lists' skin's length at their full build (every rank's alike).
    skin_len: f64,
    lists: HashMap<u32, KeptList>,
}

/// Where this rank's own particles were at the last rebuild of the halos.
struct Anchor {
    x: Vec<[f64; 3]>,
    h: Vec<f64>,
    skin: f64,
    /// The halo held every particle within this distance of one of the rank's own.
    reach: f64,
    /// The largest cut-off then.
    cut_off: f64,
}

/// The ranks are cut again when the slowest rank's neighbour-pass time exceeds the ranks' mean by
/// this factor (checked where particles are reordered, every `reorder_every` steps).
const REBALANCE_AT: f64 = 1.1;

/// The halo's skin, as a fraction of the largest cut-off, where the plan's search keeps no lists
/// (lists bring their own), until it is fitted to the particles' speed ([`SkinFit`]).
const HALO_SKIN: f64 = 0.1;

/// The fitted skin's bounds, as fractions of the largest cut-off.
const SKIN_BOUNDS: (f64, f64) = (0.02, 1.0);

/// The halo's skin fitted to the fastest particle, where the plan's search keeps no lists of its
/// own (the cell list; the adaptive search's skin beyond its reserve). A skin s keeps the halos
/// for s / 2d evaluations, d the fastest particle's displacement per evaluation. An evaluation's
/// halo updates take about A (r + s), r the cut-off (they scale with the halo's depth), and a
/// rebuild B more than an evaluation without one (the store rebuilt, the collectives), so that
/// the halos cost A (r + s) + B 2d / s per evaluation, least at
///   s = √(2 d B / A),
/// fitted whenever the halos are dropped, from that interval's d and the slowest rank's times.
/// An interval that rebuilt at every evaluation measured no A: the skin then doubles. The
/// hypervelocity impact on two ranks rebuilt its halos at each of its 643 steps with the fixed
/// tenth of the cut-off. Like the cuts that follow the measured work, the skin follows measured
/// times, so a split run repeats its figures within rounding, not bit for bit;
/// `PAIRSUM_HALO_SKIN` fixes the skin. The updates' time includes any wait for a slower rank's
/// pass, which A then overstates: where the ranks' work differs, the skin is thinner than best.
#[derive(Default)]
struct SkinFit {
    /// False where the skin is the kept lists' own or `PAIRSUM_HALO_SKIN` fixes it.
    on: bool,
    /// Evaluations since the last rebuild, the rebuild's included.
    evaluations: u64,
    /// Seconds of the last rebuild and of the halo updates of its evaluation.
    rebuild_secs: f64,
    /// Seconds of the halo updates of the evaluations since then that did not rebuild.
    update_secs: f64,
}

impl SkinFit {
    /// The skin, as a fraction of the cut-off, after an interval in which the fastest particle
    /// moved `d_over_r` of the cut-off, with `skin` that fraction then and `times` the slowest
    /// rank's halo seconds [in the rebuild's evaluation, in each other one on average].
    fn fraction(&self, skin: f64, d_over_r: f64, times: [f64; 2]) -> f64 {
        let plain = self.evaluations.saturating_sub(1);
        let f = if plain == 0 {
            2.0 * skin
        } else {
            let (b, a) = ((times[0] - times[1]).max(0.0), times[1] / (1.0 + skin));
            (2.0 * d_over_r / self.evaluations as f64 * b / a).sqrt()
        };
        if f.is_finite() {
            f.clamp(SKIN_BOUNDS.0, SKIN_BOUNDS.1)
        } else {
            skin
        }
    }
}

/// Every combination of no move and a move by ± the period along each periodic axis of
/// `mirrors` (`[0, 0, 0]` alone where none is periodic).
fn periodic_moves(mirrors: &[Mirror]) -> Vec<[f64; 3]> {
    let mut moves = vec![[0.0; 3]];
    for m in mirrors.iter().filter(|m| m.shift > 0.0) {
        moves = moves.iter().flat_map(|v| [0.0, m.shift, -m.shift].map(|d| with(*v, m.axis, d))).collect();
    }
    moves
}

/// `v` with `d` added along `axis`.
fn with(mut v: [f64; 3], axis: usize, d: f64) -> [f64; 3] {
    v[axis] += d;
    v
}

/// The model's field `name`.
fn field(plan: &Plan, name: &str) -> Result<FieldId, BackendError> {
    plan.model.field_id(name).ok_or_else(|| BackendError(format!("the model has no field `{name}`")))
}

/// One rank of a CPU run split into domains, driven by the engine as a backend.
pub struct Domain<T: Real> {
    plan: Plan,
    backend: CpuBackend<T>,
    /// The rank's own GPU, where it runs the neighbour passes (`--backend gpu`); the CPU backend
    /// runs them otherwise.
    device: Option<DevicePasses>,
    mirrors: Vec<Mirror>,
    transport: Mutex<Box<dyn Transport>>,
    rank: usize,
    size: usize,
    /// Per group range of the local store: how many of its particles this rank owns (the rest
    /// of the range is halo).
    owned: Vec<usize>,
    /// Per rank: the local particles this one sends it as halo, in the order sent.
    send: Vec<Vec<u32>>,
    /// Per rank: where the halo particles it sends this one sit here, in the order sent.
    recv: Vec<Vec<u32>>,
    cuts: Cuts,
    params: ParamTable<T>,
    /// Every particle's group, in the order of [`Backend::read`] (group-major, then by rank).
    groups: Vec<u32>,
    x: FieldId,
    h: FieldId,
    support: f64,
    /// Per pass: the stored fields it reads at j (with x and h).
    read_at_j: Vec<Vec<FieldId>>,
    /// What a halo's copy of a particle holds: the fields some pass reads at j, in layout order.
    /// The others are never read there, and do not travel.
    halo_fields: Vec<FieldId>,
    /// The halo's skin, a fraction of the largest cut-off: the halo holds the particles within
    /// the cut-off plus the skin (and the reserve), and is kept until a pair may have come closer
    /// by the skin.
    skin: f64,
    /// Beyond the skin, a fraction of the largest cut-off the halo holds for the adaptive search,
    /// whose lists are rebuilt one by one within their own skin at any evaluation (0 otherwise).
    reserve: f64,
    /// The adaptive search's lists, carried from a reordering to the next rebuild of the halos.
    carried: Option<Carried>,
    /// Every move across the periodic sides, none and both ways along each periodic axis: a
    /// particle whose move lies within a rank's reach is a neighbour of that rank's particles
    /// across the sides (the CPU backend makes the images).
    periodic_moves: Vec<[f64; 3]>,
    /// Half the shortest periodic side, if any: a particle that moved that far crossed one.
    half_period: Option<f64>,
    /// Since the last rebuild: this rank's own particles' positions and smoothing lengths, and
    /// the skin's length; `None` when the next evaluation must rebuild.
    anchor: Option<Anchor>,
    fit: SkinFit,
    /// This rank's own particles when the watchdog last kept the state.
    kept: Option<Store<T>>,
    /// Per model group: how many of its particles this rank evaluated since the last check of
    /// the balance (particles times evaluations).
    evaluated: Vec<f64>,
    pub traffic: Traffic,
    /// Bytes of positions sent again for the measures that compare neighbours
    /// ([`Backend::nearby`], which reads, so counts through `&self`; not in [`Traffic`] for that).
    nearby_sent: std::sync::atomic::AtomicU64,
}

impl<T: Real> Domain<T> {
    /// This rank's share of the particles of `store` (every rank passes the same one), split into
    /// `transport.size()` domains of equal particle counts.
    pub fn new(
        plan: Plan,
        store: Store<T>,
        mirrors: Vec<Mirror>,
        transport: Box<dyn Transport>,
    ) -> Result<Domain<T>, BackendError> {
        let x = field(&plan, "x")?;
        let positions = store.read_f64(x).map(|(_, v)| v).unwrap_or_default();
        let positions: Vec<[f64; 3]> = positions.chunks(plan.dim.max(1)).map(padded).collect();
        let (cuts, own) = Self::share(&plan, &positions, transport.rank(), transport.size())?;
        let rows: Vec<(&Store<T>, usize)> = own.into_iter().map(|i| (&store, i)).collect();
        let mine = Store::gather(&plan, &store.params, &rows);
        Self::of_own(plan, mine, store.group.clone(), cuts, mirrors, transport)
    }

    /// How the particles at `positions` (in the scene's order, the same on every rank) are cut
    /// into `size` domains of equal counts, and the indices of those in domain `rank`, ascending.
    pub fn share(
        plan: &Plan,
        positions: &[[f64; 3]],
        rank: usize,
        size: usize,
    ) -> Result<(Cuts, Vec<usize>), BackendError> {
        if size > positions.len().max(1) {
            return Err(BackendError(format!(
                "cannot split {} particles into {size} domains: run on at most {} ranks",
                positions.len(),
                positions.len().max(1)
            )));
        }
        let flat: Vec<f64> = positions.iter().flat_map(|p| p[..plan.dim].to_vec()).collect();
        let (_, cuts) = bisect_with_cuts(&flat, plan.dim, &vec![1.0; positions.len()], size)
            .map_err(|e| BackendError(format!("the initial particles cannot be split into domains: {e}")))?;
        let own = (0..positions.len()).filter(|i| cuts.locate(&positions[*i]) as usize == rank).collect();
        Ok((cuts, own))
    }

    /// Rank `transport.rank()` of a run split by `cuts`, holding `own`, its share of the
    /// particles, whose groups are `groups` (every particle's, ascending). The programs fold only
    /// the values every rank's share agrees on (the one collective here).
    pub fn of_own(
        plan: Plan,
        own: Store<T>,
        groups: Vec<u32>,
        cuts: Cuts,
        mirrors: Vec<Mirror>,
        mut transport: Box<dyn Transport>,
    ) -> Result<Domain<T>, BackendError> {
        let (rank, size) = (transport.rank(), transport.size());
        let (x, h) = (field(&plan, "x")?, field(&plan, "h")?);
        let read_at_j: Vec<Vec<FieldId>> = (0..plan.passes.len()).map(|k| plan.fields_read_at_j(k)).collect();
        let halo_fields: Vec<FieldId> =
            plan.layout.iter().map(|l| l.field).filter(|f| read_at_j.iter().flatten().any(|r| r == f)).collect();
        let fixed = crate::config::env().halo_skin;
        let (skin, reserve) = match plan.search {
            Lists::Verlet { skin } => (skin, 0.0),
            Lists::Adaptive { skin, .. } => (fixed.unwrap_or(HALO_SKIN), skin),
            Lists::Cells => (fixed.unwrap_or(HALO_SKIN), 0.0),
        };
        let fit = SkinFit { on: fixed.is_none() && !matches!(plan.search, Lists::Verlet { .. }), ..Default::default() };
        let (periodic_moves, half_period) = (periodic_moves(&mirrors), half_period(&mirrors));
        let parts: Vec<Known> =
            transport.all_gather(known(&plan, &own).encode()).iter().map(|k| Known::decode(k)).collect();
        let mut backend = CpuBackend::with_known(plan.clone(), own.clone(), mirrors.clone(), Known::agreed(&parts))?;
        backend.measure_pass_time();
        let support = backend.support;
        let mut domain = Domain {
            backend,
            device: None,
            mirrors,
            transport: Mutex::new(transport),
            rank,
            size,
            owned: vec![],
            send: vec![vec![]; size],
            recv: vec![vec![]; size],
            cuts,
            params: own.params.clone(),
            groups,
            x,
            h,
            support,
            read_at_j,
            halo_fields,
            skin,
            reserve,
            carried: None,
            periodic_moves,
            half_period,
            anchor: None,
            fit,
            kept: None,
            evaluated: vec![0.0; plan.model.groups.len()],
            traffic: Traffic::default(),
            nearby_sent: Default::default(),
            plan,
        };
        domain.set_own(own);
        Ok(domain)
    }

    /// Keeps the halo's skin at `fraction` of the largest cut-off from the next rebuild on, not
    /// fitted to the particles' speed (as `PAIRSUM_HALO_SKIN` does; the kept lists' skin stays
    /// theirs).
    pub fn fix_halo_skin(&mut self, fraction: f64) {
        if self.fit.on {
            (self.skin, self.fit.on) = (fraction, false);
        }
    }

    /// Runs this rank's neighbour passes on `gpu` from now on (its particles stay on the host,
    /// where the CPU backend integrates them: `gpu::share`).
    pub fn on_gpu(&mut self, gpu: Gpu) -> Result<(), BackendError> {
        self.device = Some(DevicePasses::new(gpu, &self.plan, &self.mirrors)?);
        Ok(())
    }

    /// Bytes of positions this rank has sent for [`Backend::nearby`] so far.
    pub fn nearby_sent(&self) -> u64 {
        self.nearby_sent.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// This rank's own particles and its halo's, as of the last evaluation.
    pub fn sizes(&self) -> (usize, usize) {
        let own: usize = self.owned.iter().sum();
        (own, self.backend.store.n - own)
    }

    fn transport(&self) -> std::sync::MutexGuard<'_, Box<dyn Transport>> {
        self.transport.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Keeps the particles of `store` that lie in this rank's box, with no halo.
    fn take_own(&mut self, store: &Store<T>) {
        let rows: Vec<(&Store<T>, usize)> = (0..store.n)
            .filter(|i| self.cuts.locate(&self.position(&Row::Here(store, *i))) as usize == self.rank)
            .map(|i| (store, i))
            .collect();
        self.set_own(Store::gather(&self.plan, &self.params, &rows));
    }

    /// Replaces the local particles by `store`, all of them owned.
    fn set_own(&mut self, store: Store<T>) {
        self.anchor = None;
        self.carried = None;
        let owned = store.ranges.iter().map(|(_, r)| r.len()).collect();
        self.replace_particles(store, owned);
        self.send.iter_mut().chain(&mut self.recv).for_each(Vec::clear);
    }

    /// Makes `store` the local particles, of which the first `owned[k]` of each group range are
    /// this rank's own.
    fn replace_particles(&mut self, store: Store<T>, owned: Vec<usize>) {
        self.backend.replace_particles(store, &owned);
        self.owned = owned;
        if let Some(d) = &mut self.device {
            d.forget();
        }
    }

    /// The indices of the local particles this rank owns, in store order.
    fn own(&self) -> Vec<usize> {
        let ranges = &self.backend.store.ranges;
        ranges.iter().zip(&self.owned).flat_map(|((_, r), n)| r.start..r.start + n).collect()
    }

    /// The fields a group stores, as (field, components), in the order rows carry them: every
    /// one, or for a halo's copy only those some pass reads at j.
    fn stored(&self, group: u32, halo: bool) -> impl Iterator<Item = (FieldId, usize)> + '_ {
        let g = crate::ir::GroupId(group);
        let carried = move |f: &FieldId| !halo || self.halo_fields.contains(f);
        self.plan.layout.iter().filter(move |l| l.groups.contains(g) && carried(&l.field)).map(|l| (l.field, l.comps))
    }

    fn row_len(&self, group: u32, halo: bool) -> usize {
        3 + self.stored(group, halo).map(|(_, c)| c).sum::<usize>()
    }

    /// Appends particle i of `store` as a travelling row, with every field its group stores.
    fn encode(&self, store: &Store<T>, i: usize, out: &mut Vec<f64>) {
        let g = store.group[i];
        out.extend([g as f64, store.material[i] as f64, store.id[i] as f64]);
        for (f, comps) in self.stored(g, false) {
            let c = store.column(f).expect("a stored field has a column");
            let row = c.row(i, g as usize);
            out.extend(c.data[row * comps..(row + 1) * comps].iter().map(|v| v.to_f64()));
        }
    }

    /// Appends a halo's copy of `row`: the fields some pass reads at j.
    fn encode_halo(&self, row: &Row<'_, T>, out: &mut Vec<f64>) {
        let g = Self::group_of(row);
        out.extend([g as f64, Self::material_of(row) as f64, Self::id_of(row) as f64]);
        for (f, _) in self.stored(g, true) {
            out.extend(self.value(row, f).expect("a stored field has values"));
        }
    }

    /// The rows of a message of whole particles, or of a halo's copies.
    fn rows<'a>(&self, message: &'a [f64], halo: bool) -> Vec<Row<'a, T>> {
        let mut out = vec![];
        let mut at = 0;
        while at < message.len() {
            let len = self.row_len(message[at] as u32, halo);
            let row = &message[at..at + len];
            out.push(if halo { Row::Halo(row) } else { Row::Sent(row) });
            at += len;
        }
        out
    }

    fn group_of(row: &Row<'_, T>) -> u32 {
        match row {
            Row::Here(s, i) => s.group[*i],
            Row::Sent(r) | Row::Halo(r) => r[0] as u32,
        }
    }

    fn material_of(row: &Row<'_, T>) -> u32 {
        match row {
            Row::Here(s, i) => s.material[*i],
            Row::Sent(r) | Row::Halo(r) => r[1] as u32,
        }
    }

    fn id_of(row: &Row<'_, T>) -> u32 {
        match row {
            Row::Here(s, i) => s.id[*i],
            Row::Sent(r) | Row::Halo(r) => r[2] as u32,
        }
    }

    /// Field `f`'s values in a row, if its group stores it.
    fn value(&self, row: &Row<'_, T>, f: FieldId) -> Option<Vec<f64>> {
        match row {
            Row::Here(s, i) => {
                let c = s.column(f)?;
                let g = s.group[*i] as usize;
                c.has(g).then(|| {
                    c.data[c.row(*i, g) * c.comps..(c.row(*i, g) + 1) * c.comps].iter().map(|v| v.to_f64()).collect()
                })
            }
            Row::Sent(r) | Row::Halo(r) => {
                let mut at = 3;
                for (field, comps) in self.stored(r[0] as u32, matches!(row, Row::Halo(_))) {
                    if field == f {
                        return Some(r[at..at + comps].to_vec());
                    }
                    at += comps;
                }
                None
            }
        }
    }

    fn position(&self, row: &Row<'_, T>) -> [f64; 3] {
        let mut p = [0.0; 3];
        for (a, v) in self.value(row, self.x).unwrap_or_default().into_iter().enumerate().take(3) {
            p[a] = v;
        }
        p
    }

    /// A store of these rows (group-major), with the state they carry (a halo's copy, what the
    /// passes read at j; the rest of its row stays as a new store has it, never read).
    fn build(&self, rows: &[Row<'_, T>]) -> Store<T> {
        // Rows already here are copied; travelled ones are written from their values.
        let group: Vec<u32> = rows.iter().map(Self::group_of).collect();
        let material: Vec<u32> = rows.iter().map(Self::material_of).collect();
        let mut out = Store::new(&self.plan, group, material, self.params.materials());
        out.params = self.params.clone();
        out.id = rows.iter().map(Self::id_of).collect();
        for (k, row) in rows.iter().enumerate() {
            let g = Self::group_of(row);
            match row {
                Row::Here(s, i) => out.copy_state(k, s, *i),
                Row::Sent(v) | Row::Halo(v) => {
                    let mut at = 3;
                    for (f, comps) in self.stored(g, matches!(row, Row::Halo(_))) {
                        let c = out.column_mut(f).expect("a stored field has a column");
                        let row = c.row(k, g as usize);
                        for (d, s) in c.data[row * comps..(row + 1) * comps].iter_mut().zip(&v[at..at + comps]) {
                            *d = T::from_f64(*s);
                        }
                        at += comps;
                    }
                }
            }
        }
        out
    }

    /// Migration and new halos: every particle goes to the rank whose box holds it; each rank
    /// then receives the others' particles within the box of its own grown by the largest
    /// cut-off, support · h_max.
    fn rebuild(&mut self) -> Result<(), BackendError> {
        let mut carried = self.carry_lists();
        let store = &self.backend.store;
        let own = self.own();
        let mut leaving = vec![vec![]; self.size];
        let mut lists_leaving: Vec<Vec<f64>> = vec![vec![]; self.size];
        let mut staying = vec![];
        for i in own {
            let to = self.cuts.locate(&self.position(&Row::Here(store, i))) as usize;
            if to == self.rank {
                staying.push(i);
            } else {
                self.encode(store, i, &mut leaving[to]);
                if let Some(list) = carried.as_mut().and_then(|c| c.lists.remove(&store.id[i])) {
                    lists_leaving[to].push(store.id[i] as f64);
                    list.encode(&mut lists_leaving[to]);
                }
            }
        }
        let sent = leaving.iter().chain(&lists_leaving).map(Vec::len).sum::<usize>();
        self.traffic.migration += (sent * T::BYTES) as u64;
        let arrived = self.transport().exchange(leaving);
        if self.carries_lists() {
            self.receive_lists(&mut carried, lists_leaving);
        }
        let mut mine: Vec<Row<'_, T>> = staying.iter().map(|i| Row::Here(store, *i)).collect();
        for m in &arrived {
            mine.extend(self.rows(m, false));
        }
        mine.sort_by_key(Self::group_of);
        // The boxes, grown by the largest cut-off.
        let h_local = mine.iter().fold(0.0, |m, r| largest_number(m, self.value(r, self.h).unwrap_or_default()));
        let h_max = self.transport().all_reduce(&[h_local], &[Reduce::Max])[0];
        let skin = self.skin * self.support * h_max;
        let reach = self.support * h_max + skin + self.reserve * self.support * h_max;
        let dim = self.plan.dim;
        let mut bounds =
            [f64::INFINITY, f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
        for r in &mine {
            let p = self.position(r);
            for a in 0..dim {
                bounds[a] = bounds[a].min(p[a] - reach);
                bounds[3 + a] = bounds[3 + a].max(p[a] + reach);
            }
        }
        let boxes = self.transport().all_gather(bounds.to_vec());
        let (wanted, asked) = self.wanted(carried.as_ref(), &mine);
        self.traffic.halo_builds += (asked * T::BYTES) as u64;
        // Halos: each rank's own particles within another's box, and those its lists name.
        let mut halo_out = vec![vec![]; self.size];
        let mut sent_rows: Vec<Vec<usize>> = vec![vec![]; self.size];
        for (d, b) in boxes.iter().enumerate().filter(|(d, _)| *d != self.rank) {
            for (k, r) in mine.iter().enumerate() {
                let p = self.position(r);
                let within = |m: &[f64; 3]| (0..dim).all(|a| p[a] + m[a] >= b[a] && p[a] + m[a] <= b[3 + a]);
                if self.periodic_moves.iter().any(within) || wanted[d].contains(&Self::id_of(r)) {
                    sent_rows[d].push(k);
                    self.encode_halo(r, &mut halo_out[d]);
                }
            }
        }
        self.traffic.halo_builds += (halo_out.iter().map(Vec::len).sum::<usize>() * T::BYTES) as u64;
        let halo_in = self.transport().exchange(halo_out);
        let halo: Vec<Vec<Row<'_, T>>> = halo_in.iter().map(|m| self.rows(m, true)).collect();
        // The local store, group-major: per group, this rank's own particles, then the halo's by
        // rank.
        let mut groups: Vec<u32> = mine.iter().chain(halo.iter().flatten()).map(Self::group_of).collect();
        groups.sort_unstable();
        groups.dedup();
        let mut rows: Vec<Row<'_, T>> = vec![];
        let mut owned = vec![];
        let mut index_of_mine = vec![0u32; mine.len()];
        let mut recv: Vec<Vec<u32>> = vec![vec![]; self.size];
        for g in groups {
            let before = rows.len();
            for (k, r) in mine.iter().enumerate().filter(|(_, r)| Self::group_of(r) == g) {
                index_of_mine[k] = rows.len() as u32;
                rows.push(r.clone());
            }
            owned.push(rows.len() - before);
            for (s, from) in halo.iter().enumerate() {
                for r in from.iter().filter(|r| Self::group_of(r) == g) {
                    recv[s].push(rows.len() as u32);
                    rows.push(r.clone());
                }
            }
        }
        // Within a group the halo comes by rank in the order sent, so the order of each rank's
        // rows here is the order it sent them (its own rows are group-major too).
        let new = self.build(&rows);
        let send: Vec<Vec<u32>> = sent_rows.iter().map(|ks| ks.iter().map(|k| index_of_mine[*k]).collect()).collect();
        self.replace_particles(new, owned);
        self.backend.lists_h_max = Some(h_max);
        (self.send, self.recv) = (send, recv);
        if let Some(c) = carried {
            self.adopt_lists(c)?;
        }
        let (x, h) = self.own().into_iter().map(|i| self.place(i)).unzip();
        self.anchor = Some(Anchor { x, h, skin, reach, cut_off: self.support * h_max });
        self.traffic.rebuilds += 1;
        self.traffic.skin = self.skin;
        (self.fit.evaluations, self.fit.update_secs) = (0, 0.0);
        self.traffic.halo_particles = self.recv.iter().map(Vec::len).sum();
        Ok(())
    }

    /// Whether the plan's search keeps lists that a split run must carry (the adaptive search's).
    fn carries_lists(&self) -> bool {
        matches!(self.plan.search, Lists::Adaptive { .. })
    }

    /// The adaptive search's lists of this rank's own particles by id: the backend's where it
    /// has built them, else those carried from a reordering (none for other searches).
    fn carry_lists(&mut self) -> Option<Carried> {
        if !self.carries_lists() {
            return None;
        }
        let lists = &self.backend.lists;
        if !lists.built {
            return self.carried.take();
        }
        let id = &self.backend.store.id;
        let by_id = self.own().into_iter().filter_map(|i| Some((id[i], lists.by_id(i, id)?))).collect();
        Some(Carried { skin_len: lists.skin_len(), lists: by_id })
    }

    /// Per rank, the particles its carried lists name and it does not own: the adaptive search
    /// keeps a pair that moved apart (it adds nothing beyond the cut-off, but counts again if the
    /// two come back), so the halo holds them wherever they are. One collective for that search;
    /// with how many ids this rank sent in it.
    fn wanted(&self, carried: Option<&Carried>, mine: &[Row<'_, T>]) -> (Vec<HashSet<u32>>, usize) {
        if !self.carries_lists() {
            return (vec![HashSet::new(); self.size], 0);
        }
        let own: HashSet<u32> = mine.iter().map(Self::id_of).collect();
        let named = carried.into_iter().flat_map(|c| c.lists.values()).flat_map(|l| l.entries.iter().map(|e| e.1));
        let need: HashSet<u32> = named.filter(|id| !own.contains(id)).collect();
        let asked = need.len() * (self.size - 1);
        let all = self.transport().all_gather(need.into_iter().map(f64::from).collect());
        (all.into_iter().map(|ids| ids.into_iter().map(|id| id as u32).collect()).collect(), asked)
    }

    /// Sends the lists of the particles that left (per rank: id, then the list, per particle; led
    /// by the lists' skin) and takes in those of the particles that arrived.
    fn receive_lists(&self, carried: &mut Option<Carried>, mut out: Vec<Vec<f64>>) {
        if let Some(c) = carried.as_ref() {
            out.iter_mut().filter(|m| !m.is_empty()).for_each(|m| m.insert(0, c.skin_len));
        }
        for m in self.transport().exchange(out).into_iter().filter(|m| !m.is_empty()) {
            let c = carried.get_or_insert_with(|| Carried { skin_len: m[0], lists: HashMap::new() });
            let mut rest = &m[1..];
            while !rest.is_empty() {
                let (list, next) = KeptList::decode(&rest[1..]);
                c.lists.insert(rest[0] as u32, list);
                rest = next;
            }
        }
    }

    /// Makes the carried lists the backend's, their neighbours' ids mapped to the local store
    /// (own particles and halo, which holds every particle they name: `wanted`).
    fn adopt_lists(&mut self, carried: Carried) -> Result<(), BackendError> {
        let store = &self.backend.store;
        let local: HashMap<u32, u32> = store.id.iter().enumerate().map(|(k, id)| (*id, k as u32)).collect();
        let mut of = vec![vec![]; store.n];
        let mut field0 = vec![f64::NAN; store.n];
        // Where each particle was at its lists' last full build (the halo's: where it is now).
        let dim = self.plan.dim;
        let mut x0 = store.column(self.x).expect("x is stored").data.clone();
        for i in self.own() {
            let id = store.id[i];
            let list = carried.lists.get(&id).ok_or_else(|| {
                BackendError(format!("particle {id} reached rank {} without its neighbour list", self.rank + 1))
            })?;
            for (t, j) in &list.entries {
                let k = local.get(j).ok_or_else(|| {
                    BackendError(format!(
                        "particle {j}, a kept neighbour of particle {id}, is missing on rank {}",
                        self.rank + 1
                    ))
                })?;
                of[i].push(k | t << TRANSFORM_SHIFT);
            }
            field0[i] = list.field0;
            for (c, v) in x0[i * dim..(i + 1) * dim].iter_mut().zip(list.x0) {
                *c = T::from_f64(v);
            }
        }
        let h = store.column(self.h).expect("h is stored").data.clone();
        self.backend.lists.adopt(of, field0, x0, carried.skin_len, &h);
        Ok(())
    }

    /// Where a particle crossed a periodic side since the adaptive search's last full build (it
    /// moved half a period), the run in one piece rebuilds every list (`Lists::prepare`): so do
    /// all ranks then, whichever rank's particle crossed (a collective where the lists are kept
    /// and a side is periodic).
    fn rebuild_lists_if_a_particle_crossed(&mut self) {
        let Some(half) = self.half_period.filter(|_| self.carries_lists()) else { return };
        let lists = &self.backend.lists;
        let x = &self.backend.store.column(self.x).expect("x is stored").data;
        let owned = |i: usize| {
            let store = &self.backend.store;
            store.ranges.iter().zip(&self.owned).any(|((_, r), n)| i >= r.start && i < r.start + n)
        };
        let mine = match lists.built {
            true => lists.displacement_since_build(x, self.plan.dim, owned),
            false => 0.0,
        };
        let moved = self.transport().all_reduce(&[mine], &[Reduce::Max])[0];
        if moved.partial_cmp(&half) != Some(std::cmp::Ordering::Less) {
            self.backend.lists.invalidate();
        }
    }

    /// Local particle i's position and smoothing length.
    fn place(&self, i: usize) -> ([f64; 3], f64) {
        let store = &self.backend.store;
        let g = store.group[i] as usize;
        let (xc, hc) = (store.column(self.x).expect("x is stored"), store.column(self.h).expect("h is stored"));
        let mut p = [0.0; 3];
        let row = xc.row(i, g) * xc.comps;
        for (a, v) in p.iter_mut().enumerate().take(xc.comps) {
            *v = xc.data[row + a].to_f64();
        }
        (p, hc.data[hc.row(i, g)].to_f64())
    }

    /// Whether the halos must be rebuilt: never built, or a pair outside them may have come
    /// within its cut-off (`Drift::exceeds`, over every rank's own particles). The skin of the
    /// next is fitted first.
    fn must_rebuild(&mut self) -> bool {
        let Some(drift) = self.global_drift() else { return true };
        let skin = self.anchor.as_ref().map_or(0.0, |a| a.skin);
        let rebuild = drift.exceeds(skin, self.support);
        if rebuild {
            self.fit_skin(drift.displacement);
        }
        rebuild
    }

    /// Every rank's largest drift since the last rebuild (a collective); `None` before the first.
    fn global_drift(&self) -> Option<crate::schedule::search::Drift> {
        let a = self.anchor.as_ref()?;
        let all = self.transport().all_reduce(&self.drift(a), &[Reduce::Max, Reduce::Max]);
        Some(crate::schedule::search::Drift { displacement: all[0], h_growth: all[1] })
    }

    /// Fits the skin of the next rebuild ([`SkinFit`]) to the interval since the last: the
    /// fastest particle moved `displacement` in it. A collective where the skin is fitted.
    fn fit_skin(&mut self, displacement: f64) {
        let Some(a) = self.anchor.as_ref().filter(|_| self.fit.on && self.fit.evaluations > 0) else { return };
        let plain = self.fit.evaluations.saturating_sub(1).max(1) as f64;
        let mine = [self.fit.rebuild_secs, self.fit.update_secs / plain];
        let slowest = self.transport().all_reduce(&mine, &[Reduce::Max, Reduce::Max]);
        self.skin = self.fit.fraction(self.skin, displacement / a.cut_off, [slowest[0], slowest[1]]);
    }

    /// The largest displacement and growth of h of this rank's own particles since `a`, the last
    /// rebuild (the displacement infinite where a position or h is not a number).
    fn drift(&self, a: &Anchor) -> [f64; 2] {
        let mut drift = [0.0f64, 0.0];
        for (k, i) in self.own().into_iter().enumerate() {
            let (x, h) = self.place(i);
            let d2: f64 = (0..3).map(|c| (x[c] - a.x[k][c]).powi(2)).sum();
            drift = [largest_number(drift[0], [d2.sqrt()]), largest_number(drift[1], [h - a.h[k]])];
            if d2.is_nan() || h.is_nan() {
                drift[0] = f64::INFINITY;
            }
        }
        drift
    }

    /// New cuts, weighted by each particle's measured cost, when the slowest rank's neighbour
    /// passes took more than `REBALANCE_AT` times the ranks' mean since the last check. A
    /// particle's cost is its group's pass time per particle-evaluation over all ranks. The
    /// particles move to their new ranks at the next evaluation.
    fn rebalance(&mut self) {
        let time = match &mut self.device {
            Some(d) => d.take_pass_time(),
            None => self.backend.take_pass_time(),
        };
        let evaluated = std::mem::replace(&mut self.evaluated, vec![0.0; time.len()]);
        let mine: f64 = time.iter().sum();
        let times: Vec<f64> = self.transport().all_gather(vec![mine]).concat();
        let mean = times.iter().sum::<f64>() / times.len() as f64;
        let slowest = times.iter().fold(0.0, |m, t| largest_number(m, [*t]));
        self.traffic.imbalance = if mean > 0.0 { slowest / mean } else { 1.0 };
        if self.size == 1 || self.traffic.imbalance.is_nan() || self.traffic.imbalance <= REBALANCE_AT {
            return;
        }
        let sums: Vec<Reduce> = vec![Reduce::Sum; 2 * time.len()];
        let both: Vec<f64> = time.iter().chain(&evaluated).copied().collect();
        let total = self.transport().all_reduce(&both, &sums);
        let (time, count) = total.split_at(time.len());
        let mean_cost = time.iter().sum::<f64>() / count.iter().sum::<f64>().max(1.0);
        let cost: Vec<f64> = time.iter().zip(count).map(|(t, n)| if *n > 0.0 { t / n } else { mean_cost }).collect();
        // Every rank's own particles (position, weight), then the same cuts on every rank.
        let mut mine = vec![];
        for i in self.own() {
            let (x, _) = self.place(i);
            mine.extend(x);
            mine.push(cost[self.backend.store.group[i] as usize]);
        }
        let all: Vec<f64> = self.transport().all_gather(mine).concat();
        let dim = self.plan.dim;
        let x: Vec<f64> = all.chunks(4).flat_map(|p| p[..dim].to_vec()).collect();
        let weight: Vec<f64> = all.chunks(4).map(|p| p[3]).collect();
        if let Ok((_, cuts)) = bisect_with_cuts(&x, dim, &weight, self.size) {
            self.cuts = cuts;
            self.traffic.rebalances += 1;
        }
    }

    /// Sends each halo the values of `fields` of the particles it copies.
    fn refresh_halos(&mut self, fields: &[FieldId]) {
        let store = &self.backend.store;
        let out: Vec<Vec<f64>> = self
            .send
            .iter()
            .map(|list| {
                let mut m = vec![];
                for i in list {
                    let (i, g) = (*i as usize, store.group[*i as usize] as usize);
                    for f in fields {
                        if let Some(c) = store.column(*f).filter(|c| c.has(g)) {
                            m.extend(
                                c.data[c.row(i, g) * c.comps..(c.row(i, g) + 1) * c.comps].iter().map(|v| v.to_f64()),
                            );
                        }
                    }
                }
                m
            })
            .collect();
        self.traffic.halo_updates += (out.iter().map(Vec::len).sum::<usize>() * T::BYTES) as u64;
        let got = self.transport().exchange(out);
        let store = &mut self.backend.store;
        for (list, m) in self.recv.iter().zip(got) {
            let mut next = m.into_iter();
            for k in list {
                let (k, g) = (*k as usize, store.group[*k as usize] as usize);
                for f in fields {
                    if let Some(c) = store.column_mut(*f).filter(|c| c.has(g)) {
                        let row = c.row(k, g);
                        for v in &mut c.data[row * c.comps..(row + 1) * c.comps] {
                            *v = T::from_f64(next.next().unwrap_or(f64::NAN));
                        }
                    }
                }
            }
        }
    }

    /// Every rank's own particles of `local` (the indices `own`), in one store in the order of
    /// [`Backend::read`]: group-major, then by rank.
    fn assemble(&self, local: &Store<T>, own: &[usize]) -> Store<T> {
        let mut m = vec![];
        for i in own {
            self.encode(local, *i, &mut m);
        }
        let all = self.transport().all_gather(m);
        let mut rows: Vec<Row<'_, T>> = all.iter().flat_map(|m| self.rows(m, false)).collect();
        rows.sort_by_key(Self::group_of);
        self.build(&rows)
    }

    /// Per rank, per model group: how many particles it owns.
    fn counts(&self) -> Vec<Vec<usize>> {
        let all = self.transport().all_gather(self.own_counts());
        all.into_iter().map(|v| v.into_iter().map(|c| c as usize).collect()).collect()
    }

    /// Per model group: how many particles this rank owns.
    fn own_counts(&self) -> Vec<f64> {
        let mut mine = vec![0.0; self.plan.model.groups.len()];
        for ((g, _), n) in self.backend.store.ranges.iter().zip(&self.owned) {
            mine[g.index()] = *n as f64;
        }
        mine
    }

    /// Values `width` per own particle (from `value`), of every rank, in the order of
    /// [`Backend::read`], in one collective: each rank's message leads with its counts per group.
    fn gather(&self, width: usize, value: impl Fn(&Store<T>, usize) -> Vec<f64>) -> Vec<f64> {
        let store = &self.backend.store;
        let groups = self.plan.model.groups.len();
        let mut mine = self.own_counts();
        for i in self.own() {
            mine.extend(value(store, i));
        }
        let all = self.transport().all_gather(mine);
        let mut at = vec![groups; self.size];
        let mut out = Vec::with_capacity(self.groups.len() * width);
        for g in 0..groups {
            for (s, m) in all.iter().enumerate() {
                let n = m[g] as usize * width;
                out.extend_from_slice(&m[at[s]..at[s] + n]);
                at[s] += n;
            }
        }
        out
    }
}

impl<T: Real> Backend for Domain<T> {
    fn describe(&self) -> String {
        let (rank, size) = (self.rank + 1, self.size);
        match &self.device {
            Some(d) => format!(
                "gpu ({}, f32) for the passes, {} for the rest, rank {rank} of {size} domains",
                d.describe(),
                self.backend.describe()
            ),
            None => format!("{}, rank {rank} of {size} domains", self.backend.describe()),
        }
    }

    fn plan(&self) -> &Plan {
        &self.plan
    }

    fn particles(&self) -> usize {
        self.groups.len()
    }

    fn initialise(&mut self) -> Result<(), BackendError> {
        self.backend.initialise()
    }

    fn save(&mut self) -> Result<(), BackendError> {
        self.backend.save()
    }

    /// Rebuilds the halos when they may miss a neighbour, else keeps them; before each pass the
    /// halo receives what that pass reads at j and it does not hold as it is now: after a
    /// rebuild (which sends what the passes read at j) what an earlier pass wrote, else what the pass reads
    /// and was not sent since the last write.
    fn evaluate(&mut self, g: Globals) -> Result<(), BackendError> {
        let rebuilt = self.must_rebuild();
        let started = std::time::Instant::now();
        let mut fresh: Vec<FieldId> = if rebuilt {
            self.rebuild()?;
            self.halo_fields.clone()
        } else {
            vec![]
        };
        let mut halo_secs = if rebuilt { started.elapsed().as_secs_f64() } else { 0.0 };
        for ((g, _), n) in self.backend.store.ranges.iter().zip(&self.owned) {
            self.evaluated[g.index()] += *n as f64;
        }
        self.fit.evaluations += 1;
        self.rebuild_lists_if_a_particle_crossed();
        let mut search = None;
        for k in 0..self.plan.passes.len() {
            let fields: Vec<FieldId> = self.read_at_j[k].iter().copied().filter(|f| !fresh.contains(f)).collect();
            if !fields.is_empty() {
                let t = std::time::Instant::now();
                self.refresh_halos(&fields);
                halo_secs += t.elapsed().as_secs_f64();
            }
            fresh.extend(&fields);
            fresh.retain(|f| !self.plan.passes[k].writes.contains(f));
            if let Some(device) = self.device.as_mut().filter(|_| self.backend.store.n > 0) {
                device.run_pass(k, g, &mut self.backend.store, &self.owned, &fields, k == 0)?;
                continue;
            }
            // The search reads the halo's positions: after the first pass's fields arrived.
            if search.is_none() && self.backend.store.n > 0 {
                search = Some(self.backend.search()?);
            }
            if let Some(search) = &search {
                self.backend.run_pass(k, g, search);
            }
        }
        match rebuilt {
            true => self.fit.rebuild_secs = halo_secs,
            false => self.fit.update_secs += halo_secs,
        }
        self.traffic.halo_secs += halo_secs;
        Ok(())
    }

    fn reductions(&mut self, g: Globals) -> Result<Vec<f64>, BackendError> {
        let reds = super::timestep::reductions(&self.plan.model, &self.plan.timesteps);
        let local = self.backend.reductions(g)?;
        let kinds: Vec<Reduce> = reds.iter().map(|(r, _)| *r).collect();
        Ok(self.transport().all_reduce(&local, &kinds))
    }

    fn update(&mut self, stage: usize, g: Globals) -> Result<(), BackendError> {
        self.backend.update(stage, g)
    }

    /// Cuts the ranks again where their measured work drifted apart (`REBALANCE_AT`), drops the
    /// halo and orders this rank's own particles along the Morton curve.
    fn reorder(&mut self) -> Result<(), BackendError> {
        self.rebalance();
        // The halo is dropped here: its interval is measured as one that ran out.
        if let Some(drift) = self.global_drift().filter(|_| self.fit.on) {
            self.fit_skin(drift.displacement);
        }
        let carried = self.carry_lists();
        let own = self.own();
        let rows: Vec<(&Store<T>, usize)> = own.iter().map(|i| (&self.backend.store, *i)).collect();
        let store = Store::gather(&self.plan, &self.params, &rows);
        self.set_own(store);
        self.carried = carried;
        self.backend.reorder()
    }

    fn read(&self, f: FieldId) -> Result<Option<(usize, Vec<f64>)>, BackendError> {
        let Some(l) = self.plan.layout.iter().find(|l| l.field == f) else { return Ok(None) };
        let comps = l.comps;
        let values =
            self.gather(comps, |s, i| self.value(&Row::Here(s, i), f).unwrap_or_else(|| vec![f64::NAN; comps]));
        Ok(Some((comps, values)))
    }

    fn ids(&self) -> Result<Vec<u32>, BackendError> {
        Ok(self.gather(1, |s, i| vec![s.id[i] as f64]).into_iter().map(|v| v as u32).collect())
    }

    /// This rank's own particles, then its halo's with their positions as they are now (sent
    /// again: the copies hold those of the last pass). The halo held every particle within its
    /// reach of an own particle at the last rebuild, and since then no particle moved farther
    /// than the largest displacement over the ranks: the reach now is the rebuild's less twice
    /// that (none before the first rebuild).
    fn nearby(&self) -> Result<Option<Nearby>, BackendError> {
        let (dim, store) = (self.plan.dim.max(1), &self.backend.store);
        let own = self.own();
        let mut x: Vec<[f64; 3]> = own.iter().map(|i| self.place(*i).0).collect();
        let mut ids: Vec<u32> = own.iter().map(|i| store.id[*i]).collect();
        let out: Vec<Vec<f64>> = self
            .send
            .iter()
            .map(|list| list.iter().flat_map(|i| self.place(*i as usize).0[..dim].to_vec()).collect())
            .collect();
        let sent = out.iter().map(Vec::len).sum::<usize>() * T::BYTES;
        self.nearby_sent.fetch_add(sent as u64, std::sync::atomic::Ordering::Relaxed);
        let got = self.transport().exchange(out);
        for (list, m) in self.recv.iter().zip(&got) {
            for (k, p) in list.iter().zip(m.chunks(dim)) {
                x.push(padded(p));
                ids.push(store.id[*k as usize]);
            }
        }
        let moved = self.anchor.as_ref().map_or(f64::INFINITY, |a| self.drift(a)[0]);
        let moved = self.transport().all_reduce(&[moved], &[Reduce::Max])[0];
        let reach = self.anchor.as_ref().map_or(0.0, |a| a.reach - 2.0 * moved);
        Ok(Some(Nearby { x, ids, own: own.len(), reach: reach.max(0.0) }))
    }

    fn groups(&self) -> Vec<u32> {
        self.groups.clone()
    }

    fn rank(&self) -> Option<(usize, usize)> {
        Some((self.rank, self.size))
    }

    fn all_gather(&self, part: Vec<f64>) -> Vec<Vec<f64>> {
        self.transport().all_gather(part)
    }

    fn read_own(&self, f: FieldId) -> Result<Option<(usize, Vec<f64>)>, BackendError> {
        let Some(l) = self.plan.layout.iter().find(|l| l.field == f) else { return Ok(None) };
        let store = &self.backend.store;
        let nan = || vec![f64::NAN; l.comps];
        let values = self.own().into_iter().flat_map(|i| self.value(&Row::Here(store, i), f).unwrap_or_else(nan));
        Ok(Some((l.comps, values.collect())))
    }

    fn ids_own(&self) -> Result<Vec<u32>, BackendError> {
        Ok(self.own().into_iter().map(|i| self.backend.store.id[i]).collect())
    }

    /// The watchdog's values ([`watch_values`](Backend::watch_values)) are reduced on each rank;
    /// probes are reduced by `scene::measure` over each rank's own particles and merged through
    /// [`all_gather`](Backend::all_gather).
    fn reduces_probes(&self) -> bool {
        true
    }

    /// The watchdog's reductions over this rank's own particles (`watchdog::Motion`), then over
    /// the ranks in rank order, in f64: the engine reads the fields only near a bound.
    fn watch_values(&self) -> Result<Option<WatchValues>, BackendError> {
        let Some(motion) = Motion::read_with(&self.plan, |f| self.read_own(f))? else { return Ok(None) };
        let w = motion.watch_values(&gravity(&self.plan, motion.dim));
        let all = self.transport().all_gather(vec![w.max_speed, w.energy, w.energy_magnitude, w.kinetic]);
        let sum = |k: usize| all.iter().map(|p| p[k]).sum::<f64>();
        Ok(Some(WatchValues {
            max_speed: max_keeping_nan(0.0, all.iter().map(|p| p[0])),
            energy: sum(1),
            energy_magnitude: sum(2),
            kinetic: sum(3),
        }))
    }

    fn snapshot(&self) -> Result<Snapshot, BackendError> {
        Ok(snapshot_of(&self.assemble(&self.backend.store, &self.own())))
    }

    fn restore(&mut self, s: &Snapshot) -> Result<(), BackendError> {
        let mut store = Store::<T>::new(&self.plan, self.groups.clone(), s.material.clone(), self.params.materials());
        store.params = self.params.clone();
        store.id = s.id.clone();
        for (c, d) in store.columns.iter_mut().zip(&s.columns) {
            if let (Some(c), Some(d)) = (c.as_mut(), d) {
                for (x, v) in c.data.iter_mut().zip(d) {
                    *x = T::from_f64(*v);
                }
            }
        }
        self.take_own(&store);
        Ok(())
    }

    fn keep(&mut self) -> Result<(), BackendError> {
        let rows: Vec<(&Store<T>, usize)> = self.own().into_iter().map(|i| (&self.backend.store, i)).collect();
        self.kept = Some(Store::gather(&self.plan, &self.params, &rows));
        Ok(())
    }

    fn kept(&self) -> Result<Snapshot, BackendError> {
        let kept = self.kept.as_ref().ok_or_else(|| BackendError("no state was kept".into()))?;
        Ok(snapshot_of(&self.assemble(kept, &(0..kept.n).collect::<Vec<_>>())))
    }

    fn restore_kept(&mut self) -> Result<(), BackendError> {
        let kept = self.kept.clone().ok_or_else(|| BackendError("no state was kept".into()))?;
        self.set_own(kept);
        Ok(())
    }

    fn search_stats(&self) -> crate::schedule::SearchStats {
        self.backend.search_stats()
    }

    /// What this rank (rank 0 writes it) held and sent, per step.
    fn timing(&self, steps: u64) -> Option<String> {
        let (own, t) = (self.sizes().0, &self.traffic);
        let per = |b: u64| b as f64 / steps.max(1) as f64 / 1e3;
        Some(format!(
            "rank {} of {}: {own} particles of its own, {} in its halo at the last evaluation; sent per \
             step (kB, {} B a value): {:.1} migrating, {:.1} rebuilding halos ({} rebuilds, the last with a skin of \
             {:.2} of the cut-off), {:.1} updating halos before a pass ({:.3} ms a step on halos), {:.1} for the measures that compare neighbours; {} rebalances, the slowest rank's \
             passes {:.2}× the mean at the last check\n",
            self.rank + 1,
            self.size,
            t.halo_particles,
            T::BYTES,
            per(t.migration),
            per(t.halo_builds),
            t.rebuilds,
            t.skin,
            per(t.halo_updates),
            t.halo_secs * 1e3 / steps.max(1) as f64,
            per(self.nearby_sent()),
            t.rebalances,
            t.imbalance
        ))
    }

    fn first_non_finite(&mut self, fields: &[FieldId]) -> Result<Option<(usize, FieldId)>, BackendError> {
        // This rank's first, as an index in the global order, then the least over the ranks.
        let rows: Vec<(&Store<T>, usize)> = self.own().into_iter().map(|i| (&self.backend.store, i)).collect();
        let mine = Store::gather(&self.plan, &self.params, &rows);
        let counts = self.counts();
        let local = first_non_finite_in(&mine, fields).map(|(i, f)| {
            let g = mine.group[i] as usize;
            let in_group = i - mine.ranges.iter().find(|(gr, _)| gr.index() == g).map_or(0, |(_, r)| r.start);
            let before: usize = counts.iter().map(|c| c[..g].iter().sum::<usize>()).sum::<usize>()
                + counts[..self.rank].iter().map(|c| c[g]).sum::<usize>();
            (before + in_group, f)
        });
        let code = local.map_or([f64::INFINITY, 0.0], |(i, f)| [i as f64, f.index() as f64]);
        let all = self.transport().all_gather(code.to_vec());
        let best = all.iter().filter(|c| c[0].is_finite()).min_by(|a, b| a[0].total_cmp(&b[0]));
        Ok(best.map(|c| (c[0] as usize, FieldId(c[1] as u32))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fit(evaluations: u64) -> SkinFit {
        SkinFit { on: true, evaluations, ..Default::default() }
    }

    #[test]
    fn the_skin_doubles_after_an_interval_that_rebuilt_at_its_only_evaluation() {
        assert_eq!(fit(1).fraction(0.1, 0.3, [1.0, 0.0]), 0.2);
        assert_eq!(fit(1).fraction(0.8, 0.3, [1.0, 0.0]), SKIN_BOUNDS.1);
    }

    #[test]
    fn the_fitted_skin_is_the_root_of_twice_the_displacement_times_the_rebuilds_cost_over_the_depths() {
        // 4 evaluations, the fastest particle 0.2 of the cut-off in all (0.05 each); the rebuild's
        // evaluation 0.5 ms more than another's 0.2 ms at a depth of 1.25 cut-offs: A = 0.16 ms
        // per cut-off of depth, B = 0.5 ms, s = √(2 · 0.05 · 0.5 / 0.16) = 0.559.
        let f = fit(4).fraction(0.25, 0.2, [0.7e-3, 0.2e-3]);
        assert!((f - (2.0 * 0.05 * 0.5 / 0.16f64).sqrt()).abs() < 1e-12, "{f}");
        assert_eq!(fit(4).fraction(0.25, 0.0, [0.7e-3, 0.2e-3]), SKIN_BOUNDS.0, "a body at rest");
        assert_eq!(fit(4).fraction(0.25, f64::NAN, [0.7e-3, 0.2e-3]), 0.25, "no measure: kept");
    }
}
