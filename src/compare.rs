//! Comparing computed values with a reference or with another computation, such that a NaN or an
//! infinity anywhere fails the comparison instead of vanishing in it.
//!
//! `f64::max` drops NaN (`1.0f64.max(NaN) == 1.0`), so a largest difference folded with it passes
//! a run that produced NaN at every particle; and `zip` stops at the shorter side, so a field read
//! back short passes too. Every test that compares numbers, and `pairsum bench`'s check of the
//! generated code against the hand-written step, goes through these functions.
//!
//! Sizing and plotting are not checks: a grid sized by the particles whose h is a number, or a
//! plot's range over the points that are numbers, leaves a NaN out on purpose. They use
//! [`largest_number`] and [`least_number`], which say so, and never `f64::max`.

/// Why two sets of values could not be compared.
#[derive(Clone, Debug, PartialEq)]
pub enum CompareError {
    /// `values[index]` of one side is NaN or infinite.
    NonFinite { side: Side, index: usize, value: f64 },
    /// The two sides hold different numbers of values.
    Length { a: usize, b: usize },
}

/// Which side of a comparison a value came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    A,
    B,
}

impl std::fmt::Display for CompareError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CompareError::NonFinite { side, index, value } => {
                let side = match side {
                    Side::A => "first",
                    Side::B => "second",
                };
                write!(f, "value {index} of the {side} side is {value}, not a finite number")
            }
            CompareError::Length { a, b } => write!(f, "the sides hold {a} and {b} values"),
        }
    }
}

impl std::error::Error for CompareError {}

fn finite(side: Side, values: &[f64]) -> Result<(), CompareError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(CompareError::NonFinite { side, index, value: values[index] }),
        None => Ok(()),
    }
}

fn same_length(a: &[f64], b: &[f64]) -> Result<(), CompareError> {
    if a.len() == b.len() {
        Ok(())
    } else {
        Err(CompareError::Length { a: a.len(), b: b.len() })
    }
}

/// The largest magnitude of `values` (0 for none); an error at the first non-finite value.
pub fn max_abs(values: &[f64]) -> Result<f64, CompareError> {
    finite(Side::A, values)?;
    Ok(values.iter().fold(0.0, |m: f64, v| m.max(v.abs())))
}

/// The least and the largest of `values` (+∞ and −∞ for none); an error at the first non-finite
/// value.
pub fn extremes(values: &[f64]) -> Result<(f64, f64), CompareError> {
    finite(Side::A, values)?;
    Ok(values.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(*v), hi.max(*v))))
}

/// The largest `|a[k] − b[k]|`; an error where a value is not finite or the lengths differ.
pub fn max_abs_diff(a: &[f64], b: &[f64]) -> Result<f64, CompareError> {
    same_length(a, b)?;
    finite(Side::A, a)?;
    finite(Side::B, b)?;
    Ok(a.iter().zip(b).fold(0.0, |m: f64, (x, y)| m.max((x - y).abs())))
}

/// The largest `|a[k] − b[k]|` over the largest magnitude of either side (over 1e-300 when both
/// are all zeros); an error where a value is not finite or the lengths differ.
pub fn max_rel_diff(a: &[f64], b: &[f64]) -> Result<f64, CompareError> {
    let diff = max_abs_diff(a, b)?;
    let scale = max_abs(a)?.max(max_abs(b)?).max(1e-300);
    Ok(diff / scale)
}

/// The largest `|a[k] − b[k]| / |a[k]|`, each difference relative to its own reference value
/// `a[k]`, which must not be zero; an error where a value is not finite or the lengths differ.
pub fn max_pointwise_rel_diff(a: &[f64], b: &[f64]) -> Result<f64, CompareError> {
    same_length(a, b)?;
    finite(Side::A, a)?;
    finite(Side::B, b)?;
    let ratios: Vec<f64> = a.iter().zip(b).map(|(x, y)| (x - y).abs() / x.abs()).collect();
    // A zero reference makes a ratio infinite (or NaN for 0/0): that fails too.
    finite(Side::A, &ratios)?;
    max_abs(&ratios)
}

/// The largest of `start` and those `values` that are numbers: a NaN is left out on purpose (for
/// sizing and plotting; a check must see it, as [`extremes`] does).
pub fn largest_number(start: f64, values: impl IntoIterator<Item = f64>) -> f64 {
    values.into_iter().fold(start, |m, v| if v > m { v } else { m })
}

/// The least of `start` and those `values` that are numbers (as [`largest_number`]).
pub fn least_number(start: f64, values: impl IntoIterator<Item = f64>) -> f64 {
    values.into_iter().fold(start, |m, v| if v < m { v } else { m })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_nan_on_either_side_fails_every_comparison() {
        let good = [1.0, 2.0, 3.0];
        let bad = [1.0, f64::NAN, 3.0];
        let nan_at_1 = |side| CompareError::NonFinite { side, index: 1, value: f64::NAN };
        // NaN != NaN, so compare what was found, not the value.
        let is_nan_at_1 = |r: Result<f64, CompareError>, side| match r {
            Err(CompareError::NonFinite { side: s, index: 1, value }) => s == side && value.is_nan(),
            other => panic!("expected {:?}, got {other:?}", nan_at_1(side)),
        };
        assert!(is_nan_at_1(max_abs(&bad), Side::A));
        assert!(matches!(extremes(&bad), Err(CompareError::NonFinite { side: Side::A, index: 1, .. })));
        assert!(is_nan_at_1(max_abs_diff(&bad, &good), Side::A));
        assert!(is_nan_at_1(max_abs_diff(&good, &bad), Side::B));
        assert!(is_nan_at_1(max_rel_diff(&good, &bad), Side::B));
        assert!(is_nan_at_1(max_pointwise_rel_diff(&good, &bad), Side::B));
        // Both sides NaN at the same place is no agreement either.
        assert!(is_nan_at_1(max_abs_diff(&bad, &bad), Side::A));
        // All NaN, which a fold with f64::max reported as a difference of 0: an error here.
        let all_nan = [f64::NAN; 3];
        assert!(max_abs_diff(&all_nan, &all_nan).is_err());
        assert!(max_rel_diff(&all_nan, &all_nan).is_err());
    }

    #[test]
    fn an_infinity_or_a_zero_reference_fails_and_lengths_must_match() {
        let inf = [0.0, f64::INFINITY];
        assert_eq!(max_abs(&inf), Err(CompareError::NonFinite { side: Side::A, index: 1, value: f64::INFINITY }));
        assert_eq!(max_abs_diff(&[1.0, 2.0], &[1.0]), Err(CompareError::Length { a: 2, b: 1 }));
        assert!(max_pointwise_rel_diff(&[0.0, 1.0], &[0.0, 1.0]).is_err(), "0/0 is not a relative difference");
    }

    #[test]
    fn finite_values_give_the_largest_difference() {
        assert_eq!(max_abs(&[-3.0, 2.0]), Ok(3.0));
        assert_eq!(max_abs_diff(&[1.0, 2.0, 3.0], &[1.5, 2.0, 1.0]), Ok(2.0));
        assert_eq!(max_rel_diff(&[4.0, -8.0], &[4.0, -6.0]), Ok(0.25));
        assert_eq!(max_pointwise_rel_diff(&[4.0, -8.0], &[5.0, -6.0]), Ok(0.25));
        assert_eq!(max_rel_diff(&[0.0], &[0.0]), Ok(0.0));
        assert_eq!(max_abs(&[]), Ok(0.0));
        assert_eq!(extremes(&[2.0, -1.0, 5.0]), Ok((-1.0, 5.0)));
    }
}
