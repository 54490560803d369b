//! The `pairsum` command line.

use crate::check::{self, Stdlib};
use crate::diag::{render, Sources};
use crate::runner::{BackendChoice, Precision};
use clap::{Parser, Subcommand};
use std::path::{Path, PathBuf};

#[derive(Parser)]
#[command(name = "pairsum", version, about = "Compile and run SPH models written in the pair-sum language")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Check model files (or every .sph file under a directory; a directory holding `prelude.sph` is
    /// checked as the stdlib, replacing the built-in one) and case files (or bundled cases' names)
    Check {
        /// Files, directories, cases
        #[arg(required = true)]
        paths: Vec<PathBuf>,
        /// Treat warnings as errors
        #[arg(long)]
        deny_warnings: bool,
        /// For case files: the resolution to check them at (a name from the case, a spacing, or
        /// name@spacing), as `run` takes it
        #[arg(long)]
        resolution: Option<String>,
        /// For case files: set a parameter (`${name}` in the case file), as `run` takes it:
        /// --set coarse_factor=3
        #[arg(long = "set", value_parser = parse_set)]
        set: Vec<(String, String)>,
    },
    /// Run a case end to end; writes VTK output, report.json and report.md into --out
    Run {
        /// The case file (cases/<name>.toml or a bundled case's name)
        case: String,
        /// cpu, gpu, or auto (the GPU when one is found, else the CPU)
        #[arg(long, value_enum, default_value_t = BackendChoice::Auto)]
        backend: BackendChoice,
        /// f32 or f64
        #[arg(long, value_enum, default_value_t = Precision::F64)]
        precision: Precision,
        /// A resolution the case defines (ci, paper), a particle spacing (0.005, "5 mm"), or a
        /// resolution's settings at another spacing (ci@2mm)
        #[arg(long)]
        resolution: Option<String>,
        /// Output directory (default: out/<case>)
        #[arg(long)]
        out: Option<PathBuf>,
        /// Simulated end time in seconds, overriding the case
        #[arg(long)]
        end_time: Option<f64>,
        /// Write a checkpoint every this many steps
        #[arg(long)]
        checkpoint_every: Option<u64>,
        /// Resume from a checkpoint written by an earlier run of the same case
        #[arg(long)]
        restart: Option<PathBuf>,
        /// Stop after this many steps
        #[arg(long)]
        max_steps: Option<u64>,
        /// No progress bar
        #[arg(long)]
        quiet: bool,
        /// Write into an output directory that holds files pairsum did not write (it replaces only
        /// its own outputs and deletes nothing)
        #[arg(long)]
        force: bool,
        /// Measure where the run's time goes (steps, watchdog, probes and output; on the GPU each
        /// kernel's device time, the submissions and the read-backs) and write it to timing.txt
        #[arg(long)]
        timing: bool,
        /// Set a case parameter (`${name}` in the case file): --set v_impact=250
        #[arg(long = "set", value_parser = parse_set)]
        set: Vec<(String, String)>,
        /// Find neighbours with Verlet lists of this skin (a fraction of the largest cut-off),
        /// whatever the case's `[neighbours]` says; no pair is missed
        #[arg(long, value_name = "SKIN")]
        verlet: Option<f64>,
        /// Run at three or more resolutions and report the error at each, the observed order and
        /// a Richardson estimate: the file's `convergence` list, or these (--convergence=2mm,1mm,0.5mm)
        #[arg(long, value_name = "RESOLUTIONS", num_args = 0..=1, require_equals = true, default_missing_value = "", conflicts_with = "resolution")]
        convergence: Option<String>,
        /// Run nothing: analyse again the reports that an earlier run of this study (with
        /// --convergence, of these resolutions) wrote into --out
        #[arg(long)]
        reanalyse: bool,
        /// Split the run into this many domains, each run by a thread of this process as a rank
        /// (on the CPU; with `--backend gpu`, each rank's neighbour passes on a GPU); `mpirun -n N
        /// pairsum run CASE` runs N processes instead
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
        domains: Option<u32>,
        /// Run this many of a study's runs, or of a case's --convergence levels, at once, each on
        /// its share of the threads (RAYON_NUM_THREADS or the cores, divided by N)
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024), value_name = "N")]
        jobs: Option<u32>,
    },
    /// List the bundled cases
    Cases,
    /// Write the generated code of a model or a case
    Emit {
        /// A model (.sph, or a stdlib model by name: models::elastic_solid), a case (.toml) or a
        /// bundled case's name; with --all, every stdlib model and bundled case
        path: Option<PathBuf>,
        /// wgsl
        #[arg(long, default_value = "wgsl")]
        target: String,
        /// Output directory (default: print to stdout)
        #[arg(short = 'o', long)]
        out: Option<PathBuf>,
        /// Dimension, for a model
        #[arg(long, default_value_t = 3)]
        dim: usize,
        /// Regenerate shaders_gen/ for every stdlib model and bundled case
        #[arg(long)]
        all: bool,
        /// Write into a directory that holds files other than generated WGSL (nothing of them is
        /// deleted; a file with the name of a generated kernel is replaced)
        #[arg(long)]
        force: bool,
    },
    /// Benchmark the closure backend against a hand-written native step (ratios from one run)
    Bench {
        /// Particle counts (`--particles 10000 100000` or `--particles 10000,100000`)
        #[arg(long, num_args = 1.., value_delimiter = ',', default_values_t = vec![10_000, 100_000])]
        particles: Vec<usize>,
        /// Repetitions per measurement (the best is kept)
        #[arg(long, default_value_t = 5)]
        reps: usize,
    },
    /// The numerical uncertainty of the finest of four or more levels of a convergence study (any
    /// quantity, from any code): power laws in the spacing fitted through every level in the
    /// least-squares sense, as a convergence report's "Numerical uncertainty" table does
    Uncertainty {
        /// Each level as SPACING=VALUE, in any order and any one unit of spacing: 1.333=219.73
        /// 1=222.78 0.8=222.76 0.667=222.91. A level that is a mean over runs may give its standard
        /// error, SPACING=VALUE±SE (or +-SE); given at every level, the order's and f0's range under
        /// that noise is printed too
        #[arg(required = true, value_parser = parse_level)]
        levels: Vec<Level>,
        /// A reference value: whether it lies within the finest value ± U
        #[arg(long)]
        reference: Option<f64>,
        /// Print one JSON object (for scripts) instead of the text
        #[arg(long)]
        json: bool,
    },
    /// Print the plan of a step: passes, fused equations, fields read and written, bytes per particle, and the parameters a material binds
    Plan {
        /// A model (.sph, or a stdlib model by name: models::elastic_solid), a case (.toml) or a
        /// bundled case's name
        path: PathBuf,
        /// Dimension, for a model
        #[arg(long, default_value_t = 3)]
        dim: usize,
        /// Integrator, for a model: euler, predictor_corrector, symplectic, pec, symplectic_pec
        #[arg(long, default_value = "predictor_corrector")]
        integrator: String,
        /// Precision of the reals: f32 or f64
        #[arg(long, value_enum, default_value_t = Precision::F64)]
        precision: Precision,
        /// For a case: the resolution (a name from the case, or a spacing)
        #[arg(long)]
        resolution: Option<String>,
        /// For a case: set a parameter (`${name}` in the case file): --set v_impact=250
        #[arg(long = "set", value_parser = parse_set)]
        set: Vec<(String, String)>,
        /// For a case: split it into this many domains (as a run across processes would) and
        /// print each one's particles and halo
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..=64))]
        domains: Option<u32>,
    },
}

/// Runs the CLI; returns the process exit code (0 ok, 1 errors in the input, 2 usage).
pub fn main() -> i32 {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() { 2 } else { 0 };
        }
    };
    let code = match cli.command {
        Command::Check { paths, deny_warnings, resolution, set } => {
            let opts = crate::scene::Options { resolution, set, ..Default::default() };
            run_check(&paths, deny_warnings, &opts)
        }
        Command::Plan { path, dim, integrator, precision, resolution, set, domains } => {
            let opts = crate::scene::Options { resolution, set, ..Default::default() };
            run_plan(&find_input(&path), dim, &integrator, precision, &opts, domains)
        }
        Command::Run {
            case,
            backend,
            precision,
            resolution,
            out,
            end_time,
            checkpoint_every,
            restart,
            max_steps,
            quiet,
            force,
            timing,
            set,
            verlet,
            convergence,
            reanalyse,
            domains,
            jobs,
        } => {
            let opts = RunArgs {
                backend,
                precision,
                resolution,
                out,
                end_time,
                checkpoint_every,
                restart,
                max_steps,
                quiet,
                force,
                timing,
                set,
                verlet,
                convergence,
                reanalyse,
                domains,
                jobs,
            };
            run_run(&case, opts)
        }
        Command::Cases => run_cases(),
        Command::Emit { path, target, out, dim, all, force } => {
            let path = path.map(|p| find_input(&p));
            run_emit(path.as_deref(), &target, out.as_deref(), dim, all, force)
        }
        Command::Uncertainty { levels, reference, json } => run_uncertainty(&levels, reference, json),
        Command::Bench { particles, reps } => match crate::bench::run(&particles, reps.max(1)) {
            Ok(table) => {
                say(&table);
                0
            }
            Err(e) => {
                eprintln!("error: {e}");
                1
            }
        },
    };
    crate::backend::transport::finalise();
    code
}

/// A level of `pairsum uncertainty`: its spacing, value and, for a mean over runs, standard error.
#[derive(Clone, Copy, Debug)]
pub struct Level {
    spacing: f64,
    value: f64,
    standard_error: Option<f64>,
}

/// `SPACING=VALUE` or `SPACING=VALUE±SE` (`+-` for `±`), numbers all.
fn parse_level(s: &str) -> Result<Level, String> {
    let number = |t: &str| t.trim().parse::<f64>().map_err(|_| format!("`{t}` is not a number"));
    let (h, v) = s
        .split_once('=')
        .ok_or_else(|| format!("`{s}` is not SPACING=VALUE or SPACING=VALUE±SE (for example 0.8=222.76)"))?;
    let (v, se) = match v.split_once('±').or_else(|| v.split_once("+-")) {
        Some((v, se)) => (v, Some(number(se)?)),
        None => (v, None),
    };
    Ok(Level { spacing: number(h)?, value: number(v)?, standard_error: se })
}

/// Prints the numerical uncertainty of the finest of `levels`, as text or one JSON object, and,
/// where every level has a standard error, the order's and f0's range under that noise; 1 where
/// there is none, or where some levels have a standard error and some not.
fn run_uncertainty(levels: &[Level], reference: Option<f64>, json: bool) -> i32 {
    use crate::report::uncertainty::{uncertainty, under_noise};
    let points: Vec<(f64, f64)> = levels.iter().map(|l| (l.spacing, l.value)).collect();
    let Some(u) = uncertainty(&points) else {
        eprintln!(
            "error: no uncertainty: it needs four levels or more, each spacing positive and given once, each value finite"
        );
        return 1;
    };
    let errors: Option<Vec<(f64, f64, f64)>> =
        levels.iter().map(|l| Some((l.spacing, l.value, l.standard_error?))).collect();
    let noise = match errors {
        Some(e) => match under_noise(&e) {
            Some(n) => Some(n),
            None => {
                eprintln!("error: a standard error is negative or not a number");
                return 1;
            }
        },
        None if levels.iter().any(|l| l.standard_error.is_some()) => {
            eprintln!("error: give every level a standard error (SPACING=VALUE±SE), or none");
            return 1;
        }
        None => None,
    };
    say(&if json {
        uncertainty_json(&u, levels.len(), reference, noise.as_ref())
    } else {
        uncertainty_text(&u, levels.len(), reference) + &noise.as_ref().map(under_noise_text).unwrap_or_default()
    });
    0
}

fn under_noise_text(n: &crate::report::uncertainty::UnderNoise) -> String {
    format!(
        "steps between neighbouring levels larger than twice their combined standard error: {} of {}\n\
         a constant within the levels' noise (χ² probability; above 0.05 they are one value): {}\n\
         weighted by 1/s²: the levels' mean {}, f0 of f0 + α Δx {}\n\
         under the levels' noise ({} draws, 10th–90th percentile): order {}, f0 {}–{}\n",
        n.resolved_steps.0,
        n.resolved_steps.1,
        n.constant_fits.map_or("— (a standard error is 0)".into(), |p| format!("{p:.3}")),
        n.constant.map_or("—".into(), |(m, s)| format!("{m} ± {s}")),
        n.first_order.map_or("—".into(), |(m, s)| format!("{m} ± {s}")),
        crate::report::uncertainty::DRAWS,
        n.describe_order(),
        n.limit.0,
        n.limit.1
    )
}

fn uncertainty_text(u: &crate::report::uncertainty::Uncertainty, levels: usize, reference: Option<f64>) -> String {
    let fit = &u.chosen;
    let mut text = format!("observed order p (least squares, all {levels} levels): {}\n", u.describe_order());
    if let Some(range) = u.describe_order_without_one() {
        text += &format!("observed order leaving out one level at a time: {range}\n");
    }
    text += &format!(
        "error estimated with: {}, {}weighted; f0 = {}, scatter σ = {}\n",
        fit.law.describe(),
        if fit.weighted { "" } else { "un" },
        fit.limit(),
        fit.sigma
    );
    text +=
        &format!("data range Δφ = {}, error of the finest ε = {}, safety factor {}\n", u.data_range, u.error, u.safety);
    text += &format!("finest (Δx = {}): {} ± {}\n", u.finest.0, u.finest.1, u.u);
    if let Some(r) = reference {
        let beyond = u.beyond(r);
        text += &if beyond <= 0.0 {
            format!("the reference {r} lies within it\n")
        } else {
            format!("the reference {r} lies {beyond} beyond it\n")
        };
    }
    text
}

/// The same as one JSON object: the observed order (and its text, which marks the search's
/// bounds), with five levels or more its range leaving out one level (and its text), the law the
/// error is estimated with, its f0 and σ, Δφ, ε, Fs, the finest level and U, and with a reference
/// how far it lies beyond the finest value ± U (≤ 0 within).
fn uncertainty_json(
    u: &crate::report::uncertainty::Uncertainty,
    levels: usize,
    reference: Option<f64>,
    noise: Option<&crate::report::uncertainty::UnderNoise>,
) -> String {
    let fit = &u.chosen;
    let mut object = serde_json::json!({
        "levels": levels,
        "order": u.order(),
        "order_text": u.describe_order(),
        "order_without_one": u.order_without_one.map(|(lo, hi)| [lo, hi]),
        "order_without_one_text": u.describe_order_without_one(),
        "law": fit.law.describe(),
        "weighted": fit.weighted,
        "f0": fit.limit(),
        "sigma": fit.sigma,
        "data_range": u.data_range,
        "error": u.error,
        "safety": u.safety,
        "finest_spacing": u.finest.0,
        "finest_value": u.finest.1,
        "u": u.u,
    });
    if let Some(r) = reference {
        object["reference"] = r.into();
        object["beyond"] = u.beyond(r).into();
    }
    if let Some(n) = noise {
        object["under_noise"] = serde_json::json!({
            "order": [n.order.0, n.order.1],
            "order_text": n.describe_order(),
            "f0": [n.limit.0, n.limit.1],
            "resolved_steps": n.resolved_steps.0,
            "constant_fits": n.constant_fits,
            "weighted_mean": n.constant.map(|(m, s)| [m, s]),
            "first_order_f0": n.first_order.map(|(m, s)| [m, s]),
            "steps": n.resolved_steps.1,
        });
    }
    format!("{object}\n")
}

/// Every .sph file under the given paths, sorted.
pub fn sph_files(paths: &[PathBuf]) -> Vec<PathBuf> {
    fn walk(p: &Path, out: &mut Vec<PathBuf>) {
        if p.is_dir() {
            let mut entries: Vec<PathBuf> =
                std::fs::read_dir(p).map(|d| d.flatten().map(|e| e.path()).collect()).unwrap_or_default();
            entries.sort();
            for e in entries {
                if e.is_dir() || e.extension().is_some_and(|x| x == "sph") {
                    walk(&e, out);
                }
            }
        } else {
            out.push(p.to_path_buf());
        }
    }
    let mut out = vec![];
    for p in paths {
        walk(p, &mut out);
    }
    out
}

/// Checks model files and case files (the latter at `opts`' resolution and settings), prints the
/// diagnostics and a count; the exit code (1 on errors, or on warnings when denied).
fn run_check(paths: &[PathBuf], deny_warnings: bool, opts: &crate::scene::Options) -> i32 {
    let (cases, models): (Vec<PathBuf>, Vec<PathBuf>) =
        paths.iter().map(|p| find_input(p)).partition(|p| p.extension().is_some_and(|e| e == "toml"));
    if cases.is_empty() && (opts.resolution.is_some() || !opts.set.is_empty()) {
        eprintln!("error: `--resolution` and `--set` are for case files, and none was given");
        return 2;
    }
    let mut errors = 0;
    let mut warnings = 0;
    let mut n = 0;
    for (f, stdlib) in model_files(&models) {
        n += 1;
        let mut sources = Sources::new();
        let checked = check::check_paths(&mut sources, &[f.as_path()], stdlib);
        if !checked.diags.is_empty() {
            eprint!("{}", render(&sources, &checked.diags));
        }
        errors += checked.diags.iter().filter(|d| d.is_error()).count();
        warnings += checked.diags.iter().filter(|d| !d.is_error()).count();
    }
    for case in &cases {
        n += 1;
        match crate::runner::check_file(case, opts) {
            Ok(w) => warnings += w,
            Err(e) => {
                eprint!("{e}");
                errors += 1;
            }
        }
    }
    if errors > 0 {
        eprintln!("checked {n} file(s): {errors} error(s), {warnings} warning(s)");
        1
    } else if deny_warnings && warnings > 0 {
        eprintln!("checked {n} file(s): {warnings} warning(s), denied");
        1
    } else {
        eprintln!("checked {n} file(s): ok ({warnings} warning(s))");
        0
    }
}

/// Every .sph file under the given paths, each with the stdlib it is checked against: a directory
/// that holds `prelude.sph` is a stdlib and replaces the built-in one for the files under it.
fn model_files(paths: &[PathBuf]) -> Vec<(PathBuf, Stdlib)> {
    let mut out = vec![];
    for p in paths {
        let stdlib = if p.join("prelude.sph").is_file() { Stdlib::Dir(p.clone()) } else { Stdlib::locate() };
        out.extend(sph_files(std::slice::from_ref(p)).into_iter().map(|f| (f, stdlib.clone())));
    }
    out
}

fn real_bytes(precision: Precision) -> usize {
    match precision {
        Precision::F32 => 4,
        Precision::F64 => 8,
    }
}

/// A model file, or a stdlib model by the name a case gives it (`models::elastic_solid`) where
/// no such file is.
fn check_model(sources: &mut Sources, path: &Path) -> check::Checked {
    let name = path.to_string_lossy();
    if !path.exists() && name.contains("::") {
        let rel = Stdlib::file_of(&name);
        return check::check_stdlib_modules(sources, &[rel.as_str()], Stdlib::locate());
    }
    check::check_paths(sources, &[path], Stdlib::locate())
}

/// Checks a model file and prints its diagnostics; the model if it has no errors.
pub fn load_model(path: &Path, sources: &mut Sources) -> Option<crate::ir::Model> {
    let checked = check_model(sources, path);
    if !checked.diags.is_empty() {
        eprint!("{}", render(sources, &checked.diags));
    }
    (!checked.has_errors()).then_some(checked.model)
}

/// The directory of the bundled cases.
pub fn cases_dir() -> PathBuf {
    if let Some(d) = &crate::config::env().cases {
        return d.clone();
    }
    let local = PathBuf::from("cases");
    if local.is_dir() {
        return local;
    }
    Path::new(env!("CARGO_MANIFEST_DIR")).join("cases")
}

/// A model or case file as given, or else a bundled case of that name (`pairsum plan cantilever`).
pub fn find_input(path: &Path) -> PathBuf {
    if path.exists() {
        path.to_path_buf()
    } else {
        find_case(&path.to_string_lossy())
    }
}

/// A case by path, or a bundled case by name.
pub fn find_case(name: &str) -> PathBuf {
    let p = PathBuf::from(name);
    if p.is_file() {
        return p;
    }
    let dir = cases_dir();
    for candidate in [dir.join(format!("{name}.toml")), dir.join(name).join("case.toml"), dir.join(name)] {
        if candidate.is_file() {
            return candidate;
        }
    }
    p
}

/// Every bundled case file.
pub fn bundled_cases() -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = vec![];
    let Ok(entries) = std::fs::read_dir(cases_dir()) else { return out };
    for e in entries.flatten() {
        let p = e.path();
        if p.extension().is_some_and(|x| x == "toml") {
            out.push(p);
        } else if p.join("case.toml").is_file() {
            out.push(p.join("case.toml"));
        }
    }
    out.sort();
    out
}

fn run_cases() -> i32 {
    for p in bundled_cases() {
        let text = std::fs::read_to_string(&p).unwrap_or_default();
        // A template case is listed with its parameters' defaults.
        let text = crate::scene::template::expand(&text, &[]).unwrap_or(text);
        let table: toml::Table = toml::from_str(&text).unwrap_or_default();
        let name = table.get("name").and_then(|v| v.as_str()).unwrap_or("?").to_string();
        let title = table.get("title").and_then(|v| v.as_str()).unwrap_or("").to_string();
        say(&format!("{name:<28} {title}\n{:<28} {}\n", "", p.display()));
    }
    0
}

fn parse_set(s: &str) -> Result<(String, String), String> {
    s.split_once('=')
        .map(|(k, v)| (k.trim().to_string(), v.trim().to_string()))
        .ok_or_else(|| format!("expected name=value, found `{s}`"))
}

struct RunArgs {
    set: Vec<(String, String)>,
    backend: BackendChoice,
    precision: Precision,
    resolution: Option<String>,
    out: Option<PathBuf>,
    end_time: Option<f64>,
    checkpoint_every: Option<u64>,
    restart: Option<PathBuf>,
    max_steps: Option<u64>,
    quiet: bool,
    force: bool,
    timing: bool,
    verlet: Option<f64>,
    convergence: Option<String>,
    reanalyse: bool,
    domains: Option<u32>,
    jobs: Option<u32>,
}

fn run_run(case: &str, a: RunArgs) -> i32 {
    use crate::runner::{run_file, RunOptions};
    let (backend, precision) = (a.backend, a.precision);
    let path = find_case(case);
    if !path.is_file() {
        eprintln!("error: no case `{case}` (a .toml file, or one of the bundled cases: pairsum cases)");
        return 1;
    }
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "case".into());
    let name = if stem == "case" {
        path.parent().and_then(|p| p.file_name()).map(|s| s.to_string_lossy().into_owned()).unwrap_or(stem)
    } else {
        stem
    };
    let out = a.out.unwrap_or_else(|| PathBuf::from("out").join(name));
    let opts = RunOptions {
        backend,
        precision,
        scene: crate::scene::Options { resolution: a.resolution, end_time: a.end_time, set: a.set, verlet: a.verlet },
        out,
        progress: !a.quiet && std::io::IsTerminal::is_terminal(&std::io::stderr()),
        checkpoint_every: a.checkpoint_every,
        restart: a.restart,
        max_steps: a.max_steps,
        vtk: true,
        force: a.force,
        timing: a.timing,
        domains: a.domains.map(|d| d as usize),
        jobs: a.jobs.unwrap_or(1) as usize,
    };
    // Under `mpirun` every rank runs the case; rank 0 writes the outputs, the others only their
    // pieces of the VTK snapshots into the same folder.
    let rank = match crate::backend::transport::launched_rank() {
        Ok(r) => r.unwrap_or(0),
        Err(e) => {
            eprintln!("error: {}", e.0);
            return 1;
        }
    };
    if opts.jobs > 1 && crate::backend::transport::launched_ranks().is_some_and(|n| n > 1) {
        eprintln!(
            "error: --jobs runs in one process; under mpirun every run is split across the ranks: leave --jobs out"
        );
        return 1;
    }
    let mut opts = opts;
    if rank > 0 {
        (opts.progress, opts.timing) = (false, false);
    }
    let outcome = match &a.convergence {
        None if a.reanalyse => crate::runner::reanalyse_file(&path, &opts),
        None => run_file(&path, &opts),
        Some(list) if list.trim().is_empty() => crate::runner::declared_levels(&path)
            .and_then(|levels| crate::runner::run_convergence(&path, &levels, &opts, a.reanalyse)),
        Some(list) => {
            let levels: Vec<String> = list.split(',').map(|l| l.trim().to_string()).filter(|l| !l.is_empty()).collect();
            crate::runner::run_convergence(&path, &levels, &opts, a.reanalyse)
        }
    };
    if rank > 0 {
        if let Err(e) = &outcome {
            // An error every rank meets (an instability) is rank 0's to report, and its abort
            // ends this process; an error on this rank alone would leave the others waiting:
            // report it and stop them all.
            std::thread::sleep(std::time::Duration::from_secs(2));
            let msg = match e {
                crate::runner::RunFailure::Input(m) | crate::runner::RunFailure::Run(m) => m,
            };
            eprintln!("rank {rank}: error: {}", msg.lines().next().unwrap_or_default());
            crate::backend::transport::abort_ranks(1);
            return 1;
        }
        return 0;
    }
    if outcome.is_err() {
        // Print the error before the other ranks are stopped.
        let code = report_outcome(outcome);
        crate::backend::transport::abort_ranks(code);
        return code;
    }
    report_outcome(outcome)
}

fn report_outcome(outcome: Result<crate::runner::RunOutcome, crate::runner::RunFailure>) -> i32 {
    use crate::runner::RunFailure;
    match outcome {
        Ok(o) => {
            let r = &o.report;
            let stats = crate::backend::cpu::ccode::build_stats();
            if let Some((s, what)) = stats.and_then(|s| s.describe().map(|w| (s, w))) {
                eprintln!(
                    "{what} compiled by the C compiler in {:.1} s, kept in {} for later runs",
                    s.secs,
                    s.cache.display()
                );
            }
            eprintln!(
                "{}: {} particles, {} steps in {:.2} s on {} ({:.3e} particle-steps/s)",
                r.case, r.particles, r.steps, r.wall_s, r.backend, r.particle_steps_per_s
            );
            for row in &r.results {
                let reference = row.reference.map(|x| format!("{x:.6e}")).unwrap_or_else(|| "-".into());
                let err = row.rel_error.map(|e| format!("{:+.2} %", 100.0 * e)).unwrap_or_default();
                // A study's mean carries its standard error, as report.md shows it.
                let se = row.standard_error.map(|s| format!(" ± {s:.2e}")).unwrap_or_default();
                eprintln!(
                    "  {:<32} {:>14.6e}{se} {:<6} reference {:>14} {}",
                    row.quantity, row.value, row.unit, reference, err
                );
            }
            say(&format!("report: {}\n", o.out.join("report.md").display()));
            0
        }
        Err(RunFailure::Input(msg)) => {
            eprint!("{msg}");
            1
        }
        Err(RunFailure::Run(msg)) => {
            eprintln!("error: {msg}");
            1
        }
    }
}

fn run_plan(
    path: &Path,
    dim: usize,
    integrator: &str,
    precision: Precision,
    opts: &crate::scene::Options,
    domains: Option<u32>,
) -> i32 {
    let real = real_bytes(precision);
    let Some(integrator) = crate::schedule::IntegratorKind::parse(integrator) else {
        eprintln!("error: unknown integrator `{integrator}` ({})", crate::schedule::IntegratorKind::NAMES);
        return 2;
    };
    if !(1..=3).contains(&dim) {
        eprintln!("error: --dim is 1, 2 or 3");
        return 2;
    }
    if path.extension().is_some_and(|e| e == "toml") {
        return match crate::runner::prepare(path, opts) {
            Ok((scene, plan)) => {
                eprint!("{}", scene.warnings.concat());
                say(&plan.describe(real));
                say(&crate::runner::material_values(&scene, &plan));
                if let Some(parts) = domains {
                    match crate::runner::domains_report(&scene, &plan, real, parts as usize) {
                        Ok(text) => say(&text),
                        Err(e) => {
                            eprint!("{e}");
                            return 1;
                        }
                    }
                }
                match crate::runner::cost_estimate(&scene, &plan, precision) {
                    Ok(text) => {
                        say(&format!("cost:\n{}", text.lines().map(|l| format!("  {l}\n")).collect::<String>()));
                        0
                    }
                    Err(e) => {
                        eprint!("{e}");
                        1
                    }
                }
            }
            Err(e) => {
                eprint!("{e}");
                1
            }
        };
    }
    let mut sources = Sources::new();
    let Some(model) = load_model(path, &mut sources) else { return 1 };
    let scene = crate::schedule::SceneSpec {
        dim,
        groups: model.all_groups(),
        outputs: vec![],
        integrator,
        gravity: None,
        loads: vec![],
        constraints: vec![],
        planes: vec![],
        search: Default::default(),
        damping: None,
        settled: vec![],
        initialised: vec![],
        axisymmetric: false,
    };
    match crate::schedule::Plan::build(&model, &scene, None) {
        Ok(plan) => {
            say(&plan.describe(real));
            0
        }
        Err(e) => {
            eprint!("{}", render(&sources, &[*e.0]));
            1
        }
    }
}

/// The plan of a model file with a default scene (every group present), or of a case.
pub fn plan_of(path: &Path, dim: usize) -> Result<crate::schedule::Plan, String> {
    if path.extension().is_some_and(|e| e == "toml") {
        return crate::runner::prepare(path, &crate::scene::Options::default())
            .map(|(_, p)| p)
            .map_err(|e| e.to_string());
    }
    let mut sources = Sources::new();
    let checked = check_model(&mut sources, path);
    if checked.has_errors() {
        return Err(render(&sources, &checked.diags));
    }
    let scene = crate::schedule::SceneSpec {
        dim,
        groups: checked.model.all_groups(),
        outputs: vec![],
        integrator: crate::schedule::IntegratorKind::PredictorCorrector,
        gravity: None,
        loads: vec![],
        constraints: vec![],
        planes: vec![],
        search: Default::default(),
        damping: None,
        settled: vec![],
        initialised: vec![],
        axisymmetric: false,
    };
    crate::schedule::Plan::build(&checked.model, &scene, None).map_err(|e| render(&sources, &[*e.0]))
}

/// Every (directory under shaders_gen, model or case path) that `emit --all` writes.
pub fn shader_sources(root: &Path) -> Vec<(PathBuf, PathBuf)> {
    let mut out = vec![];
    for m in sph_files(&[root.join("stdlib/models")]) {
        let stem = m.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        out.push((PathBuf::from("models").join(stem), m));
    }
    // A study runs its case's shaders; it has none of its own.
    let is_study = |c: &Path| std::fs::read_to_string(c).is_ok_and(|t| crate::scene::study::is_study(&t));
    for c in bundled_cases().into_iter().filter(|c| !is_study(c)) {
        let stem = c.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        out.push((PathBuf::from("cases").join(stem), c));
    }
    out
}

/// Writes the WGSL of one model or case into `dir`: its generated kernels are replaced, nothing
/// else is touched, and a directory holding anything but generated kernels is refused unless
/// `force` (see [`crate::output_dir`]).
pub fn write_wgsl(path: &Path, dim: usize, dir: &Path, force: bool) -> Result<usize, String> {
    let plan = plan_of(path, dim)?;
    let files = crate::backend::wgsl::files(&plan)?;
    crate::output_dir::write_wgsl_dir(dir, &files, force).map_err(|e| format!("error: {e}\n"))
}

fn run_emit(path: Option<&Path>, target: &str, out: Option<&Path>, dim: usize, all: bool, force: bool) -> i32 {
    if target != "wgsl" {
        eprintln!("error: the only target is wgsl");
        return 2;
    }
    if all {
        let root = Path::new(".");
        let gen = out.map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("shaders_gen"));
        for (sub, src) in shader_sources(root) {
            match write_wgsl(&src, 3, &gen.join(&sub), force) {
                Ok(n) => eprintln!("{}: {n} kernels", gen.join(&sub).display()),
                Err(e) => {
                    // Rendered diagnostics, or a refusal that names the directory.
                    eprint!("{e}");
                    return 1;
                }
            }
        }
        return 0;
    }
    let Some(path) = path else {
        eprintln!("error: name a model or a case, or use --all");
        return 2;
    };
    match out {
        Some(dir) => match write_wgsl(path, dim, dir, force) {
            Ok(n) => {
                eprintln!("{n} kernels in {}", dir.display());
                0
            }
            Err(e) => {
                eprint!("{e}");
                1
            }
        },
        None => match plan_of(path, dim).and_then(|p| crate::backend::wgsl::files(&p)) {
            Ok(files) => {
                for (name, text) in files {
                    say(&format!("// ===== {name}\n{text}\n"));
                }
                0
            }
            Err(e) => {
                eprint!("{e}");
                1
            }
        },
    }
}

/// Writes to standard output. A reader that went away (`pairsum cases | head`) ends the command
/// quietly, as other command-line tools do, where `print!` would panic.
fn say(text: &str) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            std::process::exit(0);
        }
        eprintln!("error: cannot write to standard output: {e}");
        std::process::exit(1);
    }
}
