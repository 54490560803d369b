//! The neighbour-search schedule: whether a pass searches the cell list at every evaluation, or
//! walks neighbour lists kept across evaluations, and when those lists are rebuilt. Backends ask
//! [`Search::rebuild`] before every evaluation; the rule lives here, once.

use crate::ir::FieldId;

/// How the neighbours of a particle are found.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum Search {
    /// The cell list, searched by every pass of every evaluation (the default: nothing is kept).
    #[default]
    Cells,
    /// Verlet lists: every particle within the cut-off plus a skin, rebuilt for all particles when
    /// particles may have moved (or smoothing lengths grown) enough for a pair outside the lists
    /// to come within the cut-off ([`Drift::exceeds`]). No pair is ever missed.
    Verlet {
        /// The skin as a fraction of the largest cut-off radius (support · h_max) at the build.
        skin: f64,
    },
    /// F-ANS's adaptive search: lists are built for all particles at the first evaluation; after
    /// that a particle's list is rebuilt only when its `field` (the effective plastic strain) has
    /// grown by more than `threshold` since its own last rebuild. Pairs may be missed: this is
    /// F-ANS's approximation, and `threshold = ∞` is its "search at step 0 only".
    Adaptive { field: FieldId, field_name: String, threshold: f64, skin: f64 },
}

/// How far the state has moved from the one the lists were built on.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Drift {
    /// The largest displacement of a particle since the lists were built.
    pub displacement: f64,
    /// The largest growth of a particle's smoothing length since then (0 when none grew).
    pub h_growth: f64,
}

impl Drift {
    /// Whether a pair outside lists built with a skin of length `skin` may now lie within its
    /// cut-off. A pair (i, j) outside i's list was at least `support·h_ij + skin` apart (each
    /// pair's own reach, `h_ij = (h_i + h_j)/2`); it has come closer by at most twice the largest displacement
    /// and its cut-off has grown by at most `support · h_growth`.
    pub fn exceeds(&self, skin: f64, support: f64) -> bool {
        let reach = 2.0 * self.displacement + support * self.h_growth;
        reach > skin || reach.is_nan()
    }
}

/// What a backend does before an evaluation.
#[derive(Clone, Debug, PartialEq)]
pub enum Rebuild {
    /// Nothing: the lists hold every neighbour (or the search is the cell list's).
    Keep,
    /// Build every particle's list.
    All,
    /// Rebuild the lists of the particles whose `field` grew by more than `threshold`.
    Where { field: FieldId, threshold: f64 },
}

impl Search {
    /// Whether passes walk kept lists rather than the cell list.
    pub fn keeps_lists(&self) -> bool {
        !matches!(self, Search::Cells)
    }

    /// Why `skin` cannot be a skin, if it cannot: it is a fraction of the largest cut-off.
    pub fn skin_problem(skin: f64) -> Option<String> {
        let ok = (0.0..=1.0).contains(&skin);
        (!ok).then(|| format!("the skin is a fraction of the largest cut-off between 0 and 1, found {skin}"))
    }

    /// The skin as a fraction of the largest cut-off radius.
    pub fn skin(&self) -> f64 {
        match self {
            Search::Cells => 0.0,
            Search::Verlet { skin } | Search::Adaptive { skin, .. } => *skin,
        }
    }

    /// What to do before an evaluation, given whether lists exist and, for Verlet lists, how far
    /// the state has drifted from their build and the skin's length then.
    pub fn rebuild(&self, built: bool, drift: impl FnOnce() -> (Drift, f64), support: f64) -> Rebuild {
        match self {
            Search::Cells => Rebuild::Keep,
            _ if !built => Rebuild::All,
            Search::Verlet { .. } => {
                let (d, skin) = drift();
                if d.exceeds(skin, support) {
                    Rebuild::All
                } else {
                    Rebuild::Keep
                }
            }
            Search::Adaptive { field, threshold, .. } => Rebuild::Where { field: *field, threshold: *threshold },
        }
    }

    /// One line for `pairsum plan` and the run report.
    pub fn describe(&self) -> String {
        match self {
            Search::Cells => "the cell list, searched by every pass of every evaluation".into(),
            Search::Verlet { skin } => format!(
                "Verlet lists with a skin of {skin} × the largest cut-off, rebuilt for all particles when twice \
                 the largest displacement plus the growth of the cut-off exceeds the skin (no pair is missed)"
            ),
            Search::Adaptive { field_name, threshold, skin, .. } => format!(
                "F-ANS adaptive lists (skin {skin} × the largest cut-off): built at the first evaluation, then a \
                 particle's list is rebuilt when its `{field_name}` has grown by more than {threshold:e} since its \
                 last rebuild (pairs may be missed)"
            ),
        }
    }
}

/// What the neighbour search did over a run.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SearchStats {
    pub evaluations: u64,
    /// Evaluations that rebuilt every list.
    pub full_builds: u64,
    /// Single lists rebuilt (adaptive search).
    pub particle_rebuilds: u64,
}

impl SearchStats {
    pub fn describe(&self, search: &Search) -> Option<String> {
        match search {
            Search::Cells => None,
            Search::Verlet { .. } => {
                Some(format!("neighbour lists: {} full builds over {} evaluations", self.full_builds, self.evaluations))
            }
            Search::Adaptive { .. } => Some(format!(
                "neighbour lists: {} full builds and {} single-particle rebuilds over {} evaluations",
                self.full_builds, self.particle_rebuilds, self.evaluations
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bound_admits_exactly_the_skin() {
        let d = Drift { displacement: 0.05, h_growth: 0.0 };
        assert!(!d.exceeds(0.1, 2.0));
        assert!(d.exceeds(0.0999, 2.0));
        let grown = Drift { displacement: 0.0, h_growth: 0.01 };
        assert!(grown.exceeds(0.019, 2.0));
        assert!(!grown.exceeds(0.02, 2.0));
        assert!(Drift { displacement: f64::NAN, h_growth: 0.0 }.exceeds(1.0, 2.0));
    }

    #[test]
    fn verlet_rebuilds_only_past_the_bound_and_adaptive_asks_per_particle() {
        let v = Search::Verlet { skin: 0.1 };
        let near = || (Drift { displacement: 0.01, h_growth: 0.0 }, 0.1);
        let far = || (Drift { displacement: 0.06, h_growth: 0.0 }, 0.1);
        assert_eq!(v.rebuild(false, near, 2.0), Rebuild::All);
        assert_eq!(v.rebuild(true, near, 2.0), Rebuild::Keep);
        assert_eq!(v.rebuild(true, far, 2.0), Rebuild::All);
        assert_eq!(Search::Cells.rebuild(false, far, 2.0), Rebuild::Keep);
        let a = Search::Adaptive { field: FieldId(3), field_name: "eps_p".into(), threshold: 1e-5, skin: 0.0 };
        assert_eq!(a.rebuild(false, far, 2.0), Rebuild::All);
        assert_eq!(a.rebuild(true, far, 2.0), Rebuild::Where { field: FieldId(3), threshold: 1e-5 });
    }
}
