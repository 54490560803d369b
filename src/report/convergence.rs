//! Speed against error across resolutions: the reports of one case (or study) run at three or more
//! particle spacings become each result's value and error at every spacing, its observed order of
//! convergence and a Richardson estimate of its value at zero spacing, and its error plotted
//! against wall time and against particle count. Plain `f64` data in, report parts out.

use super::json::{Curve, History, ResultRow, RunReport, Table};
use super::markdown::{fmt_num, fmt_percent, plus_minus};
use super::uncertainty::{uncertainty, under_noise, Uncertainty, DRAWS};

/// How three values, coarse to fine, behave.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Trend {
    /// They approach a limit as `f0 + C h^p`.
    Converging { order: f64, limit: f64 },
    /// Their differences change sign.
    Oscillating,
    /// Their differences keep one sign but do not shrink fast enough for an order in [0.05, 10]
    /// (or shrink faster than that).
    NoOrder,
    /// The three are equal.
    Unchanged,
    /// A value is missing (a run did not report it).
    Missing,
}

impl Trend {
    /// Three points, coarse to fine (`h[0] > h[1] > h[2]`).
    pub fn of(h: [f64; 3], f: [f64; 3]) -> Trend {
        let (d1, d2) = (f[1] - f[0], f[2] - f[1]);
        // Differences at rounding level are none.
        let noise = 1e-9 * f.iter().fold(0.0, |a: f64, v| a.max(v.abs()));
        if !(d1.is_finite() && d2.is_finite()) {
            Trend::Missing
        } else if d1.abs() <= noise && d2.abs() <= noise {
            Trend::Unchanged
        } else if d1 * d2 <= 0.0 {
            Trend::Oscillating
        } else {
            match observed_order(h, f) {
                Some(order) => Trend::Converging { order, limit: richardson(h, f, order) },
                None => Trend::NoOrder,
            }
        }
    }

    fn describe(&self) -> String {
        match self {
            Trend::Converging { order, .. } => format!("{order:.2}"),
            Trend::Oscillating => "none: oscillates".into(),
            Trend::NoOrder => "none: differences do not shrink".into(),
            Trend::Unchanged => "none: unchanged".into(),
            Trend::Missing => "none: a value is missing".into(),
        }
    }
}

/// The observed order `p` of `f(h) = f0 + C h^p` through three points, coarse to fine
/// (`h[0] > h[1] > h[2]`). `None` when the differences do not shrink with one sign (the values
/// oscillate, stall or diverge) or when `p` would lie outside [0.05, 10].
pub fn observed_order(h: [f64; 3], f: [f64; 3]) -> Option<f64> {
    let (d1, d2) = (f[1] - f[0], f[2] - f[1]);
    if d1 * d2 <= 0.0 || !(d1 * d2).is_finite() {
        return None;
    }
    let ratio = d2 / d1;
    // ratio = g(p), which falls from ln(h1/h2)/ln(h0/h1) at p → 0 towards 0 as p grows.
    let g = |p: f64| (h[1].powf(p) - h[2].powf(p)) / (h[0].powf(p) - h[1].powf(p));
    let (mut lo, mut hi) = (0.05, 10.0);
    if !(ratio < g(lo) && ratio > g(hi)) {
        return None;
    }
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if g(mid) > ratio {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(0.5 * (lo + hi))
}

/// Richardson's estimate of `f0` in `f(h) = f0 + C h^p` from the two finest points of three.
pub fn richardson(h: [f64; 3], f: [f64; 3], p: f64) -> f64 {
    f[2] + (f[2] - f[1]) * h[2].powf(p) / (h[1].powf(p) - h[2].powf(p))
}

/// The slope `q` of a least-squares line through `(ln h, ln |e|)`: the error falls as `h^q`.
/// `None` with fewer than two errors above rounding (1e-9) at distinct spacings.
pub fn error_order(points: &[(f64, f64)]) -> Option<f64> {
    let pts: Vec<(f64, f64)> = above_rounding(points).map(|(h, e)| (h.ln(), e.abs().ln())).collect();
    let n = pts.len() as f64;
    let (mx, my) = (pts.iter().map(|p| p.0).sum::<f64>() / n, pts.iter().map(|p| p.1).sum::<f64>() / n);
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    (pts.len() >= 2 && sxx > 1e-24).then(|| sxy / sxx)
}

/// The points whose error is above rounding (1e-9): an error at rounding level (an exact
/// result) has no order.
fn above_rounding(points: &[(f64, f64)]) -> impl Iterator<Item = (f64, f64)> + '_ {
    points.iter().copied().filter(|(h, e)| *h > 0.0 && e.is_finite() && e.abs() > 1e-9)
}

/// The error order where the errors keep one sign and fall at every refinement (points coarse
/// to fine); otherwise why there is none. An error that passes through the reference, or grows
/// on the way, gives a log-log slope that is no order of convergence.
pub fn error_order_if_falling(points: &[(f64, f64)]) -> Result<f64, &'static str> {
    let errors: Vec<f64> = above_rounding(points).map(|p| p.1).collect();
    if errors.windows(2).any(|w| w[0].signum() != w[1].signum()) {
        return Err("none: the error changes sign");
    }
    if errors.windows(2).any(|w| w[1].abs() >= w[0].abs()) {
        return Err("none: the error does not fall at every refinement");
    }
    error_order(points).ok_or("")
}

/// What a convergence study adds to its report.
#[derive(Debug, Default)]
pub struct Convergence {
    pub results: Vec<ResultRow>,
    pub tables: Vec<Table>,
    pub histories: Vec<History>,
    pub notes: Vec<String>,
}

/// One result followed across the resolutions (coarse to fine).
struct Followed<'a> {
    finest: &'a ResultRow,
    values: Vec<f64>,
    /// Each level's standard error where the value is a mean over runs (a study's `mean`).
    standard_errors: Vec<Option<f64>>,
}

impl Followed<'_> {
    fn errors(&self) -> Option<Vec<f64>> {
        let r = self.finest.reference.filter(|r| *r != 0.0 && r.is_finite())?;
        Some(self.values.iter().map(|v| (v - r) / r.abs()).collect())
    }
}

/// The study across `levels` (each the name a resolution was asked by and its run's report), in
/// any order: they are sorted coarse to fine by spacing. Every result of the finest run is
/// followed across the runs that report it; the order and the Richardson estimate use the three
/// finest spacings.
pub fn analyse(levels: &[(String, RunReport)]) -> Convergence {
    let mut levels: Vec<&(String, RunReport)> = levels.iter().collect();
    levels.sort_by(|a, b| b.1.dx.total_cmp(&a.1.dx));
    let Some(finest) = levels.last() else { return Convergence::default() };
    let h: Vec<f64> = levels.iter().map(|l| l.1.dx).collect();
    let followed: Vec<Followed> = finest
        .1
        .results
        .iter()
        .map(|row| {
            let at: Vec<Option<&ResultRow>> =
                levels.iter().map(|l| l.1.results.iter().find(|r| r.quantity == row.quantity)).collect();
            Followed {
                finest: row,
                values: at.iter().map(|r| r.map_or(f64::NAN, |r| r.value)).collect(),
                standard_errors: at.iter().map(|r| r.and_then(|r| r.standard_error)).collect(),
            }
        })
        .collect();

    let mut out =
        Convergence { tables: vec![levels_table(&levels), values_table(&levels, &followed)], ..Default::default() };
    let mut summary = vec![];
    for q in &followed {
        let row = q.finest;
        out.results.push(row.clone());
        let n = h.len();
        let triple = |last: usize| {
            Trend::of([h[last - 2], h[last - 1], h[last]], [q.values[last - 2], q.values[last - 1], q.values[last]])
        };
        let trend = (n >= 3).then(|| triple(n - 1));
        let coarser = (n >= 4).then(|| triple(n - 2));
        let order = match trend {
            Some(Trend::Converging { order, limit }) => Some((order, limit)),
            _ => None,
        };
        // An error that falls while the values' differences grow is passing through the
        // reference, not converging to it: no order either.
        let slope = q.errors().map(|e| match trend {
            Some(Trend::Oscillating | Trend::NoOrder) => Err("none: the values do not converge"),
            _ => error_order_if_falling(&h.iter().copied().zip(e).collect::<Vec<_>>()),
        });
        if let Some((p, f0)) = order {
            let mut est =
                ResultRow::new(format!("{}, Richardson estimate", row.quantity), &row.unit, f0, row.reference);
            est.source = row.source.clone();
            out.results.push(est);
            out.results.push(ResultRow::new(format!("{}, observed order", row.quantity), "", p, None));
        }
        if let Some(Ok(s)) = slope {
            out.results.push(ResultRow::new(format!("{}, error order", row.quantity), "", s, None));
        }
        summary.push(vec![
            row.quantity.clone(),
            row.reference.map(fmt_num).unwrap_or_default(),
            trend.map_or("none: fewer than three runs".into(), |t| t.describe()),
            order.map(|(_, f0)| fmt_num(f0)).unwrap_or_default(),
            order
                .and_then(|(_, f0)| row.reference.filter(|r| *r != 0.0).map(|r| fmt_percent((f0 - r) / r.abs())))
                .unwrap_or_default(),
            match slope {
                Some(Ok(s)) => format!("{s:.2}"),
                Some(Err(why)) => why.to_string(),
                None => String::new(),
            },
            coarser.map_or(String::new(), |t| t.describe()),
            match (trend, coarser) {
                (Some(fine), Some(coarse)) => order_holds(fine, coarse).into(),
                _ => String::new(),
            },
        ]);
    }
    out.tables.push(Table {
        title: "Convergence".into(),
        header: [
            "quantity",
            "reference",
            "observed order p",
            "Richardson estimate",
            "its error",
            "error order q",
            "p through the three coarser",
            "order holds",
        ]
        .map(String::from)
        .to_vec(),
        rows: summary,
    });
    if h.len() >= 4 {
        out.tables.push(uncertainty_table(&h, &followed));
        out.tables.extend(noise_table(&h, &followed));
    }
    out.histories = error_plots(&levels, &followed);
    out.notes = vec![
        "Observed order p: through the three finest spacings, f(Δx) = f0 + C Δx^p; none when their differences change sign or do not shrink enough for p in [0.05, 10]. Richardson estimate: that f0. It is trustworthy only in the asymptotic range: a p far from the scheme's order, or from the error order q, says the spacings are not there yet.".into(),
        "p through the three coarser: the observed order one level back (with four or more spacings). The order holds when both triples converge and their orders are within a factor of 1.5 of each other: a p that moves more than that as a level is added is not yet the scheme's order, and its Richardson estimate is not a limit.".into(),
        "Numerical uncertainty U (four or more spacings): power laws in Δx fitted through every level in the least-squares sense (after Eça & Hoekstra 2014; the rules in src/report/uncertainty.rs), so that a level's own scatter averages out where three levels' exact fit follows it; the finest value ± U is meant to hold the value at zero spacing (Eça & Hoekstra aim at 95 % coverage), and σ, the fit's standard deviation, is that scatter. A reference beyond the finest value ± U is missed by the model, not by the spacing.".into(),
        "Under the levels' noise (results that are a study's `mean` over runs at every level): each level's value drawn again with its standard error, and the best f0 + α Δx^p fitted through every draw; the 10th–90th percentile of p and f0 over the draws. A constant within the noise: how likely levels that do not depend on the spacing at all would lie as far from their weighted mean as these do (χ², n − 1 degrees of freedom); above 0.05 the levels are one value within their noise, and their mean weighted by 1/s² (± its standard error) is that value; f0 of f0 + α Δx weighted so (± its standard error) is the value at zero spacing allowing a first-order error within the noise. Where the noise is as large as the steps between levels, no step is resolved and p ranges over the search: a single run per level cannot show an order, and neither can these means until more runs make their noise smaller than the steps.".into(),
        "Error order q: the least-squares slope of ln |error| against ln Δx over every resolution (the error falls as Δx^q); none when the error changes sign or does not fall at every refinement, or when the values do not converge (no observed order p: an error that falls while the differences grow is passing through the reference).".into(),
    ];
    out
}

/// Whether the observed order survives one level more: both triples converge (the finest three
/// and the three one level back) and their orders are within a factor of 1.5.
fn order_holds(finest: Trend, coarser: Trend) -> &'static str {
    match (finest, coarser) {
        (Trend::Converging { order: p, .. }, Trend::Converging { order: q, .. }) if p.max(q) <= 1.5 * p.min(q) => "yes",
        _ => "no",
    }
}

/// Each result's numerical uncertainty over every level (`h`, coarse to fine).
fn uncertainty_table(h: &[f64], followed: &[Followed]) -> Table {
    let header: Vec<String> = [
        "quantity",
        "observed order p (all levels)",
        "p leaving out one level",
        "error estimated with",
        "f0",
        "scatter σ",
        "U",
        "finest value ± U",
        "reference within it",
    ]
    .map(String::from)
    .to_vec();
    let rows = followed
        .iter()
        .map(|q| {
            let row = q.finest;
            let points: Vec<(f64, f64)> = h.iter().copied().zip(q.values.iter().copied()).collect();
            let Some(u) = uncertainty(&points) else {
                let mut none = vec![String::new(); header.len()];
                (none[0], none[1]) = (row.quantity.clone(), "none: a value is missing".into());
                return none;
            };
            vec![
                row.quantity.clone(),
                u.describe_order(),
                u.describe_order_without_one().unwrap_or_else(|| "— (it needs five levels)".into()),
                u.chosen.law.describe(),
                fmt_num(u.chosen.limit()),
                fmt_num(u.chosen.sigma),
                fmt_num(u.u),
                format!("{} ± {}", fmt_num(u.finest.1), fmt_num(u.u)),
                row.reference.filter(|r| r.is_finite()).map(|r| covers(&u, r)).unwrap_or_default(),
            ]
        })
        .collect();
    Table {
        title: "Numerical uncertainty of the finest value (least squares through every level)".into(),
        header,
        rows,
    }
}

/// For the results that are means over runs at every level (four or more): how many steps
/// between levels their noise resolves, and the observed order's and f0's range under it
/// ([`under_noise`]); none where no result is such a mean.
fn noise_table(h: &[f64], followed: &[Followed]) -> Option<Table> {
    let rows: Vec<Vec<String>> = followed
        .iter()
        .filter_map(|q| {
            let se: Vec<f64> = q.standard_errors.iter().copied().collect::<Option<_>>()?;
            let points: Vec<(f64, f64, f64)> =
                h.iter().zip(&q.values).zip(&se).map(|((h, f), s)| (*h, *f, *s)).collect();
            let (lo, hi) = se.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, s| (a.0.min(*s), a.1.max(*s)));
            let mut row = vec![q.finest.quantity.clone(), format!("{}–{}", fmt_num(lo), fmt_num(hi))];
            row.extend(match under_noise(&points) {
                Some(n) => vec![
                    format!("{} of {}", n.resolved_steps.0, n.resolved_steps.1),
                    n.constant_fits.map_or("— (a standard error is 0)".into(), |p| format!("{p:.3}")),
                    n.constant.map_or(String::new(), plus_minus),
                    n.first_order.map_or(String::new(), plus_minus),
                    n.describe_order(),
                    format!("{}–{}", fmt_num(n.limit.0), fmt_num(n.limit.1)),
                ],
                None => {
                    let mut none = vec![String::new(); 6];
                    none[0] = "none: a value or a standard error is missing".into();
                    none
                }
            });
            Some(row)
        })
        .collect();
    (!rows.is_empty()).then(|| Table {
        title: format!("Under the levels' noise (means over runs; {DRAWS} draws, 10th–90th percentile)"),
        header: [
            "quantity",
            "standard error at a level",
            "steps larger than twice their standard error",
            "a constant within the noise (χ² probability)",
            "their mean weighted by 1/s²",
            "f0 of f0 + α Δx weighted by 1/s²",
            "observed order p under the noise",
            "f0 under the noise",
        ]
        .map(String::from)
        .to_vec(),
        rows,
    })
}

/// Whether the reference `r` lies within the finest value ± U, and if not by how much the
/// finest value misses it.
fn covers(u: &Uncertainty, r: f64) -> String {
    let beyond = u.beyond(r);
    if beyond <= 0.0 {
        "yes".into()
    } else if r != 0.0 {
        format!("no: {:.2} % of it beyond U", 100.0 * beyond / r.abs())
    } else {
        format!("no: {} beyond U", fmt_num(beyond))
    }
}

fn levels_table(levels: &[&(String, RunReport)]) -> Table {
    Table {
        title: "Each resolution".into(),
        header: ["resolution", "Δx [m]", "particles", "steps", "wall time [s]", "particle-steps/s"]
            .map(String::from)
            .to_vec(),
        rows: levels
            .iter()
            .map(|(name, r)| {
                vec![
                    name.clone(),
                    fmt_num(r.dx),
                    r.particles.to_string(),
                    r.steps.to_string(),
                    fmt_num(r.wall_s),
                    fmt_num(r.particle_steps_per_s),
                ]
            })
            .collect(),
    }
}

fn values_table(levels: &[&(String, RunReport)], followed: &[Followed]) -> Table {
    let mut header: Vec<String> = ["quantity", "unit", "reference"].map(String::from).to_vec();
    header.extend(levels.iter().map(|(name, r)| format!("{name} (Δx = {})", fmt_num(r.dx))));
    let rows = followed
        .iter()
        .map(|q| {
            let errors = q.errors();
            let mut row = vec![
                q.finest.quantity.clone(),
                q.finest.unit.clone(),
                q.finest.reference.map(fmt_num).unwrap_or_default(),
            ];
            row.extend(q.values.iter().enumerate().map(|(i, v)| {
                let value = q.standard_errors[i].map_or_else(|| fmt_num(*v), |se| plus_minus((*v, se)));
                match errors.as_ref() {
                    Some(e) if v.is_finite() => format!("{value} ({})", fmt_percent(e[i])),
                    _ => value,
                }
            }));
            row
        })
        .collect();
    Table { title: "Value (and error) at each resolution".into(), header, rows }
}

/// |error| against wall time and against particle count, log–log, one curve per result with a
/// reference.
fn error_plots(levels: &[&(String, RunReport)], followed: &[Followed]) -> Vec<History> {
    let with_errors: Vec<(&str, Vec<f64>)> =
        followed.iter().filter_map(|q| Some((q.finest.quantity.as_str(), q.errors()?))).collect();
    if with_errors.is_empty() {
        return vec![];
    }
    let plot = |name: &str, x_label: &str, x: &dyn Fn(&RunReport) -> f64| History {
        name: name.into(),
        x_label: x_label.into(),
        y_label: "|relative error|".into(),
        series: with_errors
            .iter()
            .map(|(q, e)| Curve::new(*q, levels.iter().zip(e).map(|(l, e)| (x(&l.1), e.abs())).collect()))
            .collect(),
        reference: None,
        log_log: true,
    };
    vec![
        plot("error against wall time", "wall time [s]", &|r| r.wall_s),
        plot("error against particles", "particles", &|r| r.particles as f64),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_and_richardson_recover_a_power_law() {
        for (h, p_true) in [([4.0, 2.0, 1.0], 2.0), ([3.0, 2.0, 1.2], 1.3), ([1.0, 0.5, 0.25], 0.7)] {
            let f = h.map(|h: f64| 5.0 - 0.3 * h.powf(p_true));
            let p = observed_order(h, f).expect("an order");
            assert!((p - p_true).abs() < 1e-9, "{p} vs {p_true}");
            assert!((richardson(h, f, p) - 5.0).abs() < 1e-9);
        }
    }

    #[test]
    fn no_order_when_values_oscillate_stall_or_diverge() {
        let h = [4.0, 2.0, 1.0];
        assert_eq!(observed_order(h, [1.0, 2.0, 1.5]), None, "oscillating");
        assert_eq!(observed_order(h, [1.0, 1.0, 1.0]), None, "stalled");
        assert_eq!(observed_order(h, [1.0, 2.0, 4.0]), None, "diverging: the differences grow");
        assert_eq!(observed_order(h, [1.0, f64::NAN, 2.0]), None);
        assert_eq!(Trend::of(h, [1.0, 2.0, 1.5]), Trend::Oscillating);
        assert_eq!(Trend::of(h, [1.0, 1.0, 1.0]), Trend::Unchanged);
        assert_eq!(Trend::of(h, [2190.04, 2190.04 + 1e-12, 2190.04 + 1.5e-12]), Trend::Unchanged, "rounding");
        assert_eq!(Trend::of(h, [1.0, 2.0, 4.0]), Trend::NoOrder);
        assert_eq!(Trend::of(h, [1.0, f64::NAN, 2.0]), Trend::Missing);
        let Trend::Converging { order, limit } = Trend::of(h, [1.0, 2.0, 2.5]) else { panic!("converges") };
        assert!((order - 1.0).abs() < 1e-9 && (limit - 3.0).abs() < 1e-9, "{order} {limit}");
    }

    #[test]
    fn error_order_is_the_log_log_slope() {
        let pts: Vec<(f64, f64)> = [1.0, 0.5, 0.25].iter().map(|h: &f64| (*h, -0.2 * h.powi(2))).collect();
        assert!((error_order(&pts).unwrap() - 2.0).abs() < 1e-12);
        assert_eq!(error_order(&[(1.0, 0.1)]), None);
        assert_eq!(error_order(&[(1.0, 0.1), (1.0, 0.2)]), None);
        assert_eq!(error_order(&[(1.0, 1e-16), (0.5, -2e-16), (0.25, 0.0)]), None, "exact up to rounding");
    }

    #[test]
    fn error_order_if_falling_is_none_for_an_error_that_changes_sign_or_grows() {
        let falling = [(1.0, 0.08), (0.5, 0.02), (0.25, 0.005)];
        assert!((error_order_if_falling(&falling).unwrap() - 2.0).abs() < 1e-12);
        let crossing = [(1.0, 0.0774), (0.5, 0.0102), (0.25, -0.0215)];
        assert_eq!(error_order_if_falling(&crossing), Err("none: the error changes sign"));
        let growing = [(1.0, 0.0774), (0.666, 0.0102), (0.5, 0.0215)];
        assert_eq!(error_order_if_falling(&growing), Err("none: the error does not fall at every refinement"));
    }

    #[test]
    fn the_order_holds_only_when_the_coarser_triple_converges_at_an_order_within_a_factor_of_1_5() {
        // crater = 10 − 4 Δx²: both triples give order 2.
        let power = vec![
            level("a", 2.0, 10.0 - 16.0, 1.0),
            level("b", 1.0, 6.0, 1.0),
            level("c", 0.5, 9.0, 1.0),
            level("d", 0.25, 9.75, 1.0),
        ];
        let row = &analyse(&power).tables[2].rows[0];
        assert_eq!(row[2], "2.00");
        assert_eq!(row[6..], ["2.00", "yes"]);
        // A coarse level off the power law: the coarser triple's order is 0.42, the finest's 2.
        let mut off = power.clone();
        off[0] = level("a", 2.0, 2.0, 1.0);
        assert_eq!(analyse(&off).tables[2].rows[0][6..], ["0.42", "no"]);
        // Alternating levels (the 12 mm Børvik plate's residuals): no order in either triple.
        let alternating = vec![
            level("a", 1.333, 248.47, 1.0),
            level("b", 1.0, 250.99, 1.0),
            level("c", 0.8, 249.01, 1.0),
            level("d", 0.667, 251.76, 1.0),
        ];
        assert_eq!(analyse(&alternating).tables[2].rows[0][6..], ["none: oscillates", "no"]);
    }

    #[test]
    fn four_levels_or_more_add_the_finest_values_numerical_uncertainty_and_whether_it_covers_the_reference() {
        // crater = 10 − 4 Δx^1.5 at five spacings: order 1.5, f0 = 10, U = 1.25 × 4 × 0.25^1.5.
        let levels: Vec<_> =
            [2.0, 1.0, 0.5, 0.35, 0.25].iter().map(|h: &f64| level("l", *h, 10.0 - 4.0 * h.powf(1.5), 1.0)).collect();
        let c = analyse(&levels);
        let table = c.tables.iter().find(|t| t.title.starts_with("Numerical uncertainty")).expect("the table");
        let row = &table.rows[0];
        assert_eq!((row[0].as_str(), row[1].as_str()), ("crater", "1.50"));
        assert_eq!(row[2], "1.50–1.50", "any one level left out: the same order");
        let u: f64 = row[6].parse().expect("U");
        assert!((u - 1.25 * 4.0 * 0.25f64.powf(1.5)).abs() < 1e-5, "{u}");
        assert_eq!(c.tables[3].rows[1][1], "1.50", "gap = 2 crater: the same order");
        assert_eq!(row[8], "yes", "the reference, 10, lies 0.5 from the finest value, 9.5: within U = 0.625");
        // 12 − 4 Δx^1.5: the finest value, 11.5, misses the reference by 1.5, 0.875 beyond U.
        let above: Vec<_> = levels.iter().map(|(n, r)| level(n, r.dx, r.results[0].value + 2.0, 1.0)).collect();
        let row = &analyse(&above).tables[3].rows[0];
        assert_eq!(row[8], "no: 8.75 % of it beyond U");
        assert!(analyse(&levels[1..4]).tables.iter().all(|t| !t.title.starts_with("Numerical")), "three levels: none");
    }

    #[test]
    fn a_result_that_is_a_mean_over_runs_at_every_level_gets_its_order_and_f0_under_the_noise() {
        // crater = 10 − 4 Δx^1.5, each level a mean with standard error 0.001: every step resolved,
        // the order 1.5 and f0 10 under the noise; `gap` has no standard error and no row.
        let levels: Vec<_> = [2.0, 1.0, 0.5, 0.35, 0.25]
            .iter()
            .map(|h: &f64| {
                let (name, mut r) = level("l", *h, 10.0 - 4.0 * h.powf(1.5), 1.0);
                r.results[0].standard_error = Some(0.001);
                (name, r)
            })
            .collect();
        let c = analyse(&levels);
        let table = c.tables.iter().find(|t| t.title.starts_with("Under the levels' noise")).expect("the table");
        assert_eq!(table.rows.len(), 1, "{:?}", table.rows);
        let row = &table.rows[0];
        assert_eq!((row[0].as_str(), row[2].as_str(), row[3].as_str()), ("crater", "4 of 4", "0.000"));
        let range = |cell: &str| -> (f64, f64) {
            let (a, b) = cell.split_once('–').expect("a range");
            (a.parse().expect("a number"), b.parse().expect("a number"))
        };
        // Equal standard errors: the weighted mean is the plain one, its error 0.001 / √5.
        let mean: f64 = [2.0, 1.0, 0.5, 0.35, 0.25].iter().map(|h: &f64| 10.0 - 4.0 * h.powf(1.5)).sum::<f64>() / 5.0;
        assert_eq!(row[4], format!("{} ± {}", fmt_num(mean), fmt_num(0.001 / 5f64.sqrt())));
        let (p0, p1) = range(&row[6]);
        assert!(p0 > 1.45 && p1 < 1.55, "{row:?}");
        let (f0, f1) = range(&row[7]);
        assert!(f0 < 10.0 + 1e-3 && f1 > 10.0 - 1e-3 && f1 - f0 < 0.05, "{row:?}");
        let values = c.tables.iter().find(|t| t.title.starts_with("Value")).expect("the values");
        let coarsest = 10.0 - 4.0 * 2f64.powf(1.5);
        let error = fmt_percent((coarsest - 10.0) / 10.0);
        assert_eq!(values.rows[0][3], format!("{} ± 0.001 ({error})", fmt_num(coarsest)));
        // Without standard errors there is no such table.
        let plain: Vec<_> = [2.0, 1.0, 0.5, 0.35, 0.25].iter().map(|h| level("l", *h, 10.0 - 4.0 * h, 1.0)).collect();
        assert!(analyse(&plain).tables.iter().all(|t| !t.title.starts_with("Under")));
    }

    #[test]
    fn with_four_levels_the_order_leaving_out_one_level_reads_that_it_needs_five() {
        let levels: Vec<_> =
            [1.0, 0.5, 0.35, 0.25].iter().map(|h: &f64| level("l", *h, 10.0 - 4.0 * h.powf(1.5), 1.0)).collect();
        let c = analyse(&levels);
        let table = c.tables.iter().find(|t| t.title.starts_with("Numerical uncertainty")).expect("the table");
        assert_eq!(table.rows[0][2], "— (it needs five levels)");
    }

    fn level(name: &str, dx: f64, value: f64, wall: f64) -> (String, RunReport) {
        let report = RunReport {
            dx,
            wall_s: wall,
            particles: (1.0 / dx) as usize,
            results: vec![
                ResultRow::new("crater", "m", value, Some(10.0)),
                ResultRow::new("gap", "m", 2.0 * value, None),
            ],
            ..Default::default()
        };
        (name.into(), report)
    }

    #[test]
    fn analyse_follows_each_result_across_levels_given_in_any_order() {
        // crater = 10 − 4 Δx²: order 2, Richardson exactly 10.
        let levels = vec![level("fine", 0.25, 9.75, 8.0), level("coarse", 1.0, 6.0, 0.5), level("ci", 0.5, 9.0, 1.0)];
        let c = analyse(&levels);
        let value = |q: &str| c.results.iter().find(|r| r.quantity == q).map(|r| r.value);
        assert_eq!(value("crater"), Some(9.75), "the finest run's value");
        assert!((value("crater, observed order").unwrap() - 2.0).abs() < 1e-9);
        assert!((value("crater, Richardson estimate").unwrap() - 10.0).abs() < 1e-9);
        assert!((value("crater, error order").unwrap() - 2.0).abs() < 1e-9);
        assert!((value("gap, Richardson estimate").unwrap() - 20.0).abs() < 1e-9);
        assert_eq!(value("gap, error order"), None, "no reference, no error");
        // Falling errors whose differences grow (+7.9 / +6.3 / +2.5 %): passing through, no order.
        let through = vec![level("a", 1.0, 10.79, 1.0), level("b", 0.5, 10.63, 2.0), level("c", 0.25, 10.25, 4.0)];
        let t = analyse(&through);
        assert!(t.results.iter().all(|r| r.quantity != "crater, error order"), "no error order");
        assert_eq!(t.tables[2].rows[0][5], "none: the values do not converge");
        assert_eq!(c.tables[2].rows[0][6..], ["", ""], "three levels: no coarser triple");
        let values = &c.tables[1];
        assert_eq!(values.header[3..], ["coarse (Δx = 1)", "ci (Δx = 0.5)", "fine (Δx = 0.25)"]);
        assert_eq!(values.rows[0][3], "6 (-40.00 %)");
        let wall = &c.histories[0];
        assert!(wall.log_log && wall.series.len() == 1, "one curve: the result with a reference");
        assert_eq!(wall.series[0].points, vec![(0.5, 0.4), (1.0, 0.1), (8.0, 0.025)]);
    }
}
