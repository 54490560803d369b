//! Studies: several runs of one case with different parameters (impact speeds, a switch on or
//! off, two particle distributions), and results computed across them — a Recht–Ipson fit of
//! residual velocities and its ballistic limit, a ratio of wall times, a difference between runs.

use super::quantity;
use crate::diag::{Diagnostic, Span};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct StudyFile {
    pub name: String,
    #[serde(default)]
    pub title: Option<String>,
    /// The case, relative to the study file.
    pub case: toml::Spanned<String>,
    pub runs: Vec<RunSpec>,
    #[serde(default)]
    pub results: Vec<StudyResult>,
    /// The runs the CI resolution makes (all when absent).
    #[serde(default)]
    pub ci_runs: Option<Vec<String>>,
    #[serde(default)]
    pub notes: Vec<String>,
    /// Probes whose histories are plotted together, one curve per run.
    #[serde(default)]
    pub plots: Vec<String>,
    /// The resolutions `pairsum run --convergence` runs the whole study at, at least three.
    #[serde(default)]
    pub convergence: Option<Vec<String>>,
}

#[derive(Deserialize, Debug, Clone)]
#[serde(deny_unknown_fields)]
pub struct RunSpec {
    pub name: String,
    #[serde(default)]
    pub set: BTreeMap<String, toml::Value>,
}

#[derive(Deserialize, Debug, Clone)]
#[serde(deny_unknown_fields)]
pub struct StudyResult {
    pub quantity: toml::Spanned<String>,
    #[serde(default)]
    pub unit: Option<String>,
    /// `recht_ipson`: fit y(x) over the runs (x a parameter, y a result of each run).
    #[serde(default)]
    pub fit: Option<String>,
    #[serde(default)]
    pub x: Option<String>,
    #[serde(default)]
    pub y: Option<String>,
    /// `recht_ipson`: the curve's `a` and `p` held at these values instead of fitted (Recht and
    /// Ipson's plugging form: p = 2, a = m_p / (m_p + m_plug)).
    #[serde(default)]
    pub a: Option<f64>,
    #[serde(default)]
    pub p: Option<f64>,
    /// Two runs: wall time of the first over the second.
    #[serde(default)]
    pub ratio: Option<[String; 2]>,
    /// Two runs: (second − first) / |first| of the result `of`.
    #[serde(default)]
    pub difference: Option<[String; 2]>,
    /// One run: its result `of`.
    #[serde(default)]
    pub run: Option<String>,
    /// Two runs or more: the mean of their result `of`, with its standard error (runs that
    /// differ only in what a level's value should not depend on, such as where a body's edge
    /// falls on the lattice).
    #[serde(default)]
    pub mean: Option<Vec<String>>,
    #[serde(default)]
    pub of: Option<String>,
    #[serde(default)]
    pub reference: Option<toml::Value>,
    #[serde(default)]
    pub source: Option<String>,
    #[serde(default)]
    pub tolerance: Option<f64>,
    #[serde(default)]
    pub tolerance_why: Option<String>,
}

/// Whether a TOML file is a study (it has `runs` and a `case`) rather than a case.
pub fn is_study(text: &str) -> bool {
    toml::from_str::<toml::Table>(text).is_ok_and(|t| t.contains_key("runs") && t.contains_key("case"))
}

pub struct Study {
    pub file: StudyFile,
    pub case_path: PathBuf,
    /// The study file's id in the source map.
    pub source: u32,
    /// Where the study file says what its diagnostics are about.
    pub spans: Spans,
}

/// Byte ranges of the study file: its `name`, and each entry of `plots` and `ci_runs`.
#[derive(Debug, Default)]
pub struct Spans {
    pub name: std::ops::Range<usize>,
    pub plots: Vec<std::ops::Range<usize>>,
    pub ci_runs: Vec<std::ops::Range<usize>>,
}

impl Spans {
    /// The study file read again for the positions of what `StudyFile` keeps as plain strings.
    fn of(text: &str) -> Spans {
        #[derive(Deserialize)]
        struct Located {
            name: toml::Spanned<String>,
            #[serde(default)]
            plots: Vec<toml::Spanned<String>>,
            #[serde(default)]
            ci_runs: Vec<toml::Spanned<String>>,
        }
        match toml::from_str::<Located>(text) {
            Ok(l) => Spans {
                name: l.name.span(),
                plots: l.plots.iter().map(|p| p.span()).collect(),
                ci_runs: l.ci_runs.iter().map(|p| p.span()).collect(),
            },
            Err(_) => Spans::default(),
        }
    }
}

/// What a study result computes across its runs.
#[derive(Clone, Debug)]
pub enum Across {
    /// A Recht–Ipson fit of the case's result `y` against the run parameter `x`, with `a` and
    /// `p` held where given.
    RechtIpson { x: String, y: String, held: Held },
    /// The wall time of the first run over the second's.
    Ratio([String; 2]),
    /// (second − first) / |first| of the case's result `of`.
    Difference([String; 2], String),
    /// One run's value of the case's result `of`.
    Run(String, String),
    /// The mean of the case's result `of` over the runs, with its standard error.
    Mean(Vec<String>, String),
}

impl StudyResult {
    /// What this result computes; `None` when its keys say nothing complete.
    pub fn across(&self) -> Option<Across> {
        if self.fit.is_some() {
            return match (self.fit.as_deref(), &self.x, &self.y) {
                (Some("recht_ipson"), Some(x), Some(y)) => {
                    Some(Across::RechtIpson { x: x.clone(), y: y.clone(), held: Held { a: self.a, p: self.p } })
                }
                _ => None,
            };
        }
        match (&self.ratio, &self.difference, &self.run, &self.mean, &self.of) {
            (Some(r), None, None, None, None) => Some(Across::Ratio(r.clone())),
            (None, Some(d), None, None, Some(of)) => Some(Across::Difference(d.clone(), of.clone())),
            (None, None, Some(run), None, Some(of)) => Some(Across::Run(run.clone(), of.clone())),
            (None, None, None, Some(runs), Some(of)) => Some(Across::Mean(runs.clone(), of.clone())),
            _ => None,
        }
    }
}

/// Everything a study needs that can be known before its first run, checked against its case
/// (loaded with the first run's parameters): each result says what it computes, names runs of the
/// study and results of the case, with a reference that parses; plots name probes of the case.
pub fn validate(study: &Study, case_results: &[String], case_probes: &[String]) -> Vec<Diagnostic> {
    let mut out = vec![];
    let runs: Vec<&str> = study.file.runs.iter().map(|r| r.name.as_str()).collect();
    for sr in &study.file.results {
        let q = &sr.quantity;
        let span = Span::new(study.source, q.span().start, q.span().end);
        let mut err = |msg: String, help: String| {
            out.push(
                Diagnostic::error("C0031", format!("study result `{}`: {msg}", q.get_ref()))
                    .at(span, "here")
                    .help(help),
            )
        };
        let named_runs: Vec<String> = match sr.across() {
            None => {
                err(
                    "says none of `fit = \"recht_ipson\"` (with `x`, `y`), `ratio`, `difference`, `run` or `mean` (each with `of`)".into(),
                    "give exactly one of these".into(),
                );
                continue;
            }
            Some(Across::RechtIpson { x, y, held }) => {
                if held.a.is_some_and(|a| !(a > 0.0 && a <= 1.0)) || held.p.is_some_and(|p| !(1.0..=4.0).contains(&p)) {
                    err(
                        format!("a Recht–Ipson curve with a = {:?}, p = {:?}", held.a, held.p),
                        "hold `a` within (0, 1] and `p` within [1, 4], or leave them out to fit them".into(),
                    );
                }
                if let Some(r) = study
                    .file
                    .runs
                    .iter()
                    .find(|r| r.set.get(&x).and_then(|v| quantity::parse(&text_of(v)).ok()).is_none())
                {
                    err(
                        format!("run `{}` sets no number for `{x}`", r.name),
                        format!("every run sets `{x}` in its `set`"),
                    );
                }
                if !case_results.contains(&y) {
                    err(
                        format!("the case has no result `{y}`"),
                        format!("the case's results: {}", case_results.join(", ")),
                    );
                }
                vec![]
            }
            Some(Across::Ratio(r)) => r.to_vec(),
            Some(Across::Mean(runs, _)) if runs.len() < 2 => {
                err(
                    format!("a mean over {} run(s)", runs.len()),
                    "name two runs or more: a mean's standard error needs them".into(),
                );
                vec![]
            }
            Some(Across::Difference(_, of)) | Some(Across::Run(_, of)) | Some(Across::Mean(_, of))
                if !case_results.contains(&of) =>
            {
                err(
                    format!("the case has no result `{of}`"),
                    format!("the case's results: {}", case_results.join(", ")),
                );
                vec![]
            }
            Some(Across::Difference(d, _)) => d.to_vec(),
            Some(Across::Run(r, _)) => vec![r],
            Some(Across::Mean(runs, _)) => runs,
        };
        for r in named_runs.into_iter().filter(|r| !runs.contains(&r.as_str())) {
            err(format!("no run is named `{r}`"), format!("the runs: {}", runs.join(", ")));
        }
        if sr.reference.is_some() && reference(&sr.reference).is_none() {
            err("its reference is not a quantity".into(), "a number, or a string such as \"152.5 m/s\"".into());
        }
    }
    let at = |spans: &[std::ops::Range<usize>], k: usize| {
        let r = spans.get(k).unwrap_or(&study.spans.name);
        Span::new(study.source, r.start, r.end)
    };
    for (k, p) in study.file.plots.iter().enumerate().filter(|(_, p)| !case_probes.contains(p)) {
        out.push(
            Diagnostic::error(
                "C0031",
                format!("study `{}` plots `{p}`, which is no probe of its case", study.file.name),
            )
            .at(at(&study.spans.plots, k), "no such probe")
            .help(format!("the case's probes: {}", case_probes.join(", "))),
        );
    }
    for (k, c) in study.file.ci_runs.iter().flatten().enumerate().filter(|(_, c)| !runs.contains(&c.as_str())) {
        out.push(
            Diagnostic::error("C0031", format!("study `{}`: `ci_runs` names `{c}`, which is no run", study.file.name))
                .at(at(&study.spans.ci_runs, k), "no such run"),
        );
    }
    out
}

pub fn load(path: &Path, sources: &mut crate::diag::Sources) -> Result<Study, Vec<Diagnostic>> {
    let text = super::build::read_text(path).map_err(|d| vec![*d])?;
    load_text(&text, path, sources)
}

/// A study from its text, as if read from `path` (its case is relative to `path`'s folder).
pub fn load_text(text: &str, path: &Path, sources: &mut crate::diag::Sources) -> Result<Study, Vec<Diagnostic>> {
    let id = sources.add(crate::check::load::display_path(path), text.to_string());
    let file: StudyFile = toml::from_str(text).map_err(|e| {
        let span = e.span().unwrap_or(0..0);
        vec![Diagnostic::error("C0030", format!("study file: {}", e.message().trim()))
            .at(Span::new(id, span.start, span.end), "here")]
    })?;
    let case_path = path.parent().map(Path::to_path_buf).unwrap_or_default().join(file.case.get_ref());
    // The case is read before the first run: say now, and where, when it cannot be.
    if let Err(d) = super::build::read_text(&case_path) {
        let r = file.case.span();
        return Err(vec![(*d).at(Span::new(id, r.start, r.end), "the study's case")]);
    }
    Ok(Study { file, case_path, source: id, spans: Spans::of(text) })
}

/// A value as text for `--set`.
pub fn text_of(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// A reference quantity (number or string with a unit) in SI.
pub fn reference(v: &Option<toml::Value>) -> Option<f64> {
    match v.as_ref()? {
        toml::Value::Integer(i) => Some(*i as f64),
        toml::Value::Float(f) => Some(*f),
        toml::Value::String(s) => quantity::parse(s).ok().map(|q| q.value),
        _ => None,
    }
}

/// The mean of `values` and its standard error (the sample standard deviation over √n); `None`
/// with fewer than two values. A value that is not finite makes both NaN: a run that blew up is
/// not averaged away.
pub fn mean_and_standard_error(values: &[f64]) -> Option<(f64, f64)> {
    let n = values.len();
    if n < 2 {
        return None;
    }
    let mean = values.iter().sum::<f64>() / n as f64;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    Some((mean, (var / n as f64).sqrt()))
}

/// The Recht–Ipson fit `v_r = a (v_i^p − v_bl^p)^(1/p)` (0 below the ballistic limit v_bl).
#[derive(Clone, Copy, Debug)]
pub struct RechtIpson {
    pub a: f64,
    pub p: f64,
    pub v_bl: f64,
    /// How far the curve misses the runs that perforated, root mean square.
    pub rms: f64,
    /// The mean residual of the runs that perforated, the scale `rms` is read against.
    pub mean_residual: f64,
}

impl RechtIpson {
    pub fn residual(&self, v: f64) -> f64 {
        if v <= self.v_bl {
            0.0
        } else {
            self.a * (v.powf(self.p) - self.v_bl.powf(self.p)).powf(1.0 / self.p)
        }
    }
}

/// The constants of a Recht–Ipson curve held instead of fitted.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Held {
    pub a: Option<f64>,
    pub p: Option<f64>,
}

/// A projectile whose residual velocity is below this fraction of its impact speed stopped in the
/// plate: it still rings with it (by 1–2 % of the impact speed at the end of the Børvik runs). A
/// true perforation that slow lies within 0.15 % of the limit (a ≥ 0.9, p = 2), so counting it
/// as stopped moves no fit measurably.
pub const STOPPED_BELOW: f64 = 0.05;

/// Least-squares fit over (impact, residual) pairs. Runs that did not perforate (residual below
/// [`STOPPED_BELOW`] of the impact speed) bound the limit from below; `a` is linear and solved
/// exactly for each (p, v_bl) of a search, unless `held` gives it (and `p`). With three runs and nothing held the fit has as many unknowns
/// as points and its limit swings with small changes in them; holding `a` and `p` at Recht and
/// Ipson's plugging values leaves the limit alone to fit, and then one run is enough: the limit
/// of the curve through it.
pub fn fit_recht_ipson(points: &[(f64, f64)], held: Held) -> Option<RechtIpson> {
    let perforated = |p: &(f64, f64)| p.1 > STOPPED_BELOW * p.0;
    let stopped = super::max_keeping_nan(0.0, points.iter().filter(|p| !perforated(p)).map(|p| p.0));
    let through: Vec<(f64, f64)> = points.iter().copied().filter(perforated).collect();
    let lowest = super::min_keeping_nan(f64::INFINITY, through.iter().map(|p| p.0));
    let mean_residual = through.iter().map(|p| p.1).sum::<f64>() / through.len() as f64;
    if let ([(v, y)], Held { a: Some(a), p: Some(p) }) = (through.as_slice(), held) {
        // One run and the curve's shape held: the limit is the curve through it, exactly.
        let v_bl = super::max_keeping_nan(stopped, [(v.powf(p) - (y / a).powf(p)).max(0.0).powf(1.0 / p)]);
        return Some(RechtIpson { a, p, v_bl, rms: 0.0, mean_residual });
    }
    if through.len() < 2 {
        return None;
    }
    let at = |p: f64, v_bl: f64| curve_through(&through, p, v_bl, held.a, mean_residual);
    let ps: Vec<f64> = match held.p {
        Some(p) => vec![p],
        None => (0..=300).map(|pi| 1.0 + pi as f64 * 0.01).collect(),
    };
    let step = (lowest - stopped) / 400.0;
    let mut best: Option<RechtIpson> = None;
    for p in ps {
        for v_bl in (0..=400).map(|bi| stopped + step * bi as f64).filter(|v| *v < lowest) {
            if let Some(curve) = at(p, v_bl) {
                if best.is_none_or(|b| curve.rms < b.rms) {
                    best = Some(curve);
                }
            }
        }
    }
    best.map(|b| refine_limit(b, stopped.max(b.v_bl - step), lowest.min(b.v_bl + step), at))
}

/// The curve of shape `p` and limit `v_bl` nearest the runs that went through, with `a` solved
/// exactly (linear least squares) unless held; `None` where no run lies above the limit.
fn curve_through(through: &[(f64, f64)], p: f64, v_bl: f64, a: Option<f64>, mean_residual: f64) -> Option<RechtIpson> {
    let f: Vec<f64> = through.iter().map(|(v, _)| (v.powf(p) - v_bl.powf(p)).powf(1.0 / p)).collect();
    let ff: f64 = f.iter().map(|x| x * x).sum();
    let fy: f64 = f.iter().zip(through).map(|(x, (_, y))| x * y).sum();
    if ff <= 0.0 {
        return None;
    }
    let a = a.unwrap_or((fy / ff).clamp(0.0, 1.0));
    let sse: f64 = f.iter().zip(through).map(|(x, (_, y))| (y - a * x).powi(2)).sum();
    Some(RechtIpson { a, p, v_bl, rms: (sse / through.len() as f64).sqrt(), mean_residual })
}

/// The grid's best limit refined by golden section between `lo` and `hi` (a grid step either side
/// of it) at its `p`: the grid's step, a 400th of the bracket, is 0.48 m/s on the Børvik CI study,
/// and a limit read to the grid moved by up to half that with no change in the runs.
fn refine_limit(best: RechtIpson, mut lo: f64, mut hi: f64, at: impl Fn(f64, f64) -> Option<RechtIpson>) -> RechtIpson {
    let rms = |v: f64| at(best.p, v).map_or(f64::INFINITY, |c| c.rms);
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut c, mut d) = (hi - g * (hi - lo), lo + g * (hi - lo));
    let (mut fc, mut fd) = (rms(c), rms(d));
    for _ in 0..80 {
        if fc < fd {
            (hi, d, fd) = (d, c, fc);
            c = hi - g * (hi - lo);
            fc = rms(c);
        } else {
            (lo, c, fc) = (c, d, fd);
            d = lo + g * (hi - lo);
            fd = rms(d);
        }
    }
    match at(best.p, (lo + hi) / 2.0) {
        Some(refined) if refined.rms <= best.rms => refined,
        _ => best,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_mean_over_runs_has_the_sample_standard_deviation_over_root_n_and_keeps_nan() {
        let (m, se) = mean_and_standard_error(&[222.81, 227.65, 229.43]).expect("three values");
        assert!((m - 226.63).abs() < 1e-12, "{m}");
        // Deviations −3.82, +1.02, +2.80: s² = (14.5924 + 1.0404 + 7.84) / 2.
        let s = ((14.5924f64 + 1.0404 + 7.84) / 2.0).sqrt();
        assert!((se - s / 3f64.sqrt()).abs() < 1e-12, "{se}");
        assert!(mean_and_standard_error(&[1.0]).is_none());
        let (m, se) = mean_and_standard_error(&[1.0, f64::NAN, 3.0]).expect("three values");
        assert!(m.is_nan() && se.is_nan());
    }

    #[test]
    fn recht_ipson_recovers_its_own_curve() {
        let truth = RechtIpson { a: 0.79, p: 2.2, v_bl: 152.5, rms: 0.0, mean_residual: 0.0 };
        let pts: Vec<(f64, f64)> =
            [137.4, 152.0, 156.0, 165.2, 190.7, 250.8, 298.0].iter().map(|v| (*v, truth.residual(*v))).collect();
        let fit = fit_recht_ipson(&pts, Held::default()).expect("fits");
        // p = 2.2 lies on the search's grid of p (0.01 apart) and the limit is refined between
        // the grid's points: the curve itself.
        assert!((fit.v_bl - 152.5).abs() < 1e-6 && (fit.p - 2.2).abs() < 1e-9, "{fit:?}");
        assert!(fit.rms < 1.0, "{fit:?}");
    }

    /// The Børvik 8 mm runs without the slot (stop 29): three speeds stop in the plate and ring
    /// with it, ending at +1.7, +0.24 and −0.39 m/s; counted as perforations, the two positive ones
    /// left no limit below the slowest "perforation" above the fastest stop, and the fit failed.
    #[test]
    fn a_projectile_ringing_in_the_plate_counts_as_stopped() {
        let pts = [
            (298.0, 225.473),
            (250.8, 176.858),
            (190.7, 103.036),
            (165.2, 47.068),
            (156.0, -0.390),
            (152.5, 0.244),
            (137.4, 1.718),
        ];
        let held = Held { a: Some(0.909), p: Some(2.0) };
        let fit = fit_recht_ipson(&pts, held).expect("fits");
        assert!(fit.v_bl >= 156.0 && fit.v_bl < 165.2, "{fit:?}");
        let through: Vec<f64> = pts.iter().filter(|p| p.1 > STOPPED_BELOW * p.0).map(|p| p.1).collect();
        assert_eq!(through.len(), 4);
        assert!((fit.mean_residual - through.iter().sum::<f64>() / 4.0).abs() < 1e-9, "{fit:?}");
    }

    #[test]
    fn recht_ipson_with_a_and_p_held_fits_the_limit_alone_to_a_micrometre_per_second_between_the_grids_points() {
        let truth = RechtIpson { a: 0.909, p: 2.0, v_bl: 152.5, rms: 0.0, mean_residual: 0.0 };
        let held = Held { a: Some(0.909), p: Some(2.0) };
        // Three runs well above the limit, a few per cent off the curve: the limit stays close.
        let pts: Vec<(f64, f64)> =
            [(298.0, 1.03), (250.8, 0.97), (190.7, 1.02)].iter().map(|(v, k)| (*v, k * truth.residual(*v))).collect();
        let fit = fit_recht_ipson(&pts, held).expect("fits");
        assert_eq!((fit.a, fit.p), (0.909, 2.0));
        assert!((fit.v_bl - 152.5).abs() < 10.0, "{fit:?}");
        // On the curve itself, exactly: 152.5 m/s lies between the search grid's points (a 400th
        // of the bracket 0–190.7 m/s, 0.477 m/s apart), and the refinement finds it.
        let exact: Vec<(f64, f64)> = [298.0, 190.7].iter().map(|v| (*v, truth.residual(*v))).collect();
        let fit = fit_recht_ipson(&exact, held).expect("fits");
        assert!((fit.v_bl - 152.5).abs() < 1e-6, "{fit:?}");
        assert!((fit.mean_residual - (exact[0].1 + exact[1].1) / 2.0).abs() < 1e-9, "{fit:?}");
    }

    #[test]
    fn recht_ipson_with_a_and_p_held_through_one_run_gives_that_curves_limit_and_none_when_not_held() {
        let truth = RechtIpson { a: 0.909, p: 2.0, v_bl: 152.5, rms: 0.0, mean_residual: 0.0 };
        let held = Held { a: Some(0.909), p: Some(2.0) };
        let one = [(298.0, truth.residual(298.0))];
        let fit = fit_recht_ipson(&one, held).expect("fits");
        assert!((fit.v_bl - 152.5).abs() < 1e-9, "{fit:?}");
        // A run that stopped bounds it from below.
        let fit = fit_recht_ipson(&[(298.0, 0.909 * (298.0f64.powi(2) - 100.0f64.powi(2)).sqrt()), (120.0, 0.0)], held)
            .expect("fits");
        assert!((fit.v_bl - 120.0).abs() < 1e-9, "{fit:?}");
        assert!(fit_recht_ipson(&one, Held { a: Some(0.909), p: None }).is_none());
    }
}
