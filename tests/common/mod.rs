//! Helpers for tests that run models on the CPU backend without a case file.
#![allow(dead_code)]

use pairsum::backend::cpu::CpuBackend;
use pairsum::backend::{Backend, Mirror};
use pairsum::check::{check_text, Stdlib};
use pairsum::diag::{render, Sources};
use pairsum::engine::setup::{build_store, MaterialInput, ParticleInput};
use pairsum::ir::Model;
use pairsum::particles::Real;
use pairsum::schedule::{IntegratorKind, Plan, SceneSpec};
use std::path::{Path, PathBuf};

/// A fresh folder in the temporary directory for one test's files, removed when the test
/// passes and kept when it fails (to look at what it wrote).
pub struct Scratch(PathBuf);

impl Scratch {
    /// `pairsum-{tag}-{pid}`, emptied if an earlier run left it.
    pub fn new(tag: &str) -> Scratch {
        let d = std::env::temp_dir().join(format!("pairsum-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("a folder in the temporary directory");
        Scratch(d)
    }
}

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

pub fn stdlib() -> Stdlib {
    Stdlib::Dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("stdlib"))
}

pub fn model(text: &str) -> Model {
    let mut sources = Sources::new();
    let checked = check_text(&mut sources, "test.sph", text, stdlib());
    assert!(!checked.has_errors(), "{}", render(&sources, &checked.diags));
    checked.model
}

/// A regular lattice of `n` particles per axis, spacing `dx`, starting at `dx/2`.
pub fn lattice(dim: usize, n: usize, dx: f64) -> Vec<[f64; 3]> {
    let mut out = vec![];
    let ny = if dim > 1 { n } else { 1 };
    let nz = if dim > 2 { n } else { 1 };
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..n {
                let c = |m: usize| (m as f64 + 0.5) * dx;
                out.push([c(i), if dim > 1 { c(j) } else { 0.0 }, if dim > 2 { c(k) } else { 0.0 }]);
            }
        }
    }
    out
}

pub fn input(dim: usize, x: Vec<[f64; 3]>, dx: f64) -> ParticleInput {
    let n = x.len();
    ParticleInput {
        v: vec![[0.0; 3]; n],
        vol: vec![dx.powi(dim as i32); n],
        dx: vec![dx; n],
        body: vec![0; n],
        part: vec![-1; n],
        group: vec![0; n],
        material: vec![0; n],
        initial: vec![],
        x,
    }
}

/// A material binding parameters by name.
pub fn material(model: &Model, values: &[(&str, Vec<f64>)]) -> MaterialInput {
    let mut m = MaterialInput { name: "test".into(), ..Default::default() };
    for (name, v) in values {
        let p = model.param_id(name).unwrap_or_else(|| panic!("no parameter {name}"));
        m.values.insert(p, v.clone());
    }
    m
}

pub fn scene(model: &Model, dim: usize, outputs: &[&str], integrator: IntegratorKind) -> SceneSpec {
    SceneSpec {
        dim,
        groups: model.all_groups(),
        outputs: outputs.iter().map(|n| model.field_id(n).unwrap_or_else(|| panic!("no field {n}"))).collect(),
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
    }
}

pub fn backend<T: Real>(
    model: &Model,
    scene: &SceneSpec,
    input: &ParticleInput,
    materials: &[MaterialInput],
    mirrors: Vec<Mirror>,
) -> CpuBackend<T> {
    let plan = Plan::build(model, scene, None).expect("plan");
    let store = build_store::<T>(&plan, input, materials).expect("store");
    let mut b = CpuBackend::new(plan, store, mirrors).expect("backend");
    b.initialise().expect("initialise");
    b
}

/// A field of every particle in the scene's original order.
pub fn field_by_id<B: Backend>(b: &B, name: &str) -> (usize, Vec<f64>) {
    let f = b.plan().model.field_id(name).expect("field");
    let (comps, data) = b.read(f).expect("read").expect("stored");
    let ids = b.ids().expect("ids");
    let mut out = vec![0.0; data.len()];
    for (k, id) in ids.iter().enumerate() {
        out[*id as usize * comps..(*id as usize + 1) * comps].copy_from_slice(&data[k * comps..(k + 1) * comps]);
    }
    (comps, out)
}

/// A field of the particles whose group stores it, in the scene's original order (`field_by_id`
/// gives NaN for the others, which a comparison must not read as a value).
pub fn stored_field<B: Backend>(b: &B, name: &str) -> (usize, Vec<f64>) {
    let plan = b.plan();
    let f = plan.model.field_id(name).expect("field");
    let groups = plan.layout.iter().find(|l| l.field == f).unwrap_or_else(|| panic!("`{name}` is not stored")).groups;
    let (comps, data) = b.read(f).expect("read").expect("stored");
    let mut rows: Vec<(u32, usize)> = b
        .ids()
        .expect("ids")
        .into_iter()
        .zip(b.groups())
        .enumerate()
        .filter(|(_, (_, g))| groups.contains(pairsum::ir::GroupId(*g)))
        .map(|(row, (id, _))| (id, row))
        .collect();
    rows.sort();
    let values = rows.iter().flat_map(|(_, row)| data[row * comps..(row + 1) * comps].iter().copied()).collect();
    (comps, values)
}

/// One figure a bundled case computes at its CI resolution today (`tests/data/ci_values.toml`,
/// written by `scripts/pin_ci_values.py`).
#[derive(serde::Deserialize)]
pub struct Pin {
    pub case: String,
    pub set: std::collections::BTreeMap<String, String>,
    pub quantity: String,
    pub f64: f64,
    pub f32: f64,
    pub band: f64,
}

pub fn pins() -> Vec<Pin> {
    #[derive(serde::Deserialize)]
    struct File {
        pin: Vec<Pin>,
    }
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/ci_values.toml");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    toml::from_str::<File>(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display())).pin
}

/// A result measured with the clock (a study's speed-up), which no test pins:
/// `scripts/pin_ci_values.py` applies the same rule.
pub fn is_timing(quantity: &str) -> bool {
    quantity.contains("speed-up")
}

/// Every result of a CI run of `case` (with `set`, in f32 or f64) lies within its pinned band of what the case
/// computed when it was pinned, and every pinned result was reported: a regression test, whose
/// band is the spread rounding makes (f32 against f64), not the case's error against its reference.
pub fn assert_pinned(case: &str, set: &[(&str, &str)], f32: bool, results: &[(String, f64)]) {
    let set: std::collections::BTreeMap<String, String> =
        set.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
    let pinned: Vec<Pin> = pins().into_iter().filter(|p| p.case == case && p.set == set).collect();
    for (quantity, value) in results.iter().filter(|(q, _)| !is_timing(q)) {
        let pin = pinned.iter().find(|p| &p.quantity == quantity).unwrap_or_else(|| {
            panic!("{case} {set:?}: `{quantity}` is not pinned (scripts/pin_ci_values.py writes every result)")
        });
        let (pinned_value, other) = if f32 { (pin.f32, pin.f64) } else { (pin.f64, pin.f32) };
        assert!(
            (value - pinned_value).abs() <= pin.band,
            "{case} {set:?}: `{quantity}` = {value}, pinned at {pinned_value} ± {} (the other precision gave {other})",
            pin.band
        );
    }
    for pin in &pinned {
        assert!(results.iter().any(|(q, _)| *q == pin.quantity), "{case}: pinned `{}` was not reported", pin.quantity);
    }
}

/// A model whose one equation is `tensile_part` (stdlib/solid/principal.sph) of the state `s`.
pub const TENSILE_PART_MODEL: &str = "use kernels\nuse solid::principal\ngroup all\nkernel = cubic_spline\n\
     state s: symtensor [Pa]\nparticle tension -> pulled: symtensor [Pa] { pulled = tensile_part(s) }\nintegrate { }\n";

/// The values a probe recorded, every one of them finite (a NaN would vanish from a least or a
/// largest value folded with `f64::min` or `f64::max`).
pub fn history<'a>(histories: &'a [(String, Vec<(f64, f64)>)], probe: &str) -> &'a [(f64, f64)] {
    let points = &histories.iter().find(|(n, _)| n == probe).unwrap_or_else(|| panic!("no probe `{probe}`")).1;
    if let Some((t, v)) = points.iter().find(|(t, v)| !t.is_finite() || !v.is_finite()) {
        panic!("probe `{probe}` recorded {v} at t = {t}");
    }
    points
}

/// The largest magnitude of `values`; fails the test, naming `what`, at a NaN or an infinity.
pub fn max_abs(what: &str, values: &[f64]) -> f64 {
    pairsum::compare::max_abs(values).unwrap_or_else(|e| panic!("{what}: {e}"))
}

/// The least of `values`; fails the test, naming `what`, at a NaN or an infinity.
pub fn least(what: &str, values: &[f64]) -> f64 {
    pairsum::compare::extremes(values).unwrap_or_else(|e| panic!("{what}: {e}")).0
}

/// The largest of `values`; fails the test, naming `what`, at a NaN or an infinity.
pub fn largest(what: &str, values: &[f64]) -> f64 {
    pairsum::compare::extremes(values).unwrap_or_else(|e| panic!("{what}: {e}")).1
}

/// The largest `|a[k] − b[k]|`; fails the test, naming `what`, at a NaN, an infinity or a
/// difference in length.
pub fn max_abs_diff(what: &str, a: &[f64], b: &[f64]) -> f64 {
    pairsum::compare::max_abs_diff(a, b).unwrap_or_else(|e| panic!("{what}: {e}"))
}

/// The largest `|a[k] − b[k]|` over the largest magnitude of either side; fails as `max_abs_diff`.
pub fn max_rel_diff(what: &str, a: &[f64], b: &[f64]) -> f64 {
    pairsum::compare::max_rel_diff(a, b).unwrap_or_else(|e| panic!("{what}: {e}"))
}

/// The largest `|a[k] − b[k]| / |a[k]|`; fails as `max_abs_diff`, and where an `a[k]` is 0.
pub fn max_pointwise_rel_diff(what: &str, a: &[f64], b: &[f64]) -> f64 {
    pairsum::compare::max_pointwise_rel_diff(a, b).unwrap_or_else(|e| panic!("{what}: {e}"))
}

/// A xorshift pseudo-random number in [0, 1), advancing `seed`.
pub fn rnd(seed: &mut u64) -> f64 {
    *seed ^= *seed << 13;
    *seed ^= *seed >> 7;
    *seed ^= *seed << 17;
    (*seed % 1_000_000) as f64 / 1_000_000.0
}

/// A case file of one block of 6 × 6 particles at 10 mm (x and y from 5 to 55 mm) of a material
/// `metal` (ρ0 = 1000 kg/m³), group `metal`, run with the model file `model`: `top` adds
/// top-level keys, `body` keys of the block, and `rest` tables after it (probes, results).
pub fn block_case(model: &str, top: &str, body: &str, rest: &str) -> String {
    format!(
        r#"name = "block"
model = "{model}"
dim = 2
{top}
dt_max = "1 ms"

[materials.metal]
rho0 = "1000 kg/m^3"

[[bodies]]
name = "block"
group = "metal"
material = "metal"
shape = {{ box = {{ min = [0, 0], max = ["60 mm", "60 mm"] }} }}
{body}

[resolutions]
ci = "10 mm"

{rest}
"#
    )
}

/// A 0.2 m square of water, 20 × 20 particles, at 1 % above its rest density (so under pressure),
/// moving at `vx` along x; `periodic` and `rest` are further case text.
pub fn lattice_case(vx: &str, end: &str, periodic: &str, rest: &str) -> String {
    format!(
        r#"name = "lattice"
model = "models::wcsph_fluid"
dim = 2
integrator = "symplectic"
end_time = "{end}"

[resolutions]
ci = "10 mm"

{periodic}

[materials.water]
rho0 = "1000 kg/m^3"
c0 = "10 m/s"
gamma = 7
visc_a = 0.1
visc_b = 0
nu0 = "1e-6 m^2/s"

[[bodies]]
name = "water"
group = "fluid"
material = "water"
shape = {{ box = {{ min = [0, 0], max = ["0.2 m", "0.2 m"] }} }}
velocity = ["{vx}", 0]
initial = {{ rho = "1.01 * rho0" }}

[[probes]]
name = "max_speed"
measure = "max_speed"

[[probes]]
name = "momentum"
expression = "m * v.x"
reduce = "sum"

[[probes]]
name = "x_min"
field = "x"
reduce = "min"

[[probes]]
name = "x_max"
field = "x"
reduce = "max"

{rest}
"#
    )
}

pub const BOTH_AXES: &str = "[periodic]\nx = [0, \"0.2 m\"]\ny = [0, \"0.2 m\"]";

/// `case` written as `dir/case.toml` and run on the CPU backend without VTK output (into
/// `dir/out`); the run's outcome, its probes' histories among it.
pub fn run_case_text_on_cpu(dir: &Path, case: &str) -> pairsum::runner::RunOutcome {
    std::fs::write(dir.join("case.toml"), case).expect("case.toml");
    let opts = pairsum::runner::RunOptions {
        backend: pairsum::runner::BackendChoice::Cpu,
        out: dir.join("out"),
        vtk: false,
        ..Default::default()
    };
    pairsum::runner::run_case(&dir.join("case.toml"), &opts).unwrap_or_else(|e| panic!("{e}"))
}

/// Wendland C2 in 2D at distance r with smoothing length h (stdlib/kernels.sph), written out here
/// for sums computed independently of the engine.
pub fn wendland_c2_2d(r: f64, h: f64) -> f64 {
    let q = r / h;
    if q >= 2.0 {
        return 0.0;
    }
    7.0 / (4.0 * std::f64::consts::PI * h * h) * (1.0 - q / 2.0).powi(4) * (2.0 * q + 1.0)
}

/// `steps` steps of `store` (of `scene`, under `plan`) split over `ranks` threads as ranks, each
/// rank's domain set up by `setup` first: what `read` takes of each rank's engine at the end, in
/// rank order.
pub fn run_split<T: Real, R: Send>(
    name: &str,
    (scene, plan, store): (&pairsum::scene::Scene, &Plan, &pairsum::particles::Store<T>),
    ranks: usize,
    steps: usize,
    setup: impl Fn(&mut pairsum::backend::domains::Domain<T>) + Sync,
    read: impl Fn(&pairsum::engine::Engine<pairsum::backend::domains::Domain<T>>) -> R + Sync,
) -> Vec<R> {
    use pairsum::backend::domains::Domain;
    let (setup, read) = (&setup, &read);
    std::thread::scope(|s| {
        let handles: Vec<_> = pairsum::backend::transport::Threads::ranks(ranks)
            .into_iter()
            .map(|t| {
                let (plan, store, mirrors, config) =
                    (plan.clone(), store.clone(), scene.mirrors.clone(), scene.config.clone());
                s.spawn(move || {
                    let mut split = Domain::new(plan, store, mirrors, Box::new(t)).expect("domain");
                    setup(&mut split);
                    let mut b = pairsum::engine::Engine::new(split, config);
                    b.initialise().expect("init");
                    for k in 0..steps {
                        b.step().unwrap_or_else(|e| panic!("{name}: split step {k}: {e}"));
                    }
                    read(&b)
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().expect("a rank panicked")).collect()
    })
}
