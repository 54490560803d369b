//! The halos of a run split into domains (`schedule/halo.rs`): before each pass, a domain needs
//! of its neighbours' particles the fields that pass reads at j, and only those that changed
//! since they were last sent.

use pairsum::runner::prepare;
use pairsum::schedule::Plan;
use std::path::Path;

fn plan(name: &str) -> Plan {
    let case = Path::new(env!("CARGO_MANIFEST_DIR")).join("cases").join(format!("{name}.toml"));
    let opts = pairsum::scene::Options { resolution: Some("ci".into()), ..Default::default() };
    prepare(&case, &opts).unwrap_or_else(|e| panic!("{name}: {e}")).1
}

fn names(plan: &Plan, fields: &[pairsum::ir::FieldId]) -> Vec<String> {
    let mut n: Vec<String> = fields.iter().map(|f| plan.model.field(*f).name.clone()).collect();
    n.sort();
    n
}

/// Børvik's perforation model: its first pass reads the state at j (with the mass and smoothing
/// length, which no step writes); its second reads at j the density gradient and the corrected
/// gradient's L⁻¹ the first pass computed (the case's pair forces that conserve momentum send
/// each stress through its own particle's L⁻¹). Per step, each of the two evaluations sends the
/// changed state before pass 1 and the new gradient and L⁻¹ before pass 2; the mass and h, read
/// at j by pass 1, travel only with a rebuilt halo.
#[test]
fn the_perforation_halo_sends_the_state_then_the_density_gradient_and_l_inverse_and_never_the_mass() {
    let p = plan("borvik_perforation");
    let read = names(&p, &p.fields_read_at_j(0));
    assert!(read.contains(&"m".to_string()) && read.contains(&"h".to_string()), "pass 1 reads at j: {read:?}");
    let ex = p.halo_exchanges();
    let got: Vec<(usize, usize, Vec<String>)> =
        ex.iter().map(|x| (x.evaluation, x.pass, names(&p, &x.fields))).collect();
    let state: Vec<String> = ["D", "c", "p", "rho", "s", "v", "x"].iter().map(|s| s.to_string()).collect();
    let gradient = vec!["L_inv".to_string(), "grad_rho".to_string()];
    let expected = vec![(0, 0, state.clone()), (0, 1, gradient.clone()), (1, 0, state), (1, 1, gradient)];
    assert_eq!(got, expected);
}

/// Every field an exchange sends is one its pass reads at j, and each field a pass reads at j
/// that a step writes is sent in every evaluation after its last write and before that pass (the
/// total Lagrangian cantilever: four passes, each reading at j what an earlier one wrote).
#[test]
fn each_pass_of_the_cantilever_receives_every_field_it_reads_at_j_after_its_last_write() {
    let p = plan("cantilever_2d");
    let ex = p.halo_exchanges();
    let by_updates: Vec<_> = (0..p.stages.len()).flat_map(|k| p.stage_writes(k)).collect();
    let evaluations = ex.iter().map(|x| x.evaluation).max().expect("exchanges") + 1;
    assert_eq!(evaluations, 2, "the cantilever's integrator evaluates twice a step");
    let mut checked = 0;
    for e in 0..evaluations {
        for k in 0..p.passes.len() {
            let at_j = p.fields_read_at_j(k);
            for x in ex.iter().filter(|x| x.evaluation == e && x.pass == k) {
                for f in &x.fields {
                    assert!(at_j.contains(f), "pass {k} is sent `{}`, not read at j", p.model.field(*f).name);
                }
            }
            for f in &at_j {
                let last_pass = (0..k).rev().find(|q| p.passes[*q].writes.contains(f));
                let written_later = (k..p.passes.len()).any(|q| p.passes[q].writes.contains(f));
                if last_pass.is_none() && !written_later && !by_updates.contains(f) {
                    continue; // nothing in a step writes it
                }
                let from = last_pass.map_or(0, |q| q + 1);
                let sent = ex.iter().any(|x| x.evaluation == e && (from..=k).contains(&x.pass) && x.fields.contains(f));
                assert!(sent, "evaluation {e}, pass {k}: `{}` is read at j but not sent", p.model.field(*f).name);
                checked += 1;
            }
        }
    }
    assert!(checked >= 16, "only {checked} fields checked");
}
