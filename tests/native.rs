//! The closure backend and the hand-written native step of `pairsum bench` compute the same
//! fused step (continuity, velocity gradient, momentum with viscosity, Jaumann) on a 3D block:
//! each checks the other.

use pairsum::backend::{Backend, Globals};
use pairsum::bench::{compare, elastic_block, native_step};
use pairsum::grid::Grid;

#[test]
fn closure_backend_equals_the_native_step() {
    let mut b = elastic_block(3000).expect("block");
    let h = b.plan.model.field_id("h").expect("h");
    let h_max = pairsum::compare::max_abs(&b.store.column(h).expect("h").data).expect("finite h");
    let x = b.plan.model.field_id("x").expect("x");
    let grid = Grid::build(&b.store.column(x).expect("x").data, 3, b.support * h_max);
    let native = native_step(&b, &grid);
    b.evaluate(Globals::default()).expect("evaluate");
    let diff = compare(&b, &native).unwrap_or_else(|e| panic!("closure against native: {e}"));
    assert!(diff < 1e-12, "closure and native differ by {diff:e} (relative to each field's largest value)");
}
