//! What the particles of a neighbouring domain must bring before each pass (the halos of a run
//! split across processes): the fields that pass reads at j, with the positions and smoothing
//! lengths its search reads, each sent again only when something wrote it since it was last sent.
//! The plan knows both, so a halo carries nothing a pass does not read.

use super::{Action, Plan};
use crate::ir::{set_targets, FieldId, Side};
use std::collections::BTreeSet;

/// The fields sent before one pass of one evaluation of a step.
#[derive(Clone, Debug, PartialEq)]
pub struct HaloExchange {
    /// Which evaluation of the step (from 0).
    pub evaluation: usize,
    /// Which pass of it (from 0).
    pub pass: usize,
    pub fields: Vec<FieldId>,
}

impl Plan {
    /// The stored fields pass `k` reads of its neighbours: what its pair sums read at j, and x
    /// and h, which its search reads.
    pub fn fields_read_at_j(&self, k: usize) -> Vec<FieldId> {
        let mut fields: Vec<FieldId> = ["x", "h"].iter().filter_map(|n| self.model.field_id(n)).collect();
        for e in &self.passes[k].pair_sums {
            for (f, side) in &self.equation(*e).reads {
                if *side == Side::J && !fields.contains(f) {
                    fields.push(*f);
                }
            }
        }
        fields.retain(|f| self.field_layout(*f).is_some());
        fields.sort();
        fields
    }

    /// The halo exchanges of a step once the run is under way: before each pass, the fields it
    /// reads at j that were written since they were last sent (a field no step writes, a mass,
    /// travels only when the halo is rebuilt, with the whole state of the particles that join
    /// it).
    pub fn halo_exchanges(&self) -> Vec<HaloExchange> {
        let mut current: Vec<FieldId> = vec![];
        let mut out = vec![];
        // The second of two steps: the first leaves what a step inherits from the one before.
        for round in 0..2 {
            let mut evaluation = 0;
            for action in &self.actions {
                match *action {
                    Action::Evaluate => {
                        for k in 0..self.passes.len() {
                            let stale: Vec<FieldId> =
                                self.fields_read_at_j(k).into_iter().filter(|f| !current.contains(f)).collect();
                            current.extend(&stale);
                            if round == 1 && !stale.is_empty() {
                                out.push(HaloExchange { evaluation, pass: k, fields: stale });
                            }
                            current.retain(|f| !self.passes[k].writes.contains(f));
                        }
                        evaluation += 1;
                    }
                    Action::Update { stage, .. } => {
                        let written = self.stage_writes(stage);
                        current.retain(|f| !written.contains(f));
                    }
                    Action::Save => {
                        current.retain(|f| self.model.field(*f).saved_of.is_none());
                    }
                    Action::Timestep => {}
                }
            }
        }
        out
    }

    /// The bytes a step's halo exchanges bring per particle of a halo, in reals of `real` bytes.
    pub fn halo_bytes_per_step(&self, real: usize) -> usize {
        let fields = self.halo_exchanges().into_iter().flat_map(|x| x.fields);
        fields.filter_map(|f| self.field_layout(f)).map(|l| l.comps * real).sum()
    }

    /// The fields stage `k` writes: its updates, corrections and derived equations.
    pub fn stage_writes(&self, k: usize) -> Vec<FieldId> {
        let st = &self.stages[k];
        let mut written = BTreeSet::new();
        for b in &st.updates {
            set_targets(&b.stmts, &mut written);
        }
        for e in st.corrections.iter().chain(&st.derived) {
            written.extend(&self.equation(*e).writes);
        }
        written.into_iter().collect()
    }
}
