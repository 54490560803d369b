//! Running a case end to end: scene → plan → backend → engine, with VTK output, probes, a
//! progress bar, checkpoints, and `report.json` / `report.md` at the end.

use crate::backend::cpu::CpuBackend;
use crate::backend::domains::Domain;
use crate::backend::transport::Transport;
use crate::backend::{Backend, BackendError};
use crate::diag::{Diagnostic, Sources};
use crate::engine::{checkpoint, setup, Engine, RunError};
use crate::particles::Real;
use crate::report::{self, Curve, GroupBytes, History, PointField, ResultRow, RunReport};
use crate::scene::measure::Reader;
use crate::scene::spec::{BodyInfo, ProfileSpec};
use crate::scene::{self, measure, Scene};
use crate::schedule::Plan;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Where a run computes: `--backend cpu|gpu|auto`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendChoice {
    Cpu,
    Gpu,
    Auto,
}

/// The CPU backend's reals: `--precision f32|f64`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Precision {
    F32,
    F64,
}

#[derive(Clone, Debug)]
pub struct RunOptions {
    pub backend: BackendChoice,
    pub precision: Precision,
    pub scene: scene::Options,
    pub out: PathBuf,
    pub progress: bool,
    /// Write a checkpoint every this many steps.
    pub checkpoint_every: Option<u64>,
    /// Resume from this checkpoint.
    pub restart: Option<PathBuf>,
    pub max_steps: Option<u64>,
    /// Write VTK files (off for tests that only need the report).
    pub vtk: bool,
    /// Write into an output directory that holds files pairsum did not write.
    pub force: bool,
    /// Measure where the run's time goes and write it to `timing.txt` (on the GPU, each
    /// kernel's device time where the adapter has timestamp queries).
    pub timing: bool,
    /// Split the run into this many domains, each a thread of this process as a rank
    /// (`backend::domains`; on the CPU backend). Under `mpirun` the ranks are MPI's instead.
    pub domains: Option<usize>,
    /// Run this many of a study's runs (or a case's convergence levels) side by side, each on
    /// its share of the threads (`run_side_by_side`); 1: one after another.
    pub jobs: usize,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            backend: BackendChoice::Auto,
            precision: Precision::F64,
            scene: scene::Options::default(),
            out: PathBuf::from("out"),
            progress: false,
            checkpoint_every: None,
            restart: None,
            max_steps: None,
            vtk: true,
            force: false,
            timing: false,
            domains: None,
            jobs: 1,
        }
    }
}

/// Why a run did not complete.
#[derive(Debug)]
pub enum RunFailure {
    /// The case or its model has errors (rendered with their sources).
    Input(String),
    /// The run itself failed (unstable, backend error); the report up to there was written.
    Run(String),
}

impl RunFailure {
    /// An error in what was asked for, which every further run would meet too: it stops a
    /// convergence study, where a run that did not complete only leaves its level out.
    fn is_input(&self) -> bool {
        matches!(self, RunFailure::Input(_))
    }

    /// The failure as a study's run `name` reports it: a run that did not complete is named (an
    /// input error is the study's, whichever run met it).
    fn of_run(self, name: &str) -> RunFailure {
        match self {
            RunFailure::Run(s) => RunFailure::Run(format!("run `{name}`: {s}")),
            input => input,
        }
    }
}

impl std::fmt::Display for RunFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RunFailure::Input(s) | RunFailure::Run(s) => f.write_str(s),
        }
    }
}

pub struct RunOutcome {
    pub report: RunReport,
    pub out: PathBuf,
    /// Probe histories, by probe name.
    pub histories: Vec<(String, Vec<(f64, f64)>)>,
}

fn input_error(sources: &Sources, diags: &[Diagnostic]) -> RunFailure {
    RunFailure::Input(crate::diag::render(sources, diags))
}

/// Loads a case and its plan, without running it.
pub fn prepare(path: &Path, opts: &scene::Options) -> Result<(Scene, Plan), RunFailure> {
    let mut sources = Sources::new();
    let scene = scene::load(path, &mut sources, opts).map_err(|d| input_error(&sources, &d))?;
    let plan = Plan::build(&scene.model, &scene.spec, scene.kernel.as_deref()).map_err(|e| {
        let d = (*e.0).note(format!("while planning the case `{}`", path.display()));
        input_error(&sources, &[d])
    })?;
    let resolved = setup::resolved_materials(&plan, &scene.materials);
    if let Some((mi, e)) = setup::unbound_parameter(&plan, &scene.particles, &scene.materials, &resolved) {
        let mut d = Diagnostic::error(e.code, e.message);
        if let Some(span) = scene.material_spans.get(mi).copied().flatten() {
            d = d.at(span, "in this material");
        }
        return Err(input_error(&sources, &[d]));
    }
    Ok((scene, plan))
}

/// What a run of the case will cost on this machine (`pairsum plan CASE`): the particles of each
/// body, the first time step and the steps it implies, and the wall time those take at the cost
/// per step measured here, on the CPU backend, over a few steps (about a second of them).
pub fn cost_estimate(scene: &Scene, plan: &Plan, precision: Precision) -> Result<String, RunFailure> {
    match precision {
        Precision::F32 => estimate_on::<f32>(scene, plan),
        Precision::F64 => estimate_on::<f64>(scene, plan),
    }
}

/// Each material's value of every parameter it may bind on its bodies' groups (`pairsum plan
/// CASE`), in SI units, `(default)` where the material leaves it to the model.
pub fn material_values(scene: &Scene, plan: &Plan) -> String {
    let model = &plan.model;
    let read = plan.params_a_material_binds();
    let by_scene = |p: &crate::ir::ParamId| plan.scene_params.iter().any(|sp| sp.param == *p);
    let mut out = String::new();
    for (k, material) in scene.materials.iter().enumerate() {
        let groups = setup::material_groups(&scene.particles, k);
        if groups == crate::ir::GroupSet::default() {
            continue;
        }
        let values = setup::resolve_material(model, plan.dim, material);
        out += &format!("material {} (on {}):\n", material.name, model.group_names(groups));
        for (p, _) in read.iter().filter(|(p, on)| !by_scene(p) && on.intersect(groups) != Default::default()) {
            let param = &model.params[p.index()];
            let value = values[p.index()].as_ref().map_or("none".into(), |v| number_list(v));
            let default = if material.values.contains_key(p) { "" } else { " (default)" };
            let unit = param.ty.unit.label();
            let unit = if unit.is_empty() { unit } else { format!(" {unit}") };
            out += &format!("  {} = {value}{unit}{default}\n", param.name);
        }
    }
    out
}

/// `7850`, `6e9`, `(0, 0, -9.81)`: a parameter's value as `pairsum plan` prints it.
fn number_list(v: &[f64]) -> String {
    let one = |x: f64| if x != 0.0 && !(1e-3..1e5).contains(&x.abs()) { format!("{x:e}") } else { format!("{x}") };
    match v {
        [x] => one(*x),
        _ => format!("({})", v.iter().map(|x| one(*x)).collect::<Vec<_>>().join(", ")),
    }
}

/// The case split into `parts` domains of equal particle counts as a run splits it (the cut
/// planes of `grid::decompose::bisect_with_cuts` at the initial positions, a particle on a plane
/// on its high side): each domain's particles, the particles of the others within reach of it
/// (its halo), and the bytes its halo brings in a step (`Plan::halo_exchanges`).
pub fn domains_report(scene: &Scene, plan: &Plan, real: usize, parts: usize) -> Result<String, RunFailure> {
    use crate::grid::decompose::{bisect_with_cuts, halo_sizes};
    let store =
        setup::build_store::<f64>(plan, &scene.particles, &scene.materials).map_err(|e| setup_failure(scene, e))?;
    let mut backend = CpuBackend::new(plan.clone(), store, scene.mirrors.clone()).map_err(|e| RunFailure::Run(e.0))?;
    backend.initialise().map_err(|e| RunFailure::Run(e.0))?;
    let field = |name: &str| -> Result<Vec<f64>, RunFailure> {
        let f = plan.model.field_id(name).ok_or_else(|| RunFailure::Run(format!("the model has no `{name}`")))?;
        let read = crate::backend::Backend::read(&backend, f).map_err(|e| RunFailure::Run(e.0))?;
        read.map(|(_, v)| v).ok_or_else(|| RunFailure::Run(format!("`{name}` is not stored")))
    };
    let (x, h) = (field("x")?, field("h")?);
    let dim = plan.dim;
    let invalid = |e: crate::compare::CompareError| RunFailure::Run(format!("the initial particles: {e}"));
    let (_, cuts) = bisect_with_cuts(&x, dim, &vec![1.0; h.len()], parts).map_err(invalid)?;
    let domain: Vec<u32> = x.chunks(dim).map(|p| cuts.locate(p)).collect();
    let halo = halo_sizes(&x, dim, &h, backend.support, &domain, parts).map_err(invalid)?;
    let per_particle = plan.halo_bytes_per_step(real);
    let mut out = format!(
        "domains: {parts}, cut as a run cuts them, by recursive coordinate bisection at equal particle counts \
         (at the initial positions; a particle on a cut goes to its high side; halos of {per_particle} B a \
         particle a step)\n"
    );
    for (d, halo) in halo.iter().enumerate() {
        let own = domain.iter().filter(|k| **k as usize == d).count();
        let share = 100.0 * *halo as f64 / own.max(1) as f64;
        let bytes = (*halo * per_particle) as f64;
        out.push_str(&format!(
            "  domain {}: {own} particles, {halo} in its halo ({share:.1} %), {:.1} kB of halo a step\n",
            d + 1,
            bytes / 1e3
        ));
    }
    Ok(out)
}

fn estimate_on<T: Real>(scene: &Scene, plan: &Plan) -> Result<String, RunFailure> {
    let mut out = String::new();
    let bodies: Vec<String> = scene.bodies.iter().map(|b| format!("{} {}", b.name, b.particles.len())).collect();
    out.push_str(&format!("particles: {} ({} in all)\n", bodies.join(", "), scene.particles.len()));
    out.push_str(&crate::backend::gpu::runtime::step_traffic(plan, scene.particles.len()).map_err(RunFailure::Run)?);
    let store =
        setup::build_store::<T>(plan, &scene.particles, &scene.materials).map_err(|e| setup_failure(scene, e))?;
    let backend = CpuBackend::new(plan.clone(), store, scene.mirrors.clone()).map_err(|e| RunFailure::Run(e.0))?;
    let mut engine = Engine::new(backend, scene.config.clone());
    engine.initialise().map_err(|e| RunFailure::Run(e.to_string()))?;
    let (dt0, end) = (engine.dt, scene.config.end_time);
    let steps = (end / dt0).ceil();
    out.push_str(&format!(
        "first time step: {dt0:.4e} s; to the end time {end:.4e} s that is about {steps:.0} steps\n"
    ));
    // The first step pays for what is built once (lists, caches); time the ones after it.
    let first = Instant::now();
    engine.step().map_err(|e| RunFailure::Run(e.to_string()))?;
    let first = first.elapsed().as_secs_f64();
    let (started, t_start) = (Instant::now(), engine.time);
    let mut timed = 0u32;
    let ended = |e: &Engine<CpuBackend<T>>| e.time >= end * (1.0 - 1e-12);
    while !ended(&engine) && (timed < 3 || started.elapsed().as_secs_f64() < 1.0) {
        engine.step().map_err(|e| RunFailure::Run(e.to_string()))?;
        timed += 1;
    }
    let elapsed = started.elapsed().as_secs_f64();
    let on = engine.backend.describe();
    if ended(&engine) {
        out.push_str(&format!(
            "measured on {on}: the whole run, {} steps in {} (the GPU backend costs differently)\n",
            engine.step,
            human_seconds(first + elapsed)
        ));
        return Ok(out);
    }
    let per_step = elapsed / timed as f64;
    // The steps left at the mean time step of those timed, which follows the run better than
    // the first (a shock, an impact shorten it).
    let mean_dt = (engine.time - t_start) / timed as f64;
    let total = engine.step as f64 + (end - engine.time) / mean_dt;
    out.push_str(&format!(
        "measured on {on}: {per_step:.3e} s per step ({:.1} ns per particle-step), mean time step {mean_dt:.4e} s, \
         over {timed} steps; the run: about {total:.0} steps, {} (the GPU backend costs differently)\n",
        per_step / scene.particles.len().max(1) as f64 * 1e9,
        human_seconds(per_step * total)
    ));
    Ok(out)
}

/// A duration for a person: seconds, minutes or hours.
fn human_seconds(s: f64) -> String {
    if s < 120.0 {
        format!("{s:.1} s")
    } else if s < 7200.0 {
        format!("{:.1} min", s / 60.0)
    } else {
        format!("{:.1} h", s / 3600.0)
    }
}

/// Runs a case on the chosen backend and writes its outputs and report into `opts.out`.
pub fn run_case(path: &Path, opts: &RunOptions) -> Result<RunOutcome, RunFailure> {
    let (scene, plan) = prepare(path, &opts.scene)?;
    eprint!("{}", scene.warnings.concat());
    let split_on_gpus = split_ranks(opts) > 1 && opts.backend == BackendChoice::Gpu;
    if let Some(e) = crate::backend::gpu::share::DevicePasses::refuses(&plan).filter(|_| split_on_gpus) {
        return Err(RunFailure::Input(format!("error: {}\n", e.0)));
    }
    let ours = leads() && claim_out(opts)?;
    if ours && opts.vtk && opts.restart.is_none() {
        // A fresh series: an earlier run's frames past this one's last would be left beside it.
        crate::output_dir::remove_earlier_series(&opts.out.join("vtk"), &scene.name)
            .map_err(|e| RunFailure::Run(format!("removing the earlier run's VTK frames: {e}")))?;
    }
    if split_on_gpus {
        // Each rank's passes on its own GPU, in f32; `--backend auto` splits on the CPU.
        note_gpu_precision(opts);
        return run_cpu::<f32>(scene, plan, opts);
    }
    if split_ranks(opts) > 1 {
        return run_cpu_precision(scene, plan, opts);
    }
    match opts.backend {
        BackendChoice::Cpu => run_cpu_precision(scene, plan, opts),
        BackendChoice::Gpu => match crate::backend::gpu::device::Gpu::with_timing(opts.timing) {
            Ok(gpu) => run_gpu(gpu, scene, plan, opts),
            Err(e) => Err(RunFailure::Run(e.to_string())),
        },
        BackendChoice::Auto => match crate::backend::gpu::device::Gpu::with_timing(opts.timing) {
            Ok(gpu) if gpu.is_software() && crate::config::env().adapter.is_none() => {
                eprintln!(
                    "note: running on the CPU backend: the only GPU adapter, {}, is a software one (`--backend gpu` uses it)",
                    gpu.describe()
                );
                run_cpu_precision(scene, plan, opts)
            }
            Ok(gpu) => run_gpu(gpu, scene, plan, opts),
            Err(e) => {
                eprintln!("note: running on the CPU backend: {}", e.to_string().lines().next().unwrap_or_default());
                run_cpu_precision(scene, plan, opts)
            }
        },
    }
}

/// Claims `opts.out` for this run's outputs (see [`crate::output_dir`]); returns whether it was
/// pairsum's already.
fn claim_out(opts: &RunOptions) -> Result<bool, RunFailure> {
    crate::output_dir::claim_run_dir(&opts.out, opts.force).map_err(|e| RunFailure::Input(format!("error: {e}\n")))
}

fn run_cpu_precision(scene: Scene, plan: Plan, opts: &RunOptions) -> Result<RunOutcome, RunFailure> {
    match opts.precision {
        Precision::F64 => run_cpu::<f64>(scene, plan, opts),
        Precision::F32 => run_cpu::<f32>(scene, plan, opts),
    }
}

/// Where `--backend gpu` was asked for in f64: the GPU computes in f32.
fn note_gpu_precision(opts: &RunOptions) {
    if opts.precision == Precision::F64 && opts.backend == BackendChoice::Gpu {
        eprintln!("note: the GPU backend computes in f32");
    }
}

/// The GPU computes in f32 whatever precision was asked for (the report says so).
fn run_gpu(
    gpu: crate::backend::gpu::device::Gpu,
    scene: Scene,
    plan: Plan,
    opts: &RunOptions,
) -> Result<RunOutcome, RunFailure> {
    note_gpu_precision(opts);
    let store =
        setup::build_store::<f32>(&plan, &scene.particles, &scene.materials).map_err(|e| setup_failure(&scene, e))?;
    let backend =
        crate::backend::gpu::GpuBackend::new(gpu, plan, store, &scene.mirrors).map_err(|e| RunFailure::Run(e.0))?;
    drive(scene, backend, opts, "f32", true)
}

/// A scene that cannot be set up, as an error of its case file.
fn setup_failure(scene: &Scene, e: setup::SetupError) -> RunFailure {
    RunFailure::Input(format!("{e}\n  = in the case file {}\n", scene.path.display()))
}

/// Whether this process writes a run's files: a single process, or rank 0 under `mpirun` (the
/// others write only their pieces of the VTK snapshots, [`Recorder::write_vtk`]).
fn leads() -> bool {
    crate::backend::transport::launched_rank().ok().flatten().unwrap_or(0) == 0
}

/// The ranks a run is split into: MPI's under `mpirun`, else `--domains`, else 1.
fn split_ranks(opts: &RunOptions) -> usize {
    crate::backend::transport::launched_ranks().unwrap_or(opts.domains.unwrap_or(1))
}

fn run_cpu<T: Real>(scene: Scene, plan: Plan, opts: &RunOptions) -> Result<RunOutcome, RunFailure> {
    if let Some(world) = crate::backend::transport::world().map_err(|e| RunFailure::Run(e.0))? {
        let backend = domain::<T>(&scene, plan, world, opts)?;
        return drive(scene, backend, opts, T::NAME, true);
    }
    if let Some(n) = opts.domains.filter(|n| *n > 1) {
        return run_threads::<T>(scene, plan, opts, n);
    }
    let store =
        setup::build_store::<T>(&plan, &scene.particles, &scene.materials).map_err(|e| setup_failure(&scene, e))?;
    let backend = CpuBackend::new(plan, store, scene.mirrors.clone()).map_err(|e| RunFailure::Run(e.0))?;
    drive(scene, backend, opts, T::NAME, true)
}

/// This rank's domain of a run split over `transport`: every rank cuts the scene's particles
/// alike and builds the store of its own share only, so that no rank ever holds every particle's
/// state. With `--backend gpu`, each rank runs its passes on a GPU of its machine
/// ([`Gpu::for_rank`](crate::backend::gpu::device::Gpu::for_rank)).
fn domain<T: Real>(
    scene: &Scene,
    plan: Plan,
    transport: Box<dyn Transport>,
    opts: &RunOptions,
) -> Result<Domain<T>, RunFailure> {
    let input = &scene.particles;
    let (rank, size) = (transport.rank(), transport.size());
    let (cuts, own) =
        Domain::<T>::share(&plan, &input.x, rank, size).map_err(|e| RunFailure::Input(format!("error: {e}\n")))?;
    let store =
        setup::build_store_of::<T>(&plan, input, &scene.materials, &own).map_err(|e| setup_failure(scene, e))?;
    let mut groups = input.group.clone();
    groups.sort_unstable();
    let mut domain = Domain::of_own(plan, store, groups, cuts, scene.mirrors.clone(), transport)
        .map_err(|e| RunFailure::Run(e.0))?;
    if opts.backend == BackendChoice::Gpu {
        let local = crate::backend::transport::local_rank().unwrap_or(rank);
        let gpu = crate::backend::gpu::device::Gpu::for_rank(false, local)
            .map_err(|e| RunFailure::Run(format!("rank {}: {e}", rank + 1)))?;
        domain.on_gpu(gpu).map_err(|e| RunFailure::Input(format!("error: {}\n", e.0)))?;
    }
    Ok(domain)
}

/// A run split into `ranks` domains, each run by a thread of this process as a rank. Rank 0
/// writes the outputs; the others run the same loop (every read of a field is collective) and
/// write only their pieces of the VTK snapshots. A rank that fails alone (a setup error in its
/// share) leaves the others waiting on a transport it dropped, which stops them: the run reports
/// the first error a rank returned.
fn run_threads<T: Real>(scene: Scene, plan: Plan, opts: &RunOptions, ranks: usize) -> Result<RunOutcome, RunFailure> {
    use crate::backend::transport::Threads;
    let path = scene.path.clone();
    let mut first = Some((scene, plan.clone()));
    let results: Vec<_> = std::thread::scope(|s| {
        let handles: Vec<_> = Threads::ranks(ranks)
            .into_iter()
            .map(|t| {
                let (mine, plan, path) = (first.take(), plan.clone(), path.clone());
                s.spawn(move || -> Result<Option<RunOutcome>, RunFailure> {
                    let leads = mine.is_some();
                    let (scene, plan) = match mine {
                        Some(prepared) => prepared,
                        None => (prepare(&path, &opts.scene)?.0, plan),
                    };
                    let backend = domain::<T>(&scene, plan, Box::new(t), opts)?;
                    let theirs = if leads {
                        opts.clone()
                    } else {
                        RunOptions { progress: false, timing: false, ..opts.clone() }
                    };
                    let outcome = drive(scene, backend, &theirs, T::NAME, false)?;
                    Ok(leads.then_some(outcome))
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join()).collect()
    });
    let mut outcome = None;
    for r in results {
        match r {
            Ok(Ok(Some(o))) => outcome = Some(o),
            Ok(Ok(None)) => {}
            Ok(Err(e)) => return Err(e),
            Err(_) => {}
        }
    }
    outcome.ok_or_else(|| RunFailure::Run("a rank of the split run panicked".into()))
}

/// Everything a run records while it goes.
struct Recorder<'a> {
    scene: &'a Scene,
    opts: &'a RunOptions,
    series: Option<report::Series>,
    next_output: f64,
    histories: Vec<measure::History>,
    /// Per profile, the index of its next time.
    next_profile: Vec<usize>,
    progress: Option<indicatif::ProgressBar>,
    started: Instant,
    /// Whether this rank writes the run's files: a run in one piece or rank 0 of a split run. The
    /// other ranks take part in every collective read and write only their pieces of the VTK
    /// snapshots.
    leads: bool,
}

/// What a run has recorded so far, kept in its checkpoints so that a restarted run reports the
/// same histories and results as one that was never stopped. Every f64 is kept as its bits: JSON
/// has no NaN, and the restart must be exact.
#[derive(serde::Serialize, serde::Deserialize)]
struct RecordSoFar {
    next_output: u64,
    vtk: Vec<(u64, String)>,
    histories: Vec<HistoryBits>,
    /// Each probe's last value sampled, which an integrating probe integrates on from (absent
    /// from the checkpoints of runs before `integrate` was a key: none then integrates).
    #[serde(default)]
    last_values: Vec<Option<u64>>,
}

/// A probe's points (t, value) and the value a relative probe measures from, as bits.
type HistoryBits = (Vec<(u64, u64)>, Option<u64>);

impl Recorder<'_> {
    fn record_so_far(&self) -> Vec<u8> {
        let record = RecordSoFar {
            next_output: self.next_output.to_bits(),
            vtk: self.series.iter().flat_map(|s| s.entries()).map(|(t, f)| (t.to_bits(), f.clone())).collect(),
            histories: self
                .histories
                .iter()
                .map(|h| {
                    let points = h.points.iter().map(|(t, v)| (t.to_bits(), v.to_bits())).collect();
                    (points, h.initial().map(f64::to_bits))
                })
                .collect(),
            last_values: self.histories.iter().map(|h| h.last().map(f64::to_bits)).collect(),
        };
        serde_json::to_vec(&record).expect("plain data serialises")
    }

    /// Takes up what an earlier run had recorded up to its checkpoint.
    fn resume(&mut self, bytes: &[u8]) -> Result<(), String> {
        let record: RecordSoFar =
            serde_json::from_slice(bytes).map_err(|e| format!("the checkpoint's record of the run: {e}"))?;
        if record.histories.len() != self.histories.len() {
            return Err(format!(
                "the checkpoint records {} probes where the case has {}",
                record.histories.len(),
                self.histories.len()
            ));
        }
        let f = f64::from_bits;
        self.next_output = f(record.next_output);
        if let Some(series) = &mut self.series {
            series.continue_after(record.vtk.into_iter().map(|(t, name)| (f(t), name)).collect());
        }
        let last_values = record.last_values.into_iter().chain(std::iter::repeat(None));
        for (h, ((points, initial), last)) in
            self.histories.iter_mut().zip(record.histories.into_iter().zip(last_values))
        {
            let points = points.into_iter().map(|(t, v)| (f(t), f(v))).collect();
            *h = measure::History::resumed(points, initial.map(f), last.map(f));
        }
        Ok(())
    }

    fn observe<B: Backend>(&mut self, e: &Engine<B>) -> Result<(), String> {
        let now = measure::Moment::new(&e.backend);
        for (p, h) in self.scene.probes.iter().zip(&mut self.histories) {
            if e.step.is_multiple_of(p.every) {
                let v = measure::evaluate(p, self.scene, &now).map_err(|e| format!("probe `{}`: {e}", p.name))?;
                h.record(p, e.time, v);
            }
        }
        for (k, p) in self.scene.profiles.iter().enumerate() {
            while p.times.get(self.next_profile[k]).is_some_and(|t| reached(e.time, *t)) {
                let columns = profile_columns(self.scene, p, &now);
                if self.leads {
                    columns
                        .and_then(|c| write_profile(p, self.next_profile[k], &c, &self.opts.out))
                        .map_err(|err| format!("profile `{}`: {err}", p.name))?;
                }
                self.next_profile[k] += 1;
            }
        }
        if let Some(interval) = self.scene.output_interval {
            if e.time >= self.next_output - 1e-12 * interval {
                self.write_vtk(&e.backend, &now, e.time)?;
                self.next_output += interval;
            }
        }
        if self.opts.checkpoint_every.is_some_and(|n| n > 0 && e.step.is_multiple_of(n)) {
            self.checkpoint(e)?;
        }
        if let Some(pb) = &self.progress {
            let end = e.config.end_time;
            pb.set_position((1000.0 * e.time / end).min(1000.0) as u64);
            let rate = e.step as f64 / self.started.elapsed().as_secs_f64().max(1e-9);
            pb.set_message(format!("t = {:.4e} s, step {}, {:.1} steps/s, dt = {:.2e} s", e.time, e.step, rate, e.dt));
        }
        Ok(())
    }

    /// Writes `histories.csv` up to this step, then `checkpoint.bin`: a run killed at any time
    /// leaves histories at least as far as its last checkpoint.
    fn checkpoint<B: Backend>(&self, e: &Engine<B>) -> Result<(), String> {
        if !self.leads {
            // The checkpoint holds the whole state, gathered from every rank.
            return e.backend.snapshot().map(|_| ()).map_err(|err| err.0);
        }
        report::write_histories_csv(&self.opts.out, &history_plots(self.scene, &self.histories))
            .map_err(|err| format!("writing histories.csv with a checkpoint: {err}"))?;
        checkpoint::write(e, &self.record_so_far(), &self.opts.out.join("checkpoint.bin"))
            .map_err(|err| format!("writing a checkpoint: {err} (the last one written, if any, is kept)"))
    }

    /// A snapshot of the particles (`now`: the backend read at this moment). A run split into
    /// domains writes it as a partitioned data set: each rank its own particles as a piece,
    /// rank 0 the `.pvtu` that joins them, with nothing gathered.
    fn write_vtk<B: Backend>(&mut self, backend: &B, now: &dyn Reader, time: f64) -> Result<(), String> {
        let Some(series) = &mut self.series else { return Ok(()) };
        let written = match backend.rank() {
            Some(rank) => vtk_data(self.scene, &measure::Own(backend))
                .map_err(|e| e.0)
                .and_then(|(x, fields)| series.add_piece(time, rank, &x, &fields).map_err(|e| e.to_string())),
            None => vtk_data(self.scene, now)
                .map_err(|e| e.0)
                .and_then(|(x, fields)| series.add(time, &x, &fields).map_err(|e| e.to_string())),
        };
        written.map(|_| ()).map_err(|e| format!("writing VTK: {e}"))
    }
}

/// Whether the clock at `time` has reached `at` (to a relative 1e-12, the engine's end test).
fn reached(time: f64, at: f64) -> bool {
    time >= at * (1.0 - 1e-12)
}

/// A profile's columns now: the selected particles' coordinates, id, body and fields, sorted
/// along the profile's axis (then by id). Each rank of a split run selects among its own
/// particles, and the selected rows of every rank are gathered.
fn profile_columns(scene: &Scene, p: &ProfileSpec, b: &dyn Reader) -> Result<Vec<(String, Vec<f64>)>, String> {
    let (dim, model) = (b.plan().dim, &b.plan().model);
    let x = measure::own_positions(b).map_err(|e| e.0)?.unwrap_or_default();
    let ids = b.ids_own().map_err(|e| e.0)?;
    let inside = match &p.region {
        Some(r) => crate::scene::geometry::inside(r, dim, &x).map_err(|e| e.to_string())?,
        None => vec![true; x.len()],
    };
    let body = |k: usize| scene.particles.body[ids[k] as usize] as usize;
    let rows: Vec<usize> = (0..x.len()).filter(|k| inside[*k] && p.body.is_none_or(|b| body(*k) == b)).collect();
    let mut names: Vec<String> = (0..dim).map(|a| format!("{} [m]", crate::ir::AXIS_NAMES[a])).collect();
    names.extend(["id".to_string(), "body".to_string()]);
    // Each field's component: the column and which component.
    let mut fields = vec![];
    for f in &p.fields {
        let field = model.field(*f);
        let Some(column) = b.read_own(*f).map_err(|e| e.0)? else { continue };
        for (c, suffix) in crate::ir::component_names(field.ty.shape, dim).iter().enumerate() {
            let name = if suffix.is_empty() { field.name.clone() } else { format!("{}.{suffix}", field.name) };
            let name = if field.ty.unit.is_one() { name } else { format!("{name} [{}]", field.ty.unit.label()) };
            names.push(name);
            fields.push((column.clone(), c));
        }
    }
    // Row by row: this rank's rows, then every rank's.
    let width = names.len();
    let row = |k: usize| {
        let at = [ids[k] as f64, body(k) as f64];
        let values = fields.iter().map(move |(column, c)| column.1[k * column.0 + c]);
        x[k][..dim].iter().copied().chain(at).chain(values)
    };
    let mine: Vec<f64> = rows.iter().flat_map(|k| row(*k)).collect();
    let all = b.all_gather(mine).concat();
    let mut table: Vec<&[f64]> = all.chunks(width).collect();
    table.sort_by(|a, c| a[p.along].total_cmp(&c[p.along]).then(a[dim].total_cmp(&c[dim])));
    Ok(names.into_iter().enumerate().map(|(k, name)| (name, table.iter().map(|row| row[k]).collect())).collect())
}

/// Writes `profiles/<name>_<k>.csv`.
fn write_profile(p: &ProfileSpec, k: usize, columns: &[(String, Vec<f64>)], out: &Path) -> Result<(), String> {
    let dir = out.join("profiles");
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let path = dir.join(format!("{}_{k}.csv", p.name));
    crate::output_dir::write_atomic(&path, report::csv::profile_csv(columns).as_bytes())
        .map_err(|e| format!("{}: {e}", path.display()))
}

/// Positions and output fields of every particle, for a VTK file.
pub fn vtk_data(scene: &Scene, b: &dyn Reader) -> Result<(Vec<[f64; 3]>, Vec<PointField>), BackendError> {
    let positions = measure::positions(b)?.unwrap_or_default();
    let ids = b.ids()?;
    let mut fields = vec![
        PointField::scalar("id", ids.iter().map(|i| *i as f64).collect()),
        PointField::scalar("body", ids.iter().map(|i| scene.particles.body[*i as usize] as f64).collect()),
    ];
    let plan = b.plan();
    for f in &scene.output_fields {
        if let Some(column) = b.read(*f)? {
            let (comps, data) = (column.0, column.1.clone());
            fields.push(PointField::new(plan.model.field(*f).name.clone(), comps, data));
        }
    }
    Ok((positions, fields))
}

/// Runs the engine over `backend` and records the run. `on_pool`: run the time loop on one of
/// rayon's workers (not for ranks that are threads of one process: a rank waiting for the others
/// would hold a worker they need).
fn drive<B: Backend + Send>(
    scene: Scene,
    backend: B,
    opts: &RunOptions,
    precision: &str,
    on_pool: bool,
) -> Result<RunOutcome, RunFailure> {
    let mut config = scene.config.clone();
    config.max_steps = opts.max_steps;
    let mut engine = Engine::new(backend, config);
    let leads = engine.backend.rank().is_none_or(|(rank, _)| rank == 0);
    // Rank 0 has claimed the output folder before the others write their first piece into it.
    engine.backend.synchronise();
    engine.initialise().map_err(|e| RunFailure::Run(e.to_string()))?;
    let cannot_restart = |e: &dyn std::fmt::Display| {
        let file = opts.restart.as_deref().unwrap_or(Path::new("")).display();
        RunFailure::Run(format!("cannot restart from `{file}`: {e}"))
    };
    let record = match &opts.restart {
        Some(r) => Some(checkpoint::read(&mut engine, r).map_err(|e| cannot_restart(&e))?),
        None => None,
    };
    let series = if opts.vtk {
        Some(
            report::Series::new(opts.out.join("vtk"), scene.name.clone())
                .map_err(|e| RunFailure::Run(format!("VTK output: {e}")))?,
        )
    } else {
        None
    };
    let progress = opts.progress.then(|| {
        let pb = indicatif::ProgressBar::new(1000);
        pb.set_style(
            indicatif::ProgressStyle::with_template("{bar:40} {percent:>3}% {msg} (ETA {eta})")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        pb
    });
    let mut rec = Recorder {
        scene: &scene,
        opts,
        series,
        next_output: engine.time,
        histories: vec![measure::History::default(); scene.probes.len()],
        next_profile: vec![0; scene.profiles.len()],
        progress,
        started: Instant::now(),
        leads,
    };
    match record.filter(|r| !r.is_empty()) {
        // The checkpoint was written after its step was observed.
        Some(r) => {
            rec.resume(&r).map_err(|e| cannot_restart(&e))?;
            // Profiles up to the checkpoint's time were written by the run that wrote it.
            for (next, p) in rec.next_profile.iter_mut().zip(&scene.profiles) {
                *next = p.times.iter().filter(|t| reached(engine.time, **t)).count();
            }
        }
        None => rec.observe(&engine).map_err(RunFailure::Run)?,
    }
    let (start_step, start_time) = (engine.step, engine.time);
    let started = Instant::now();
    // The loop runs on one of rayon's workers: from there each pass's parallel loop over its
    // chunks starts without handing off to the pool and blocking on its latch, which cost half
    // the time of an 80-particle beam (1.73 s for 3.44 s over 2,000 steps, the same histories).
    let result = if on_pool {
        rayon::scope(|_| engine.run(&mut |e| rec.observe(e)))
    } else {
        engine.run(&mut |e| rec.observe(e))
    };
    let wall = started.elapsed().as_secs_f64();
    if let Some(pb) = &rec.progress {
        pb.finish_and_clear();
    }
    let mut failure = None;
    match result {
        Ok(()) => {
            if scene.output_interval.is_none()
                || rec.series.as_ref().is_some_and(|s| s.entries().last().is_none_or(|(t, _)| *t < engine.time))
            {
                let now = measure::Moment::new(&engine.backend);
                rec.write_vtk(&engine.backend, &now, engine.time).map_err(RunFailure::Run)?;
            }
            // A run that checkpoints ends with one, so that `--restart` with a later
            // `--end-time` extends it.
            if opts.checkpoint_every.is_some() {
                rec.checkpoint(&engine).map_err(RunFailure::Run)?;
            }
        }
        Err(RunError::Unstable(u)) => {
            // Keep the last good state where the user will look for it.
            let path = opts.out.join("last_good.vtu");
            let kept = engine
                .backend
                .restore(&u.last_good)
                .and_then(|()| vtk_data(&scene, &engine.backend))
                .map_err(|e| e.0)
                .and_then(|(positions, fields)| match leads {
                    true => {
                        report::write_vtu(&path, &positions, &fields).map_err(|e| format!("{}: {e}", path.display()))
                    }
                    false => Ok(()),
                });
            failure = Some(match kept {
                Ok(()) => format!("{}; written to {}", RunError::Unstable(u), path.display()),
                Err(e) => format!("{}; the last good state could not be written: {e}", RunError::Unstable(u)),
            });
        }
        Err(e) => failure = Some(e.to_string()),
    }
    let steps = engine.step - start_step;
    if opts.timing && leads {
        write_timing(&opts.out, &engine, steps, wall).map_err(RunFailure::Run)?;
    }
    let mut report = make_report(&scene, &engine, &rec.histories, wall, steps, precision, failure.as_deref());
    if opts.restart.is_some() {
        report.notes.push(format!(
            "restarted from the checkpoint at step {start_step} (t = {:e} s); steps and wall time count from there",
            start_time
        ));
    }
    let written = if leads { report::write(&opts.out, &report) } else { Ok(()) };
    match (failure, written) {
        (Some(f), Ok(())) => {
            let report = opts.out.join("report.md");
            return Err(RunFailure::Run(format!("{f}\nreport of the run up to there: {}", report.display())));
        }
        (Some(f), Err(e)) => return Err(RunFailure::Run(format!("{f}; then writing the report failed too: {e}"))),
        (None, Err(e)) => return Err(RunFailure::Run(format!("writing the report: {e}"))),
        (None, Ok(())) => {}
    }
    let histories = scene.probes.iter().zip(&rec.histories).map(|(p, h)| (p.name.clone(), h.points.clone())).collect();
    Ok(RunOutcome { report, out: opts.out.clone(), histories })
}

/// `timing.txt`: where the run's time went, on the host and on the backend; also printed.
fn write_timing<B: Backend>(out: &Path, engine: &Engine<B>, steps: u64, wall: f64) -> Result<(), String> {
    let mut text = format!(
        "{} particles, {steps} steps in {wall:.3} s on {} ({:.3} ms per step)\n",
        engine.backend.particles(),
        engine.backend.describe(),
        wall * 1e3 / steps.max(1) as f64
    );
    text += &engine.phases.describe(steps);
    if let Some(t) = engine.backend.timing(steps) {
        text += &t;
    }
    eprint!("{text}");
    let path = out.join("timing.txt");
    crate::output_dir::write_atomic(&path, text.as_bytes()).map_err(|e| format!("{}: {e}", path.display()))
}

fn make_report<B: Backend>(
    scene: &Scene,
    engine: &Engine<B>,
    histories: &[measure::History],
    wall: f64,
    steps: u64,
    precision: &str,
    failure: Option<&str>,
) -> RunReport {
    let n = engine.backend.particles();
    let plan = engine.backend.plan();
    let real = if precision == "f32" { 4 } else { 8 };
    // A run that was stopped reports no figures: a result of its histories so far (a maximum, a
    // value at the end) would read as the case's. Its histories and plots show what happened.
    let completed = if failure.is_none() { scene.results.as_slice() } else { &[] };
    let results = completed
        .iter()
        .map(|r| {
            let v = measure::result_value(r, &histories[r.probe]);
            let mut row = ResultRow::new(r.quantity.clone(), r.unit.clone(), v, r.reference);
            if let Some(s) = &r.source {
                row = row.with_source(s.clone());
            }
            row
        })
        .collect();
    let bytes = plan
        .groups
        .iter(plan.model.groups.len())
        .map(|g| GroupBytes {
            group: plan.model.groups[g.index()].name.clone(),
            bytes: plan.bytes_per_particle(g, real),
        })
        .collect();
    let plots = history_plots(scene, histories);
    let mut notes = vec![format!("resolution `{}`: particle spacing {} m", scene.resolution, scene.dx)];
    notes.extend(scene.bodies.iter().filter_map(|b| own_spacing_note(scene, b)));
    let search = &engine.backend.plan().search;
    if search.keeps_lists() {
        notes.push(format!("neighbour search: {}", search.describe()));
        notes.extend(engine.backend.search_stats().describe(search));
    }
    if let Some(f) = failure {
        notes.push(format!("the run did not complete: {f}"));
    }
    RunReport {
        case: scene.name.clone(),
        backend: engine.backend.describe(),
        precision: precision.to_string(),
        particles: n,
        steps,
        wall_s: wall,
        particle_steps_per_s: if wall > 0.0 { n as f64 * steps as f64 / wall } else { 0.0 },
        results,
        bytes_per_particle: bytes,
        histories: plots,
        notes,
        resolution: scene.resolution.clone(),
        dx: scene.dx,
        end_time: engine.time,
        tables: vec![],
    }
}

/// A note for a body filled at one spacing of its own (`spacing_factor`, `spacing_divides`).
fn own_spacing_note(scene: &Scene, body: &BodyInfo) -> Option<String> {
    let dx = &scene.particles.dx[body.particles.clone()];
    let first = *dx.first()?;
    let uniform = dx.iter().all(|&s| s == first);
    (uniform && (first / scene.dx - 1.0).abs() > 1e-9)
        .then(|| format!("body `{}`: particle spacing {first} m", body.name))
}

/// Each probe's history as a plot (and a column of `histories.csv`), with its result's reference.
fn history_plots(scene: &Scene, histories: &[measure::History]) -> Vec<History> {
    scene
        .probes
        .iter()
        .zip(histories)
        .map(|(p, h)| History {
            name: p.name.clone(),
            x_label: "t [s]".into(),
            y_label: if p.unit.is_empty() { p.name.clone() } else { format!("{} [{}]", p.name, p.unit) },
            series: vec![Curve::new(p.name.clone(), h.points.clone())],
            reference: scene
                .results
                .iter()
                .find(|r| scene.probes[r.probe].name == p.name)
                .and_then(|r| r.reference.map(|x| (x - r.offset) / r.scale)),
            log_log: false,
        })
        .collect()
}

/// For the GPU backend's caller: a backend error as a run failure.
pub fn backend_failure(e: BackendError) -> RunFailure {
    RunFailure::Run(e.0)
}

/// Runs a study: every run of its case (the CI subset at the CI resolution), then the results
/// across runs. Each run writes into `out/<run>/`, the study's report into `out/`.
/// With `reanalyse`, nothing runs: the reports its runs wrote into `out/<run>/` in an earlier
/// run of the study are analysed again (after a change to the study's results or the analysis).
pub fn run_study(path: &Path, opts: &RunOptions, reanalyse: bool) -> Result<RunOutcome, RunFailure> {
    use crate::scene::study;
    let PreparedStudy { study: st, runs, .. } = prepare_study(path, opts)?;
    // Reanalysing writes the study's report too: the folder is claimed as a run claims it.
    if leads() {
        claim_out(opts)?;
    }
    let jobs = if reanalyse { 1 } else { opts.jobs };
    let runs: Vec<_> =
        runs.into_iter().map(|(r, o)| (r, RunOptions { progress: o.progress && jobs == 1, ..o })).collect();
    let done = run_side_by_side(
        jobs,
        &runs,
        |_| true,
        |(r, o)| {
            if reanalyse {
                earlier_outcome(&o.out)
            } else {
                eprintln!("{}: run `{}`", st.file.name, r.name);
                run_case(&st.case_path, o)
            }
        },
    );
    let mut outcomes: Vec<(study::RunSpec, RunOutcome)> = vec![];
    for ((r, _), outcome) in runs.into_iter().zip(done) {
        // A run not made follows one that failed and stopped the rest (`run_side_by_side`).
        let Some(outcome) = outcome else { break };
        let outcome = outcome.map_err(|e| e.of_run(&r.name))?;
        outcomes.push((r, outcome));
    }
    let first = &outcomes
        .first()
        .ok_or_else(|| RunFailure::Input(format!("study `{}` has no runs to make\n", st.file.name)))?
        .1
        .report;
    let (backend, precision) = (first.backend.clone(), first.precision.clone());
    let mut results = vec![];
    let mut histories = vec![];
    let (mut fit_rows, mut fit_notes) = (vec![], vec![]);
    let value_of = |run: &str, q: &str| -> Option<f64> {
        outcomes.iter().find(|(r, _)| r.name == run)?.1.report.results.iter().find(|x| x.quantity == q).map(|x| x.value)
    };
    let wall_of = |run: &str| outcomes.iter().find(|(r, _)| r.name == run).map(|(_, o)| o.report.wall_s);
    for sr in &st.file.results {
        let reference = study::reference(&sr.reference);
        let unit = sr.unit.clone().unwrap_or_default();
        let quantity = sr.quantity.get_ref();
        // `study::validate` has checked every result before the runs.
        let Some(across) = sr.across() else { continue };
        let mut standard_error = None;
        let value = match across {
            study::Across::RechtIpson { x, y, held } => {
                let points: Vec<(f64, f64)> = outcomes
                    .iter()
                    .filter_map(|(r, o)| {
                        let xv = r
                            .set
                            .get(&x)
                            .and_then(|v| crate::scene::quantity::parse(&study::text_of(v)).ok())
                            .map(|q| q.value)?;
                        let yv = o.report.results.iter().find(|q| q.quantity == y)?.value;
                        Some((xv, yv.max(0.0)))
                    })
                    .collect();
                let fit = study::fit_recht_ipson(&points, held);
                histories.push(recht_ipson_plot(quantity, &x, &y, &unit, &points, fit, reference));
                if let Some(f) = fit {
                    fit_rows.push(ResultRow::new(format!("{quantity}, fit rms"), unit.clone(), f.rms, None));
                    fit_notes.push(format!(
                        "`{quantity}`: the curve misses the runs that perforated by {:.3} {unit} rms, {:.0} % of \
                         their mean residual; where that is large the runs do not follow a Recht–Ipson curve \
                         and its limit means little",
                        f.rms,
                        100.0 * f.rms / f.mean_residual
                    ));
                }
                fit.map(|f| f.v_bl).unwrap_or(f64::NAN)
            }
            study::Across::Ratio([a, b]) => match (wall_of(&a), wall_of(&b)) {
                (Some(x), Some(y)) if y > 0.0 => x / y,
                _ => f64::NAN,
            },
            study::Across::Difference([a, b], of) => match (value_of(&a, &of), value_of(&b, &of)) {
                (Some(x), Some(y)) => (y - x) / x.abs().max(1e-300),
                _ => f64::NAN,
            },
            study::Across::Run(run, of) => value_of(&run, &of).unwrap_or(f64::NAN),
            study::Across::Mean(runs, of) => {
                let values: Vec<f64> = runs.iter().map(|r| value_of(r, &of).unwrap_or(f64::NAN)).collect();
                let (mean, se) = study::mean_and_standard_error(&values).unwrap_or((f64::NAN, f64::NAN));
                standard_error = Some(se);
                mean
            }
        };
        let mut row = ResultRow::new(quantity.clone(), unit, value, reference);
        row.standard_error = standard_error;
        if let Some(s) = &sr.source {
            row = row.with_source(s.clone());
        }
        results.push(row);
    }
    results.append(&mut fit_rows);
    for probe in &st.file.plots {
        let series: Vec<Curve> = outcomes
            .iter()
            .filter_map(|(r, o)| {
                let (_, pts) = o.histories.iter().find(|(n, _)| n == probe)?;
                Some(Curve::new(r.name.clone(), pts.clone()))
            })
            .collect();
        let unit = first.histories.iter().find(|h| h.name == *probe).map(|h| h.y_label.clone());
        histories.push(History {
            name: format!("{probe}, every run"),
            x_label: "t [s]".into(),
            y_label: unit.unwrap_or_else(|| probe.clone()),
            series,
            reference: None,
            log_log: false,
        });
    }
    for (r, o) in &outcomes {
        for row in &o.report.results {
            let mut row = row.clone();
            row.quantity = format!("{}: {}", r.name, row.quantity);
            results.push(row);
        }
    }
    let wall: f64 = outcomes.iter().map(|(_, o)| o.report.wall_s).sum();
    let steps: u64 = outcomes.iter().map(|(_, o)| o.report.steps).sum();
    let work: f64 = outcomes.iter().map(|(_, o)| o.report.particles as f64 * o.report.steps as f64).sum();
    let mut notes = vec![format!("{} runs of `{}`", outcomes.len(), st.case_path.display())];
    notes.extend(st.file.notes.iter().cloned());
    notes.extend(fit_notes);
    for (r, o) in &outcomes {
        notes.push(format!(
            "run `{}`: {} particles, {} steps, {:.1} s; report in {}/",
            r.name,
            o.report.particles,
            o.report.steps,
            o.report.wall_s,
            sanitize(&r.name)
        ));
    }
    let report = RunReport {
        case: st.file.name.clone(),
        backend,
        precision,
        particles: outcomes.iter().map(|(_, o)| o.report.particles).max().unwrap_or(0),
        steps,
        wall_s: wall,
        particle_steps_per_s: if wall > 0.0 { work / wall } else { 0.0 },
        results,
        bytes_per_particle: first.bytes_per_particle.clone(),
        histories,
        notes,
        resolution: first.resolution.clone(),
        dx: first.dx,
        end_time: first.end_time,
        tables: vec![],
    };
    if leads() {
        report::write(&opts.out, &report).map_err(|e| RunFailure::Run(format!("writing the report: {e}")))?;
    }
    Ok(RunOutcome { report, out: opts.out.clone(), histories: vec![] })
}

/// The plot of a Recht–Ipson fit: the runs' points, the fitted curve, the reference limit.
fn recht_ipson_plot(
    quantity: &str,
    x: &str,
    y: &str,
    unit: &str,
    points: &[(f64, f64)],
    fit: Option<crate::scene::study::RechtIpson>,
    reference: Option<f64>,
) -> History {
    let mut series = vec![Curve::new(format!("{y} (pairsum)"), points.to_vec())];
    if let Some(f) = fit {
        // The plotted range of the fit: the speeds that are numbers (a NaN run is left out of
        // the plot, not of the fit, which keeps it).
        let speeds = || points.iter().map(|p| p.0);
        let lo = crate::compare::least_number(f64::INFINITY, speeds());
        let hi = crate::compare::largest_number(0.0, speeds());
        let curve = (0..=100).map(|k| lo + (hi - lo) * k as f64 / 100.0).map(|v| (v, f.residual(v))).collect();
        series
            .push(Curve::new(format!("Recht–Ipson fit: a = {:.3}, p = {:.2}, v_bl = {:.1}", f.a, f.p, f.v_bl), curve));
    }
    if let Some(v_bl) = reference {
        // The reference limit is an impact speed: a vertical line.
        // The line's height: the largest residual that is a number, at least 1.
        let top = crate::compare::largest_number(1.0, points.iter().map(|p| p.1));
        series.push(Curve::new(format!("{quantity} (reference): {v_bl}"), vec![(v_bl, 0.0), (v_bl, top)]));
    }
    History {
        name: format!("{quantity} ({y})"),
        x_label: format!("{x} [{unit}]"),
        y_label: format!("{y} [{unit}]"),
        series,
        reference: None,
        log_log: false,
    }
}

/// A study, its runs with their options, the spacing its case runs at, and the distinct warnings
/// its runs' scenes raise.
struct PreparedStudy {
    study: crate::scene::study::Study,
    runs: Vec<(crate::scene::study::RunSpec, RunOptions)>,
    dx: f64,
    warnings: Vec<String>,
}

/// Loads a study and checks everything it needs before its first run: every run's case loads and
/// plans, and the results and plots name what the case reports. Returns the study and the runs to
/// make (the CI subset at the CI resolution), each with its options.
fn prepare_study(path: &Path, opts: &RunOptions) -> Result<PreparedStudy, RunFailure> {
    use crate::scene::study;
    let mut sources = Sources::new();
    let st = study::load(path, &mut sources).map_err(|d| input_error(&sources, &d))?;
    // `ci@2mm` (the CI settings at another spacing) makes the CI runs too.
    let ci = opts.scene.resolution.as_deref().is_none_or(|r| scene::split_resolution(r).0 == "ci");
    let mut runs = vec![];
    for r in st.file.runs.iter().filter(|r| !ci || st.file.ci_runs.as_ref().is_none_or(|c| c.contains(&r.name))) {
        let mut o = opts.clone();
        // `--set` applies to every run; what a run sets itself wins.
        o.scene.set.extend(r.set.iter().map(|(k, v)| (k.clone(), study::text_of(v))));
        o.out = opts.out.join(sanitize(&r.name));
        runs.push((r.clone(), o));
    }
    let mut case = None;
    let mut warnings: Vec<String> = vec![];
    for (r, o) in &runs {
        let (scene, _) = prepare(&st.case_path, &o.scene)
            .map_err(|e| RunFailure::Input(format!("study `{}`, run `{}`:\n{e}", st.file.name, r.name)))?;
        for w in &scene.warnings {
            if !warnings.contains(w) {
                warnings.push(w.clone());
            }
        }
        case.get_or_insert(scene);
    }
    let case = case.ok_or_else(|| RunFailure::Input(format!("study `{}` has no runs to make\n", st.file.name)))?;
    let case_results: Vec<String> = case.results.iter().map(|r| r.quantity.clone()).collect();
    let case_probes: Vec<String> = case.probes.iter().map(|p| p.name.clone()).collect();
    let problems = study::validate(&st, &case_results, &case_probes);
    if !problems.is_empty() {
        return Err(input_error(&sources, &problems));
    }
    Ok(PreparedStudy { study: st, runs, dx: case.dx, warnings })
}

/// A name usable as a directory.
fn sanitize(s: &str) -> String {
    s.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '.' { c } else { '_' }).collect()
}

/// Checks a case or a study without running it: the case loads and plans; a study's every run
/// loads and plans, and its results name what its case reports. Prints the warnings (a study's:
/// those of its runs, each once) and returns how many.
pub fn check_file(path: &Path, opts: &scene::Options) -> Result<usize, RunFailure> {
    let text = read_text(path)?;
    if crate::scene::study::is_study(&text) {
        let o = RunOptions { scene: opts.clone(), ..RunOptions::default() };
        prepare_study(path, &o).map(|p| print_warnings(&p.warnings))
    } else {
        prepare(path, opts).map(|(scene, _)| print_warnings(&scene.warnings))
    }
}

fn print_warnings(warnings: &[String]) -> usize {
    eprint!("{}", warnings.concat());
    warnings.len()
}

/// The resolutions a case or study file lists under `convergence`.
pub fn declared_levels(path: &Path) -> Result<Vec<String>, RunFailure> {
    let text = read_text(path)?;
    let text = crate::scene::template::expand(&text, &[]).unwrap_or(text);
    let table: toml::Table = toml::from_str(&text).unwrap_or_default();
    let levels = table
        .get("convergence")
        .and_then(|v| v.as_array())
        .map(|a| a.iter().map(|v| v.as_str().map_or_else(|| v.to_string(), str::to_string)).collect::<Vec<_>>());
    levels.ok_or_else(|| {
        RunFailure::Input(format!(
            "error: `{}` lists no `convergence` resolutions: add e.g. `convergence = [\"2 mm\", \"1 mm\", \"0.5 mm\"]` or give them: --convergence=2mm,1mm,0.5mm\n",
            path.display()
        ))
    })
}

/// Runs a case or study at each of `levels` (resolution names or spacings, at least three) into
/// `out/<level>/`, then writes into `out/` every result's value and error at each spacing, its
/// observed order and Richardson estimate, and the error against wall time and particle count
/// ([`report::convergence`]). A level whose run fails is reported and left out of the analysis.
/// With `reanalyse`, nothing runs: the levels' reports that an earlier convergence run wrote into
/// `out/<level>/` are analysed again (after a change to the analysis).
pub fn run_convergence(
    path: &Path,
    levels: &[String],
    opts: &RunOptions,
    reanalyse: bool,
) -> Result<RunOutcome, RunFailure> {
    let study = crate::scene::study::is_study(&read_text(path)?);
    let jobs = if reanalyse { 1 } else { opts.jobs };
    let at = |level: &str| {
        let mut o = opts.clone();
        o.progress &= jobs == 1;
        if !study {
            // A case's levels are the jobs, each one run.
            o.jobs = 1;
        }
        o.scene.resolution = Some(level.to_string());
        o.out = opts.out.join(sanitize(level));
        o
    };
    // Every level loads, and no two share a spacing, before the first run.
    let mut spacings: Vec<(String, f64)> = vec![];
    for level in levels {
        let dx = spacing(path, &at(level).scene)?;
        if let Some((other, _)) = spacings.iter().find(|(_, d)| (d - dx).abs() <= 1e-9 * dx) {
            return Err(RunFailure::Input(format!(
                "error: resolutions `{other}` and `{level}` have the same spacing ({dx} m)\n"
            )));
        }
        spacings.push((level.clone(), dx));
    }
    if spacings.len() < 3 {
        return Err(RunFailure::Input(format!(
            "error: a convergence study needs at least three resolutions; got {}\n",
            levels.join(", ")
        )));
    }
    // Reanalysing writes the study's report too: the folder is claimed as a run claims it.
    if leads() {
        claim_out(opts)?;
    }
    let mut reports = vec![];
    let mut notes = vec![];
    // A study's runs, at every level, are the jobs: all of them side by side first, then each
    // level's report from what they wrote, as `--reanalyse` makes it.
    let runs_made = study && jobs > 1;
    let failed = if runs_made { make_study_runs(path, levels, &at, jobs)? } else { vec![] };
    let level_jobs = if study { 1 } else { jobs };
    let done = run_side_by_side(level_jobs, levels, RunFailure::is_input, |level| {
        if let Some((_, msg)) = failed.iter().find(|(l, _)| l == level) {
            Err(RunFailure::Run(msg.clone()))
        } else if reanalyse || runs_made {
            reanalyse_file(path, &at(level)).map(|o| o.report)
        } else {
            eprintln!("convergence: resolution `{level}`");
            run_file(path, &at(level)).map(|o| o.report)
        }
    });
    for (level, outcome) in levels.iter().zip(done) {
        let Some(outcome) = outcome else { break };
        match outcome {
            Ok(r) => {
                notes.push(format!(
                    "`{level}`: {} particles, {} steps, {:.1} s; report in {}/",
                    r.particles,
                    r.steps,
                    r.wall_s,
                    sanitize(level)
                ));
                reports.push((level.clone(), r));
            }
            Err(RunFailure::Run(msg)) => {
                notes.push(format!("`{level}` did not complete and is left out: {msg}"));
            }
            Err(e) => return Err(e),
        }
    }
    let c = report::convergence::analyse(&reports);
    let finest = reports.iter().min_by(|a, b| a.1.dx.total_cmp(&b.1.dx)).map(|(_, r)| r.clone()).unwrap_or_default();
    let wall: f64 = reports.iter().map(|(_, r)| r.wall_s).sum();
    let work: f64 = reports.iter().map(|(_, r)| r.particle_steps_per_s * r.wall_s).sum();
    notes.extend(c.notes);
    let report = RunReport {
        case: format!("{}, convergence", finest.case),
        steps: reports.iter().map(|(_, r)| r.steps).sum(),
        wall_s: wall,
        particle_steps_per_s: if wall > 0.0 { work / wall } else { 0.0 },
        results: c.results,
        histories: c.histories,
        notes,
        resolution: levels.join(", "),
        tables: c.tables,
        ..finest
    };
    if leads() {
        report::write(&opts.out, &report).map_err(|e| RunFailure::Run(format!("writing the report: {e}")))?;
    }
    Ok(RunOutcome { report, out: opts.out.clone(), histories: vec![] })
}

/// Every run of a study at every level, `jobs` at a time, each writing into `<level>/<run>/` as
/// the study would. Returns the levels with a run that did not complete, each with the first such
/// run's failure, to be left out as one at a time they would be; an input error stops the rest
/// and is returned.
fn make_study_runs(
    path: &Path,
    levels: &[String],
    at: &dyn Fn(&str) -> RunOptions,
    jobs: usize,
) -> Result<Vec<(String, String)>, RunFailure> {
    let mut tasks = vec![];
    for level in levels {
        let o = at(level);
        let PreparedStudy { study: st, runs, .. } = prepare_study(path, &o)?;
        if leads() {
            claim_out(&o)?;
        }
        tasks.extend(runs.into_iter().map(|(r, ro)| (level.clone(), r.name, ro, st.case_path.clone())));
    }
    let done = run_side_by_side(jobs, &tasks, RunFailure::is_input, |(level, run, o, case)| {
        eprintln!("convergence: resolution `{level}`, run `{run}`");
        run_case(case, o).map(|_| ()).map_err(|e| e.of_run(run))
    });
    let mut failed: Vec<(String, String)> = vec![];
    for ((level, ..), d) in tasks.iter().zip(done) {
        match d {
            Some(Err(RunFailure::Input(e))) => return Err(RunFailure::Input(e)),
            Some(Err(RunFailure::Run(e))) if !failed.iter().any(|(l, _)| l == level) => {
                failed.push((level.clone(), e));
            }
            _ => {}
        }
    }
    Ok(failed)
}

/// Runs `run` on every task, `jobs` of them at a time, and returns their results in the tasks'
/// order. With more than one job each task runs on its own thread inside a rayon pool of its
/// share of the threads (the current pool's divided by `jobs`, at least one); the callers turn
/// the runs' progress bars off, which would overwrite one another. A failure that `stops`
/// starts no further task: the tasks not started are `None`, and they all follow it in order,
/// as one after another the caller would have stopped there.
fn run_side_by_side<T: Sync, X: Send>(
    jobs: usize,
    tasks: &[T],
    stops: impl Fn(&RunFailure) -> bool + Sync,
    run: impl Fn(&T) -> Result<X, RunFailure> + Sync,
) -> Vec<Option<Result<X, RunFailure>>> {
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
    use std::sync::Mutex;
    let done: Vec<Mutex<Option<Result<X, RunFailure>>>> = tasks.iter().map(|_| Mutex::new(None)).collect();
    let (next, stopped) = (AtomicUsize::new(0), AtomicBool::new(false));
    let work = || {
        while !stopped.load(Ordering::SeqCst) {
            let i = next.fetch_add(1, Ordering::SeqCst);
            let Some(task) = tasks.get(i) else { break };
            let result = run(task);
            if result.as_ref().is_err_and(&stops) {
                stopped.store(true, Ordering::SeqCst);
            }
            *done[i].lock().unwrap_or_else(|e| e.into_inner()) = Some(result);
        }
    };
    let jobs = jobs.clamp(1, tasks.len().max(1));
    if jobs == 1 {
        work();
    } else {
        let threads = (rayon::current_num_threads() / jobs).max(1);
        std::thread::scope(|s| {
            for _ in 0..jobs {
                s.spawn(|| match rayon::ThreadPoolBuilder::new().num_threads(threads).build() {
                    Ok(pool) => pool.install(work),
                    Err(_) => work(),
                });
            }
        });
    }
    done.into_iter().map(|m| m.into_inner().unwrap_or_else(|e| e.into_inner())).collect()
}

/// A completed run's report and probe histories, read back from what it wrote into `dir`.
fn earlier_outcome(dir: &Path) -> Result<RunOutcome, RunFailure> {
    let report = earlier_report(dir)?;
    // A run's report plots each probe alone, named as the probe (`make_report`).
    let histories =
        report.histories.iter().filter_map(|h| Some((h.name.clone(), h.series.first()?.points.clone()))).collect();
    Ok(RunOutcome { report, out: dir.to_path_buf(), histories })
}

/// The report a completed run wrote into `dir`; a run that did not complete is a `Run` failure.
fn earlier_report(dir: &Path) -> Result<RunReport, RunFailure> {
    let path = dir.join("report.json");
    let text = std::fs::read_to_string(&path)
        .map_err(|e| RunFailure::Input(format!("error: no report of an earlier run at `{}`: {e}\n", path.display())))?;
    let r = report::json::from_json(&text)
        .map_err(|e| RunFailure::Input(format!("error: `{}` is no pairsum report: {e}\n", path.display())))?;
    match r.notes.iter().find(|n| n.starts_with("the run did not complete")) {
        Some(n) => Err(RunFailure::Run(n.clone())),
        None => Ok(r),
    }
}

/// The particle spacing a case or study runs at with `opts` (checking that it loads and plans).
fn spacing(path: &Path, opts: &scene::Options) -> Result<f64, RunFailure> {
    let text = read_text(path)?;
    if crate::scene::study::is_study(&text) {
        let o = RunOptions { scene: opts.clone(), ..RunOptions::default() };
        prepare_study(path, &o).map(|p| p.dx)
    } else {
        prepare(path, opts).map(|(scene, _)| scene.dx)
    }
}

/// A case or study file's text.
fn read_text(path: &Path) -> Result<String, RunFailure> {
    std::fs::read_to_string(path)
        .map_err(|e| RunFailure::Input(format!("error: cannot read `{}`: {e}\n", path.display())))
}

/// Runs a case or a study, whichever the file is.
pub fn run_file(path: &Path, opts: &RunOptions) -> Result<RunOutcome, RunFailure> {
    let text = read_text(path)?;
    if crate::scene::study::is_study(&text) {
        run_study(path, opts, false)
    } else if opts.jobs > 1 {
        Err(RunFailure::Input(format!(
            "error: `{}` is a case, one run: --jobs runs a study's runs, or a case's --convergence levels, side by side\n",
            path.display()
        )))
    } else {
        run_case(path, opts)
    }
}

/// Analyses again, without running, what an earlier run of a case or study wrote into `opts.out`:
/// a study's results are recomputed from its runs' reports; a case's report is read as it is.
pub fn reanalyse_file(path: &Path, opts: &RunOptions) -> Result<RunOutcome, RunFailure> {
    let text = read_text(path)?;
    if crate::scene::study::is_study(&text) {
        run_study(path, opts, true)
    } else {
        earlier_outcome(&opts.out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Side by side or one after another, the results come back in the tasks' order, and a
    /// failure that stops starts nothing after it: every task not made follows it.
    #[test]
    fn tasks_run_side_by_side_come_back_in_order_and_a_stop_starts_nothing_after_it() {
        let tasks: Vec<usize> = (0..8).collect();
        let run = |&i: &usize| if i == 2 { Err(RunFailure::Input(format!("task {i}"))) } else { Ok(10 * i) };
        for jobs in [1, 3] {
            let done = run_side_by_side(jobs, &tasks, |_| true, run);
            assert_eq!(done.len(), 8);
            for (i, d) in done.iter().enumerate().take(2) {
                assert!(matches!(d, Some(Ok(x)) if *x == 10 * i), "jobs {jobs}, task {i}: {d:?}");
            }
            assert!(matches!(&done[2], Some(Err(RunFailure::Input(m))) if m == "task 2"), "jobs {jobs}");
            let first_not_made = done.iter().position(Option::is_none).unwrap_or(done.len());
            assert!(first_not_made > 2, "jobs {jobs}: {done:?}");
            assert!(done[first_not_made..].iter().all(Option::is_none), "jobs {jobs}: {done:?}");
            if jobs == 1 {
                assert_eq!(first_not_made, 3, "one after another, nothing runs after the stop");
            }
        }
        // A failure that does not stop (a convergence level that did not complete) lets the rest run.
        let done = run_side_by_side(3, &tasks, |_| false, run);
        assert!(done.iter().all(Option::is_some));
        assert!(matches!(&done[7], Some(Ok(70))));
    }
}
