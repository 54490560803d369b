//! Splitting the particles into domains, for a run across processes: recursive coordinate
//! bisection balanced by a weight per particle (a count, or a measured cost), and the halo each
//! domain then needs of the others.

use super::{Coord, Grid};
use crate::compare::{extremes, CompareError};

/// The domain (`0..parts`) of each of the `x.len() / dim` particles. The set is cut across the
/// longest side of its bounding box where its weight splits in the ratio of the domains given to
/// each side (⌊parts/2⌋ : ⌈parts/2⌉), and each side is cut again the same way. Deterministic:
/// particles at one coordinate are ordered by index.
/// An error where a position or a weight is not finite.
pub fn bisect<T: Coord>(x: &[T], dim: usize, weight: &[f64], parts: usize) -> Result<Vec<u32>, CompareError> {
    Ok(bisect_with_cuts(x, dim, weight, parts)?.0)
}

/// [`bisect`]'s domains and the planes that cut them, which place any point ([`Cuts::locate`]):
/// a plane lies halfway between the last particle of its low side and the first of its high
/// side, so a particle at the same coordinate on both sides is placed on the high one.
pub fn bisect_with_cuts<T: Coord>(
    x: &[T],
    dim: usize,
    weight: &[f64],
    parts: usize,
) -> Result<(Vec<u32>, Cuts), CompareError> {
    let n = x.len() / dim.max(1);
    assert_eq!(weight.len(), n, "one weight per particle");
    extremes(&as_f64(x))?;
    extremes(weight)?;
    let mut domain = vec![0u32; n];
    let mut all: Vec<u32> = (0..n as u32).collect();
    let cuts = split(x, dim, weight, &mut all, 0, parts.max(1), &mut domain);
    Ok((domain, cuts))
}

/// The planes of a recursive bisection, as a tree.
#[derive(Clone, Debug, PartialEq)]
pub enum Cuts {
    Domain(u32),
    /// Points with `p[axis] < at` are on the `low` side.
    Plane {
        axis: usize,
        at: f64,
        low: Box<Cuts>,
        high: Box<Cuts>,
    },
}

impl Cuts {
    /// The domain of point `p`.
    pub fn locate(&self, p: &[f64]) -> u32 {
        let mut node = self;
        loop {
            match node {
                Cuts::Domain(d) => return *d,
                Cuts::Plane { axis, at, low, high } => node = if p[*axis] < *at { low } else { high },
            }
        }
    }
}

fn as_f64<T: Coord>(values: &[T]) -> Vec<f64> {
    values.iter().map(|v| v.to_f64()).collect()
}

fn split<T: Coord>(
    x: &[T],
    dim: usize,
    weight: &[f64],
    set: &mut [u32],
    first: u32,
    parts: usize,
    domain: &mut [u32],
) -> Cuts {
    if parts == 1 || set.is_empty() {
        set.iter().for_each(|i| domain[*i as usize] = first);
        return Cuts::Domain(first);
    }
    let coord = |i: u32, a: usize| x[i as usize * dim + a].to_f64();
    let axis = (0..dim)
        .map(|a| {
            let (lo, hi) = set
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), i| (lo.min(coord(*i, a)), hi.max(coord(*i, a))));
            (a, hi - lo)
        })
        .fold((0, f64::NEG_INFINITY), |best, (a, extent)| if extent > best.1 { (a, extent) } else { best });
    let axis = axis.0;
    set.sort_by(|p, q| coord(*p, axis).total_cmp(&coord(*q, axis)).then(p.cmp(q)));
    let low_parts = parts / 2;
    let total: f64 = set.iter().map(|i| weight[*i as usize]).sum();
    let target = total * low_parts as f64 / parts as f64;
    // The cut: the first count whose running weight reaches the low side's share.
    let mut running = 0.0;
    let mut cut = set.len();
    for (k, i) in set.iter().enumerate() {
        if running >= target {
            cut = k;
            break;
        }
        running += weight[*i as usize];
    }
    let at = match cut {
        0 => f64::NEG_INFINITY,
        k if k == set.len() => f64::INFINITY,
        k => 0.5 * (coord(set[k - 1], axis) + coord(set[k], axis)),
    };
    let (low, high) = set.split_at_mut(cut);
    let low = split(x, dim, weight, low, first, low_parts, domain);
    let high = split(x, dim, weight, high, first + low_parts as u32, parts - low_parts, domain);
    Cuts::Plane { axis, at, low: Box::new(low), high: Box::new(high) }
}

/// Per domain, how many particles of the other domains lie within reach of one of its own:
/// within `support · (h_i + h_j) / 2`, the cut-off of the pair. An error where a position or a
/// smoothing length is not finite.
pub fn halo_sizes<T: Coord>(
    x: &[T],
    dim: usize,
    h: &[T],
    support: f64,
    domain: &[u32],
    parts: usize,
) -> Result<Vec<usize>, CompareError> {
    let n = domain.len();
    extremes(&as_f64(x))?;
    let (_, h_max) = extremes(&as_f64(h))?;
    let grid = Grid::build(x, dim, support * h_max);
    // Bit d of `in_halo[j]`: particle j is in domain d's halo (at most 64 domains).
    assert!(parts <= 64, "at most 64 domains");
    let mut in_halo = vec![0u64; n];
    for i in 0..n {
        let mut p = [0.0; 3];
        for (a, c) in p.iter_mut().enumerate().take(dim) {
            *c = x[i * dim + a].to_f64();
        }
        let di = domain[i];
        grid.for_each_candidate(p, |j| {
            let j = j as usize;
            if domain[j] == di {
                return;
            }
            let r2: f64 = (0..dim).map(|a| (x[i * dim + a].to_f64() - x[j * dim + a].to_f64()).powi(2)).sum();
            let reach = support * 0.5 * (h[i].to_f64() + h[j].to_f64());
            if r2 < reach * reach {
                in_halo[j] |= 1 << di;
            }
        });
    }
    Ok((0..parts).map(|d| in_halo.iter().filter(|m| *m >> d & 1 == 1).count()).collect())
}
