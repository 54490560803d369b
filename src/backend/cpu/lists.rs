//! Neighbour lists kept across evaluations (the Verlet and the F-ANS adaptive search of
//! [`Search`]): per particle, every particle (or mirror image) within its cut-off plus a skin at
//! the last build, each entry an index and the mirror transform of the image. Passes walk the
//! lists and keep the pairs within the current cut-off; when a list is rebuilt is the schedule's
//! decision ([`Search::rebuild`]).

use super::Mirror;
use crate::grid::{Grid, Level, SizeLevels};
use crate::ir::FieldId;
use crate::particles::Real;
use crate::schedule::{Drift, Rebuild, Search, SearchStats};
use rayon::prelude::*;

/// An entry holds the transform (which image planes, `Mirror`s, make the neighbour's image; at
/// most 6) in its top bits, its index (below 2^26) in the others.
pub const TRANSFORM_SHIFT: u32 = 26;

/// The most image planes a scene may have: three symmetry planes, or two per periodic axis.
pub const MAX_PLANES: usize = 6;
pub const INDEX_MASK: u32 = (1 << TRANSFORM_SHIFT) - 1;

/// Per model group, the groups some pass reads neighbours from on it, a bit per group: what its
/// particles' lists hold.
pub fn sources_per_group(plan: &crate::schedule::Plan) -> Vec<u64> {
    let mut sources = vec![0u64; plan.model.groups.len()];
    for v in plan.passes.iter().flat_map(|p| &p.variants) {
        sources[v.group.index()] |= v.sources.0;
    }
    sources
}

/// The lists, with the state they were built on.
#[derive(Default)]
pub struct Lists<T> {
    /// Per particle (in the store's order): its entries, grouped by transform.
    pub of: Vec<Vec<u32>>,
    /// Positions and smoothing lengths at the last full build (Verlet's bound).
    x0: Vec<T>,
    h0: Vec<T>,
    /// The skin's length at the last full build.
    skin_len: f64,
    /// The adaptive search's field at each particle's last rebuild (NaN where not stored).
    field0: Vec<f64>,
    pub built: bool,
    pub stats: SearchStats,
}

/// What a build reads.
pub struct BuildInput<'a, T> {
    pub x: &'a [T],
    pub h: &'a [T],
    pub dim: usize,
    pub support: f64,
    pub h_max: f64,
    pub mirrors: &'a [Mirror],
    /// Every particle's group, and per group the groups some pass reads neighbours from on it
    /// (a bit per group): a list holds only those (a wall that takes only from the fluid lists
    /// no other wall). `None`: every group.
    pub sources: Option<(&'a [u32], &'a [u64])>,
}

impl<T: Real> Lists<T> {
    /// Brings the lists up to date for an evaluation, as the search asks; `field` reads a scalar
    /// field per particle (NaN where it is not stored) for the adaptive search.
    pub fn prepare(&mut self, search: &Search, inp: &BuildInput<T>, field: impl Fn(FieldId) -> Vec<f64>) {
        self.stats.evaluations += 1;
        let support = inp.support;
        let mut rebuild = search.rebuild(self.built, || (self.drift(inp), self.skin_len), support);
        // A particle that crossed a periodic side has new images: the adaptive search, which
        // rebuilds only some lists, rebuilds them all then.
        if let (Rebuild::Where { .. }, Some(half)) = (&rebuild, half_period(inp.mirrors)) {
            if self.drift(inp).displacement.partial_cmp(&half) != Some(std::cmp::Ordering::Less) {
                rebuild = Rebuild::All;
            }
        }
        match rebuild {
            Rebuild::Keep => {}
            Rebuild::All => {
                self.skin_len = search.skin() * support * inp.h_max;
                self.of.resize(inp.h.len(), vec![]);
                self.rebuild_where(inp, |_| true);
                self.x0 = inp.x.to_vec();
                self.h0 = inp.h.to_vec();
                self.field0 = match search {
                    Search::Adaptive { field: f, .. } => field(*f),
                    _ => vec![],
                };
                self.built = true;
                self.stats.full_builds += 1;
            }
            Rebuild::Where { field: f, threshold } => {
                let now = field(f);
                let stale: Vec<bool> = now.iter().zip(&self.field0).map(|(a, b)| a - b > threshold).collect();
                let count = stale.iter().filter(|s| **s).count();
                if count > 0 {
                    self.rebuild_where(inp, |i| stale[i]);
                    for (i, s) in stale.iter().enumerate() {
                        if *s {
                            self.field0[i] = now[i];
                        }
                    }
                }
                self.stats.particle_rebuilds += count as u64;
            }
        }
    }

    /// The largest displacement and growth of h since the last full build.
    fn drift(&self, inp: &BuildInput<T>) -> Drift {
        let displacement = self.displacement_since_build(inp.x, inp.dim, |_| true);
        let h_growth = inp.h.iter().zip(&self.h0).map(|(a, b)| (*a - *b).to_f64()).fold(0.0, |m: f64, g| {
            if g.is_nan() {
                g
            } else {
                m.max(g)
            }
        });
        Drift { displacement, h_growth }
    }

    /// Rebuilds the lists of the particles `which` picks, from a fresh cell list.
    fn rebuild_where(&mut self, inp: &BuildInput<T>, which: impl Fn(usize) -> bool + Sync) {
        let reach = inp.support * inp.h_max + self.skin_len;
        let levels = SizeLevels::build(inp.x, inp.dim, inp.h, inp.support, self.skin_len);
        let h_near = Grid::nearby_max(inp.x, inp.dim, inp.h, reach);
        let near = Near { skin: self.skin_len, h_near: &h_near };
        self.of.par_iter_mut().enumerate().for_each_init(Vec::new, |ranges, (i, list)| {
            if which(i) {
                list.clear();
                match inp.dim {
                    1 => collect::<T, 1>(&levels, inp, &near, i, ranges, list),
                    2 => collect::<T, 2>(&levels, inp, &near, i, ranges, list),
                    _ => collect::<T, 3>(&levels, inp, &near, i, ranges, list),
                }
            }
        });
    }

    /// The lists follow a reordering of the store (`perm[new] = old`).
    pub fn permute(&mut self, perm: &[u32]) {
        if !self.built {
            return;
        }
        let mut new_of_old = vec![0u32; perm.len()];
        for (new, old) in perm.iter().enumerate() {
            new_of_old[*old as usize] = new as u32;
        }
        let remap = |e: &u32| (e & !INDEX_MASK) | new_of_old[(e & INDEX_MASK) as usize];
        self.of = perm.iter().map(|old| self.of[*old as usize].iter().map(remap).collect()).collect();
        let d = self.x0.len() / perm.len().max(1);
        self.x0 = perm.iter().flat_map(|old| self.x0[*old as usize * d..(*old as usize + 1) * d].to_vec()).collect();
        self.h0 = perm.iter().map(|old| self.h0[*old as usize]).collect();
        if !self.field0.is_empty() {
            self.field0 = perm.iter().map(|old| self.field0[*old as usize]).collect();
        }
    }

    /// Forgets the lists (the state was replaced): the next evaluation builds them all.
    pub fn invalidate(&mut self) {
        self.built = false;
    }

    /// Particle i's list with its neighbours named by `id` (every particle's id, in the store's
    /// order), to follow it into another store; `None` before the lists are built.
    pub fn by_id(&self, i: usize, id: &[u32]) -> Option<KeptList> {
        let list = self.of.get(i).filter(|_| self.built)?;
        let entries = list.iter().map(|e| (e >> TRANSFORM_SHIFT, id[(e & INDEX_MASK) as usize])).collect();
        let d = self.x0.len() / self.of.len().max(1);
        let mut x0 = [0.0; 3];
        for (c, v) in x0.iter_mut().zip(&self.x0[i * d..(i + 1) * d]) {
            *c = v.to_f64();
        }
        Some(KeptList { field0: self.field0.get(i).copied().unwrap_or(f64::NAN), x0, entries })
    }

    /// The largest displacement since the last full build of the particles that `counted` takes
    /// (at `x`, now), infinite where one is not a number: where it reaches half a period, a
    /// particle crossed a periodic side ([`prepare`](Self::prepare)).
    pub fn displacement_since_build(&self, x: &[T], dim: usize, counted: impl Fn(usize) -> bool + Sync) -> f64 {
        let d = x
            .par_chunks(dim)
            .zip(self.x0.par_chunks(dim))
            .enumerate()
            .filter(|(i, _)| counted(*i))
            .map(|(_, (a, b))| a.iter().zip(b).map(|(p, q)| (*p - *q).to_f64().powi(2)).sum::<f64>())
            .reduce(|| 0.0, |a, b| if a.is_nan() || b.is_nan() { f64::NAN } else { a.max(b) })
            .sqrt();
        if d.is_nan() {
            f64::INFINITY
        } else {
            d
        }
    }

    /// The skin's length at the last full build.
    pub fn skin_len(&self) -> f64 {
        self.skin_len
    }

    /// Takes lists kept in another store as this store's, built: `of` per particle, the adaptive
    /// search's field at each one's last rebuild, the positions at the lists' last full build, the
    /// skin's length then, and the smoothing lengths now.
    pub fn adopt(&mut self, of: Vec<Vec<u32>>, field0: Vec<f64>, x0: Vec<T>, skin_len: f64, h: &[T]) {
        (self.of, self.field0, self.skin_len) = (of, field0, skin_len);
        (self.x0, self.h0) = (x0, h.to_vec());
        self.built = true;
    }
}

/// One particle's kept list, its neighbours named by id (see [`Lists::by_id`]).
#[derive(Clone, Debug, PartialEq)]
pub struct KeptList {
    /// The adaptive search's field at the list's last rebuild.
    pub field0: f64,
    /// The particle's position at the last full build (padded to three components).
    pub x0: [f64; 3],
    /// Per entry: the mirror transform of the neighbour's image and the neighbour's id.
    pub entries: Vec<(u32, u32)>,
}

impl KeptList {
    /// Appends the list to `out` as numbers: the field, the position, the count, then transform
    /// and id per entry.
    pub fn encode(&self, out: &mut Vec<f64>) {
        out.push(self.field0);
        out.extend(self.x0);
        out.push(self.entries.len() as f64);
        out.extend(self.entries.iter().flat_map(|(t, id)| [*t as f64, *id as f64]));
    }

    /// The list that `encode` wrote at the start of `m`, and what follows it.
    pub fn decode(m: &[f64]) -> (KeptList, &[f64]) {
        let n = m[4] as usize;
        let entries = m[5..5 + 2 * n].chunks(2).map(|e| (e[0] as u32, e[1] as u32)).collect();
        (KeptList { field0: m[0], x0: [m[1], m[2], m[3]], entries }, &m[5 + 2 * n..])
    }
}

/// Half the shortest periodic domain, if any: no particle moves that far between two builds
/// unless it crossed a side.
pub fn half_period(mirrors: &[Mirror]) -> Option<f64> {
    mirrors.iter().filter(|m| m.shift > 0.0).map(|m| 0.5 * m.shift).reduce(f64::min)
}

/// The transform `t` applied to particle i's position: the point whose neighbours are the images
/// (i reflected across the symmetry planes of `t`, moved across the periodic sides of `t`), and
/// the axes it flips.
pub fn transformed<T: Real>(xi: [T; 3], t: u32, mirrors: &[Mirror]) -> ([T; 3], [bool; 3]) {
    let mut yi = xi;
    let mut flip = [false; 3];
    for (m, mirror) in mirrors.iter().enumerate() {
        if t >> m & 1 == 1 {
            if mirror.shift == 0.0 {
                yi[mirror.axis] = T::from_f64(2.0 * mirror.offset) - xi[mirror.axis];
                flip[mirror.axis] = !flip[mirror.axis];
            } else {
                yi[mirror.axis] = xi[mirror.axis] + T::from_f64(mirror.shift);
            }
        }
    }
    (yi, flip)
}

/// Whether transform `t` holds no image within `radius` of i: images of j are near i exactly when
/// j is near the transformed i, and none is when i is that far from a plane of `t`. Both sides of
/// one periodic axis together move i nowhere: that transform is never taken.
pub fn beyond_reach<T: Real>(xi: [T; 3], t: u32, mirrors: &[Mirror], radius: f64) -> bool {
    let far =
        |(m, mirror): (usize, &Mirror)| t >> m & 1 == 1 && (xi[mirror.axis].to_f64() - mirror.offset).abs() >= radius;
    mirrors.iter().enumerate().any(far) || both_sides(t, mirrors)
}

/// The periodic sides transform `t` moves i across.
fn sides(t: u32, mirrors: &[Mirror]) -> impl Iterator<Item = &Mirror> {
    mirrors.iter().enumerate().filter(move |(m, mirror)| t >> m & 1 == 1 && mirror.shift != 0.0).map(|(_, p)| p)
}

/// Whether `t` takes both sides of a periodic axis.
fn both_sides(t: u32, mirrors: &[Mirror]) -> bool {
    let mut per_axis = [0; 3];
    sides(t, mirrors).for_each(|p| per_axis[p.axis] += 1);
    per_axis.iter().any(|c| *c > 1)
}

/// Whether `t` moves i across a periodic side: its images' neighbours lie across the domain, and
/// the largest smoothing length near i does not bound theirs.
pub fn shifts(t: u32, mirrors: &[Mirror]) -> bool {
    sides(t, mirrors).next().is_some()
}

/// The skin, and per particle the largest smoothing length within the build reach of it
/// (`Grid::nearby_max`).
struct Near<'a> {
    skin: f64,
    h_near: &'a [f64],
}

/// Every particle or image within the pair's build reach: its own cut-off `support · h_ij` plus
/// the skin (the cells searched reach `support · (h_i + h_near_i)/2` plus the skin, which holds
/// every such pair). With particles of several sizes a fine particle's list then holds its
/// neighbours, not every particle a coarse one's reach could bring in.
fn collect<T: Real, const D: usize>(
    levels: &SizeLevels,
    inp: &BuildInput<T>,
    near: &Near,
    i: usize,
    ranges: &mut Vec<(u32, u32)>,
    out: &mut Vec<u32>,
) {
    let mut xi = [T::zero(); 3];
    xi[..D].copy_from_slice(&inp.x[i * D..i * D + D]);
    // h_ij ≤ (h_i + h_near_i)/2: no neighbour lies beyond support · that.
    let (hi, skin) = (inp.h[i].to_f64(), near.skin);
    let wanted = inp.sources.map_or(u64::MAX, |(group, sources)| sources[group[i] as usize]);
    if wanted == 0 {
        return;
    }
    for t in 0..1u32 << inp.mirrors.len() {
        // Across a periodic side the neighbours are not near i: any h may be among them.
        let h_far = if shifts(t, inp.mirrors) { inp.h_max } else { near.h_near[i] };
        let radius = inp.support * 0.5 * (hi + h_far) + skin;
        if beyond_reach(xi, t, inp.mirrors, radius) {
            continue;
        }
        let (yi, _) = transformed(xi, t, inp.mirrors);
        let mut p = [0.0; 3];
        for c in 0..D {
            p[c] = yi[c].to_f64();
        }
        let reach = |level: &Level| level.reach(inp.support, hi, h_far, skin);
        levels.for_each_candidate(p, reach, ranges, |j| {
            if t == 0 && j as usize == i {
                return;
            }
            if let Some((group, _)) = inp.sources.filter(|_| wanted != u64::MAX) {
                if (wanted >> group[j as usize]) & 1 == 0 {
                    return;
                }
            }
            let xj = &inp.x[j as usize * D..j as usize * D + D];
            let r2: f64 = (0..D).map(|c| (yi[c] - xj[c]).to_f64().powi(2)).sum();
            let reach = inp.support * 0.5 * (hi + inp.h[j as usize].to_f64()) + skin;
            if r2 < reach * reach {
                out.push(j | t << TRANSFORM_SHIFT);
            }
        });
    }
}
