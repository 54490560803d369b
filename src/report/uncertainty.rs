//! The numerical uncertainty of a convergence study's finest value, from power laws in the
//! spacing fitted in the least-squares sense through all of its levels (four or more), after
//! Eça & Hoekstra (J. Comput. Phys. 262 (2014) 104–130).
//!
//! Three levels fix `f0 + C Δx^p` exactly, so a level's own scatter (where a body's edge falls
//! on the lattice, which particle fails first) moves the order and the Richardson value at will,
//! and scatter as large as the steps leaves no order at all. Fitted through every level, the
//! scatter averages out and its size, the fit's standard deviation σ, enters the uncertainty.
//!
//! The procedure, as implemented here:
//! - Each law is fitted twice, unweighted and with the weights `w_i ∝ 1/Δx_i` (the finer levels
//!   count more), and the one with the smaller σ is kept; σ² = n Σ w_i r_i² / (n − k) for `n`
//!   levels, `k` fitted constants and the residuals `r_i`.
//! - The observed order `p` is that of the best `f0 + α Δx^p`, `p` searched over [0.05, 8].
//! - The error is estimated with that fit where 0.95 ≤ p ≤ 2.05. Otherwise an order outside the
//!   range SPH's kernel sums reach says the levels are not yet in the asymptotic range, and the
//!   error is estimated with the fit of the smallest σ among laws of fixed order: where p > 2.05,
//!   `f0 + α Δx` and `f0 + α Δx²`; where p < 0.95, `f0 + α Δx` and the observed-order fit (not
//!   where p lies at the search's lower bound: levels whose steps do not shrink follow no power); and
//!   with five levels or more, `f0 + α1 Δx + α2 Δx²` too, where it has no extremum between zero
//!   and the coarsest spacing (through four levels its one degree of freedom rates it on a single
//!   residual, and one that turns back bends to follow a coarse level's kink and extrapolates past
//!   every level).
//!   These choices among the fixed-order laws are this code's; the fits, their weighting, σ, the
//!   data range and the safety factors are Eça & Hoekstra's.
//! - The error of the finest value is `ε = |fit(Δx_1) − f0|`; the data's range is
//!   `Δφ = (max f − min f) / (n − 1)`.
//! - Where σ < Δφ the uncertainty is `U = Fs ε + σ + |f_1 − fit(Δx_1)|`, with the safety factor
//!   `Fs` 1.25 where 0.5 ≤ p < 2.1 and 3 otherwise; where the scatter is as large as the data's
//!   range, `U = 3 (σ/Δφ) (ε + σ + |f_1 − fit(Δx_1)|)`.
//! - With five levels or more, the observed order is also fitted leaving out each level in turn
//!   ([`Uncertainty::order_without_one`]): an order that holds moves little whichever level is left
//!   out, and one that rests on a single level (the coarsest, out of the asymptotic range; the
//!   finest, off by its own scatter) swings. This check is ours, not Eça & Hoekstra's.

/// The power law a [`Fit`] fits in the spacing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Law {
    /// `f0 + α Δx^p`, `p` fitted too.
    Power(f64),
    /// `f0 + α Δx`.
    First,
    /// `f0 + α Δx²`.
    Second,
    /// `f0 + α1 Δx + α2 Δx²`.
    FirstSecond,
}

impl Law {
    /// The law's terms other than the constant at `h`.
    fn terms(&self, h: f64) -> Vec<f64> {
        match self {
            Law::Power(p) => vec![h.powf(*p)],
            Law::First => vec![h],
            Law::Second => vec![h * h],
            Law::FirstSecond => vec![h, h * h],
        }
    }

    /// How many constants it fits: `f0`, the α's, and `p` for [`Law::Power`].
    fn constants(&self) -> usize {
        match self {
            Law::First | Law::Second => 2,
            Law::Power(_) | Law::FirstSecond => 3,
        }
    }

    pub fn describe(&self) -> String {
        match self {
            Law::Power(p) => format!("f0 + α Δx^{p:.2}"),
            Law::First => "f0 + α Δx".into(),
            Law::Second => "f0 + α Δx²".into(),
            Law::FirstSecond => "f0 + α1 Δx + α2 Δx²".into(),
        }
    }
}

/// A law fitted through the levels.
#[derive(Clone, Debug, PartialEq)]
pub struct Fit {
    pub law: Law,
    /// `f0`, then the α's, for the spacing over the finest level's.
    pub constants: Vec<f64>,
    /// Whether the finer levels were weighted more (`w_i ∝ 1/Δx_i`).
    pub weighted: bool,
    /// The fit's standard deviation.
    pub sigma: f64,
}

impl Fit {
    /// The fitted value at spacing `h` (over the finest level's).
    pub fn at(&self, h: f64) -> f64 {
        self.constants[0] + self.law.terms(h).iter().zip(&self.constants[1..]).map(|(t, a)| t * a).sum::<f64>()
    }

    /// The value at zero spacing.
    pub fn limit(&self) -> f64 {
        self.constants[0]
    }
}

/// The finest level's numerical uncertainty.
#[derive(Clone, Debug, PartialEq)]
pub struct Uncertainty {
    /// The best `f0 + α Δx^p`: the observed order.
    pub observed: Fit,
    /// The fit the error is estimated with.
    pub chosen: Fit,
    /// The finest level's spacing and value, as given.
    pub finest: (f64, f64),
    /// `(max f − min f) / (n − 1)`.
    pub data_range: f64,
    /// The finest level's error estimate, `|fit(Δx_1) − f0|`.
    pub error: f64,
    /// The safety factor, 1.25 or 3 (`U`'s second form has none).
    pub safety: f64,
    /// The uncertainty `U`: the finest value ± U is meant to hold the value at zero spacing.
    pub u: f64,
    /// With five levels or more, the least and the greatest observed order of the fits leaving
    /// out one level each: how far the order rests on any one level.
    pub order_without_one: Option<(f64, f64)>,
}

impl Uncertainty {
    /// The observed order.
    pub fn order(&self) -> f64 {
        match self.observed.law {
            Law::Power(p) => p,
            _ => unreachable!("the observed fit is a power law"),
        }
    }

    /// The least and greatest order leaving out one level, as text (`0.96–1.65`), each marked
    /// as [`Uncertainty::describe_order`] marks the search's bounds; none with four levels.
    pub fn describe_order_without_one(&self) -> Option<String> {
        let (lo, hi) = self.order_without_one?;
        Some(format!("{}–{}", describe_order(lo), describe_order(hi)))
    }

    /// How far the reference `r` lies beyond the finest value ± U; zero or less where within.
    pub fn beyond(&self, r: f64) -> f64 {
        (self.finest.1 - r).abs() - self.u
    }

    /// The observed order as text: marked where it lies at the search's bound (no power fits
    /// better), none where the levels are all equal.
    pub fn describe_order(&self) -> String {
        if self.data_range == 0.0 {
            return "none: unchanged".into();
        }
        let p = self.order();
        bound(p).map_or_else(|| describe_order(p), |b| format!("{b} (the search's bound)"))
    }
}

/// An order at the search's lower bound ([`ORDERS`]): no power fits better than the flattest.
fn at_lower_bound(p: f64) -> bool {
    p <= ORDERS.0 * (1.0 + 1e-6)
}

/// `≥ 8` or `≤ 0.05` where an order lies at a bound of the search ([`ORDERS`]).
fn bound(p: f64) -> Option<String> {
    if p >= ORDERS.1 * (1.0 - 1e-6) {
        Some(format!("≥ {}", ORDERS.1))
    } else if at_lower_bound(p) {
        Some(format!("≤ {}", ORDERS.0))
    } else {
        None
    }
}

/// An order to two decimals, or its bound.
fn describe_order(p: f64) -> String {
    bound(p).unwrap_or_else(|| format!("{p:.2}"))
}

/// The uncertainty of the finest of `points` (spacing, value; any order), or `None` with fewer
/// than four levels, a spacing repeated or not positive, or a value not finite.
pub fn uncertainty(points: &[(f64, f64)]) -> Option<Uncertainty> {
    let n = points.len();
    let finest = finest_of(points)?;
    // Spacings over the finest's: the fits' equations stay well scaled whatever the unit.
    let scaled: Vec<(f64, f64)> = points.iter().map(|(h, f)| (h / finest.0, *f)).collect();
    let points = &scaled[..];
    let observed = best_power(points)?;
    let p = match observed.law {
        Law::Power(p) => p,
        _ => unreachable!(),
    };
    let mut candidates = vec![];
    if (0.95..=2.05).contains(&p) {
        candidates.push(observed.clone());
    } else {
        candidates.push(best_weighting(points, Law::First)?);
        if p > 2.05 {
            candidates.push(best_weighting(points, Law::Second)?);
        } else if !at_lower_bound(p) {
            candidates.push(observed.clone());
        }
        if n >= 5 {
            let coarsest = points.iter().fold(0.0f64, |a, q| a.max(q.0));
            candidates.extend(best_weighting(points, Law::FirstSecond).filter(|f| monotone(f, coarsest)));
        }
    }
    let chosen = candidates.into_iter().min_by(|a, b| a.sigma.total_cmp(&b.sigma))?;
    let (lo, hi) = points.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, q| (a.0.min(q.1), a.1.max(q.1)));
    let data_range = (hi - lo) / (n - 1) as f64;
    let fitted = chosen.at(1.0);
    let error = (fitted - chosen.limit()).abs();
    let miss = (finest.1 - fitted).abs();
    let sigma = chosen.sigma;
    let good = (0.5..2.1).contains(&p) && sigma < data_range;
    let safety = if good { 1.25 } else { 3.0 };
    let u = if data_range == 0.0 {
        0.0
    } else if sigma < data_range {
        safety * error + sigma + miss
    } else {
        3.0 * sigma / data_range * (error + sigma + miss)
    };
    let order_without_one = (n >= 5).then(|| leave_one_out(points)).flatten();
    Some(Uncertainty { observed, chosen, finest, data_range, error, safety, u, order_without_one })
}

/// The finest of `points` (spacing, value), or `None` with fewer than four levels, a spacing
/// repeated or not positive, or a value not finite: what [`uncertainty`] needs of its levels.
fn finest_of(points: &[(f64, f64)]) -> Option<(f64, f64)> {
    let valid = points.iter().all(|(h, f)| *h > 0.0 && h.is_finite() && f.is_finite());
    let mut sorted: Vec<f64> = points.iter().map(|p| p.0).collect();
    sorted.sort_by(f64::total_cmp);
    if points.len() < 4 || !valid || sorted.windows(2).any(|w| w[1] <= w[0] * (1.0 + 1e-9)) {
        return None;
    }
    points.iter().min_by(|a, b| a.0.total_cmp(&b.0)).copied()
}

/// How far the levels' own noise moves the observed order and the value at zero spacing, where
/// each level's value is a mean over runs with a standard error (a study's `mean`): a parametric
/// bootstrap. The levels are drawn again [`DRAWS`] times, each value moved by a normal deviate
/// times its standard error, and the best `f0 + α Δx^p` is fitted through every draw as through
/// the levels themselves. An order that holds keeps a narrow range; one the noise makes up
/// ranges over the search.
#[derive(Clone, Debug, PartialEq)]
pub struct UnderNoise {
    /// The 10th and the 90th percentile of the observed order over the draws.
    pub order: (f64, f64),
    /// The same of the observed fit's `f0`.
    pub limit: (f64, f64),
    /// How many steps between neighbouring levels exceed twice their combined standard error
    /// (√(s_i² + s_j²)), and how many steps there are.
    pub resolved_steps: (usize, usize),
    /// How likely levels that do not depend on the spacing at all would lie as far from their
    /// weighted mean (weights 1/s²) as these do: the χ² test with n − 1 degrees of freedom.
    /// Above 0.05 the levels are one value within their noise, and no order can be read from
    /// them; `None` where a standard error is 0.
    pub constant_fits: Option<f64>,
    /// The levels' mean weighted by 1/s², and its standard error (1/√Σ 1/s²): the value where a
    /// constant fits.
    pub constant: Option<(f64, f64)>,
    /// `f0` of `f0 + α Δx` fitted with the weights 1/s², and its standard error: the value at
    /// zero spacing where a first-order error may hide within the noise.
    pub first_order: Option<(f64, f64)>,
}

impl UnderNoise {
    /// The order's range as text (`0.62–1.48`), its bounds marked as [`Uncertainty::describe_order`] marks them.
    pub fn describe_order(&self) -> String {
        format!("{}–{}", describe_order(self.order.0), describe_order(self.order.1))
    }
}

/// The draws [`under_noise`] makes; its generator is seeded, so a report is reproducible.
pub const DRAWS: usize = 400;

/// [`UnderNoise`] of `points` (spacing, value, standard error; any order); `None` where
/// [`uncertainty`] has none or a standard error is negative or not finite.
pub fn under_noise(points: &[(f64, f64, f64)]) -> Option<UnderNoise> {
    if points.iter().any(|p| !(p.2 >= 0.0 && p.2.is_finite())) {
        return None;
    }
    let mut sorted = points.to_vec();
    sorted.sort_by(|a, b| b.0.total_cmp(&a.0));
    let levels: Vec<(f64, f64)> = sorted.iter().map(|p| (p.0, p.1)).collect();
    let finest = finest_of(&levels)?.0;
    let resolved = sorted.windows(2).filter(|w| (w[1].1 - w[0].1).abs() > 2.0 * w[0].2.hypot(w[1].2)).count();
    let mut normal = Normal::seeded(0x5eed_0f11_a77c_e500);
    let (mut orders, mut limits) = (Vec::with_capacity(DRAWS), Vec::with_capacity(DRAWS));
    for _ in 0..DRAWS {
        let drawn: Vec<(f64, f64)> = sorted.iter().map(|(h, f, s)| (h / finest, f + s * normal.next())).collect();
        let fit = best_power(&drawn)?;
        let Law::Power(p) = fit.law else { return None };
        orders.push(p);
        limits.push(fit.limit());
    }
    let weighted = weighted(&sorted);
    Some(UnderNoise {
        order: percentiles(&mut orders),
        limit: percentiles(&mut limits),
        resolved_steps: (resolved, sorted.len() - 1),
        constant_fits: weighted.as_ref().map(|w| w.constant_fits),
        constant: weighted.as_ref().map(|w| w.constant),
        first_order: weighted.map(|w| w.first_order),
    })
}

/// The levels fitted with the weights 1/s² (see [`UnderNoise`]).
struct Weighted {
    constant_fits: f64,
    constant: (f64, f64),
    first_order: (f64, f64),
}

/// [`Weighted`] of `points` (spacing, value, standard error); `None` where a standard error is 0.
fn weighted(points: &[(f64, f64, f64)]) -> Option<Weighted> {
    if points.iter().any(|p| p.2 <= 0.0) {
        return None;
    }
    let sum = |f: &dyn Fn(f64, f64) -> f64| points.iter().map(|(h, v, s)| f(*h, *v) / (s * s)).sum::<f64>();
    let (w, wh, whh, wf, whf) =
        (sum(&|_, _| 1.0), sum(&|h, _| h), sum(&|h, _| h * h), sum(&|_, f| f), sum(&|h, f| h * f));
    let mean = wf / w;
    let chi2 = sum(&|_, f| (f - mean).powi(2));
    let det = w * whh - wh * wh;
    Some(Weighted {
        constant_fits: upper_gamma_regularised(0.5 * (points.len() - 1) as f64, 0.5 * chi2),
        constant: (mean, w.sqrt().recip()),
        first_order: ((whh * wf - wh * whf) / det, (whh / det).sqrt()),
    })
}

/// Q(a, x) = Γ(a, x) / Γ(a), the chance that χ² with 2a degrees of freedom exceeds 2x: its
/// series below x = a + 1, its continued fraction (Lentz) above (Numerical Recipes §6.2).
fn upper_gamma_regularised(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let front = (a * x.ln() - x - ln_gamma(a)).exp();
    if x < a + 1.0 {
        let (mut term, mut sum, mut n) = (1.0 / a, 1.0 / a, a);
        while term.abs() > sum.abs() * 1e-15 {
            n += 1.0;
            term *= x / n;
            sum += term;
        }
        (1.0 - sum * front).max(0.0)
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let (mut c, mut d) = (1.0 / tiny, 1.0 / b);
        let mut h = d;
        for i in 1..300 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            d = if d.abs() < tiny { tiny } else { d };
            c = b + an / c;
            c = if c.abs() < tiny { tiny } else { c };
            d = 1.0 / d;
            let step = d * c;
            h *= step;
            if (step - 1.0).abs() < 1e-15 {
                break;
            }
        }
        front * h
    }
}

/// ln Γ(x) for x > 0 (Lanczos, g = 7, nine terms; relative error below 1e-13).
fn ln_gamma(x: f64) -> f64 {
    const G: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    let x = x - 1.0;
    let t = x + 7.5;
    let sum = G[0] + (1..9).map(|i| G[i] / (x + i as f64)).sum::<f64>();
    0.5 * std::f64::consts::TAU.ln() + (x + 0.5) * t.ln() - t + sum.ln()
}

/// The 10th and the 90th percentile (the nearest rank).
fn percentiles(values: &mut [f64]) -> (f64, f64) {
    values.sort_by(f64::total_cmp);
    let at = |q: f64| values[((values.len() - 1) as f64 * q).round() as usize];
    (at(0.1), at(0.9))
}

/// Standard normal deviates: SplitMix64's integers through the Box–Muller transform.
struct Normal {
    state: u64,
}

impl Normal {
    fn seeded(seed: u64) -> Normal {
        Normal { state: seed }
    }

    /// A uniform deviate in (0, 1].
    fn uniform(&mut self) -> f64 {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        ((z >> 11) as f64 + 1.0) / (1u64 << 53) as f64
    }

    fn next(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

/// The least and the greatest observed order of the fits through `points` less one level each.
fn leave_one_out(points: &[(f64, f64)]) -> Option<(f64, f64)> {
    let mut range = (f64::INFINITY, f64::NEG_INFINITY);
    for k in 0..points.len() {
        let rest: Vec<(f64, f64)> = points.iter().enumerate().filter(|(i, _)| *i != k).map(|(_, q)| *q).collect();
        let Law::Power(p) = best_power(&rest)?.law else { return None };
        range = (range.0.min(p), range.1.max(p));
    }
    Some(range)
}

/// The orders the observed order is searched over.
pub const ORDERS: (f64, f64) = (0.05, 8.0);

/// The best `f0 + α Δx^p` over `p` in [`ORDERS`], of the two weightings.
fn best_power(points: &[(f64, f64)]) -> Option<Fit> {
    let (lo, hi) = ORDERS;
    let grid = 400;
    let p_at = |k: usize| lo * (hi / lo).powf(k as f64 / grid as f64);
    let mut best: Option<Fit> = None;
    for weighted in [false, true] {
        let sum = |p: f64| fit(points, Law::Power(p), weighted).map_or(f64::INFINITY, |f| f.sigma);
        let sums: Vec<f64> = (0..=grid).map(|k| sum(p_at(k))).collect();
        let k = (0..=grid).min_by(|a, b| sums[*a].total_cmp(&sums[*b]))?;
        // Golden-section search between the grid's neighbours of the best.
        let (mut a, mut b) = (p_at(k.saturating_sub(1)), p_at((k + 1).min(grid)));
        let g = 0.5 * (5f64.sqrt() - 1.0);
        for _ in 0..80 {
            let (c, d) = (b - g * (b - a), a + g * (b - a));
            if sum(c) <= sum(d) {
                b = d;
            } else {
                a = c;
            }
        }
        let p = 0.5 * (a + b);
        let candidate = fit(points, Law::Power(p), weighted)?;
        if best.as_ref().is_none_or(|b| candidate.sigma < b.sigma) {
            best = Some(candidate);
        }
    }
    best
}

/// Whether `f0 + α1 Δx + α2 Δx²` has no extremum between zero spacing and `coarsest`: one that
/// turns back extrapolates past the levels it bends to follow (a coarse level's kink).
fn monotone(fit: &Fit, coarsest: f64) -> bool {
    let (a1, a2) = (fit.constants[1], fit.constants[2]);
    let turn = -a1 / (2.0 * a2);
    !(turn > 0.0 && turn < coarsest)
}

/// `law` fitted both ways; the one with the smaller σ.
fn best_weighting(points: &[(f64, f64)], law: Law) -> Option<Fit> {
    let (a, b) = (fit(points, law, false)?, fit(points, law, true)?);
    Some(if b.sigma < a.sigma { b } else { a })
}

/// `law` fitted through `points` in the least-squares sense, unweighted or with `w_i ∝ 1/Δx_i`.
fn fit(points: &[(f64, f64)], law: Law, weighted: bool) -> Option<Fit> {
    let n = points.len();
    let inverse: f64 = points.iter().map(|p| 1.0 / p.0).sum();
    let weight = |h: f64| if weighted { 1.0 / h / inverse } else { 1.0 / n as f64 };
    let rows: Vec<Vec<f64>> = points.iter().map(|(h, _)| [vec![1.0], law.terms(*h)].concat()).collect();
    let m = rows[0].len();
    let (mut a, mut b) = (vec![vec![0.0; m]; m], vec![0.0; m]);
    for ((h, f), row) in points.iter().zip(&rows) {
        let w = weight(*h);
        for i in 0..m {
            b[i] += w * row[i] * f;
            for j in 0..m {
                a[i][j] += w * row[i] * row[j];
            }
        }
    }
    let constants = solve(a, b)?;
    let residuals: f64 = points
        .iter()
        .zip(&rows)
        .map(|((h, f), row)| weight(*h) * (f - row.iter().zip(&constants).map(|(t, k)| t * k).sum::<f64>()).powi(2))
        .sum();
    let dof = n.checked_sub(law.constants()).filter(|d| *d > 0)?;
    let sigma = (n as f64 * residuals / dof as f64).sqrt();
    sigma.is_finite().then_some(Fit { law, constants, weighted, sigma })
}

/// `x` with `a x = b` by Gaussian elimination with partial pivoting (the fits' normal
/// equations, at most 3 × 3); `None` where `a` is singular.
fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let m = b.len();
    for k in 0..m {
        let pivot = (k..m).max_by(|i, j| a[*i][k].abs().total_cmp(&a[*j][k].abs()))?;
        if a[pivot][k].abs() <= 1e-300 || a[pivot][k].is_nan() {
            return None;
        }
        a.swap(k, pivot);
        b.swap(k, pivot);
        let (upper, lower) = a.split_at_mut(k + 1);
        let row = &upper[k];
        for (i, other) in lower.iter_mut().enumerate() {
            let factor = other[k] / row[k];
            for (x, y) in other[k..].iter_mut().zip(&row[k..]) {
                *x -= factor * y;
            }
            b[k + 1 + i] -= factor * b[k];
        }
    }
    let mut x = vec![0.0; m];
    for k in (0..m).rev() {
        x[k] = (b[k] - (k + 1..m).map(|j| a[k][j] * x[j]).sum::<f64>()) / a[k][k];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_exact_power_law_gives_its_order_and_limit_and_an_uncertainty_of_1_25_its_error() {
        let h: [f64; 5] = [2.0, 1.5, 1.0, 0.75, 0.5];
        let points: Vec<(f64, f64)> = h.iter().map(|h| (*h, 5.0 - 0.3 * h.powf(1.3))).collect();
        let u = uncertainty(&points).expect("five levels");
        assert!((u.order() - 1.3).abs() < 1e-4, "{}", u.order());
        assert_eq!(u.chosen.law, u.observed.law, "p within 0.95–2.05: the observed-order fit");
        assert!((u.chosen.limit() - 5.0).abs() < 1e-6, "{}", u.chosen.limit());
        assert!(u.chosen.sigma < 1e-6, "{}", u.chosen.sigma);
        let error = 0.3 * 0.5f64.powf(1.3);
        assert!((u.u - 1.25 * error).abs() < 1e-5, "{} vs {}", u.u, 1.25 * error);
    }

    #[test]
    fn leaving_out_any_one_level_of_an_exact_power_law_keeps_its_order_and_four_levels_have_no_such_range() {
        let h: [f64; 5] = [2.0, 1.5, 1.0, 0.75, 0.5];
        let points: Vec<(f64, f64)> = h.iter().map(|h| (*h, 5.0 - 0.3 * h.powf(1.3))).collect();
        let (lo, hi) = uncertainty(&points).and_then(|u| u.order_without_one).expect("five levels");
        assert!((lo - 1.3).abs() < 1e-4 && (hi - 1.3).abs() < 1e-4, "{lo}–{hi}");
        assert_eq!(uncertainty(&points[1..]).map(|u| u.order_without_one), Some(None));
    }

    #[test]
    fn an_order_that_rests_on_one_level_swings_when_that_level_is_left_out() {
        // 5 − 0.3 Δx^1.3 with the coarsest of six levels 0.3 high: left out, the order is 1.3
        // again; in, the fits flatten.
        let h: [f64; 6] = [2.0, 1.5, 1.0, 0.75, 0.6, 0.5];
        let mut points: Vec<(f64, f64)> = h.iter().map(|h| (*h, 5.0 - 0.3 * h.powf(1.3))).collect();
        points[0].1 += 0.3;
        let u = uncertainty(&points).expect("six levels");
        let (lo, hi) = u.order_without_one.expect("six levels");
        assert!(lo < 1.3 && (hi - 1.3).abs() < 1e-4, "{lo}–{hi}: the coarsest left out gives 1.3");
        assert!(hi - lo > 0.5, "{lo}–{hi}");
        assert!(u.order() < 1.0, "with it the order falls: {}", u.order());
    }

    #[test]
    fn the_first_order_fit_is_ordinary_least_squares_in_the_spacing() {
        // An independent computation: the textbook slope and intercept of a regression line.
        let points = [(1.333, 10.9), (1.0, 11.8), (0.8, 11.4), (0.667, 12.1)];
        let n = points.len() as f64;
        let (mx, my) = (points.iter().map(|p| p.0).sum::<f64>() / n, points.iter().map(|p| p.1).sum::<f64>() / n);
        let sxy: f64 = points.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
        let sxx: f64 = points.iter().map(|p| (p.0 - mx).powi(2)).sum();
        let (slope, intercept) = (sxy / sxx, my - sxy / sxx * mx);
        let line = fit(&points, Law::First, false).expect("a line");
        assert!((line.constants[1] - slope).abs() < 1e-12 && (line.limit() - intercept).abs() < 1e-12);
        let rss: f64 = points.iter().map(|p| (p.1 - intercept - slope * p.0).powi(2)).sum();
        assert!((line.sigma - (rss / (n - 2.0)).sqrt()).abs() < 1e-12, "σ with n − 2 degrees of freedom");
    }

    #[test]
    fn an_order_above_2_05_is_estimated_with_a_first_or_second_order_law_and_a_safety_factor_of_3() {
        let points: Vec<(f64, f64)> = [1.6, 1.3, 1.0, 0.8].iter().map(|h: &f64| (*h, 1.0 + h.powi(3))).collect();
        let u = uncertainty(&points).expect("four levels");
        assert!((u.order() - 3.0).abs() < 1e-4, "{}", u.order());
        assert!(matches!(u.chosen.law, Law::First | Law::Second), "four levels: {:?}", u.chosen.law);
        assert_eq!(u.safety, 3.0);
        assert!(u.u >= 0.8f64.powi(3), "U {} covers the true error {}", u.u, 0.8f64.powi(3));
    }

    #[test]
    fn scatter_as_large_as_the_trend_gives_an_uncertainty_covering_every_level() {
        // Alternating levels about a flat line: σ is as large as the data's range.
        let points = [(1.333, 222.0), (1.0, 224.0), (0.8, 222.2), (0.667, 223.8), (0.571, 222.4)];
        let u = uncertainty(&points).expect("five levels");
        assert!(u.chosen.sigma >= u.data_range, "σ {} against Δφ {}", u.chosen.sigma, u.data_range);
        let spread = crate::scene::max_keeping_nan(0.0, points.iter().map(|p| (p.1 - 222.4f64).abs()));
        assert!(u.u >= spread, "U {} against the levels' largest distance from the finest {spread}", u.u);
    }

    #[test]
    fn a_first_and_second_order_law_that_turns_back_between_the_levels_is_not_used() {
        // A coarse level 2.5 below four that agree within 0.5 (the 8 mm Børvik plate at 40 µs):
        // f0 + α1 Δx + α2 Δx² fits them by turning back between the levels and extrapolates
        // below every level; the law used does not.
        let points = [(4.0 / 3.0, 241.30), (1.0, 243.80), (0.8, 243.63), (2.0 / 3.0, 243.52), (4.0 / 7.0, 243.96)];
        let bent = best_weighting(&points, Law::FirstSecond).expect("a fit");
        assert!(!monotone(&bent, 4.0 / 3.0), "the fit turns back: {:?}", bent.constants);
        let u = uncertainty(&points).expect("five levels");
        assert!(matches!(u.chosen.law, Law::First | Law::Second), "{:?}", u.chosen.law);
        assert!(u.chosen.limit() > 243.0, "f0 {} lies with the finer levels", u.chosen.limit());
    }

    #[test]
    fn fewer_than_four_levels_a_repeated_spacing_or_a_missing_value_give_none() {
        assert_eq!(uncertainty(&[(3.0, 1.0), (2.0, 2.0), (1.0, 2.5)]), None);
        assert_eq!(uncertainty(&[(3.0, 1.0), (2.0, 2.0), (2.0, 2.1), (1.0, 2.5)]), None);
        assert_eq!(uncertainty(&[(4.0, 0.5), (3.0, 1.0), (2.0, f64::NAN), (1.0, 2.5)]), None);
    }

    #[test]
    fn the_normal_deviates_have_mean_zero_and_variance_one() {
        let mut n = Normal::seeded(7);
        let x: Vec<f64> = (0..20000).map(|_| n.next()).collect();
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (x.len() - 1) as f64;
        assert!(mean.abs() < 0.03 && (var - 1.0).abs() < 0.04, "{mean}, {var}");
    }

    #[test]
    fn small_noise_keeps_the_order_of_a_first_order_law_and_noise_as_large_as_the_steps_spreads_it() {
        // 228 − 8 Δx through six levels, 0.5 mm to 1 mm apart as the Børvik ladder.
        let h = [1.0, 0.8, 2.0 / 3.0, 0.5, 0.4, 1.0 / 3.0];
        let exact = |s: f64| -> Vec<(f64, f64, f64)> { h.iter().map(|h| (*h, 228.0 - 8.0 * h, s)).collect() };
        let quiet = under_noise(&exact(0.02)).expect("six levels");
        assert!(quiet.order.0 > 0.9 && quiet.order.1 < 1.1, "{quiet:?}");
        assert!(quiet.limit.0 < 228.0 && quiet.limit.1 > 228.0 && quiet.limit.1 - quiet.limit.0 < 0.5, "{quiet:?}");
        assert_eq!(quiet.resolved_steps, (5, 5), "every step (0.53 to 1.6) is larger than 2 √2 × 0.02");
        let noisy = under_noise(&exact(1.0)).expect("six levels");
        assert!(noisy.order.1 - noisy.order.0 > 1.0, "{noisy:?}");
        assert_eq!(noisy.resolved_steps, (0, 5), "no step is larger than 2 √2 × 1");
        // The same draws each time.
        assert_eq!(under_noise(&exact(1.0)), Some(noisy));
    }

    #[test]
    fn the_chi_square_tail_matches_its_closed_forms_and_tables() {
        // Two degrees of freedom: exactly e^(−χ²/2).
        for chi2 in [0.5, 2.0, 7.3, 40.0] {
            let q = upper_gamma_regularised(1.0, 0.5 * chi2);
            assert!((q - (-0.5 * chi2).exp()).abs() < 1e-12, "{chi2}: {q}");
        }
        // The 5 % points of χ² with 1, 7 and 12 degrees of freedom: 3.841, 14.067, 21.026.
        for (dof, chi2) in [(1.0, 3.841_459), (7.0, 14.067_140), (12.0, 21.026_070)] {
            let q = upper_gamma_regularised(0.5 * dof, 0.5 * chi2);
            assert!((q - 0.05).abs() < 1e-6, "{dof}: {q}");
        }
        // Γ(5) = 24, Γ(1/2) = √π.
        assert!((ln_gamma(5.0) - 24f64.ln()).abs() < 1e-12);
        assert!((ln_gamma(0.5) - std::f64::consts::PI.sqrt().ln()).abs() < 1e-12);
    }

    #[test]
    fn levels_within_their_noise_fit_a_constant_and_levels_on_a_trend_do_not() {
        // Six levels 0.1 about 228 with standard errors 0.5: a constant fits. On 228 − 8 Δx with
        // standard errors 0.05: it does not.
        let h = [1.0, 0.8, 2.0 / 3.0, 0.5, 0.4, 1.0 / 3.0];
        let flat: Vec<(f64, f64, f64)> =
            h.iter().enumerate().map(|(i, h)| (*h, 228.0 + if i % 2 == 0 { 0.1 } else { -0.1 }, 0.5)).collect();
        let p = under_noise(&flat).and_then(|n| n.constant_fits).expect("a probability");
        assert!(p > 0.99, "{p}");
        let trend: Vec<(f64, f64, f64)> = h.iter().map(|h| (*h, 228.0 - 8.0 * h, 0.05)).collect();
        let p = under_noise(&trend).and_then(|n| n.constant_fits).expect("a probability");
        assert!(p < 1e-10, "{p}");
        let exact: Vec<(f64, f64, f64)> = h.iter().map(|h| (*h, 228.0 - 8.0 * h, 0.0)).collect();
        assert_eq!(under_noise(&exact).map(|n| n.constant_fits), Some(None), "a standard error of 0");
    }

    #[test]
    fn the_weighted_mean_and_first_order_limit_are_those_of_weighted_least_squares() {
        // Two levels of equal error and one of half: the mean weights the third four times; the
        // line through 228 − 8 Δx is exact, its f0 228, with the textbook standard error.
        let pts = [(1.0, 220.0, 1.0), (0.5, 224.0, 1.0), (0.25, 226.0, 0.5)];
        let mut four = pts.to_vec();
        four.push((0.75, 222.0, 1.0));
        let n = under_noise(&four).expect("four levels");
        let (mean, se) = n.constant.expect("a mean");
        assert!((mean - (220.0 + 224.0 + 4.0 * 226.0 + 222.0) / 7.0).abs() < 1e-12, "{mean}");
        assert!((se - 7f64.sqrt().recip()).abs() < 1e-12, "{se}");
        let (f0, se0) = n.first_order.expect("a line");
        assert!((f0 - 228.0).abs() < 1e-9, "{f0}");
        // Σw = 7, Σw h = 1 + 0.5 + 1 + 0.75 = 3.25, Σw h² = 1 + 0.25 + 0.25 + 0.5625 = 2.0625.
        let det = 7.0 * 2.0625 - 3.25 * 3.25;
        assert!((se0 - (2.0625f64 / det).sqrt()).abs() < 1e-12, "{se0}");
    }

    #[test]
    fn a_negative_or_missing_standard_error_or_three_levels_give_no_range() {
        let pts = [(4.0, 1.0, 0.1), (3.0, 2.0, 0.1), (2.0, 2.5, 0.1), (1.0, 2.7, 0.1)];
        assert!(under_noise(&pts).is_some());
        let mut bad = pts;
        bad[1].2 = -0.1;
        assert_eq!(under_noise(&bad), None);
        bad[1].2 = f64::NAN;
        assert_eq!(under_noise(&bad), None);
        assert_eq!(under_noise(&pts[1..]), None);
    }

    #[test]
    fn levels_that_do_not_change_have_no_uncertainty() {
        let u = uncertainty(&[(4.0, 7.0), (3.0, 7.0), (2.0, 7.0), (1.0, 7.0)]).expect("four levels");
        assert_eq!((u.u, u.chosen.limit()), (0.0, 7.0));
    }
}
