//! Case file → scene: the model checked, bodies filled with particles, materials bound with
//! their units checked, loads, constraints and symmetry planes, outputs, probes and results.
//! Every mistake in the case file is a diagnostic at its line and column.

use super::case::{self, CaseFile, Value};
use super::geometry::{self, Primitive};
use super::measure::Measure;
use super::quantity;
use super::spec::{BodyInfo, Options, Pick, ProbeKind, ProbeSpec, ProbeValue, ProfileSpec, Record, ResultSpec, Scene};
use crate::backend::Mirror;
use crate::check::{self, Stdlib};
use crate::diag::{closest, Diagnostic, Sources, Span};
use crate::engine::setup::{InitialValue, MaterialInput, ParticleInput};
use crate::engine::RunConfig;
use crate::ir::{self, FieldId, GroupSet, Model, Shape};
use crate::schedule::{Constraint, IntegratorKind, Load, SceneSpec, Search, Target};
use crate::units::Unit;
use std::collections::BTreeMap;
use std::path::Path;

struct Ctx<'a> {
    file: u32,
    dim: usize,
    diags: &'a mut Vec<Diagnostic>,
    /// Where the options stand, for errors in them.
    cli: &'a CommandLine,
    /// The case text (placeholders expanded): what spans in `file` index.
    text: &'a str,
    /// The materials as the case's own parameters and the resolution's `set` give them, without
    /// `--set` or a study run's values: what a material's `optional` keys may keep under a model
    /// that does not take them. None where nothing was set.
    default_materials: Option<&'a BTreeMap<String, BTreeMap<String, Value>>>,
}

/// The options a case was loaded with, written out as a source of their own (`<command line>`)
/// so that an error in one points at it like an error in the case file.
#[derive(Default)]
struct CommandLine {
    file: u32,
    resolution: Option<std::ops::Range<usize>>,
    set: Vec<std::ops::Range<usize>>,
    verlet: Option<std::ops::Range<usize>>,
    end_time: Option<std::ops::Range<usize>>,
}

impl CommandLine {
    fn new(opts: &Options, sources: &mut Sources) -> CommandLine {
        let mut text = String::new();
        let mut arg = |flag: &str, value: String| -> std::ops::Range<usize> {
            if !text.is_empty() {
                text.push(' ');
            }
            text.push_str(flag);
            text.push(' ');
            let start = text.len();
            text.push_str(&value);
            start..text.len()
        };
        let resolution = opts.resolution.as_ref().map(|r| arg("--resolution", r.clone()));
        let set = opts.set.iter().map(|(k, v)| arg("--set", format!("{k}={v}"))).collect();
        let verlet = opts.verlet.map(|v| arg("--verlet", v.to_string()));
        let end_time = opts.end_time.map(|t| arg("--end-time", t.to_string()));
        let file = if text.is_empty() { u32::MAX } else { sources.add("<command line>", text) };
        CommandLine { file, resolution, set, verlet, end_time }
    }

    fn span(&self, r: &Option<std::ops::Range<usize>>) -> Option<Span> {
        r.as_ref().map(|r| Span::new(self.file, r.start, r.end))
    }
}

impl Ctx<'_> {
    fn span(&self, r: std::ops::Range<usize>) -> Span {
        Span::new(self.file, r.start, r.end)
    }
    fn err(
        &mut self,
        span: std::ops::Range<usize>,
        code: &'static str,
        msg: impl Into<String>,
        label: impl Into<String>,
    ) {
        let s = self.span(span);
        self.diags.push(Diagnostic::error(code, msg).at(s, label));
    }

    /// A scalar quantity: a number (SI) or a string with a unit, checked against `unit`.
    fn scalar(&mut self, v: &Value, unit: Unit, what: &str) -> Option<f64> {
        let span = v.span();
        let q = match v.get_ref() {
            toml::Value::Integer(i) => quantity::Quantity { value: *i as f64, unit },
            toml::Value::Float(f) => quantity::Quantity { value: *f, unit },
            toml::Value::String(s) => match quantity::parse(s) {
                Ok(q) => q,
                Err(e) => {
                    self.err(span, "C0002", format!("{what}: {e}"), "not a quantity");
                    return None;
                }
            },
            other => {
                self.err(
                    span,
                    "C0002",
                    format!("{what} must be a number or a quantity like \"490 MPa\", found {}", other.type_str()),
                    "here",
                );
                return None;
            }
        };
        if q.unit != unit {
            let s = self.span(span);
            self.diags.push(
                Diagnostic::error("C0003", format!("wrong unit for {what}: expected {unit}, found {}", q.unit))
                    .at(s, format!("this is {}", q.unit))
                    .help(format!("write a value in {unit} (prefixes such as k, M, G, m, u are fine)")),
            );
            return None;
        }
        Some(q.value)
    }

    /// `x` when it is positive and finite; C0002 at `span` otherwise.
    fn positive(&mut self, span: std::ops::Range<usize>, x: f64, what: &str) -> Option<f64> {
        if x.is_finite() && x > 0.0 {
            return Some(x);
        }
        self.err(span, "C0002", format!("{what} must be positive and finite, found {x}"), "here");
        None
    }

    /// A vector of `dim` quantities (a list), each checked against `unit`.
    fn vector(&mut self, v: &Value, unit: Unit, what: &str) -> Option<[f64; 3]> {
        let span = v.span();
        let toml::Value::Array(items) = v.get_ref() else {
            self.err(span, "C0002", format!("{what} must be a list of {} components", self.dim), "not a list");
            return None;
        };
        if items.len() < self.dim || items.len() > 3 {
            self.err(
                span,
                "C0002",
                format!("{what} needs {} components (the case is {}D), found {}", self.dim, self.dim, items.len()),
                "here",
            );
            return None;
        }
        let mut out = [0.0; 3];
        for (k, item) in items.iter().enumerate() {
            let spanned = toml::Spanned::new(span.clone(), item.clone());
            out[k] = self.scalar(&spanned, unit, what)?;
        }
        if let Some(k) = (self.dim..items.len()).find(|k| out[*k] != 0.0) {
            let msg = format!(
                "{what} has a non-zero component {} beyond the {}D case's axes: leave it out or make it 0",
                "xyz".as_bytes()[k] as char,
                self.dim
            );
            self.err(span, "C0002", msg, "here");
            return None;
        }
        Some(out)
    }

    /// A direction: `dim` to 3 dimensionless components, all kept (an axis along z is
    /// perpendicular to a 2D case's plane).
    fn direction(&mut self, v: &Value, what: &str) -> Option<[f64; 3]> {
        let saved = self.dim;
        self.dim = 3.min(v.get_ref().as_array().map_or(saved, Vec::len)).max(saved);
        let out = self.vector(v, Unit::ONE, what);
        self.dim = saved;
        out
    }

    /// A polygon's vertices: a list of `[x, y]` points in m.
    fn vertices(&mut self, v: &Value, what_span: &str) -> Option<Vec<[f64; 2]>> {
        let span = v.span();
        let toml::Value::Array(items) = v.get_ref() else {
            self.err(span, "C0002", format!("{what_span} must be a list of [x, y] points"), "not a list");
            return None;
        };
        let mut out = vec![];
        for item in items {
            let spanned = toml::Spanned::new(span.clone(), item.clone());
            let ok = item.as_array().is_some_and(|a| a.len() == 2);
            if !ok {
                self.err(span.clone(), "C0002", format!("each of the {what_span} is an [x, y] point"), "here");
                return None;
            }
            let saved = self.dim;
            self.dim = 2;
            let p = self.vector(&spanned, Unit::M, what_span);
            self.dim = saved;
            let p = p?;
            out.push([p[0], p[1]]);
        }
        Some(out)
    }
}

fn unit(s: &str) -> Unit {
    crate::units::parse_simple(s).unwrap_or(Unit::ONE)
}

/// The parameter values the chosen resolution sets (`[resolutions] ci = { dx = …, set = { … } }`),
/// read from the unexpanded text (placeholders live inside strings, so it parses).
fn resolution_set(text: &str, opts: &Options) -> Vec<(String, String)> {
    let Ok(table) = super::template::skeleton(text) else { return vec![] };
    let wanted = opts
        .resolution
        .clone()
        .or_else(|| table.get("default_resolution").and_then(|r| r.as_str()).map(str::to_string))
        .unwrap_or_else(|| "ci".into());
    let (name, _) = super::spec::split_resolution(&wanted);
    let set = table.get("resolutions").and_then(|r| r.get(name)).and_then(|r| r.get("set")).and_then(|s| s.as_table());
    set.map(|s| s.iter().map(|(k, v)| (k.clone(), super::study::text_of(v))).collect()).unwrap_or_default()
}

/// The most particles a scene may hold unless its case file says otherwise (`max_particles`).
pub const DEFAULT_MAX_PARTICLES: u64 = geometry::MAX_PARTICLES;

/// Bounds on what loading a case may build, whatever its file says (a fuzzer's or a service's).
#[derive(Clone, Copy, Debug, Default)]
pub struct Limits {
    /// At most this many particles in the scene, even if the case's `max_particles` allows more.
    pub max_particles: Option<u64>,
}

/// Where the case text gives the resolution whose `set` is applied.
fn resolution_span(text: &str, opts: &Options) -> Option<std::ops::Range<usize>> {
    #[derive(serde::Deserialize)]
    struct Located {
        #[serde(default)]
        default_resolution: Option<String>,
        #[serde(default)]
        resolutions: std::collections::BTreeMap<String, toml::Spanned<toml::Value>>,
    }
    let l: Located = toml::from_str(&super::template::skeleton_text(text)).ok()?;
    let wanted = opts.resolution.clone().or(l.default_resolution).unwrap_or_else(|| "ci".into());
    let (name, _) = super::spec::split_resolution(&wanted);
    l.resolutions.get(name).map(|r| r.span())
}

/// Reads and builds a case. Diagnostics (DSL and case file) are returned on failure.
pub fn load(path: &Path, sources: &mut Sources, opts: &Options) -> Result<Scene, Vec<Diagnostic>> {
    let text = read_text(path).map_err(|d| vec![*d])?;
    load_text(&text, path, sources, opts, Limits::default())
}

/// The text of a case or study file: a regular file only (a device or a pipe, `/dev/zero`, would
/// be read forever).
pub fn read_text(path: &Path) -> Result<String, Box<Diagnostic>> {
    let read = match std::fs::metadata(path) {
        Ok(m) if !m.is_file() => Err(std::io::Error::other("not a regular file")),
        _ => std::fs::read_to_string(path),
    };
    read.map_err(|e| Box::new(Diagnostic::error("C0001", format!("cannot read `{}`: {e}", path.display()))))
}

/// Builds a case from its text, as if read from `path` (which names it in diagnostics and
/// places what it refers to: a model file, node files).
pub fn load_text(
    text: &str,
    path: &Path,
    sources: &mut Sources,
    opts: &Options,
    limits: Limits,
) -> Result<Scene, Vec<Diagnostic>> {
    let mut set = resolution_set(text, opts);
    let from_case = set.len();
    set.extend(opts.set.iter().cloned());
    let text_unexpanded = text;
    let text = match super::template::expand(text, &set) {
        Ok(t) => t,
        Err(e) => {
            let file = sources.add(check::load::display_path(path), text.to_string());
            let d = match e.set_entry {
                // A name the chosen resolution's `set` gives, or a `--set`.
                Some(k) if k < from_case => {
                    let r = resolution_span(text, opts).unwrap_or(0..0);
                    Diagnostic::error("C0026", e.message).at(Span::new(file, r.start, r.end), "this resolution sets it")
                }
                Some(k) => {
                    let cli = CommandLine::new(opts, sources);
                    let r = cli.set.get(k - from_case).cloned().unwrap_or(0..0);
                    Diagnostic::error("C0026", e.message).at(Span::new(cli.file, r.start, r.end), "no such parameter")
                }
                None if e.not_toml => {
                    let msg = e.message.trim().to_string();
                    Diagnostic::error("C0001", format!("case file: {msg}")).at(Span::new(file, e.start, e.end), msg)
                }
                None => e.diagnostic(file),
            };
            return Err(vec![d]);
        }
    };
    let file = sources.add(check::load::display_path(path), text.clone());
    let case: CaseFile = toml::from_str(&text).map_err(|e| vec![toml_error(file, &e)])?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut diags = vec![];
    // The model.
    let model = load_model(&case, &dir, file, sources, &mut diags);
    let Some(model) = model else { return Err(diags) };
    let dim = *case.dim.get_ref();
    if !(1..=3).contains(&dim) {
        diags.push(
            Diagnostic::error("C0004", format!("dim must be 1, 2 or 3, found {dim}"))
                .at(Span::new(file, case.dim.span().start, case.dim.span().end), "here"),
        );
        return Err(diags);
    }
    let cli = CommandLine::new(opts, sources);
    let defaults = default_materials(text_unexpanded, &set[..from_case], opts, &case);
    let mut cx = Ctx { file, dim, diags: &mut diags, cli: &cli, text: &text, default_materials: defaults.as_ref() };
    let scene = build(&case, path, &dir, model, opts, limits, &mut cx);
    match scene {
        Some(mut s) if !diags.iter().any(|d| d.is_error()) => {
            s.warnings = diags.iter().map(|d| crate::diag::render(sources, std::slice::from_ref(d))).collect();
            Ok(s)
        }
        _ => Err(diags),
    }
}

/// The material key that lists the keys only some of a case's models take.
const OPTIONAL: &str = "optional";

/// A material's `optional = ["p_spall", …]`: keys of its own that only some of the case's models
/// take (a case that switches models with a parameter). Error C0052 for a list that is not one of
/// its keys' names.
fn optional_keys(mat: &str, values: &BTreeMap<String, Value>, cx: &mut Ctx) -> Vec<String> {
    let Some(list) = values.get(OPTIONAL) else { return vec![] };
    let names = list.get_ref().as_array().map(|a| a.iter().map(|k| k.as_str()).collect::<Option<Vec<_>>>());
    let Some(Some(names)) = names else {
        let msg = format!("material `{mat}`: `{OPTIONAL}` must be a list of its keys' names");
        cx.err(list.span(), "C0052", msg, "here");
        return vec![];
    };
    for name in &names {
        if !values.contains_key(*name) || *name == OPTIONAL {
            let msg = format!("material `{mat}`: `{OPTIONAL}` lists `{name}`, which it does not set");
            cx.err(list.span(), "C0052", msg, "in this list");
        }
    }
    names.into_iter().map(str::to_string).collect()
}

/// Whether a material's key that the model does not take is one of its `optional` keys at the
/// case's default value, and so left out. Set away from it (`--set`, a study run) it is error
/// C0007: the run would not do what was asked.
fn optional_left_out(mat: &str, key: &str, v: &Value, optional: &[String], case: &CaseFile, cx: &mut Ctx) -> bool {
    if !optional.iter().any(|k| k == key) {
        return false;
    }
    let default = cx.default_materials.map_or(Some(v), |m| m.get(mat).and_then(|vals| vals.get(key)));
    if default.is_some_and(|d| same_value(d.get_ref(), v.get_ref())) {
        return true;
    }
    let model = case.model.get_ref();
    let d =
        Diagnostic::error("C0007", format!("material `{mat}` sets `{key}`, which the model `{model}` does not take"))
            .at(cx.span(v.span()), "set away from the case's default")
            .help(format!(
        "`{key}` is one of the material's `{OPTIONAL}` keys: under a model without it, it may only keep its default"
    ));
    cx.diags.push(d);
    true
}

/// Whether two values of a key are the same: equal as written, or the same quantity however
/// written (`1e20 GPa` and `100000000000000000000.0 GPa`, `6 GPa` and `6000 MPa`), to 1 part in
/// 10¹².
fn same_value(a: &toml::Value, b: &toml::Value) -> bool {
    let quantity = |v: &toml::Value| match v {
        toml::Value::Integer(i) => Some(quantity::Quantity { value: *i as f64, unit: Unit::ONE }),
        toml::Value::Float(f) => Some(quantity::Quantity { value: *f, unit: Unit::ONE }),
        toml::Value::String(s) => quantity::parse(s).ok(),
        _ => None,
    };
    a == b
        || quantity(a).zip(quantity(b)).is_some_and(|(a, b)| {
            a.unit == b.unit && (a.value - b.value).abs() <= 1e-12 * a.value.abs().max(b.value.abs())
        })
}

/// The materials of the case with only its own parameters and the resolution's `set` (see
/// [`Ctx::default_materials`]); None where `--set` or a study run changed nothing, or where no
/// material has `optional` keys to compare.
fn default_materials(
    text: &str,
    resolution_set: &[(String, String)],
    opts: &Options,
    case: &CaseFile,
) -> Option<BTreeMap<String, BTreeMap<String, Value>>> {
    if opts.set.is_empty() || !case.materials.values().any(|m| m.contains_key(OPTIONAL)) {
        return None;
    }
    let text = super::template::expand(text, resolution_set).ok()?;
    toml::from_str::<CaseFile>(&text).ok().map(|c| c.materials)
}

/// The keys serde's "unknown field" message lists after the key: "expected `a`", "expected `a`
/// or `b`", "expected one of `a`, `b`, `c`", or none ("there are no fields").
fn expected_keys(message: &str) -> Vec<&str> {
    let Some((_, list)) = message.split_once("expected ") else { return vec![] };
    let list = list.strip_prefix("one of ").unwrap_or(list);
    list.split(", ")
        .flat_map(|k| k.split(" or "))
        .map(|k| k.trim().trim_matches('`'))
        .filter(|k| !k.is_empty())
        .collect()
}

/// A TOML or shape error of the case file, with a suggestion for a misspelt key.
fn toml_error(file: u32, e: &toml::de::Error) -> Diagnostic {
    let span = e.span().unwrap_or(0..0);
    let msg = e.message().trim().to_string();
    let at = Span::new(file, span.start, span.end);
    if let Some(rest) = msg.strip_prefix("unknown field `") {
        let key = rest.split('`').next().unwrap_or("");
        let expected = expected_keys(rest);
        let mut d = Diagnostic::error("C0001", format!("case file: unknown key `{key}`")).at(at, "not a key here");
        d = match (closest(key, expected.iter().copied()), expected.is_empty()) {
            (Some(best), _) => d.help(format!("did you mean `{best}`?")),
            (None, false) => d.note(format!("the keys here are: {}", expected.join(", "))),
            (None, true) => d.note("this table takes no keys"),
        };
        return d;
    }
    Diagnostic::error("C0001", format!("case file: {msg}")).at(at, msg)
}

fn load_model(
    case: &CaseFile,
    dir: &Path,
    file: u32,
    sources: &mut Sources,
    diags: &mut Vec<Diagnostic>,
) -> Option<Model> {
    let m = case.model.get_ref();
    let checked = if m.ends_with(".sph") {
        let p = dir.join(m);
        if !p.is_file() {
            let s = case.model.span();
            diags.push(
                Diagnostic::error("C0005", format!("model file `{}` not found", p.display()))
                    .at(Span::new(file, s.start, s.end), "no such file"),
            );
            return None;
        }
        check::check_paths(sources, &[p.as_path()], Stdlib::locate())
    } else {
        let rel = Stdlib::file_of(m);
        let mut loader = check::Loader::new(sources, Stdlib::locate());
        loader.load_stdlib_module(&rel, None, true);
        if loader.diags.iter().any(|d| d.code == "E0003") {
            let s = case.model.span();
            let modules = Stdlib::locate().module_names();
            let help = match crate::diag::closest(m, modules.iter().map(String::as_str)) {
                Some(near) => format!("did you mean `{near}`?"),
                None => "name a model file next to the case, or a stdlib module such as `models::elastic_solid`".into(),
            };
            diags.push(
                Diagnostic::error("C0005", format!("no stdlib model `{m}`"))
                    .at(Span::new(file, s.start, s.end), "not a file (ending in .sph) nor a stdlib module")
                    .help(help),
            );
            return None;
        }
        check::check_stdlib_modules(sources, &[rel.as_str()], Stdlib::locate())
    };
    let has_errors = checked.has_errors();
    diags.extend(checked.diags.into_iter().filter(|d| d.is_error()));
    (!has_errors).then_some(checked.model)
}

/// The `pairsum plan` command that lists the parameters of the case's model.
fn plan_command(case: &CaseFile, dir: &Path, dim: usize) -> String {
    let m = case.model.get_ref();
    let model = if m.ends_with(".sph") { dir.join(m).display().to_string() } else { m.clone() };
    let dim = if dim == 3 { String::new() } else { format!(" --dim {dim}") };
    format!("pairsum plan {model}{dim}")
}

fn build(
    case: &CaseFile,
    path: &Path,
    dir: &Path,
    model: Model,
    opts: &Options,
    limits: Limits,
    cx: &mut Ctx,
) -> Option<Scene> {
    let dim = cx.dim;
    let m = Unit::M;
    let s = Unit::S;
    // Resolution.
    let mut resolutions = vec![];
    for (name, r) in case.resolutions.get_ref() {
        let (dx_value, _) = match r.get_ref() {
            case::Resolution::Spacing(v) => (v.clone(), None::<f64>),
            case::Resolution::Table(t) => (t.dx.clone(), t.tolerance),
        };
        let v = toml::Spanned::new(r.span(), dx_value);
        let what = format!("the spacing of resolution `{name}`");
        if let Some(dx) = cx.scalar(&v, m, &what).and_then(|dx| cx.positive(r.span(), dx, &what)) {
            resolutions.push((name.clone(), dx));
        }
    }
    let wanted = opts
        .resolution
        .clone()
        .or_else(|| case.default_resolution.as_ref().map(|r| r.get_ref().clone()))
        .unwrap_or_else(|| "ci".to_string());
    let (settings, at) = super::spec::split_resolution(&wanted);
    let named = resolutions.iter().find(|(n, _)| n == settings).map(|(_, dx)| *dx);
    // An unknown resolution the case file asked for is shown where it asks for it.
    let located = |d: Diagnostic| -> Diagnostic {
        if let Some(span) = cx.cli.span(&cx.cli.resolution) {
            return d.at(span, "not a resolution of the case");
        }
        match &case.default_resolution {
            Some(r) => d.at(cx.span(r.span()), "the default resolution"),
            None => d
                .at(cx.span(case.resolutions.span()), "no resolution `ci` here")
                .help("name one with `default_resolution`, or add a resolution `ci`"),
        }
    };
    let dx = match (named, at) {
        (Some(dx), None) => dx,
        (None, Some(_)) => {
            let names: Vec<String> = resolutions.iter().map(|(n, _)| n.clone()).collect();
            let d = located(Diagnostic::error(
                "C0006",
                format!("unknown resolution `{settings}` in `{wanted}`: the case has {}", names.join(", ")),
            ));
            cx.diags.push(d);
            return None;
        }
        // `name@spacing` with a known name, or a bare spacing.
        (_, at) => {
            match quantity::parse(at.unwrap_or(settings)).ok().filter(|q| q.unit == m || q.unit == Unit::ONE) {
                Some(q) if q.value > 0.0 && q.value.is_finite() => q.value,
                _ => {
                    let names: Vec<String> = resolutions.iter().map(|(n, _)| n.clone()).collect();
                    let d = located(Diagnostic::error(
                    "C0006",
                    format!("unknown resolution `{wanted}`: the case has {} (or give a spacing such as 0.005 or \"5 mm\")", names.join(", ")),
                ));
                    cx.diags.push(d);
                    return None;
                }
            }
        }
    };
    let res_table = case.resolutions.get_ref().get(settings).and_then(|r| match r.get_ref() {
        case::Resolution::Table(t) => Some(t),
        _ => None,
    });
    // A resolution may run the case faster in time (loads, ramps, outputs and result windows
    // scale with it), e.g. a quicker but still quasi-static load for CI.
    let res_span = case.resolutions.get_ref().get(settings).map_or(case.resolutions.span(), |r| r.span());
    let time_scale = res_table.and_then(|t| t.time_scale).unwrap_or(1.0);
    let time_scale = cx.positive(res_span.clone(), time_scale, "`time_scale`")?;
    let mut end_time = cx.scalar(&case.end_time, s, "end_time")?;
    end_time = time_scale * cx.positive(case.end_time.span(), end_time, "end_time")?;
    if let Some(t) = res_table.and_then(|t| t.end_time.clone()) {
        end_time = cx.scalar(&toml::Spanned::new(res_span.clone(), t), s, "end_time")?;
        end_time = cx.positive(res_span.clone(), end_time, "the resolution's end_time")?;
    }
    if let Some(t) = opts.end_time {
        if !(t.is_finite() && t > 0.0) {
            let span = cx.cli.span(&cx.cli.end_time).unwrap_or_default();
            let d = Diagnostic::error("C0002", format!("--end-time must be a positive, finite time, found {t}"))
                .at(span, "here");
            cx.diags.push(d);
            return None;
        }
        end_time = t;
    }
    // Materials.
    let mut materials = vec![];
    let material_spans: Vec<Option<Span>> =
        case.materials.values().map(|values| first_key(values).map(|v| cx.span(v.span()))).collect();
    let used: std::collections::BTreeSet<&str> =
        case.bodies.get_ref().iter().map(|b| b.material.get_ref().as_str()).collect();
    for (mat_name, values) in &case.materials {
        let mut mi = MaterialInput { name: mat_name.clone(), ..Default::default() };
        let unused = !used.contains(mat_name.as_str());
        if let Some(first) = first_key(values).filter(|_| unused) {
            let msg = format!("material `{mat_name}` is used by no body: its keys are not checked against the model");
            cx.diags.push(Diagnostic::warning("C0042", msg).at(cx.span(first.span()), "in this material"));
        }
        let optional = optional_keys(mat_name, values, cx);
        for (key, v) in values {
            if key == OPTIONAL {
                continue;
            }
            let Some(p) = model.param_id(key) else {
                if unused || optional_left_out(mat_name, key, v, &optional, case, cx) {
                    continue;
                }
                let names: Vec<&str> = model.params.iter().map(|p| p.name.as_str()).collect();
                let mut d = Diagnostic::error(
                    "C0007",
                    format!("material `{}` sets `{key}`, which is not a parameter of the model", mi.name),
                )
                .at(cx.span(v.span()), "unknown parameter");
                d = match closest(key, names.iter().copied()) {
                    Some(b) => d.help(format!("did you mean `{b}`?")),
                    None => d.help(format!("`{}` lists the parameters the model reads", plan_command(case, dir, dim))),
                };
                cx.diags.push(d);
                continue;
            };
            if key == crate::ir::AXISYMMETRIC {
                cx.err(v.span(), "C0007", "axisymmetric is the case's top-level `axisymmetric = true`", "here");
                continue;
            }
            if key == crate::ir::GRAVITY {
                cx.err(
                    v.span(),
                    "C0007",
                    "gravity is the case's top-level `gravity`, the same for every material",
                    "here",
                );
                continue;
            }
            let ty = model.params[p.index()].ty;
            let what = format!("`{key}` of material `{}`", mi.name);
            let value = match ty.shape {
                Shape::Scalar => cx.scalar(v, ty.unit, &what).map(|x| vec![x]),
                Shape::Vec => cx.vector(v, ty.unit, &what).map(|x| x[..dim].to_vec()),
                other => {
                    cx.err(
                        v.span(),
                        "C0008",
                        format!("{what} is a {}; case files bind scalars and vecs", other.name()),
                        "here",
                    );
                    None
                }
            };
            if let Some(value) = value {
                mi.values.insert(p, value);
            }
        }
        materials.push(mi);
    }
    // Symmetry planes: the scene is the part of space on the side each keeps (above, by default;
    // an axis may have two planes, the lower keeping above and the upper below).
    let mut mirrors = vec![];
    for sym in &case.symmetry {
        let axis = match sym.axis.get_ref().as_str() {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            other => {
                cx.err(sym.axis.span(), "C0014", format!("symmetry axis is x, y or z, found `{other}`"), "here");
                continue;
            }
        };
        if axis >= dim {
            cx.err(sym.axis.span(), "C0014", format!("a {dim}D case has no axis {}", ir::AXIS_NAMES[axis]), "here");
            continue;
        }
        let at = match &sym.at {
            Some(v) => cx.scalar(v, m, "symmetry plane position")?,
            None => 0.0,
        };
        let plane = match sym.keep.as_ref().map(|k| k.get_ref().as_str()) {
            None | Some("above") => Mirror::symmetry(axis, at),
            Some("below") => Mirror::symmetry_below(axis, at),
            Some(other) => {
                let span = sym.keep.as_ref().map(|k| k.span()).unwrap_or_else(|| sym.axis.span());
                cx.err(span, "C0014", format!("`keep` is \"above\" or \"below\", found `{other}`"), "here");
                continue;
            }
        };
        let same_axis: Vec<&Mirror> = mirrors.iter().filter(|m: &&Mirror| m.axis == axis).collect();
        let pair_ok = match same_axis.as_slice() {
            [] => true,
            [other] => {
                let (lower, upper) = if plane.side > 0.0 { (&plane, *other) } else { (*other, &plane) };
                lower.side > 0.0 && upper.side < 0.0 && lower.offset < upper.offset
            }
            _ => false,
        };
        if !pair_ok {
            cx.err(
                sym.axis.span(),
                "C0014",
                format!(
                    "axis {} has at most two symmetry planes: the lower keeping \"above\", the upper keeping \"below\"",
                    ir::AXIS_NAMES[axis]
                ),
                "here",
            );
            continue;
        }
        mirrors.push(plane);
    }
    let axisymmetric = case.axisymmetric.as_ref().is_some_and(|a| *a.get_ref());
    if axisymmetric {
        axis_of_symmetry(case, &model, &mut mirrors, cx)?;
    }
    let mut periodic_spans = vec![];
    if let Some(periodic) = &case.periodic {
        for (axis, range) in [&periodic.x, &periodic.y, &periodic.z].into_iter().enumerate() {
            let Some(range) = range else { continue };
            let name = ir::AXIS_NAMES[axis];
            let bounds: Option<Vec<f64>> =
                range.get_ref().iter().map(|v| cx.scalar(v, m, "a periodic domain's side")).collect();
            let Some(bounds) = bounds else { continue };
            let problem = if axis >= dim {
                Some(format!("a {dim}D case has no axis {name}"))
            } else if bounds.len() != 2 || bounds[0].partial_cmp(&bounds[1]) != Some(std::cmp::Ordering::Less) {
                Some(format!("`{name}` is the domain [min, max) along the axis, two lengths with min < max"))
            } else if mirrors.iter().any(|m| m.axis == axis) {
                Some(format!("axis {name} has a symmetry plane: an axis is periodic or has one, not both"))
            } else {
                None
            };
            if let Some(p) = problem {
                cx.err(range.span(), "C0047", p, "here");
                continue;
            }
            mirrors.extend(Mirror::periodic(axis, bounds[0], bounds[1]));
            periodic_spans.push((axis, range.span()));
        }
    }
    // Bodies, within the scene's particle budget.
    let max_particles = match &case.max_particles {
        Some(n) => *n.get_ref(),
        None => DEFAULT_MAX_PARTICLES,
    }
    .min(limits.max_particles.unwrap_or(u64::MAX));
    let mut particles = ParticleInput::default();
    let mut bodies: Vec<BodyInfo> = vec![];
    // A body is cut at the symmetry planes; a periodic domain holds its bodies whole.
    let symmetry: Vec<Mirror> = mirrors.iter().filter(|m| m.shift == 0.0).copied().collect();
    for (b, body) in case.bodies.get_ref().iter().enumerate() {
        let name = body.name.get_ref().clone();
        let Some(group) = model.group_id(body.group.get_ref()) else {
            let names: Vec<&str> = model.groups.iter().map(|g| g.name.as_str()).collect();
            let mut d =
                Diagnostic::error("C0009", format!("body `{name}`: the model has no group `{}`", body.group.get_ref()))
                    .at(cx.span(body.group.span()), "unknown group");
            d = match closest(body.group.get_ref(), names.iter().copied()) {
                Some(best) => d.help(format!("did you mean `{best}`?")),
                None => d.note(format!("the model's groups: {}", names.join(", "))),
            };
            cx.diags.push(d);
            continue;
        };
        let Some(material) = materials.iter().position(|m| m.name == *body.material.get_ref()) else {
            cx.err(
                body.material.span(),
                "C0010",
                format!("body `{name}`: no material `{}` in the case", body.material.get_ref()),
                "unknown material",
            );
            continue;
        };
        let Some(spacing) = body_spacing(body, dx, cx) else { continue };
        let budget = Budget { left: max_particles.saturating_sub(particles.len() as u64), limit: max_particles };
        let Some(mut placed) = place(body, spacing, dx, dir, &symmetry, budget, cx) else { continue };
        if axisymmetric {
            sweep_exact_volume(body, &mut placed, cx);
        }
        let velocity = match &body.velocity {
            Some(v) => cx.vector(v, unit("m/s"), &format!("velocity of body `{name}`"))?,
            None => [0.0; 3],
        };
        let start = particles.len();
        let rho0 = model.param_id("rho0").and_then(|p| materials[material].values.get(&p)).map(|v| v[0]).unwrap_or(0.0);
        let mass = placed.volumes.iter().sum::<f64>() * rho0;
        for k in 0..placed.len() {
            particles.x.push(placed.positions[k]);
            particles.v.push(velocity);
            particles.vol.push(placed.volumes[k]);
            particles.dx.push(placed.spacing[k]);
            particles.body.push(b as u32);
            particles.part.push(-1);
            particles.group.push(group.0);
            particles.material.push(material as u32);
        }
        let mut set_here = vec![];
        for (field, text) in &body.initial {
            if let Some(value) = initial_value(&model, field, text, &set_here, cx) {
                set_here.push(value.0);
                particles.initial.push(InitialValue { field: value.0, body: b as u32, value: value.1 });
            }
        }
        bodies.push(BodyInfo { name, group, material, particles: start..particles.len(), mass });
    }
    // Every particle inside each periodic domain [lo, hi).
    for (axis, span) in &periodic_spans {
        let Some(plane) = mirrors.iter().find(|m| m.axis == *axis && m.shift > 0.0) else { continue };
        let (lo, hi) = (plane.offset, plane.offset + plane.shift);
        if let Some(k) = particles.x.iter().position(|x| !(x[*axis] >= lo && x[*axis] < hi)) {
            let name = &bodies[particles.body[k] as usize].name;
            let at = particles.x[k][*axis];
            let msg = format!("body `{name}` has a particle at {at} m along the periodic axis, outside [{lo}, {hi}) m");
            cx.err(span.clone(), "C0047", msg, "the periodic domain");
        }
    }
    if particles.is_empty() {
        if !cx.diags.iter().any(|d| d.is_error()) {
            let span = cx.span(case.bodies.span());
            cx.diags.push(Diagnostic::error("C0011", "the case places no particles").at(span, "no body here"));
        }
        return None;
    }
    let body_index = |cx: &mut Ctx, n: &toml::Spanned<String>| -> Option<usize> {
        let found = case.bodies.get_ref().iter().position(|b| b.name.get_ref() == n.get_ref());
        if found.is_none() {
            cx.err(n.span(), "C0012", format!("no body `{}` in the case", n.get_ref()), "unknown body");
        }
        found
    };
    // Loads and constraints act on a body, or on the part of it inside a region.
    let rho0_of =
        |mat: usize| model.param_id("rho0").and_then(|p| materials[mat].values.get(&p)).map(|v| v[0]).unwrap_or(0.0);
    let mut parts = 0usize;
    let mut target = |cx: &mut Ctx,
                      particles: &mut ParticleInput,
                      body: &toml::Spanned<String>,
                      region: &Option<toml::Spanned<case::Shape>>|
     -> Option<(Target, f64, crate::ir::GroupId)> {
        let b = body_index(cx, body)?;
        let info = bodies.iter().find(|x| x.name == *case.bodies.get_ref()[b].name.get_ref())?;
        let Some(region) = region else { return Some((Target::Body(b), info.mass, info.group)) };
        let shape = primitive(region.get_ref(), cx)?;
        let range = info.particles.clone();
        let inside = match geometry::inside(&shape, dim, &particles.x[range.clone()]) {
            Ok(v) => v,
            Err(e) => {
                cx.err(region.span(), "C0024", format!("region: {e}"), "here");
                return None;
            }
        };
        let id = parts;
        parts += 1;
        let mut mass = 0.0;
        for (k, inside) in range.zip(inside) {
            if inside {
                particles.part[k] = id as i32;
                mass += particles.vol[k] * rho0_of(particles.material[k] as usize);
            }
        }
        if mass == 0.0 {
            cx.err(
                region.span(),
                "C0024",
                format!("this region holds no particle of body `{}`", body.get_ref()),
                "empty region",
            );
            return None;
        }
        Some((Target::Part(id), mass, info.group))
    };
    let mut loads = vec![];
    for l in &case.loads {
        let Some((t, mass, _)) = target(cx, &mut particles, &l.body, &l.region) else { continue };
        let Some(force) = cx.vector(&l.force, Unit::named("N").unwrap_or(Unit::ONE), "load force") else { continue };
        let ramp = match &l.ramp {
            Some(r) => time_scale * cx.scalar(r, s, "load ramp")?,
            None => 0.0,
        };
        if mass <= 0.0 {
            cx.err(l.body.span(), "C0013", "a load needs a body with mass (its material binds rho0)", "massless body");
            continue;
        }
        loads.push(Load { target: t, accel: force[..dim].iter().map(|f| f / mass).collect(), ramp });
    }
    let mut constraints = vec![];
    for c in &case.constraints {
        let Some((t, _, group)) = target(cx, &mut particles, &c.body, &c.region) else { continue };
        let groups = GroupSet::default().with(group);
        let rotation = match &c.rotation {
            Some(r) => Some(rotation(cx, r, dim, time_scale)?),
            None => None,
        };
        let velocity = match &c.velocity {
            Some(v) => cx.vector(v, unit("m/s"), "constraint velocity")?,
            None => [0.0; 3],
        };
        let ramp = match &c.ramp {
            Some(r) => time_scale * cx.scalar(r, s, "constraint ramp")?,
            None => 0.0,
        };
        // A faster clock keeps prescribed displacements: velocities grow as the times shrink.
        let velocity = velocity[..dim].iter().map(|v| v / time_scale).collect();
        constraints.push(Constraint { target: t, groups, velocity, rotation, ramp });
    }
    let gravity = match &case.gravity {
        Some(g) => Some(cx.vector(g, unit("m/s^2"), "gravity")?[..dim].to_vec()),
        None => None,
    };
    // Outputs and probes.
    let field = |cx: &mut Ctx, n: &toml::Spanned<String>| -> Option<FieldId> {
        let f = model.field_id(n.get_ref()).filter(|f| model.field(*f).storage != crate::ir::Storage::Temp);
        if f.is_none() {
            let names: Vec<&str> = model.fields.iter().map(|f| f.name.as_str()).filter(|n| !n.contains('.')).collect();
            let mut d = Diagnostic::error("C0015", format!("the model has no field `{}`", n.get_ref()))
                .at(cx.span(n.span()), "unknown field");
            if let Some(b) = closest(n.get_ref(), names.iter().copied()) {
                d = d.help(format!("did you mean `{b}`?"));
            }
            cx.diags.push(d);
        }
        f
    };
    let mut output_fields = vec![];
    let mut output_interval = None;
    if let Some(o) = &case.output {
        for f in &o.fields {
            if let Some(id) = field(cx, f) {
                output_fields.push(id);
            }
        }
        if let Some(i) = &o.interval {
            output_interval = cx
                .scalar(i, s, "output interval")
                .and_then(|x| cx.positive(i.span(), x, "the output interval"))
                .map(|x| x * time_scale);
        }
    }
    let mut probes = vec![];
    for p in &case.probes {
        let kind = if let Some(m) = &p.measure {
            let Some(measure) = Measure::parse(m.get_ref()) else {
                let known: Vec<&str> = Measure::ALL.iter().map(|m| m.name()).collect();
                cx.err(
                    m.span(),
                    "C0016",
                    format!("unknown measure `{}`; known: {}", m.get_ref(), known.join(", ")),
                    "here",
                );
                continue;
            };
            ProbeKind::Measure(measure)
        } else {
            let value = match (&p.field, &p.expression) {
                (Some(fname), None) => match field(cx, fname) {
                    Some(f) => ProbeValue::Field(f),
                    None => continue,
                },
                (None, Some(text)) => match probe_expression(&model, text, cx) {
                    Some(e) => ProbeValue::Expression(e),
                    None => continue,
                },
                (Some(_), Some(text)) => {
                    cx.err(
                        text.span(),
                        "C0016",
                        "a probe takes a `field` or an `expression`, not both",
                        "second value",
                    );
                    continue;
                }
                (None, None) => {
                    cx.err(
                        p.name.span(),
                        "C0016",
                        "a probe needs a `field` or an `expression` (with `body`, `component`, `reduce`), or a `measure`",
                        "here",
                    );
                    continue;
                }
            };
            let body = match &p.body {
                Some(b) => Some(body_index(cx, b)?),
                None => None,
            };
            let mut select: Option<Vec<bool>> = body.map(|b| particles.body.iter().map(|x| *x as usize == b).collect());
            if let Some(region) = &p.region {
                let shape = primitive(region.get_ref(), cx)?;
                match geometry::inside(&shape, dim, &particles.x) {
                    Ok(inside) => {
                        let sel = select.get_or_insert_with(|| vec![true; particles.len()]);
                        for (s, i) in sel.iter_mut().zip(inside) {
                            *s &= i;
                        }
                    }
                    Err(e) => {
                        cx.err(region.span(), "C0024", format!("probe region: {e}"), "here");
                        continue;
                    }
                }
                if !select.as_ref().is_some_and(|s| s.iter().any(|x| *x)) {
                    cx.err(region.span(), "C0024", "the probe's region holds no particle", "empty region");
                    continue;
                }
            }
            let shape = match &value {
                ProbeValue::Field(f) => model.field(*f).ty.shape,
                ProbeValue::Expression(e) => e.ty.shape,
            };
            let pick = match &p.component {
                None => Pick::Component(0),
                Some(c) => match (c.get_ref().as_str(), shape) {
                    ("norm", Shape::Vec) => Pick::Norm,
                    ("von_mises", Shape::SymTensor) => Pick::VonMises,
                    (name, _) => match component_index(shape, dim, name) {
                        Some(k) => Pick::Component(k),
                        None => {
                            cx.err(
                                c.span(),
                                "C0017",
                                format!(
                                    "`{name}` is not a component of a {dim}D {} (components such as `x` or `xy`, \
                                     `norm` of a vec, `von_mises` of a symtensor)",
                                    shape.name()
                                ),
                                "here",
                            );
                            continue;
                        }
                    },
                },
            };
            let reduce = p.reduce.as_ref().map(|r| r.get_ref().clone()).unwrap_or_else(|| "mean".into());
            if !["mean", "min", "max", "sum", "abs_max"].contains(&reduce.as_str()) {
                let span = p.reduce.as_ref().map(|r| r.span()).unwrap_or(0..0);
                cx.err(span, "C0017", format!("reduce is mean, min, max, sum or abs_max, found `{reduce}`"), "here");
                continue;
            }
            let locate = match &p.locate {
                None => None,
                Some(a) => match ("xyz".find(a.get_ref().as_str()).filter(|k| *k < dim), reduce.as_str()) {
                    (Some(k), "min" | "max" | "abs_max") if a.get_ref().len() == 1 => Some(k),
                    _ => {
                        cx.err(
                            a.span(),
                            "C0017",
                            format!("`locate` is an axis (x, y, z) of a {dim}D case, with reduce min, max or abs_max"),
                            "here",
                        );
                        continue;
                    }
                },
            };
            ProbeKind::Field { select, value, pick, reduce, locate }
        };
        let record = match (p.relative, p.integrate) {
            (false, false) => Record::Value,
            (true, false) => Record::Change,
            (false, true) => Record::Integral,
            (true, true) => {
                cx.err(
                    p.name.span(),
                    "C0017",
                    format!(
                        "probe `{}` records its change from the first value (`relative`) or its integral in time \
                         (`integrate`), not both",
                        p.name.get_ref()
                    ),
                    "this probe",
                );
                continue;
            }
        };
        probes.push(ProbeSpec {
            record,
            name: p.name.get_ref().clone(),
            kind,
            unit: p.unit.clone().unwrap_or_default(),
            every: p.every.unwrap_or(1).max(1),
        });
    }
    let mut results = vec![];
    for r in &case.results {
        let Some(probe) = probes.iter().position(|p| p.name == *r.probe.get_ref()) else {
            cx.err(r.probe.span(), "C0018", format!("no probe `{}`", r.probe.get_ref()), "unknown probe");
            continue;
        };
        let at = r.at.as_ref().map(|a| a.get_ref().clone()).unwrap_or_else(|| "end".into());
        const AT: [&str; 11] = [
            "end",
            "min",
            "max",
            "abs_max",
            "mean",
            "mean_after",
            "period",
            "frequency",
            "slope",
            "zero_crossing",
            "at_time",
        ];
        if !AT.contains(&at.as_str()) {
            let span = r.at.as_ref().map(|a| a.span()).unwrap_or(0..0);
            cx.err(span, "C0019", format!("`at` is {}, found `{at}`", AT.join(", ")), "here");
            continue;
        }
        if (at == "at_time") != r.time.is_some() {
            let span = r.time.as_ref().map(|t| t.span()).or(r.at.as_ref().map(|a| a.span())).unwrap_or(0..0);
            cx.err(span, "C0019", "`time` goes with `at = \"at_time\"`, and `at_time` needs a `time`", "here");
            continue;
        }
        let unit_text = r.unit.clone().unwrap_or_else(|| probes[probe].unit.clone());
        let (_, runit) = quantity::parse_unit(&unit_text).unwrap_or((1.0, Unit::ONE));
        let reference = match &r.reference {
            Some(v) => Some(cx.scalar(v, runit, &format!("reference of `{}`", r.quantity.get_ref()))?),
            None => None,
        };
        let offset = match &r.offset {
            Some(v) => cx.scalar(v, runit, &format!("offset of `{}`", r.quantity.get_ref()))?,
            None => 0.0,
        };
        let from = match &r.from {
            Some(v) => Some(time_scale * cx.scalar(v, s, "from")?),
            None => None,
        };
        let to = match &r.to {
            Some(v) => Some(time_scale * cx.scalar(v, s, "to")?),
            None => None,
        };
        let time = match &r.time {
            Some(v) => Some(time_scale * cx.scalar(v, s, "time")?),
            None => None,
        };
        results.push(ResultSpec {
            quantity: r.quantity.get_ref().clone(),
            probe,
            at,
            from,
            to,
            time,
            scale: r.scale.unwrap_or(1.0),
            offset,
            unit: unit_text,
            reference,
            source: r.source.clone(),
            tolerance: r.tolerance,
            tolerance_why: r.tolerance_why.clone(),
        });
    }
    // What the run needs of the model.
    let integrator = match &case.integrator {
        Some(i) => match IntegratorKind::parse(i.get_ref()) {
            Some(k) => k,
            None => {
                cx.err(
                    i.span(),
                    "C0020",
                    format!("unknown integrator `{}` ({})", i.get_ref(), IntegratorKind::NAMES),
                    "here",
                );
                return None;
            }
        },
        None => IntegratorKind::PredictorCorrector,
    };
    let mut outputs = output_fields.clone();
    for p in &case.profiles {
        outputs.extend(p.fields.iter().filter_map(|f| model.field_id(f.get_ref())));
        outputs.extend(model.field_id("x"));
    }
    for p in &probes {
        if let ProbeKind::Field { value, locate, .. } = &p.kind {
            outputs.extend(value.fields());
            if locate.is_some() {
                outputs.extend(model.field_id("x"));
            }
        }
        if let ProbeKind::Measure(m) = &p.kind {
            for name in m.fields_needed() {
                if let Some(f) = model.field_id(name) {
                    outputs.push(f);
                }
            }
        }
    }
    let search = neighbour_search(cx, &model, case.neighbours.as_ref(), opts.verlet)?;
    let list_limit = crate::backend::cpu::lists::INDEX_MASK as usize + 1;
    if search.keeps_lists() && particles.len() > list_limit {
        let msg =
            format!("{} particles: with kept neighbour lists a scene holds at most {list_limit}", particles.len());
        cx.err(case.bodies.span(), "C0039", msg, "these bodies");
        return None;
    }
    if let Search::Adaptive { field, .. } = &search {
        outputs.push(*field);
    }
    outputs.sort();
    outputs.dedup();
    requirements_hold(case, &model, &particles, &materials, cx)?;
    let groups = particles.groups();
    let kernel = case.kernel.as_ref().map(|k| k.get_ref().clone());
    if let Some(k) = case.kernel.as_ref().filter(|k| model.kernel_id(k.get_ref()).is_none()) {
        let names: Vec<&str> = model.kernels.iter().map(|k| k.name.as_str()).collect();
        let mut d = Diagnostic::error("C0040", format!("the model has no kernel `{}`", k.get_ref()))
            .at(cx.span(k.span()), "unknown kernel")
            .note(format!("the model's kernels: {}", names.join(", ")));
        if let Some(b) = closest(k.get_ref(), names.iter().copied()) {
            d = d.help(format!("did you mean `{b}`?"));
        }
        cx.diags.push(d);
        return None;
    }
    let dt_max = match &case.dt_max {
        // Infinite is fine (no bound); zero, negative or NaN would stop the clock.
        Some(v) => match cx.scalar(v, s, "dt_max")? {
            x if x > 0.0 => x,
            x => {
                cx.err(v.span(), "C0002", format!("dt_max must be a positive time, found {x}"), "here");
                return None;
            }
        },
        None => f64::INFINITY,
    };
    let planes = mirrors.clone();
    let damping = match &case.damping {
        Some(v) => {
            let c = cx.scalar(v, unit("1/s"), "damping")?;
            Some(cx.positive(v.span(), c, "damping")?)
        }
        None => None,
    };
    let mut settled = settled_params(&model, dim, &materials, &used);
    if let Some(p) = model.param_id(ir::AXISYMMETRIC).filter(|p| settled.len() > p.index()) {
        settled[p.index()] = Some(vec![f64::from(u8::from(axisymmetric))]);
    }
    let initialised: std::collections::BTreeSet<FieldId> = particles.initial.iter().map(|iv| iv.field).collect();
    let spec = SceneSpec {
        dim,
        groups,
        outputs,
        integrator,
        gravity,
        loads,
        constraints,
        planes,
        search,
        damping,
        settled,
        initialised: initialised.into_iter().collect(),
        axisymmetric,
    };
    let mut config =
        RunConfig { end_time, dt_max, reorder_every: case.reorder_every.unwrap_or(25), ..RunConfig::default() };
    if let Some(r) = &case.min_dt_ratio {
        if !(*r.get_ref() > 0.0 && *r.get_ref() < 1.0) {
            let msg = format!("`min_dt_ratio` must lie between 0 and 1, found {}", r.get_ref());
            cx.err(r.span(), "C0027", msg, "not a fraction of the first time step");
            return None;
        }
        config.min_dt_ratio = *r.get_ref();
    }
    let watchdog = case.watchdog.as_ref();
    for (factor, name, into) in [
        (watchdog.and_then(|w| w.speed_factor.as_ref()), "speed_factor", &mut config.speed_factor),
        (watchdog.and_then(|w| w.energy_factor.as_ref()), "energy_factor", &mut config.energy_factor),
    ] {
        let Some(f) = factor else { continue };
        if f.get_ref().is_nan() || *f.get_ref() <= 0.0 {
            let msg = format!("`watchdog.{name}` must be positive (inf turns the bound off), found {}", f.get_ref());
            cx.err(f.span(), "C0041", msg, "not a positive factor");
            return None;
        }
        *into = *f.get_ref();
    }
    let profiles = profiles(case, &field, &body_index, end_time, time_scale, cx);
    Some(Scene {
        warnings: vec![],
        name: case.name.get_ref().clone(),
        title: case.title.clone().unwrap_or_default(),
        path: path.to_path_buf(),
        model,
        spec,
        kernel,
        particles,
        materials,
        material_spans,
        bodies,
        mirrors,
        config,
        resolution: wanted.clone(),
        dx,
        time_scale,
        // A tolerance holds at its resolution's own spacing only.
        tolerance: res_table.filter(|_| at.is_none()).and_then(|t| t.tolerance),
        output_interval,
        output_fields,
        probes,
        results,
        profiles,
        resolutions,
    })
}

/// The case's `[[profiles]]`: their fields, times (× the time scale; past the end time they are
/// never reached, and say so) and selection.
fn profiles(
    case: &CaseFile,
    field: &dyn Fn(&mut Ctx, &toml::Spanned<String>) -> Option<FieldId>,
    body_index: &dyn Fn(&mut Ctx, &toml::Spanned<String>) -> Option<usize>,
    end_time: f64,
    time_scale: f64,
    cx: &mut Ctx,
) -> Vec<ProfileSpec> {
    let mut out = vec![];
    for p in &case.profiles {
        let fields: Option<Vec<FieldId>> = p.fields.iter().map(|f| field(cx, f)).collect();
        let times: Option<Vec<f64>> = p
            .times
            .get_ref()
            .iter()
            .map(|t| cx.scalar(t, Unit::S, "a profile's time").map(|x| x * time_scale))
            .collect();
        let body = match &p.body {
            Some(b) => body_index(cx, b).map(Some),
            None => Some(None),
        };
        let region = match &p.region {
            Some(r) => primitive(r.get_ref(), cx).map(Some),
            None => Some(None),
        };
        let along = match &p.along {
            None => Some(0),
            Some(a) => {
                let k = "xyz".find(a.get_ref().as_str()).filter(|k| *k < cx.dim && a.get_ref().len() == 1);
                if k.is_none() {
                    cx.err(a.span(), "C0043", format!("`along` is an axis (x, y, z) of a {}D case", cx.dim), "here");
                }
                k
            }
        };
        let (Some(fields), Some(mut times), Some(body), Some(region), Some(along)) =
            (fields, times, body, region, along)
        else {
            continue;
        };
        if times.is_empty() || times.iter().any(|t| t.is_nan() || *t < 0.0) {
            cx.err(p.times.span(), "C0043", "a profile needs one or more times, none negative", "here");
            continue;
        }
        if times.iter().any(|t| *t > end_time * (1.0 + 1e-12)) {
            let d = Diagnostic::warning("C0044", "a profile time is past the end time: that profile is not written")
                .at(cx.span(p.times.span()), "here");
            cx.diags.push(d);
        }
        times.sort_by(f64::total_cmp);
        out.push(ProfileSpec { name: p.name.get_ref().clone(), fields, times, body, region, along });
    }
    out
}

/// A constraint's rigid rotation: its centre, angular speed (divided by the time scale, like
/// velocities) and unit axis (z in 2D; required in 3D).
fn rotation(
    cx: &mut Ctx,
    r: &toml::Spanned<case::Rotation>,
    dim: usize,
    time_scale: f64,
) -> Option<crate::schedule::Rotation> {
    let spec = r.get_ref();
    let center = cx.vector(&spec.center, unit("m"), "rotation centre")?[..dim].to_vec();
    let omega = cx.scalar(&spec.omega, unit("1/s"), "rotation omega")? / time_scale;
    let axis = match (&spec.axis, dim) {
        (_, 1) => {
            cx.err(r.span(), "C0035", "a 1D body cannot turn", "here");
            return None;
        }
        (None, 2) => [0.0, 0.0, 1.0],
        (Some(a), 3) => {
            let a = cx.vector(a, Unit::ONE, "rotation axis")?;
            let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
            if n == 0.0 {
                cx.err(r.span(), "C0035", "the rotation axis is the zero vector", "here");
                return None;
            }
            [a[0] / n, a[1] / n, a[2] / n]
        }
        (Some(_), _) => {
            cx.err(r.span(), "C0035", "a 2D body turns about z: a rotation takes no `axis`", "here");
            return None;
        }
        (None, _) => {
            cx.err(r.span(), "C0035", "a 3D rotation needs an `axis`", "no axis");
            return None;
        }
    };
    Some(crate::schedule::Rotation { center, axis, omega })
}

fn component_index(shape: Shape, dim: usize, name: &str) -> Option<usize> {
    let axis = |c: char| "xyz".find(c).filter(|a| *a < dim);
    let chars: Vec<char> = name.chars().collect();
    match (shape, chars.as_slice()) {
        (Shape::Scalar, _) => Some(0),
        (Shape::Vec, [a]) => axis(*a),
        (s, [a, b]) => {
            let (r, c) = (axis(*a)?, axis(*b)?);
            crate::ir::component_indices(s, dim)
                .iter()
                .position(|&(x, y)| (x, y) == (r.min(c), r.max(c)) || (x, y) == (r, c))
        }
        _ => None,
    }
}

/// How many particles a body may still place: what the scene's limit leaves.
#[derive(Clone, Copy)]
struct Budget {
    left: u64,
    limit: u64,
}

impl Budget {
    /// C0039 at the body's shape when it would place `count` particles (about, when `estimated`).
    fn exceeded(self, cx: &mut Ctx, body: &case::Body, count: u64, estimated: bool) {
        let name = body.name.get_ref();
        let about = if estimated { "about " } else { "" };
        let msg = if self.left == self.limit {
            format!("body `{name}` would place {about}{count} particles, more than the limit of {}", self.limit)
        } else {
            format!(
                "body `{name}` would place {about}{count} particles, more than the {} the scene's limit of {} leaves",
                self.left, self.limit
            )
        };
        let d = Diagnostic::error("C0039", msg).at(cx.span(body.shape.span()), "too many particles").help(format!(
            "use a coarser spacing, or raise the case's `max_particles` (default {DEFAULT_MAX_PARTICLES})"
        ));
        cx.diags.push(d);
    }
}

/// The body's spacing, `spacing_factor × dx`; with `spacing_divides = L`, the largest spacing not
/// above it that goes into L a whole number of times (a radius of 10 mm at 1.333 mm: 1.25 mm);
/// `spacing_divides = 0` is the plain `spacing_factor × dx`.
fn body_spacing(body: &case::Body, dx: f64, cx: &mut Ctx) -> Option<f64> {
    let spacing = dx * body.spacing_factor.unwrap_or(1.0);
    let Some(length) = divides_length(body, cx)? else { return Some(spacing) };
    match &body.refine {
        None => Some(fitted(length, spacing)),
        // A graded ring fill fits its fine rings' width ([`fill_in_rings`]).
        Some(_) if body.fill_at() == case::FillAt::Rings => Some(spacing),
        Some(refine) => {
            let msg =
                format!("body `{}`: `spacing_divides` fits a uniform fill; this one is graded", body.name.get_ref());
            cx.err(refine.region.span(), "C0049", msg, "a graded fill");
            None
        }
    }
}

/// The body's `spacing_divides` length (m), `Some(None)` when it has none or 0; `None` on an error.
fn divides_length(body: &case::Body, cx: &mut Ctx) -> Option<Option<f64>> {
    let Some(divides) = &body.spacing_divides else { return Some(None) };
    let what = format!("`spacing_divides` of body `{}`", body.name.get_ref());
    let length = cx.scalar(divides, unit("m"), &what)?;
    if length == 0.0 {
        return Some(None);
    }
    cx.positive(divides.span(), length, &what).map(Some)
}

/// The largest spacing not above `spacing` that goes into `length` a whole number of times (a
/// length already a whole number of spacings keeps it, up to round-off).
fn fitted(length: f64, spacing: f64) -> f64 {
    length / (length / spacing * (1.0 - 1e-9)).ceil().max(1.0)
}

/// A body filled in rings about its cylinder's axis (`fill = "rings"`, [`geometry::fill_rings`]):
/// rings of the body's spacing (fitted already when uniform), or with `refine` the fine rings,
/// their width fitted to `spacing_divides`, out to the refine cylinder's radius and coarse rings
/// beyond.
fn fill_in_rings(
    body: &case::Body,
    shape: &Primitive,
    spacing: f64,
    dx: f64,
    budget: Budget,
    cx: &mut Ctx,
) -> Option<geometry::Particles> {
    let name = body.name.get_ref();
    let core = match &body.refine {
        None => None,
        Some(r) => {
            let region = primitive(r.region.get_ref(), cx)?;
            let Some(radius) = coaxial_radius(shape, &region) else {
                let msg = format!(
                    "body `{name}`: a ring fill's `refine` region must be a cylinder on the body's axis, at least as long"
                );
                cx.err(r.region.span(), "C0051", msg, "not a cylinder on the body's axis");
                return None;
            };
            let fine = dx * r.factor;
            let width = divides_length(body, cx)?.map_or(fine, |l| fitted(l, fine));
            Some(geometry::Core { radius, spacing: fine, width })
        }
    };
    let how = geometry::Rings { spacing, width: spacing, core };
    match geometry::fill_rings(shape, &how, cx.dim, budget.left) {
        Ok(p) => Some(p),
        Err(geometry::GeometryError::TooManyParticles { count, estimated, .. }) => {
            budget.exceeded(cx, body, count, estimated);
            None
        }
        Err(e) => {
            let span = body.fill.as_ref().map_or(body.shape.span(), |f| f.span());
            cx.err(span, "C0051", format!("body `{name}`: {e}"), "a ring fill");
            None
        }
    }
}

/// The radius of `region` when it is a cylinder on the axis of the cylinder `shape` that spans its
/// whole length (the fine core of a graded ring fill).
fn coaxial_radius(shape: &Primitive, region: &Primitive) -> Option<f64> {
    let (
        Primitive::Cylinder { base, axis, length, radius: outer },
        Primitive::Cylinder { base: rb, axis: ra, radius, length: rl },
    ) = (shape, region)
    else {
        return None;
    };
    let ((k, [u, v]), (rk, _)) = (geometry::axis_index(*axis)?, geometry::axis_index(*ra)?);
    let tol = 1e-9 * outer.max(*radius);
    let span = |b: &[f64; 3], a: &[f64; 3], l: f64| {
        let end = b[k] + a[k].signum() * l;
        (b[k].min(end), b[k].max(end))
    };
    let ((lo, hi), (rlo, rhi)) = (span(base, axis, *length), span(rb, ra, *rl));
    let on_axis = (base[u] - rb[u]).abs() <= tol && (base[v] - rb[v]).abs() <= tol;
    (rk == k && on_axis && rlo <= lo + tol && rhi >= hi - tol).then_some(*radius)
}

/// In an axisymmetric case, scales the volumes of a body's particles so that their rings, V 2π r
/// each, sweep the exact volume of the solid of revolution where it is known
/// ([`Primitive::revolved_volume`]). Why: a disc's lattice holds the disc's exact area, but its
/// rings miss the ball's volume by as much as the lattice misses the disc's first moment: the
/// hypervelocity sphere's rings held +1.3 / −0.5 / +0.4 / +0.7 % of its mass at 1 / 0.667 / 0.5 /
/// 0.333 mm, and its kinetic energy with them.
fn sweep_exact_volume(body: &case::Body, placed: &mut geometry::Particles, cx: &mut Ctx) {
    if matches!(body.shape.get_ref(), case::Shape::Nodes { .. }) {
        return;
    }
    let Some(exact) = primitive(body.shape.get_ref(), cx).and_then(|p| p.revolved_volume()) else { return };
    let swept: f64 = placed.volumes.iter().zip(&placed.positions).map(|(v, x)| v * crate::schedule::ring(x[0])).sum();
    if swept > 0.0 {
        placed.volumes.iter_mut().for_each(|v| *v *= exact / swept);
        placed.volume_scale *= exact / swept;
    }
}

/// Particles of one body: a primitive filled at its spacing (graded if asked), or a node list.
/// With symmetry planes, the lattice (uniform or graded) is anchored half a spacing off each plane,
/// and only the particles on the planes' positive side are kept.
fn place(
    body: &case::Body,
    spacing: f64,
    dx: f64,
    dir: &Path,
    mirrors: &[Mirror],
    budget: Budget,
    cx: &mut Ctx,
) -> Option<geometry::Particles> {
    let placed = place_whole(body, spacing, dx, dir, mirrors, budget, cx)?;
    if mirrors.is_empty() {
        return Some(placed);
    }
    let keep: Vec<usize> =
        (0..placed.len()).filter(|k| mirrors.iter().all(|m| m.keeps(placed.positions[*k][m.axis]))).collect();
    let name = body.name.get_ref();
    if keep.is_empty() {
        cx.err(body.shape.span(), "C0025", format!("body `{name}` lies behind a symmetry plane"), "no particle kept");
        return None;
    }
    // A particle on a plane (or within a quarter spacing of it, on either side) would sit on its
    // mirror image, or leave a gap along the plane where it is dropped.
    if let Some(k) = (0..placed.len())
        .find(|k| mirrors.iter().any(|m| (placed.positions[*k][m.axis] - m.offset).abs() < 0.25 * placed.spacing[*k]))
    {
        cx.err(
            body.shape.span(),
            "C0025",
            format!(
                "body `{name}`: a particle at {:?} lies within a quarter spacing of a symmetry plane, too close to its mirror image",
                placed.positions[k]
            ),
            match (body.shape.get_ref(), body.fill_at()) {
                (case::Shape::Nodes { .. }, _) => "a node list's first row must lie half a spacing off the plane",
                (_, case::FillAt::Nodes) => {
                    "a node-centred fill puts particles on a plane through the body: use `fill = \"cells\"`"
                }
                (_, case::FillAt::Cells) => "a cell fill starts half a spacing off the plane; this one did not",
                (_, case::FillAt::Rings) => "a ring fill keeps off the planes through its axis; this plane is not one of them",
            },
        );
        return None;
    }
    warn_gap_at_planes(name, body.shape.span(), &placed, &keep, mirrors, cx);
    let pick = |v: &[f64]| keep.iter().map(|k| v[*k]).collect::<Vec<f64>>();
    Some(geometry::Particles {
        positions: keep.iter().map(|k| placed.positions[*k]).collect(),
        volumes: pick(&placed.volumes),
        spacing: pick(&placed.spacing),
        volume_scale: placed.volume_scale,
    })
}

fn place_whole(
    body: &case::Body,
    spacing: f64,
    dx: f64,
    dir: &Path,
    mirrors: &[Mirror],
    budget: Budget,
    cx: &mut Ctx,
) -> Option<geometry::Particles> {
    let name = body.name.get_ref();
    let span = body.shape.span();
    if let case::Shape::Nodes { file, scale } = body.shape.get_ref() {
        if let Some(span) = body.refine.as_ref().map(|r| r.region.span()).or(body.fill.as_ref().map(|f| f.span())) {
            let msg =
                format!("body `{name}`: a node list places its own particles; `refine` and `fill` are for shapes");
            cx.err(span, "C0036", msg, "not for a node list");
            return None;
        }
        let p = dir.join(file.get_ref());
        // Only a regular file: a device or a pipe (`/dev/zero`) would be read forever.
        let read = match std::fs::metadata(&p) {
            Ok(m) if !m.is_file() => Err(std::io::Error::other("not a regular file")),
            _ => std::fs::read_to_string(&p),
        };
        let text = match read {
            Ok(t) => t,
            Err(e) => {
                cx.err(file.span(), "C0021", format!("body `{name}`: cannot read `{}`: {e}", p.display()), "here");
                return None;
            }
        };
        let display = check::load::display_path(&p);
        let parsed = if p.extension().is_some_and(|e| e == "csv") {
            geometry::read_csv_nodes(&text, &display)
        } else {
            geometry::read_lsdyna_nodes(&text, &display)
        };
        let mut nodes = match parsed {
            Ok(n) => n,
            Err(e) => {
                cx.diags.push(Diagnostic::error("C0022", format!("{e}")).at(cx.span(file.span()), "in this node file"));
                return None;
            }
        };
        if nodes.positions.len() as u64 > budget.left {
            budget.exceeded(cx, body, nodes.positions.len() as u64, false);
            return None;
        }
        let k = scale.unwrap_or(1.0);
        for q in &mut nodes.positions {
            for c in q.iter_mut() {
                *c *= k;
            }
        }
        if let Some(v) = &mut nodes.volumes {
            for x in v.iter_mut() {
                *x *= k.powi(cx.dim as i32);
            }
        }
        return match nodes.to_particles(cx.dim) {
            Ok(p) => Some(p),
            Err(e) => {
                cx.err(span, "C0023", format!("body `{name}`: {e}"), "here");
                None
            }
        };
    }
    let shape = primitive(body.shape.get_ref(), cx)?;
    if body.fill_at() == case::FillAt::Rings {
        return fill_in_rings(body, &shape, spacing, dx, budget, cx);
    }
    // With symmetry planes the lattice's cells are anchored on the planes, so that the first row of
    // particles sits half a spacing off each plane, at the right distance from its mirror image.
    let corner = if mirrors.is_empty() {
        None
    } else {
        match shape.bbox(cx.dim) {
            Ok((mut min, _)) => {
                for m in mirrors.iter().filter(|m| m.side > 0.0) {
                    min[m.axis] = m.offset;
                }
                // an upper plane alone on its axis: the corner a whole number of spacings below it
                for m in
                    mirrors.iter().filter(|m| m.side < 0.0 && !mirrors.iter().any(|o| o.axis == m.axis && o.side > 0.0))
                {
                    min[m.axis] = m.offset - ((m.offset - min[m.axis]) / spacing).ceil() * spacing;
                }
                Some(min)
            }
            Err(e) => {
                cx.err(span, "C0023", format!("body `{name}`: {e}"), "here");
                return None;
            }
        }
    };
    let filled = match (&body.refine, corner) {
        (Some(r), _) => {
            let region = primitive(r.region.get_ref(), cx)?;
            geometry::fill_graded_with_limit(&shape, dx * r.factor, spacing, &region, cx.dim, corner, budget.left)
        }
        (None, None) => geometry::fill_with_limit(&shape, &geometry::Fill::new(spacing), cx.dim, budget.left),
        (None, Some(corner)) => geometry::fill_with_limit(
            &shape,
            &geometry::Fill::from_corner(spacing, corner, cx.dim),
            cx.dim,
            budget.left,
        ),
    };
    match (&filled, &shape, &body.refine) {
        (Ok(cells), Primitive::Box { min, max }, None) => {
            warn_box_overhang(name, span.clone(), (min, max), spacing, cells.total_volume(), cx)
        }
        (Ok(cells), _, Some(r)) => {
            warn_graded_rescale(name, span.clone(), cells.volume_scale, (dx * r.factor, spacing), cx)
        }
        _ => {}
    }
    let filled = match body.fill_at() {
        case::FillAt::Nodes => filled.map(|cells| geometry::at_corners(&cells, cx.dim)),
        case::FillAt::Cells | case::FillAt::Rings => filled,
    };
    match filled {
        Ok(p) if p.len() as u64 > budget.left => {
            // A node-centred fill has more particles than cells.
            budget.exceeded(cx, body, p.len() as u64, false);
            None
        }
        Ok(p) if !p.is_empty() => Some(p),
        Ok(_) => {
            cx.err(
                span,
                "C0023",
                format!("body `{name}` holds no particle at spacing {spacing} m"),
                "empty at this spacing",
            );
            None
        }
        Err(geometry::GeometryError::TooManyParticles { count, estimated, .. }) => {
            budget.exceeded(cx, body, count, estimated);
            None
        }
        Err(e @ geometry::GeometryError::TooManyRows { .. }) => {
            let d = Diagnostic::error("C0039", format!("body `{name}`: {e}"))
                .at(cx.span(span), "too many rows")
                .help("use a coarser spacing");
            cx.diags.push(d);
            None
        }
        Err(e) => {
            cx.err(span, "C0023", format!("body `{name}`: {e}"), "here");
            None
        }
    }
}

/// A body's `initial` value of `field`: a state field other than those the scene places, and an
/// expression of the language of its type.
fn initial_value(
    model: &Model,
    field: &str,
    text: &toml::Spanned<String>,
    set_before: &[FieldId],
    cx: &mut Ctx,
) -> Option<(FieldId, ir::Expr)> {
    let f =
        model.field_id(field).filter(|f| model.field(*f).storage == ir::Storage::State && !ir::PLACED.contains(&field));
    let Some(f) = f else {
        let states: Vec<&str> = model
            .fields
            .iter()
            .filter(|f| f.storage == ir::Storage::State && !ir::PLACED.contains(&f.name.as_str()))
            .map(|f| f.name.as_str())
            .collect();
        let d = Diagnostic::error("C0032", format!("`{field}` is not a state field a case can give an initial value"))
            .at(cx.span(text.span()), "here")
            .help(format!("the model's state fields: {}", states.join(", ")));
        cx.diags.push(d);
        return None;
    };
    let (offset, expr) = as_written(text, cx);
    let e = match check::case_expression(model, cx.file, offset, &expr, Some(f)) {
        Ok(e) => e,
        Err(d) => {
            cx.diags.extend(d);
            return None;
        }
    };
    // Computed on the host before the run (engine::setup), from what the scene places, the
    // model's initial values and this body's earlier ones (in the order of their names).
    let known =
        |g: FieldId| ["v"].iter().chain(&ir::PLACED).any(|n| *n == model.field(g).name) || set_before.contains(&g);
    let mut leaves = BeforeTheRun { model, dim: cx.dim, known: &known };
    if let Err(what) = crate::host_eval::check(&e, cx.dim, &mut leaves) {
        let d = Diagnostic::error(
            "C0045",
            format!("the initial value of `{field}` cannot be computed before the run: {what}"),
        )
        .at(cx.span(text.span()), "this expression");
        cx.diags.push(d);
        return None;
    }
    Some((f, e))
}

/// The leaves of an initial value as the host will know them before the run, with stand-in
/// values: `check` asks only whether each can be had.
struct BeforeTheRun<'a> {
    model: &'a Model,
    dim: usize,
    known: &'a dyn Fn(FieldId) -> bool,
}

impl crate::host_eval::Leaves for BeforeTheRun<'_> {
    fn field(&mut self, g: FieldId) -> Result<Vec<f64>, String> {
        let field = self.model.field(g);
        if (self.known)(g) || field.init.is_some() {
            Ok(vec![0.0; ir::components(field.ty.shape, self.dim)])
        } else if field.storage == ir::Storage::State {
            Err(format!("it reads `{}`, which neither the scene nor the model sets before the run", field.name))
        } else {
            Err(format!("it reads `{}`, which is computed during each step, after the initial values", field.name))
        }
    }
    fn param(&mut self, p: ir::ParamId) -> Result<Vec<f64>, String> {
        Ok(vec![0.0; ir::components(self.model.params[p.index()].ty.shape, self.dim)])
    }
    fn global(&mut self, g: ir::Global) -> Result<f64, String> {
        match g {
            ir::Global::Dim => Ok(self.dim as f64),
            ir::Global::Time => Err("it reads `t`, which has no value before the run".into()),
            ir::Global::Dt => Err("it reads `dt`, which has no value before the run".into()),
        }
    }
    fn reduction(&mut self, _: ir::Reduce, _: &ir::Expr) -> Result<f64, String> {
        Err("it takes a reduction over particles".into())
    }
}

/// A probe's `expression`: any shape, checked like an initial value (names, units, and the errors
/// pointing into the string).
fn probe_expression(model: &Model, text: &toml::Spanned<String>, cx: &mut Ctx) -> Option<ir::Expr> {
    let (offset, expr) = as_written(text, cx);
    check::case_expression(model, cx.file, offset, &expr, None).map_err(|d| cx.diags.extend(d)).ok()
}

/// An expression in a case string as the file writes it, escapes and all, with where it starts,
/// so that its diagnostics point into the file; the TOML value itself when the string cannot be
/// read back (it always can).
fn as_written(text: &toml::Spanned<String>, cx: &Ctx) -> (usize, String) {
    let span = text.span();
    cx.text
        .get(span.clone())
        .and_then(string_layout)
        .map_or((span.start + 1, text.get_ref().clone()), |(k, e)| (span.start + k, e))
}

/// A TOML string as written (`"…"`, `'…'`, or either tripled) → where its content starts, and its
/// value laid out byte for byte as the file has it: each escape sequence (`\t`, `\u00e9`, a
/// line-ending backslash) becomes its character followed by spaces to the escape's length. So a
/// position in the value is the same position in the file, and an expression's diagnostics point
/// at what the file shows. `None` when `raw` is not a string the reader knows.
fn string_layout(raw: &str) -> Option<(usize, String)> {
    let (open, literal) = if raw.starts_with("\"\"\"") {
        (3, false)
    } else if raw.starts_with("'''") {
        (3, true)
    } else if raw.starts_with('"') {
        (1, false)
    } else if raw.starts_with('\'') {
        (1, true)
    } else {
        return None;
    };
    let body = raw.get(open..raw.len().checked_sub(open)?)?;
    if literal {
        return Some((open, body.to_string()));
    }
    let mut out = String::with_capacity(body.len());
    let mut chars = body.char_indices().peekable();
    while let Some((k, c)) = chars.next() {
        if c != '\\' {
            out.push(c);
            continue;
        }
        let &(_, e) = chars.peek()?;
        let (decoded, len) = match e {
            'b' => (Some('\u{8}'), 2),
            't' => (Some('\t'), 2),
            'n' => (Some('\n'), 2),
            'f' => (Some('\u{c}'), 2),
            'r' => (Some('\r'), 2),
            '"' => (Some('"'), 2),
            '\\' => (Some('\\'), 2),
            'e' => (Some('\u{1b}'), 2),
            'u' | 'U' | 'x' => {
                let n = match e {
                    'u' => 4,
                    'U' => 8,
                    _ => 2,
                };
                let hex = body.get(k + 2..k + 2 + n)?;
                (Some(u32::from_str_radix(hex, 16).ok().and_then(char::from_u32)?), 2 + n)
            }
            // A line-ending backslash: the line break and the whitespace after it are dropped.
            w if w.is_whitespace() => {
                let end = body[k + 1..].find(|c: char| !c.is_whitespace()).map_or(body.len(), |n| k + 1 + n);
                (None, end - k)
            }
            _ => return None,
        };
        let start = out.len();
        if let Some(d) = decoded {
            out.push(d);
        }
        while out.len() < start + len {
            out.push(' ');
        }
        // The rest of the escape.
        while chars.peek().is_some_and(|(j, _)| *j < k + len) {
            chars.next();
        }
    }
    Some((open, out))
}

/// Warns (C0038) when a body's row nearest a symmetry plane lies between ¾ and 1½ of its spacing
/// off the plane: its mirror image is then 1.5 to 3 spacings away, a slot along the plane (a node
/// list whose first row is a whole spacing off). Filled shapes are anchored half a spacing off;
/// a body farther off is taken to stand clear of the plane.
fn warn_gap_at_planes(
    name: &str,
    span: std::ops::Range<usize>,
    placed: &geometry::Particles,
    keep: &[usize],
    mirrors: &[Mirror],
    cx: &mut Ctx,
) {
    for m in mirrors {
        let off = |k: &usize| m.side * (placed.positions[*k][m.axis] - m.offset) / placed.spacing[*k];
        let nearest = keep.iter().map(off).fold(f64::INFINITY, f64::min);
        if !(0.75..=1.5).contains(&nearest) {
            continue;
        }
        let msg = format!(
            "body `{name}`: its particles nearest the symmetry plane {} = {} m lie {nearest:.2} spacings off it, {:.2} spacings from their mirror images: a slot along the plane",
            ir::AXIS_NAMES[m.axis],
            m.offset,
            2.0 * nearest
        );
        let d = Diagnostic::warning("C0038", msg)
            .at(cx.span(span.clone()), "this body")
            .help("a body that touches the plane needs its first row half a spacing off it");
        cx.diags.push(d);
    }
}

/// Warns (C0037) when a box is not a whole number of spacings along an axis: its cell-centred
/// lattice then holds more or less volume, and mass, than the box (a 4 mm plate at 1.41 mm holds
/// three layers, 4.24 mm of material).
fn warn_box_overhang(
    name: &str,
    span: std::ops::Range<usize>,
    (min, max): (&[f64; 3], &[f64; 3]),
    spacing: f64,
    filled: f64,
    cx: &mut Ctx,
) {
    let exact: f64 = (0..cx.dim).map(|a| max[a] - min[a]).product();
    let excess = filled / exact - 1.0;
    if excess.abs() <= 0.01 {
        return;
    }
    let axes: Vec<String> = (0..cx.dim)
        .map(|a| (a, (max[a] - min[a]) / spacing))
        .filter(|(_, n)| (n - n.round()).abs() > 1e-6)
        .map(|(a, n)| format!("{} ({:.4} m = {n:.2} spacings)", ir::AXIS_NAMES[a], max[a] - min[a]))
        .collect();
    let more = if excess > 0.0 { "more" } else { "less" };
    let msg = format!(
        "body `{name}`: its particles hold {:.1} % {more} volume, and mass, than its box, which is not a whole number of spacings ({spacing} m) along {}",
        100.0 * excess.abs(),
        axes.join(", ")
    );
    let d = Diagnostic::warning("C0037", msg)
        .at(cx.span(span), "this box")
        .help("choose a spacing that divides the box, or a box that is a whole number of spacings");
    cx.diags.push(d);
}

/// Warns (C0050) when a graded fill's lattices hold more than 1 % more or less volume than its
/// shape: the fill scales every particle's volume, fine and coarse alike, to the shape's, so a
/// coarse lattice that does not fit the shape changes the mass of the fine particles too (an 8 mm
/// plate whose coarse spacing is 4.57 mm holds two coarse layers, 9.14 mm, and its fine particles
/// near the axis keep 0.876 of their mass).
fn warn_graded_rescale(name: &str, span: std::ops::Range<usize>, scale: f64, (fine, coarse): (f64, f64), cx: &mut Ctx) {
    if (scale - 1.0).abs() <= 0.01 {
        return;
    }
    let more = if scale < 1.0 { "more" } else { "less" };
    let msg = format!(
        "body `{name}`: its graded lattices (fine {fine:.4e} m, coarse {coarse:.4e} m) hold {:.1} % {more} volume than its shape, so every particle's volume and mass, fine and coarse alike, is scaled by {scale:.4}",
        100.0 * (1.0 / scale - 1.0).abs(),
    );
    let d = Diagnostic::warning("C0050", msg)
        .at(cx.span(span), "this body")
        .help("choose spacings that fit the shape: a plate a whole number of coarse spacings thick");
    cx.diags.push(d);
}

fn primitive(s: &case::Shape, cx: &mut Ctx) -> Option<Primitive> {
    let m = Unit::M;
    Some(match s {
        case::Shape::Box { min, max } => {
            Primitive::Box { min: cx.vector(min, m, "box min")?, max: cx.vector(max, m, "box max")? }
        }
        case::Shape::Sphere { center, radius } => Primitive::Sphere {
            center: cx.vector(center, m, "sphere center")?,
            radius: cx.scalar(radius, m, "sphere radius")?,
        },
        case::Shape::Cylinder { base, axis, radius, length } => Primitive::Cylinder {
            base: cx.vector(base, m, "cylinder base")?,
            axis: cx.direction(axis, "cylinder axis")?,
            radius: cx.scalar(radius, m, "cylinder radius")?,
            length: cx.scalar(length, m, "cylinder length")?,
        },
        case::Shape::HollowCylinder { base, axis, inner_radius, outer_radius, length } => Primitive::HollowCylinder {
            base: cx.vector(base, m, "tube base")?,
            axis: cx.direction(axis, "tube axis")?,
            inner_radius: cx.scalar(inner_radius, m, "tube inner radius")?,
            outer_radius: cx.scalar(outer_radius, m, "tube outer radius")?,
            length: cx.scalar(length, m, "tube length")?,
        },
        case::Shape::Plate { center, normal, radius, thickness } => Primitive::Plate {
            center: cx.vector(center, m, "plate center")?,
            normal: cx.direction(normal, "plate normal")?,
            radius: cx.scalar(radius, m, "plate radius")?,
            thickness: cx.scalar(thickness, m, "plate thickness")?,
        },
        case::Shape::Disc { center, radius } => Primitive::Disc {
            center: cx.vector(center, m, "disc center")?,
            radius: cx.scalar(radius, m, "disc radius")?,
        },
        case::Shape::Annulus { center, inner_radius, outer_radius } => Primitive::Annulus {
            center: cx.vector(center, m, "annulus center")?,
            inner_radius: cx.scalar(inner_radius, m, "annulus inner radius")?,
            outer_radius: cx.scalar(outer_radius, m, "annulus outer radius")?,
        },
        case::Shape::Polygon { vertices } => {
            Primitive::Polygon { vertices: cx.vertices(vertices, "polygon vertices")? }
        }
        // A body's node list is read by `place`; anywhere else it has no inside.
        case::Shape::Nodes { file, .. } => {
            cx.err(file.span(), "C0033", "a node list is the shape of a body, not a region: it has no inside", "here");
            return None;
        }
    })
}

/// The `[neighbours]` table (the cell list when absent), or Verlet lists of `--verlet`'s skin.
fn neighbour_search(cx: &mut Ctx, model: &Model, n: Option<&case::Neighbours>, verlet: Option<f64>) -> Option<Search> {
    if let Some(skin) = verlet {
        if let Some(msg) = Search::skin_problem(skin) {
            let span = cx.cli.span(&cx.cli.verlet).unwrap_or_default();
            cx.diags.push(Diagnostic::error("C0034", format!("--verlet: {msg}")).at(span, "out of range"));
            return None;
        }
        return Some(Search::Verlet { skin });
    }
    let Some(n) = n else { return Some(Search::Cells) };
    let skin = match &n.skin {
        Some(s) => {
            if let Some(msg) = Search::skin_problem(*s.get_ref()) {
                cx.err(s.span(), "C0034", msg, "out of range");
                return None;
            }
            Some(*s.get_ref())
        }
        None => None,
    };
    // The cell list reads nothing else, and `field` and `threshold` are read by the adaptive
    // search only, so that a study can switch `search` alone.
    let kind = n.search.get_ref().as_str();
    match kind {
        "cells" => Some(Search::Cells),
        "verlet" => Some(Search::Verlet { skin: skin.unwrap_or(0.1) }),
        "adaptive" => {
            let Some(f) = &n.field else {
                cx.err(n.search.span(), "C0034", "the adaptive search needs `field` (e.g. \"eps_p\")", "no field");
                return None;
            };
            let Some(field) = model.field_id(f.get_ref()).filter(|id| model.field(*id).ty.shape == Shape::Scalar)
            else {
                cx.err(f.span(), "C0034", format!("`{}` is not a scalar field of the model", f.get_ref()), "here");
                return None;
            };
            let threshold = match &n.threshold {
                Some(t) => cx.scalar(t, Unit::ONE, "threshold")?,
                None => {
                    cx.err(n.search.span(), "C0034", "the adaptive search needs `threshold`", "no threshold");
                    return None;
                }
            };
            if threshold.is_nan() || threshold < 0.0 {
                let span = n.threshold.as_ref().map(|t| t.span()).unwrap_or(n.search.span());
                cx.err(span, "C0034", format!("the threshold is a non-negative number, found {threshold}"), "here");
                return None;
            }
            let field_name = f.get_ref().clone();
            Some(Search::Adaptive { field, field_name, threshold, skin: skin.unwrap_or(0.0) })
        }
        other => {
            let msg = format!("unknown neighbour search `{other}`: cells, verlet or adaptive");
            cx.err(n.search.span(), "C0034", msg, "here");
            None
        }
    }
}

/// An axisymmetric case (`axisymmetric = true`): a 2D case whose x is the radius and y the axis,
/// so the axis is a symmetry plane at x = 0 (added here, unless the case lists it), and a model
/// that integrates the hoop stress `s_hoop` wherever it integrates `v` (solid/hoop_stress.sph),
/// since its other equations then carry the hoop terms. Error C0053 otherwise.
fn axis_of_symmetry(case: &CaseFile, model: &Model, mirrors: &mut Vec<Mirror>, cx: &mut Ctx) -> Option<()> {
    let span = case.axisymmetric.as_ref().map(|a| a.span()).unwrap_or_default();
    if cx.dim != 2 {
        let msg = format!("an axisymmetric case is 2D (x the radius, y the axis), and this one is {}D", cx.dim);
        cx.err(span, "C0053", msg, "here");
        return None;
    }
    let axis = Mirror::symmetry(0, 0.0);
    match mirrors.iter().find(|m| m.axis == 0) {
        None => mirrors.push(axis),
        Some(m) if m.offset == 0.0 && m.side > 0.0 => {}
        Some(_) => {
            cx.err(span, "C0053", "an axisymmetric case's only plane on x is its axis, x = 0 (kept above)", "here");
            return None;
        }
    }
    let rate_groups = |name: &str| {
        model.field_id(name).map_or(GroupSet::default(), |f| {
            model.rates.iter().filter(|r| r.state == f).fold(GroupSet::default(), |g, r| g.union(r.dest))
        })
    };
    let moving = rate_groups("v");
    if moving.intersect(rate_groups("s_hoop")).intersect(rate_groups("m")) != moving {
        let d = Diagnostic::error(
            "C0053",
            "the model is not axisymmetric: it does not integrate `s_hoop` and `m` wherever it integrates `v`",
        )
        .at(cx.span(span), "axisymmetric")
        .help("an axisymmetric model uses solid::hoop_stress and integrates `s_hoop' = ds_hoop  m' = hoop_mass_rate()` beside `s' = ds`; the stdlib's: models::ftlr19_perforation_shaped and models::ek18_solid_failure (docs/CASE_FILES.md, \"Axisymmetric cases\")");
        cx.diags.push(d);
        return None;
    }
    Some(())
}

/// A material's key that comes first in the case file.
fn first_key(values: &BTreeMap<String, Value>) -> Option<&Value> {
    values.values().min_by_key(|v| v.span().start)
}

/// Every `require` of the model that the case's materials decide holds (error C0048 at the keys
/// of the material that the broken condition reads, else at the material's first key). A
/// condition that reads a scene constant (gravity, a load) cannot be decided here: the store's
/// setup checks it, naming the case file.
fn requirements_hold(
    case: &CaseFile,
    model: &Model,
    particles: &ParticleInput,
    materials: &[MaterialInput],
    cx: &mut Ctx,
) -> Option<()> {
    let resolved: Vec<_> = materials.iter().map(|m| crate::engine::setup::resolve_material(model, cx.dim, m)).collect();
    let broken = crate::engine::setup::broken_requirement(model, cx.dim, particles, materials, &resolved)
        .filter(|b| b.evaluated);
    let Some(broken) = broken else { return Some(()) };
    let keys = case.materials.get(&materials[broken.material].name);
    let read: Vec<&Value> = broken.reads.iter().filter_map(|p| keys?.get(&model.params[p.index()].name)).collect();
    let mut d = Diagnostic::error(broken.error.code, broken.error.message);
    if let Some((first, rest)) = read.split_first() {
        d = d.at(cx.span(first.span()), "the condition reads this value");
        for v in rest {
            d = d.also(cx.span(v.span()), "and this one");
        }
    } else if let Some(v) = keys.and_then(first_key) {
        d = d.at(cx.span(v.span()), "in this material");
    }
    cx.diags.push(d);
    None
}

/// By parameter id: the value every material a body uses binds the parameter to (its default
/// resolved), where they all agree; the plan takes the branches these decide
/// (`schedule/settle.rs`).
fn settled_params(
    model: &Model,
    dim: usize,
    materials: &[MaterialInput],
    used: &std::collections::BTreeSet<&str>,
) -> Vec<Option<Vec<f64>>> {
    let resolved: Vec<Vec<Option<Vec<f64>>>> = materials
        .iter()
        .filter(|m| used.contains(m.name.as_str()))
        .map(|m| crate::engine::setup::resolve_material(model, dim, m))
        .collect();
    (0..model.params.len())
        .map(|p| {
            let first = resolved.first()?[p].clone()?;
            resolved.iter().all(|r| r[p].as_ref() == Some(&first)).then_some(first)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::{expected_keys, string_layout};

    #[test]
    fn the_keys_of_an_unknown_key_message_are_read_for_one_two_or_many_keys_or_none() {
        for (message, keys) in [
            ("axs`, expected `axis`", vec!["axis"]),
            ("foo`, expected `min` or `max`", vec!["min", "max"]),
            ("foo`, expected one of `name`, `group`, `shape`", vec!["name", "group", "shape"]),
            ("foo`, there are no fields", vec![]),
        ] {
            assert_eq!(expected_keys(message), keys, "{message}");
        }
    }

    #[test]
    fn a_string_is_laid_out_as_the_file_writes_it() {
        for (raw, open, value) in [
            (r#""x + 1""#, 1, "x + 1"),
            (r#""\té""#, 1, "\t é"),
            (r#""\u00e9 x""#, 1, "é     x"),
            (r#""a\"b""#, 1, "a\" b"),
            ("'\\t'", 1, "\\t"),
            ("\"\"\"x \\\n   y\"\"\"", 3, "x      y"),
            ("'''x'''", 3, "x"),
        ] {
            let (k, v) = string_layout(raw).expect("a string");
            assert_eq!((k, v.as_str()), (open, value), "{raw}");
            assert_eq!(v.len(), raw.len() - 2 * open, "{raw}");
        }
        assert!(string_layout("12").is_none());
        assert!(string_layout(r#""\q""#).is_none());
    }
}
