//! Probes: what a case measures during a run — a field component reduced over a body, or a named
//! measurement with a documented, automatic definition — and the results taken from them.

use super::build::{ProbeKind, ProbeSpec, ResultSpec, Scene};
use crate::backend::Backend;

/// Named measurements and what each reads.
pub const NAMES: [&str; 3] = ["min_interbody_distance", "interpenetrated", "front_position"];

pub fn fields_needed(name: &str) -> Vec<&'static str> {
    match name {
        "min_interbody_distance" | "interpenetrated" => vec!["x"],
        "front_position" => vec!["x", "v"],
        _ => vec![],
    }
}

/// The recorded history of a probe.
#[derive(Clone, Debug, Default)]
pub struct History {
    pub points: Vec<(f64, f64)>,
    initial: Option<f64>,
}

/// Each particle's body, in the backend's current order.
fn bodies_now(scene: &Scene, ids: &[u32]) -> Vec<u32> {
    ids.iter().map(|i| scene.particles.body[*i as usize]).collect()
}

/// Positions in the backend's current order.
pub fn positions(b: &dyn Backend) -> Option<Vec<[f64; 3]>> {
    let x = b.plan().model.field_id("x")?;
    let (c, v) = b.read(x)?;
    Some(
        (0..v.len() / c)
            .map(|k| {
                let mut p = [0.0; 3];
                p[..c].copy_from_slice(&v[k * c..(k + 1) * c]);
                p
            })
            .collect(),
    )
}

/// The value of a probe now.
pub fn evaluate(p: &ProbeSpec, scene: &Scene, b: &dyn Backend) -> f64 {
    match &p.kind {
        ProbeKind::Field { select, field, component, reduce, .. } => {
            let Some((comps, values)) = b.read(*field) else { return f64::NAN };
            let ids = b.ids();
            let selected: Vec<f64> = (0..ids.len())
                .filter(|k| select.as_ref().is_none_or(|s| s[ids[*k] as usize]))
                .map(|k| values[k * comps + component])
                .filter(|v| !v.is_nan())
                .collect();
            reduce_values(reduce, &selected)
        }
        ProbeKind::Measure(name) => measure(name, scene, b),
    }
}

fn reduce_values(reduce: &str, v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    match reduce {
        "min" => v.iter().copied().fold(f64::INFINITY, f64::min),
        "max" => v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        "abs_max" => v.iter().map(|x| x.abs()).fold(0.0, f64::max),
        "sum" => v.iter().sum(),
        _ => v.iter().sum::<f64>() / v.len() as f64,
    }
}

fn measure(name: &str, scene: &Scene, b: &dyn Backend) -> f64 {
    let Some(x) = positions(b) else { return f64::NAN };
    let which = bodies_now(scene, &b.ids());
    let dim = b.plan().dim;
    match name {
        // The least distance between a particle of the first body and one of the second, over Δx.
        "min_interbody_distance" => interbody(&x, &which, dim, scene.dx).0 / scene.dx,
        // Particles of the first two bodies closer than Δx/2 to a particle of the other body.
        "interpenetrated" => interbody(&x, &which, dim, scene.dx).1 as f64,
        // Where a wave front driven by the first body has got to.
        "front_position" => front_position(&x, &which, b),
        _ => f64::NAN,
    }
}

/// Where a wave front driven by the first body has got to: along the first axis, the position at
/// which the speed falls through half the driver's mean speed, interpolated linearly between the
/// last particle above and the next one below (particles ordered by position).
fn front_position(x: &[[f64; 3]], body: &[u32], b: &dyn Backend) -> f64 {
    let Some(v) = b.plan().model.field_id("v") else { return f64::NAN };
    let Some((c, v)) = b.read(v) else { return f64::NAN };
    let speed: Vec<f64> =
        (0..x.len()).map(|k| v[k * c..(k + 1) * c].iter().map(|u| u * u).sum::<f64>().sqrt()).collect();
    let driver: Vec<f64> = (0..x.len()).filter(|k| body[*k] == 0).map(|k| speed[k]).collect();
    if driver.is_empty() {
        return f64::NAN;
    }
    let half = 0.5 * driver.iter().sum::<f64>() / driver.len() as f64;
    let mut order: Vec<usize> = (0..x.len()).collect();
    order.sort_by(|a, b| x[*a][0].total_cmp(&x[*b][0]));
    let last_above = order.iter().rposition(|k| speed[*k] > half);
    match last_above {
        Some(p) if p + 1 < order.len() => {
            let (a, b) = (order[p], order[p + 1]);
            let t = (speed[a] - half) / (speed[a] - speed[b]);
            x[a][0] + t * (x[b][0] - x[a][0])
        }
        Some(p) => x[order[p]][0],
        None => f64::NAN,
    }
}

/// (least distance between bodies 0 and 1, number of particles of either closer than Δx/2 to the
/// other body). Neighbours come from a cell list of body 1; if no pair is within two spacings, the
/// distance is found by brute force (bodies still apart).
fn interbody(x: &[[f64; 3]], body: &[u32], dim: usize, dx: f64) -> (f64, usize) {
    let a: Vec<usize> = (0..x.len()).filter(|k| body[*k] == 0).collect();
    let b: Vec<usize> = (0..x.len()).filter(|k| body[*k] == 1).collect();
    if a.is_empty() || b.is_empty() {
        return (f64::NAN, 0);
    }
    let flat: Vec<f64> = b.iter().flat_map(|k| x[*k][..dim].to_vec()).collect();
    let grid = crate::grid::Grid::build(&flat, dim, 2.0 * dx);
    let dist = |p: [f64; 3], q: [f64; 3]| (0..dim).map(|c| (p[c] - q[c]).powi(2)).sum::<f64>().sqrt();
    let mut least = f64::INFINITY;
    let mut close_a = 0;
    let mut close_b = vec![false; b.len()];
    for &i in &a {
        let mut near = false;
        grid.for_each_candidate(x[i], |j| {
            let r = dist(x[i], x[b[j as usize]]);
            least = least.min(r);
            if r < 0.5 * dx {
                near = true;
                close_b[j as usize] = true;
            }
        });
        close_a += usize::from(near);
    }
    if least > 2.0 * dx && a.len().saturating_mul(b.len()) <= 100_000_000 {
        for &i in &a {
            for &j in &b {
                least = least.min(dist(x[i], x[j]));
            }
        }
    }
    (least, close_a + close_b.iter().filter(|c| **c).count())
}

impl History {
    pub fn record(&mut self, p: &ProbeSpec, t: f64, value: f64) {
        let relative = matches!(p.kind, ProbeKind::Field { relative: true, .. });
        let base = *self.initial.get_or_insert(value);
        self.points.push((t, if relative { value - base } else { value }));
    }
}

/// A result from its probe's history.
pub fn result_value(r: &ResultSpec, h: &History) -> f64 {
    let pts = &h.points;
    let v = match r.at.as_str() {
        "min" => pts.iter().map(|p| p.1).fold(f64::INFINITY, f64::min),
        "max" => pts.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max),
        "abs_max" => pts.iter().map(|p| p.1.abs()).fold(0.0, f64::max),
        "mean_after" => {
            let from = r.from.unwrap_or(0.0);
            let sel: Vec<f64> = pts.iter().filter(|p| p.0 >= from).map(|p| p.1).collect();
            if sel.is_empty() {
                f64::NAN
            } else {
                sel.iter().sum::<f64>() / sel.len() as f64
            }
        }
        // The least-squares slope of the history between `from` and `to`.
        "slope" => {
            let (from, to) = (r.from.unwrap_or(f64::NEG_INFINITY), r.to.unwrap_or(f64::INFINITY));
            let sel: Vec<(f64, f64)> =
                pts.iter().copied().filter(|p| p.0 >= from && p.0 <= to && p.1.is_finite()).collect();
            let n = sel.len() as f64;
            if sel.len() < 2 {
                f64::NAN
            } else {
                let (mt, mv) = (sel.iter().map(|p| p.0).sum::<f64>() / n, sel.iter().map(|p| p.1).sum::<f64>() / n);
                let cov: f64 = sel.iter().map(|p| (p.0 - mt) * (p.1 - mv)).sum();
                let var: f64 = sel.iter().map(|p| (p.0 - mt).powi(2)).sum();
                cov / var
            }
        }
        _ => pts.last().map(|p| p.1).unwrap_or(f64::NAN),
    };
    v * r.scale
}
