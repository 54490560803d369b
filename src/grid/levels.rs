//! Cell grids by particle size, for graded scenes: one grid per factor of two in smoothing
//! length, each with cells of half its own largest cut-off over its own particles' box.
//!
//! One grid for every size must either have cells of the coarse cut-off, which a fine particle
//! walks through by the hundred, or cells of the fine one over the coarse plate's whole box.
//! Here the 1 mm particles near the axis have a 1.3 mm grid over their own box and the 4 mm plate
//! its own coarse grid. A particle searches a level only if [`Grid::nearby_max`]'s bound says a
//! particle of that size may lie within its reach, and only as far as the level's largest h
//! needs: no pair is missed, since a neighbour j of i in level L has `h_j ≤ min(h_hi(L), h_near_i)`.
//! With a single size there is one level, the grid [`Grid::build`] gives.

use super::{check_layout, Coord, Grid};

/// The particles whose smoothing length lies within a factor of two, and their grid, whose
/// [`order`](Grid::order) holds the scene's particle indices.
#[derive(Clone, Debug)]
pub struct Level {
    pub grid: Grid,
    /// The smallest and largest smoothing length in the level.
    pub h_lo: f64,
    pub h_hi: f64,
}

impl Level {
    /// How far a particle of smoothing length `h` whose nearby bound is `h_near` (plus `skin`)
    /// must search this level: `None` when no particle of the level can be within its reach.
    #[inline]
    pub fn reach(&self, support: f64, h: f64, h_near: f64, skin: f64) -> Option<f64> {
        (self.h_lo <= h_near).then(|| support * 0.5 * (h + self.h_hi.min(h_near)) + skin)
    }
}

/// The most levels: a particle smaller than the largest by more than 2^(MAX_LEVELS − 1) joins
/// the finest level.
const MAX_LEVELS: usize = 8;

/// The grids of a scene's particle sizes, coarsest first.
#[derive(Clone, Debug)]
pub struct SizeLevels {
    levels: Vec<Level>,
}

impl SizeLevels {
    /// Bins the `x.len() / dim` particles by `h` (level k holds `h_max / 2^(k+1) < h ≤ h_max / 2^k`;
    /// NaN and non-positive h join the finest level) and builds each level's grid with cells of
    /// `(support · h_hi + skin) / 2`: with one level, the grid of one cut-off of the largest h.
    pub fn build<T: Coord>(x: &[T], dim: usize, h: &[T], support: f64, skin: f64) -> SizeLevels {
        let n = check_layout(x, dim);
        assert_eq!(h.len(), n, "levels: {} smoothing lengths for {n} particles", h.len());
        // The largest h that is a number: a NaN h joins the finest level below (the watchdog names
        // it), it does not size the grid.
        let h_max = crate::compare::largest_number(0.0, h.iter().map(|v| v.to_f64()));
        let level_of = |v: T| {
            let ratio = h_max / v.to_f64();
            if ratio.is_finite() && ratio >= 1.0 {
                (ratio.log2().floor() as usize).min(MAX_LEVELS - 1)
            } else {
                MAX_LEVELS - 1
            }
        };
        let mut members: Vec<Vec<u32>> = vec![vec![]; MAX_LEVELS];
        for (i, v) in h.iter().enumerate() {
            members[level_of(*v)].push(i as u32);
        }
        let occupied = members.iter().filter(|m| !m.is_empty()).count();
        let levels = members
            .iter()
            .filter(|m| !m.is_empty())
            .map(|ids| {
                let (lo, hi) = ids.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &i| {
                    let v = h[i as usize].to_f64();
                    (lo.min(v), hi.max(v))
                });
                let cell = 0.5 * (support * hi + skin);
                let grid = if occupied == 1 {
                    Grid::build(x, dim, cell)
                } else {
                    let xs: Vec<T> =
                        ids.iter().flat_map(|&i| &x[i as usize * dim..(i as usize + 1) * dim]).copied().collect();
                    let mut grid = Grid::build(&xs, dim, cell);
                    for o in grid.order.iter_mut() {
                        *o = ids[*o as usize];
                    }
                    grid
                };
                Level { grid, h_lo: lo, h_hi: hi }
            })
            .collect();
        SizeLevels { levels }
    }

    pub fn levels(&self) -> &[Level] {
        &self.levels
    }

    /// Calls `visit` with every run of consecutive candidates (one cell range of a grid's order)
    /// in the cells that a search at `p` walks: in each level as far as `reach` says (usually
    /// [`Level::reach`]), skipping levels it answers `None` for. `ranges` is scratch space for the
    /// cell ranges.
    #[inline(always)]
    pub fn for_each_candidate_run(
        &self,
        p: [f64; 3],
        reach: impl Fn(&Level) -> Option<f64>,
        ranges: &mut Vec<(u32, u32)>,
        mut visit: impl FnMut(&[u32]),
    ) {
        for level in &self.levels {
            let Some(radius) = reach(level) else { continue };
            level.grid.cell_ranges_within(p, radius, ranges);
            let order = level.grid.order();
            for &(s, e) in ranges.iter() {
                visit(&order[s as usize..e as usize]);
            }
        }
    }

    /// As [`for_each_candidate_run`](Self::for_each_candidate_run), one particle index at a time.
    #[inline(always)]
    pub fn for_each_candidate(
        &self,
        p: [f64; 3],
        reach: impl Fn(&Level) -> Option<f64>,
        ranges: &mut Vec<(u32, u32)>,
        mut visit: impl FnMut(u32),
    ) {
        self.for_each_candidate_run(p, reach, ranges, |run| run.iter().for_each(|&j| visit(j)));
    }
}
