//! `pairsum plan`: the passes, what each fuses, reads and writes, and bytes per particle.

use super::{Action, Plan, TailItem};
use crate::ir::{FieldId, Storage};
use std::fmt::Write;

fn names(plan: &Plan, ids: &[crate::ir::EqId]) -> String {
    ids.iter().map(|e| plan.equation(*e).name.as_str()).collect::<Vec<_>>().join(", ")
}

/// A pass variant's pair sums, each that sees fewer groups than the variant with its own
/// (`continuity (from fluid)`).
fn sums_with_their_neighbours(plan: &Plan, v: &super::PassVariant) -> String {
    let m = &plan.model;
    let each = v.pair_sums.iter().map(|e| {
        let eq = plan.equation(*e);
        let sources = v.sources_of(eq);
        if sources == v.sources {
            eq.name.clone()
        } else {
            format!("{} (from {})", eq.name, m.group_names(sources))
        }
    });
    each.collect::<Vec<_>>().join(", ")
}

fn bytes(plan: &Plan, fields: &[FieldId], real: usize) -> usize {
    fields.iter().filter_map(|f| plan.field_layout(*f)).map(|l| l.comps * real).sum()
}

fn field_list(plan: &Plan, fields: &[FieldId]) -> String {
    fields
        .iter()
        .filter(|f| plan.field_layout(**f).is_some())
        .map(|f| plan.model.field(*f).name.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

pub fn describe(plan: &Plan, real: usize) -> String {
    let m = &plan.model;
    let mut s = String::new();
    let evals = plan.actions.iter().filter(|a| **a == Action::Evaluate).count();
    let _ = writeln!(
        s,
        "plan: {}D, groups {}, kernel {}, integrator {} ({} evaluation(s) per step), {} byte reals",
        plan.dim,
        m.group_names(plan.groups),
        m.kernels[plan.kernel.index()].name,
        plan.integrator.name(),
        evals,
        real
    );
    let _ = writeln!(s, "neighbours: {}", plan.search.describe());
    for p in &plan.planes {
        let axis = crate::ir::AXIS_NAMES[p.axis];
        if p.shift == 0.0 {
            let keeps = if p.side > 0.0 { "" } else { " (the scene below it)" };
            let _ = writeln!(s, "symmetry plane: {axis} = {} m{keeps}", p.offset);
        } else if p.shift > 0.0 {
            let _ = writeln!(s, "periodic: {axis} in [{}, {}) m", p.offset, p.offset + p.shift);
        }
    }
    let x_h: Vec<FieldId> = ["x", "h"].iter().filter_map(|n| m.field_id(n)).collect();
    let mut total_r = 0;
    let mut total_w = 0;
    for (k, p) in plan.passes.iter().enumerate() {
        let _ = writeln!(s, "pass {}: neighbour loop of {}", k + 1, names(plan, &p.pair_sums));
        let tail: Vec<String> = p
            .tail
            .iter()
            .map(|t| match t {
                TailItem::Finally(e) => format!("finally {}", plan.equation(*e).name),
                TailItem::Particle(e) => plan.equation(*e).name.clone(),
            })
            .collect();
        if !tail.is_empty() {
            let _ = writeln!(s, "  then per particle: {}", tail.join(", "));
        }
        for v in &p.variants {
            let _ = writeln!(
                s,
                "  on {} from {}: {}",
                m.groups[v.group.index()].name,
                m.group_names(v.sources),
                sums_with_their_neighbours(plan, v)
            );
        }
        let mut reads = p.reads.clone();
        for f in &x_h {
            if !reads.contains(f) {
                reads.push(*f);
            }
        }
        reads.sort();
        let writes: Vec<FieldId> = p.writes.iter().copied().filter(|f| m.field(*f).storage != Storage::Temp).collect();
        let (r, w) = (bytes(plan, &reads, real), bytes(plan, &writes, real));
        total_r += r;
        total_w += w;
        let _ = writeln!(s, "  reads  {r:>4} B/particle: {}", field_list(plan, &reads));
        let _ = writeln!(s, "  writes {w:>4} B/particle: {}", field_list(plan, &writes));
    }
    for (k, st) in plan.stages.iter().enumerate() {
        let ups: Vec<&str> = st.updates.iter().map(|b| b.name.as_str()).collect();
        let _ = writeln!(
            s,
            "update {} ({}): {}; corrections: {}; then: {}",
            k + 1,
            st.name,
            ups.join(", "),
            if st.corrections.is_empty() { "none".into() } else { names(plan, &st.corrections) },
            if st.derived.is_empty() { "nothing".into() } else { names(plan, &st.derived) }
        );
    }
    let _ = writeln!(s, "per step: passes read {total_r} B and write {total_w} B per particle, per evaluation");
    describe_halo(plan, real, &mut s);
    let _ = writeln!(s, "stored fields:");
    for l in &plan.layout {
        let f = m.field(l.field);
        let _ = writeln!(
            s,
            "  {:<12} {:<10} {:>3} B  on {}",
            f.name,
            f.ty.shape.name(),
            l.comps * real,
            m.group_names(l.groups)
        );
    }
    describe_params(plan, &mut s);
    for g in plan.groups.iter(m.groups.len()) {
        let _ = writeln!(
            s,
            "particle state on {}: {} B/particle",
            m.groups[g.index()].name,
            plan.bytes_per_particle(g, real)
        );
    }
    s
}

/// The halo exchanges of a step (`Plan::halo_exchanges`), with their bytes per halo particle.
fn describe_halo(plan: &Plan, real: usize, s: &mut String) {
    let exchanges = plan.halo_exchanges();
    let total = plan.halo_bytes_per_step(real);
    let _ = writeln!(
        s,
        "halo (a run split into domains): {total} B per step per particle within reach of a domain's edge, in {} exchange(s)",
        exchanges.len()
    );
    for x in &exchanges {
        let _ = writeln!(
            s,
            "  evaluation {}, before pass {}: {} ({} B)",
            x.evaluation + 1,
            x.pass + 1,
            field_list(plan, &x.fields),
            bytes(plan, &x.fields, real)
        );
    }
}

/// The parameters a material binds (`Plan::params_a_material_binds`), as declared, with the groups that read
/// them, their comment and where they are declared: what a case's materials can bind.
fn describe_params(plan: &Plan, s: &mut String) {
    let m = &plan.model;
    let _ = writeln!(
        s,
        "parameters the step reads (a case's material binds them by name; those it leaves take the default after `=`):"
    );
    for (p, groups) in plan.params_a_material_binds() {
        let param = &m.params[p.index()];
        if param.location.is_empty() {
            continue; // the scene's own (a load's value), which no material names
        }
        let by_scene = plan.scene_params.iter().any(|sp| sp.param == p);
        let needed = if by_scene {
            " (set by the scene)"
        } else if param.default.is_none() {
            " (no default)"
        } else {
            ""
        };
        let doc = if param.doc.is_empty() || by_scene { String::new() } else { format!(": {}", param.doc) };
        let at = if param.location.is_empty() { String::new() } else { format!(" ({})", param.location) };
        let _ = writeln!(s, "  {}{needed}  on {}{doc}{at}", param.declared, m.group_names(groups));
    }
}
