//! Fusion: assigns every live evaluation equation to a neighbour pass (pair sums) or to a pass's
//! tail (particle equations, `finally` blocks), as early as its inputs allow; particle equations
//! that need only state go to the integrator's per-particle update.
//!
//! A pair sum that reads another equation's output inside its neighbour loop (on either side) must
//! run in a later pass; one that reads it only in `finally` may share the pass, its `finally`
//! ordered after the writer. So continuity, the velocity gradient and the correction matrix L_i
//! share a pass even when the velocity gradient is corrected by L_i⁻¹ in its `finally`.

use super::live::{stmts_of, Live};
use super::{Pass, PassVariant, PlanError, SceneSpec, TailItem};
use crate::ir::{self, EqId, EquationKind, ExprKind, FieldId, GroupSet, Model, Side, Storage};
use std::collections::{BTreeMap, BTreeSet};

/// What an equation reads, split by where.
struct Reads {
    /// Read in the neighbour loop or `init` (any side), or anywhere in a particle equation.
    early: BTreeSet<(FieldId, Side)>,
    /// Read (at i) only in a pair sum's `finally`.
    finally: BTreeSet<FieldId>,
}

fn fields_in(stmts: &[ir::Stmt], out: &mut BTreeSet<(FieldId, Side)>) {
    ir::walk_stmts(stmts, &mut |e| {
        if let ExprKind::Field(f, s) = e.kind {
            out.insert((f, s));
        }
    });
}

fn reads_of(model: &Model, e: EqId) -> Reads {
    let eq = &model.equations[e.index()];
    let mut early = BTreeSet::new();
    let mut late = BTreeSet::new();
    match &eq.kind {
        EquationKind::PairSum { init, body, finally, .. } => {
            fields_in(init, &mut early);
            fields_in(body, &mut early);
            fields_in(finally, &mut late);
        }
        EquationKind::Particle { body } => fields_in(body, &mut early),
    }
    let own = |f: &FieldId| eq.writes.contains(f) || model.field(*f).storage == Storage::Temp;
    early.retain(|(f, _)| !own(f));
    let finally = late.into_iter().map(|(f, _)| f).filter(|f| !own(f) && !early.contains(&(*f, Side::I))).collect();
    Reads { early, finally }
}

fn writes_state(model: &Model, e: EqId) -> bool {
    model.is_correction(&model.equations[e.index()])
}

/// The passes, then the corrections and the state-only particle equations, in run order.
pub struct Fused {
    pub passes: Vec<Pass>,
    pub corrections: Vec<EqId>,
    pub derived: Vec<EqId>,
}

pub fn fuse(model: &Model, scene: &SceneSpec, live: &Live) -> Result<Fused, PlanError> {
    let eval: Vec<EqId> = live.dest.keys().copied().filter(|e| !writes_state(model, *e)).collect();
    let corrections_unordered: Vec<EqId> = live.dest.keys().copied().filter(|e| writes_state(model, *e)).collect();
    let reads: BTreeMap<EqId, Reads> = live.dest.keys().map(|e| (*e, reads_of(model, *e))).collect();
    // Writers of each derived field among live evaluation equations.
    let writers = |f: FieldId, groups: GroupSet| -> Vec<EqId> {
        eval.iter()
            .copied()
            .filter(|w| model.equations[w.index()].writes.contains(&f) && !live.dest[w].intersect(groups).is_empty())
            .collect()
    };
    let is_pair = |e: EqId| model.equations[e.index()].is_pair();
    // Levels: pair sum → its pass (≥ 1); particle equation → the pass whose tail runs it (0: update).
    let mut level: BTreeMap<EqId, usize> = BTreeMap::new();
    let mut deps: BTreeMap<EqId, BTreeSet<EqId>> = BTreeMap::new();
    let order = topological(&eval, |e| {
        let r = &reads[&e];
        let eq = &model.equations[e.index()];
        let mut d = BTreeSet::new();
        // A field, or a state a pair sum computes (`writers` finds no other state's writer).
        for &(f, side) in &r.early {
            if model.field(f).storage != Storage::Temp {
                let groups = if side == Side::I { live.dest[&e] } else { eq.sources() };
                d.extend(writers(f, groups));
            }
        }
        for &f in &r.finally {
            if model.field(f).storage != Storage::Temp {
                d.extend(writers(f, live.dest[&e]));
            }
        }
        d.remove(&e);
        d
    })
    .ok_or_else(|| PlanError::new("P0004", "the equations of one step form a cycle"))?;
    for &(e, ref d) in &order {
        deps.insert(e, d.clone());
        let tail_level = |w: &EqId, level: &BTreeMap<EqId, usize>| level[w];
        let r = &reads[&e];
        let early_dep = |w: &EqId| {
            let wf = &model.equations[w.index()].writes;
            r.early.iter().any(|(f, _)| wf.contains(f))
        };
        let l = if is_pair(e) {
            d.iter()
                .map(|w| {
                    let tl = tail_level(w, &level);
                    if early_dep(w) {
                        tl + 1
                    } else {
                        tl.max(1)
                    }
                })
                .max()
                .unwrap_or(1)
                .max(1)
        } else {
            d.iter().map(|w| tail_level(w, &level)).max().unwrap_or(0)
        };
        level.insert(e, l);
    }
    let n_passes = level.iter().filter(|(e, _)| is_pair(**e)).map(|(_, l)| *l).max().unwrap_or(0);
    let mut passes = vec![];
    for k in 1..=n_passes {
        let pair_sums: Vec<EqId> = order.iter().map(|(e, _)| *e).filter(|e| is_pair(*e) && level[e] == k).collect();
        // The tail in dependency order: `order` is topological already.
        let tail: Vec<TailItem> = order
            .iter()
            .map(|(e, _)| *e)
            .filter(|e| level[e] == k)
            .filter_map(|e| {
                let eq = &model.equations[e.index()];
                match &eq.kind {
                    EquationKind::PairSum { finally, .. } if !finally.is_empty() => Some(TailItem::Finally(e)),
                    EquationKind::PairSum { .. } => None,
                    EquationKind::Particle { .. } => Some(TailItem::Particle(e)),
                }
            })
            .collect();
        let variants = scene
            .groups
            .iter(model.groups.len())
            .filter_map(|g| {
                let on = |e: &EqId| live.dest[e].contains(g);
                let ps: Vec<EqId> = pair_sums.iter().copied().filter(on).collect();
                let tl: Vec<TailItem> = tail
                    .iter()
                    .copied()
                    .filter(|t| match t {
                        TailItem::Finally(e) | TailItem::Particle(e) => on(e),
                    })
                    .collect();
                if ps.is_empty() && tl.is_empty() {
                    return None;
                }
                let sources = ps
                    .iter()
                    .fold(GroupSet::default(), |a, e| a.union(model.equations[e.index()].sources_for(g)))
                    .intersect(scene.groups);
                Some(PassVariant { group: g, pair_sums: ps, tail: tl, sources })
            })
            .collect();
        let mut rd = BTreeSet::new();
        let mut wr = BTreeSet::new();
        for (e, _) in order.iter().filter(|(e, _)| level[e] == k) {
            let eq = &model.equations[e.index()];
            for s in stmts_of(eq) {
                let mut fs = BTreeSet::new();
                fields_in(s, &mut fs);
                rd.extend(fs.into_iter().map(|(f, _)| f).filter(|f| model.field(*f).storage != Storage::Temp));
            }
            wr.extend(eq.writes.iter().copied());
        }
        passes.push(Pass {
            pair_sums,
            tail,
            variants,
            reads: rd.into_iter().collect(),
            writes: wr.into_iter().collect(),
        });
    }
    let derived: Vec<EqId> = order.iter().map(|(e, _)| *e).filter(|e| !is_pair(*e) && level[e] == 0).collect();
    let writes_read = |a: &ir::Equation, b: &ir::Equation| b.reads.iter().any(|(f, _)| a.writes.contains(f));
    let corrections = topological(&corrections_unordered, |e| {
        corrections_unordered
            .iter()
            .copied()
            .filter(|w| *w != e && model.correction_before(*w, e, writes_read))
            .collect()
    })
    .ok_or_else(|| PlanError::new("P0005", "the corrections form a cycle"))?
    .into_iter()
    .map(|(e, _)| e)
    .collect();
    Ok(Fused { passes, corrections, derived })
}

/// Kahn's algorithm, stable in the given order; None on a cycle. Returns each node with its deps.
fn topological(nodes: &[EqId], deps_of: impl Fn(EqId) -> BTreeSet<EqId>) -> Option<Vec<(EqId, BTreeSet<EqId>)>> {
    let deps: Vec<BTreeSet<EqId>> =
        nodes.iter().map(|e| deps_of(*e).into_iter().filter(|d| nodes.contains(d)).collect()).collect();
    let mut done: BTreeSet<EqId> = BTreeSet::new();
    let mut out = vec![];
    while out.len() < nodes.len() {
        let before = out.len();
        for (k, e) in nodes.iter().enumerate() {
            if !done.contains(e) && deps[k].iter().all(|d| done.contains(d)) {
                done.insert(*e);
                out.push((*e, deps[k].clone()));
            }
        }
        if out.len() == before {
            return None;
        }
    }
    Some(out)
}
