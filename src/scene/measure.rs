//! Probes: what a case measures during a run — a field component reduced over a body, or a named
//! measurement with a documented, automatic definition — and the results taken from them.

use super::max_keeping_nan;
use super::spec::{Pick, ProbeKind, ProbeSpec, ProbeValue, Record, ResultSpec, Scene};
use crate::backend::{Backend, BackendError, FieldReduction, Nearby, Partial, WatchValues};
use crate::ir::FieldId;
use crate::ir::{component_indices, Shape};
use crate::schedule::Plan;
use crate::schedule::Target;
use std::cell::{OnceCell, RefCell};
use std::collections::HashMap;
use std::rc::Rc;

/// A named measurement with a documented, automatic definition (`docs/CASE_FILES.md`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Measure {
    /// Over every particle, the least distance to another, over its own Δx (clumping).
    MinPairDistance,
    /// Over every particle, the largest distance to its nearest neighbour, over its own Δx.
    MaxNeighbourGap,
    /// The least distance between the first two bodies, over Δx.
    MinInterbodyDistance,
    /// Particles of the first two bodies closer than Δx/2 to a particle of the other.
    Interpenetrated,
    /// Where a wave front driven by the first body has got to.
    FrontPosition,
    KineticEnergy,
    MaxSpeed,
    CraterDiameter,
    /// The crater in the plate's intact material: failed particles (`D ≥ 1`) do not count.
    IntactCraterDiameter,
    DebrisLength,
    DebrisWidth,
    DebrisLengthToWidth,
    /// The speed of the plug the first body pushes out of the second.
    PlugVelocity,
}

impl Measure {
    pub const ALL: [Measure; 13] = [
        Measure::MinPairDistance,
        Measure::MaxNeighbourGap,
        Measure::MinInterbodyDistance,
        Measure::Interpenetrated,
        Measure::FrontPosition,
        Measure::KineticEnergy,
        Measure::MaxSpeed,
        Measure::CraterDiameter,
        Measure::IntactCraterDiameter,
        Measure::DebrisLength,
        Measure::DebrisWidth,
        Measure::DebrisLengthToWidth,
        Measure::PlugVelocity,
    ];

    /// Its name in case files.
    pub fn name(self) -> &'static str {
        match self {
            Measure::MinPairDistance => "min_pair_distance",
            Measure::MaxNeighbourGap => "max_neighbour_gap",
            Measure::MinInterbodyDistance => "min_interbody_distance",
            Measure::Interpenetrated => "interpenetrated",
            Measure::FrontPosition => "front_position",
            Measure::KineticEnergy => "kinetic_energy",
            Measure::MaxSpeed => "max_speed",
            Measure::CraterDiameter => "crater_diameter",
            Measure::IntactCraterDiameter => "intact_crater_diameter",
            Measure::DebrisLength => "debris_length",
            Measure::DebrisWidth => "debris_width",
            Measure::DebrisLengthToWidth => "debris_length_to_width",
            Measure::PlugVelocity => "plug_velocity",
        }
    }

    pub fn parse(name: &str) -> Option<Measure> {
        Measure::ALL.into_iter().find(|m| m.name() == name)
    }

    /// The fields it reads, which the run must store.
    pub fn fields_needed(self) -> &'static [&'static str] {
        match self {
            Measure::MinInterbodyDistance | Measure::Interpenetrated | Measure::CraterDiameter => &["x"],
            Measure::MinPairDistance | Measure::MaxNeighbourGap => &["x", "dx"],
            Measure::IntactCraterDiameter => &["x", "D"],
            Measure::DebrisLength | Measure::DebrisWidth | Measure::DebrisLengthToWidth => &["x"],
            Measure::FrontPosition | Measure::PlugVelocity => &["x", "v"],
            Measure::KineticEnergy => &["v", "m"],
            Measure::MaxSpeed => &["v"],
        }
    }
}

/// The recorded history of a probe.
#[derive(Clone, Debug, Default)]
pub struct History {
    pub points: Vec<(f64, f64)>,
    initial: Option<f64>,
    /// The last value sampled: an integrating probe's integrand at its last point.
    last: Option<f64>,
}

/// A field of every particle as a [`Reader`] gives it: components per particle, and `n × comps`
/// values (NaN where the particle's group does not store it), shared rather than copied.
pub type Column = Rc<(usize, Vec<f64>)>;

/// What probes, profiles and output read of the particles: the plan, fields and ids, in the
/// backend's current order. In a run split into domains, `read` and `ids` gather every rank's
/// particles; a probe reduces its rank's own ones (`read_own`, `ids_own`) and merges the ranks'
/// parts (`all_gather`), so that a few numbers travel instead of the field.
pub trait Reader {
    fn plan(&self) -> &Plan;
    fn read(&self, f: FieldId) -> Result<Option<Column>, BackendError>;
    fn ids(&self) -> Result<Rc<Vec<u32>>, BackendError>;
    /// [`read`](Self::read) over this rank's own particles (every particle in a run in one piece).
    fn read_own(&self, f: FieldId) -> Result<Option<Column>, BackendError> {
        self.read(f)
    }
    /// [`ids`](Self::ids) of this rank's own particles, in the order of [`read_own`](Self::read_own).
    fn ids_own(&self) -> Result<Rc<Vec<u32>>, BackendError> {
        self.ids()
    }
    /// Every rank's `part`, in rank order ([`Backend::all_gather`]): every rank calls it alike.
    fn all_gather(&self, part: Vec<f64>) -> Vec<Vec<f64>> {
        vec![part]
    }
    /// This rank's own particles and those near them ([`Backend::nearby`]); by default every
    /// particle [`read`](Self::read) gives, with no limit to the reach.
    fn nearby(&self) -> Result<Option<Rc<Nearby>>, BackendError> {
        let Some(x) = positions(self)? else { return Ok(None) };
        Ok(Some(Rc::new(Nearby { own: x.len(), x, ids: self.ids()?.to_vec(), reach: f64::INFINITY })))
    }
    /// A probe's reduction where the backend computes it itself ([`Backend::reduce_field`]).
    fn reduce_field(&self, r: &FieldReduction) -> Result<Option<f64>, BackendError> {
        let _ = r;
        Ok(None)
    }
    /// The largest speed and the kinetic energy where the backend reduces them itself
    /// ([`Backend::watch_values`], when [`Backend::reduces_probes`]).
    fn motion(&self) -> Result<Option<WatchValues>, BackendError> {
        Ok(None)
    }
}

impl<B: Backend> Reader for B {
    fn plan(&self) -> &Plan {
        Backend::plan(self)
    }
    fn read(&self, f: FieldId) -> Result<Option<Column>, BackendError> {
        Ok(Backend::read(self, f)?.map(Rc::new))
    }
    fn ids(&self) -> Result<Rc<Vec<u32>>, BackendError> {
        Ok(Rc::new(Backend::ids(self)?))
    }
    fn read_own(&self, f: FieldId) -> Result<Option<Column>, BackendError> {
        Ok(Backend::read_own(self, f)?.map(Rc::new))
    }
    fn ids_own(&self) -> Result<Rc<Vec<u32>>, BackendError> {
        Ok(Rc::new(Backend::ids_own(self)?))
    }
    fn all_gather(&self, part: Vec<f64>) -> Vec<Vec<f64>> {
        Backend::all_gather(self, part)
    }
    fn nearby(&self) -> Result<Option<Rc<Nearby>>, BackendError> {
        Ok(Backend::nearby(self)?.map(Rc::new))
    }
    fn reduce_field(&self, r: &FieldReduction) -> Result<Option<f64>, BackendError> {
        Backend::reduce_field(self, r)
    }
    fn motion(&self) -> Result<Option<WatchValues>, BackendError> {
        if self.reduces_probes() {
            self.watch_values()
        } else {
            Ok(None)
        }
    }
}

/// A backend read at one moment: each field and the ids come from the backend once, however many
/// probes, profiles and outputs read them (on the GPU every read waits for the device).
pub struct Moment<'a, B: Backend> {
    backend: &'a B,
    /// By field and whether of this rank's own particles only.
    fields: RefCell<HashMap<(FieldId, bool), Option<Column>>>,
    ids: OnceCell<Rc<Vec<u32>>>,
    ids_own: OnceCell<Rc<Vec<u32>>>,
    motion: OnceCell<Option<WatchValues>>,
    nearby: OnceCell<Option<Rc<Nearby>>>,
}

impl<'a, B: Backend> Moment<'a, B> {
    pub fn new(backend: &'a B) -> Self {
        Moment {
            backend,
            fields: RefCell::new(HashMap::new()),
            ids: OnceCell::new(),
            ids_own: OnceCell::new(),
            motion: OnceCell::new(),
            nearby: OnceCell::new(),
        }
    }

    /// Field `f` (of the own particles only if `own`), read from the backend the first time; a
    /// run in one piece owns every particle, and reads each field once.
    fn column(&self, f: FieldId, own: bool) -> Result<Option<Column>, BackendError> {
        let own = own && self.backend.rank().is_some();
        if let Some(column) = self.fields.borrow().get(&(f, own)) {
            return Ok(column.clone());
        }
        let column = if own { Reader::read_own(self.backend, f)? } else { Reader::read(self.backend, f)? };
        self.fields.borrow_mut().insert((f, own), column.clone());
        Ok(column)
    }
}

/// `cell`'s value, computed by `make` the first time.
fn cached<T: Clone>(cell: &OnceCell<T>, make: impl FnOnce() -> Result<T, BackendError>) -> Result<T, BackendError> {
    if let Some(v) = cell.get() {
        return Ok(v.clone());
    }
    let v = make()?;
    Ok(cell.get_or_init(|| v).clone())
}

impl<B: Backend> Reader for Moment<'_, B> {
    fn plan(&self) -> &Plan {
        self.backend.plan()
    }
    fn read(&self, f: FieldId) -> Result<Option<Column>, BackendError> {
        self.column(f, false)
    }
    fn ids(&self) -> Result<Rc<Vec<u32>>, BackendError> {
        cached(&self.ids, || Reader::ids(self.backend))
    }
    fn read_own(&self, f: FieldId) -> Result<Option<Column>, BackendError> {
        self.column(f, true)
    }
    fn ids_own(&self) -> Result<Rc<Vec<u32>>, BackendError> {
        match self.backend.rank() {
            Some(_) => cached(&self.ids_own, || Reader::ids_own(self.backend)),
            None => self.ids(),
        }
    }
    fn all_gather(&self, part: Vec<f64>) -> Vec<Vec<f64>> {
        Backend::all_gather(self.backend, part)
    }
    fn nearby(&self) -> Result<Option<Rc<Nearby>>, BackendError> {
        cached(&self.nearby, || Reader::nearby(self.backend))
    }
    fn reduce_field(&self, r: &FieldReduction) -> Result<Option<f64>, BackendError> {
        Backend::reduce_field(self.backend, r)
    }
    fn motion(&self) -> Result<Option<WatchValues>, BackendError> {
        cached(&self.motion, || Reader::motion(self.backend))
    }
}

/// A rank's own particles of a run split into domains, read without the other ranks
/// ([`Backend::read_own`]): what the rank writes as its piece of a VTK snapshot. Every particle
/// of a run in one piece.
pub struct Own<'a, B: Backend>(pub &'a B);

impl<B: Backend> Reader for Own<'_, B> {
    fn plan(&self) -> &Plan {
        self.0.plan()
    }
    fn read(&self, f: FieldId) -> Result<Option<Column>, BackendError> {
        Ok(self.0.read_own(f)?.map(Rc::new))
    }
    fn ids(&self) -> Result<Rc<Vec<u32>>, BackendError> {
        Ok(Rc::new(self.0.ids_own()?))
    }
    fn nearby(&self) -> Result<Option<Rc<Nearby>>, BackendError> {
        Ok(None)
    }
}

/// Each particle's body, in the backend's current order.
fn bodies_now(scene: &Scene, ids: &[u32]) -> Vec<u32> {
    ids.iter().map(|i| scene.particles.body[*i as usize]).collect()
}

/// Positions in the backend's current order.
pub fn positions<R: Reader + ?Sized>(b: &R) -> Result<Option<Vec<[f64; 3]>>, BackendError> {
    let Some(x) = b.plan().model.field_id("x") else { return Ok(None) };
    Ok(b.read(x)?.map(|column| padded(&column)))
}

/// The positions of this rank's own particles ([`Reader::read_own`]).
pub fn own_positions(b: &dyn Reader) -> Result<Option<Vec<[f64; 3]>>, BackendError> {
    let Some(x) = b.plan().model.field_id("x") else { return Ok(None) };
    Ok(b.read_own(x)?.map(|column| padded(&column)))
}

/// A column of positions as three coordinates each.
fn padded(column: &Column) -> Vec<[f64; 3]> {
    column.1.chunks(column.0.max(1)).map(crate::backend::padded).collect()
}

/// The value of a probe now (NaN where it has none); an error only when the backend fails.
pub fn evaluate(p: &ProbeSpec, scene: &Scene, b: &dyn Reader) -> Result<f64, BackendError> {
    match &p.kind {
        ProbeKind::Field { select, value, pick, reduce, locate, .. } => {
            // An axisymmetric case's sums and means weigh each particle as its ring, on the host.
            let host = scene.spec.axisymmetric || locate.is_some();
            if let Some(v) = reduced_by_backend(value, *pick, reduce, select.as_deref(), host, b)? {
                return Ok(v);
            }
            let Some((column, shape)) = probed_values(value, select.as_deref(), scene, b)? else {
                return Ok(f64::NAN);
            };
            let (comps, values) = (column.0, &column.1);
            let dim = b.plan().dim;
            let ids = b.ids_own()?;
            // This rank's selected particles' values, NaN left out, without collecting them
            // unless the extreme's position is asked for.
            let selected = (0..ids.len())
                .filter(|k| select.as_ref().is_none_or(|s| s[ids[*k] as usize]))
                .map(|k| (k, picked(*pick, shape, dim, &values[k * comps..(k + 1) * comps])))
                .filter(|(_, v)| !v.is_nan());
            match locate {
                Some(axis) => locate_extreme(reduce, &selected.collect::<Vec<_>>(), *axis, b),
                None if scene.spec.axisymmetric => {
                    let x = own_positions(b)?.unwrap_or_default();
                    let rings = selected.map(|(k, v)| (v, x.get(k).map_or(f64::NAN, ring)));
                    let part = rings.fold(Partial::new(reduce), |p, (v, w)| p.taking_weighted(v, w));
                    Ok(merged(b, part).value())
                }
                None => Ok(merged(b, Partial::of(reduce, selected.map(|p| p.1))).value()),
            }
        }
        ProbeKind::Measure(m) => measure(*m, scene, b),
    }
}

/// A probe of a field's component or length, reduced where the backend holds the field (the
/// GPU); None where the backend does not, or for an expression, a von Mises stress, or `on_host`
/// (the position of an extreme, an axisymmetric case's rings), which the host computes from the
/// fields.
fn reduced_by_backend(
    value: &ProbeValue,
    pick: Pick,
    reduce: &str,
    select: Option<&[bool]>,
    on_host: bool,
    b: &dyn Reader,
) -> Result<Option<f64>, BackendError> {
    let component = match pick {
        Pick::Component(c) => Some(c),
        Pick::Norm => None,
        Pick::VonMises => return Ok(None),
    };
    match value {
        ProbeValue::Field(field) if !on_host => {
            b.reduce_field(&FieldReduction { field: *field, component, reduce, select })
        }
        _ => Ok(None),
    }
}

/// Every particle's value of a probe's field or expression (`comps` numbers each), of this rank's
/// own particles in the backend's order ([`Reader::read_own`]), and its shape; `None` where a field
/// it reads is not stored. An expression is evaluated only for the particles `select` picks (by
/// scene index); the others get zeros, never read.
fn probed_values(
    value: &ProbeValue,
    select: Option<&[bool]>,
    scene: &Scene,
    b: &dyn Reader,
) -> Result<Option<(Column, Shape)>, BackendError> {
    let plan = b.plan();
    let e = match value {
        ProbeValue::Field(f) => return Ok(b.read_own(*f)?.map(|c| (c, plan.model.field(*f).ty.shape))),
        ProbeValue::Expression(e) => e,
    };
    let mut fields = crate::engine::setup::HostFields::new();
    for f in value.fields() {
        let Some(column) = b.read_own(f)? else { return Ok(None) };
        fields.insert(f, (column.0, column.1.clone()));
    }
    let ids = b.ids_own()?;
    let mut materials = crate::engine::setup::resolved_materials(plan, &scene.materials);
    let comps = crate::ir::components(e.ty.shape, plan.dim);
    let mut out = vec![0.0; ids.len() * comps];
    for (k, id) in ids.iter().enumerate() {
        if select.is_some_and(|s| !s[*id as usize]) {
            continue;
        }
        let params = &mut materials[scene.particles.material[*id as usize] as usize];
        let v = crate::engine::setup::particle_value(plan, e, params, &fields, k)
            .map_err(|what| BackendError(format!("cannot evaluate the expression: {what}")))?;
        out[k * comps..(k + 1) * comps].copy_from_slice(&v[..comps]);
    }
    Ok(Some((Rc::new((comps, out)), e.ty.shape)))
}

/// One particle's value of a field as a probe reads it.
fn picked(pick: Pick, shape: Shape, dim: usize, v: &[f64]) -> f64 {
    match pick {
        Pick::Component(c) => v[c],
        Pick::Norm => v.iter().map(|x| x * x).sum::<f64>().sqrt(),
        Pick::VonMises => {
            // s:s over the full tensor: off-diagonal components count twice; the diagonal
            // components a 1D or 2D tensor does not store follow from tr(s) = 0 (1D: equal halves).
            let mut ss = 0.0;
            let mut trace = 0.0;
            for (k, (r, c)) in component_indices(shape, dim).into_iter().enumerate() {
                ss += if r == c { v[k] * v[k] } else { 2.0 * v[k] * v[k] };
                if r == c {
                    trace += v[k];
                }
            }
            ss += match dim {
                1 => 2.0 * (0.5 * trace).powi(2),
                2 => trace * trace,
                _ => 0.0,
            };
            (1.5 * ss).sqrt()
        }
    }
}

/// The `axis` coordinate of the particle where the reduction is reached: each rank's extreme among
/// `values` (its own particles', by index in its own order), then the ranks' extreme (the last
/// of equal ones, as within a rank).
fn locate_extreme(reduce: &str, values: &[(usize, f64)], axis: usize, b: &dyn Reader) -> Result<f64, BackendError> {
    let key = |v: f64| match reduce {
        "min" => -v,
        "abs_max" => v.abs(),
        _ => v,
    };
    let best = values.iter().max_by(|p, q| key(p.1).total_cmp(&key(q.1)));
    let mine = match best {
        Some(&(k, v)) => Some(vec![key(v), own_positions(b)?.map_or(f64::NAN, |x| x[k][axis])]),
        None => None,
    };
    Ok(greatest(b, mine, |p, q| p[0].total_cmp(&q[0])).map_or(f64::NAN, |p| p[1]))
}

/// What a particle of an axisymmetric case stands for in a sum over particles: its ring
/// (`schedule::ring`).
fn ring(x: &[f64; 3]) -> f64 {
    crate::schedule::ring(x[0])
}

/// Every rank's part of a reduction, merged in rank order.
fn merged(b: &dyn Reader, mine: Partial) -> Partial {
    mine.merge_all(&b.all_gather(mine.parts().to_vec()))
}

/// Every rank's `mine`, summed element by element in rank order.
fn summed(b: &dyn Reader, mine: Vec<f64>) -> Vec<f64> {
    let mut total = vec![0.0; mine.len()];
    for part in b.all_gather(mine) {
        total.iter_mut().zip(part).for_each(|(t, p)| *t += p);
    }
    total
}

/// The greatest by `order` of every rank's row `mine` (the last of equal ones); `None` where no
/// rank has one.
fn greatest(
    b: &dyn Reader,
    mine: Option<Vec<f64>>,
    order: impl Fn(&[f64], &[f64]) -> std::cmp::Ordering,
) -> Option<Vec<f64>> {
    let all = b.all_gather(mine.unwrap_or_default());
    all.into_iter().filter(|r| !r.is_empty()).max_by(|p, q| order(p, q))
}

/// A measure of the particles' positions (in the backend's order) and each one's body.
type AtPositions<'a> = dyn Fn(&[[f64; 3]], &[u32]) -> Result<f64, BackendError> + 'a;

fn measure(m: Measure, scene: &Scene, b: &dyn Reader) -> Result<f64, BackendError> {
    let (dim, dx) = (b.plan().dim, scene.dx);
    // Where the particles are and which body each is in, read only by the measures that need
    // them: every rank's particles, for the measures that compare neighbours or order them along
    // an axis (gathered whole in a split run), ...
    let placed = |f: &AtPositions| {
        let Some(x) = positions(b)? else { return Ok(f64::NAN) };
        f(&x, &bodies_now(scene, &b.ids()?))
    };
    // ... and this rank's own, for those that merge the ranks' parts.
    let own = |f: &AtPositions| {
        let Some(x) = own_positions(b)? else { return Ok(f64::NAN) };
        f(&x, &bodies_now(scene, &b.ids_own()?))
    };
    Ok(match m {
        // Both are among the watchdog's reductions where the backend reduces them itself.
        Measure::KineticEnergy => match b.motion()? {
            Some(w) if !scene.spec.axisymmetric => w.kinetic,
            _ => kinetic_energy(scene, b)?,
        },
        Measure::MaxSpeed => match b.motion()? {
            Some(w) => w.max_speed,
            None => max_keeping_nan(0.0, speeds(b)?),
        },
        // The least distance between a particle of the first body and one of the second, over Δx.
        Measure::MinInterbodyDistance => match near_each_rank(m, scene, b)? {
            Some(v) => v,
            None => placed(&|x, which| Ok(interbody(x, which, dim, dx).0 / dx))?,
        },
        // Particles of the first two bodies closer than Δx/2 to a particle of the other body.
        Measure::Interpenetrated => match near_each_rank(m, scene, b)? {
            Some(v) => v,
            None => placed(&|x, which| Ok(interbody(x, which, dim, dx).1 as f64))?,
        },
        // Where a wave front driven by the first moving constraint, or the first body, has got to.
        Measure::FrontPosition => own(&|x, which| front_position(x, &drivers(scene, which, b)?, b))?,
        Measure::MinPairDistance => match near_each_rank(m, scene, b)? {
            Some(v) => v,
            None => placed(&|x, _| Ok(spacing_extremes(x, b)?.0))?,
        },
        Measure::MaxNeighbourGap => match near_each_rank(m, scene, b)? {
            Some(v) => v,
            None => placed(&|x, _| Ok(spacing_extremes(x, b)?.1))?,
        },
        Measure::CraterDiameter => own(&|x, which| Ok(crater_diameter(x, which, &counted(scene, b)?, scene, None, b)))?,
        Measure::IntactCraterDiameter => {
            own(&|x, which| Ok(crater_diameter(x, which, &counted(scene, b)?, scene, damage(b)?.as_deref(), b)))?
        }
        Measure::DebrisLength => own(&|x, _| Ok(debris(x, &counted(scene, b)?, scene, b).0))?,
        Measure::DebrisWidth => own(&|x, _| Ok(debris(x, &counted(scene, b)?, scene, b).1))?,
        Measure::DebrisLengthToWidth => own(&|x, _| {
            let (l, w) = debris(x, &counted(scene, b)?, scene, b);
            Ok(l / w)
        })?,
        Measure::PlugVelocity => own(&|x, which| plug_velocity(x, which, scene, b))?,
    })
}

/// The speed of the plug a projectile (the first body) pushes out of a plate (the second): the
/// mean velocity along the impact axis of the plate's particles now beyond both the plate's
/// initial rear face (by more than Δx) and the projectile's nose. Whether the plug leaves whole
/// or breaks up and spreads sideways, that is the plate material ahead of the projectile; zero
/// while there is none (below the ballistic limit, or before the plug leaves). `x` and `body` are
/// this rank's own particles; the nose and the mean are taken over the ranks.
fn plug_velocity(x: &[[f64; 3]], body: &[u32], scene: &Scene, b: &dyn Reader) -> Result<f64, BackendError> {
    let (Some(axis), Some(plate)) = (Axis::of(scene), scene.bodies.get(1)) else { return Ok(f64::NAN) };
    let Some(vf) = b.plan().model.field_id("v") else { return Ok(f64::NAN) };
    let Some(column) = b.read_own(vf)? else { return Ok(f64::NAN) };
    let (c, v) = (column.0, &column.1);
    let rear = max_keeping_nan(f64::NEG_INFINITY, plate.particles.clone().map(|k| axis.coords(scene.particles.x[k]).0));
    let mine = max_keeping_nan(f64::NEG_INFINITY, (0..x.len()).filter(|k| body[*k] == 0).map(|k| axis.coords(x[k]).0));
    let nose = max_keeping_nan(f64::NEG_INFINITY, b.all_gather(vec![mine]).into_iter().map(|p| p[0]));
    if nose.is_nan() {
        return Ok(f64::NAN);
    }
    let beyond = (rear + scene.dx).max(nose);
    let weight = |k: usize| if scene.spec.axisymmetric { ring(&x[k]) } else { 1.0 };
    let speeds: Vec<(f64, f64)> = (0..x.len())
        .filter(|k| body[*k] == 1 && axis.coords(x[*k]).0 > beyond)
        .map(|k| ((0..c).map(|d| v[k * c + d] * axis.dir[d]).sum::<f64>(), weight(k)))
        .collect();
    // A NaN speed makes the mean NaN.
    let plug = summed(b, vec![speeds.iter().map(|(s, w)| s * w).sum(), speeds.iter().map(|(_, w)| w).sum()]);
    let (sum, count) = (plug[0], plug[1]);
    Ok(if count == 0.0 { 0.0 } else { sum / count })
}

/// A measure that compares neighbours (`min_interbody_distance`, `interpenetrated`,
/// `min_pair_distance`, `max_neighbour_gap`) reduced on each rank over its own particles against
/// those near them ([`Reader::nearby`]), then over the ranks, where that gives what the undivided
/// particles give; `None` where it may not (the measure then gathers every particle) or for
/// another measure. Every rank calls it alike.
pub fn near_each_rank(m: Measure, scene: &Scene, b: &dyn Reader) -> Result<Option<f64>, BackendError> {
    Ok(match m {
        Measure::MinInterbodyDistance => interbody_near(scene, b)?.map(|(least, _)| least / scene.dx),
        Measure::Interpenetrated => interbody_near(scene, b)?.map(|(_, close)| close),
        Measure::MinPairDistance => spacing_near(b)?.map(|(least, _)| least),
        Measure::MaxNeighbourGap => spacing_near(b)?.map(|(_, gap)| gap),
        _ => None,
    })
}

/// [`spacing_extremes`] reduced on each rank over its own particles against those near them
/// ([`Reader::nearby`]), then over the ranks; `None` where that may not be what the undivided
/// particles give (a particle's nearest neighbour, capped at 3 Δx_i, lies past the reach), and the
/// caller gathers every particle.
fn spacing_near(b: &dyn Reader) -> Result<Option<(f64, f64)>, BackendError> {
    let (Some(near), Some(dxf)) = (b.nearby()?, b.plan().model.field_id("dx")) else { return Ok(None) };
    let Some(column) = b.read_own(dxf)? else { return Ok(None) };
    let mine = match column.1.len() == near.own {
        true => spacing_of(&near.x, &column.1, b.plan().dim, near.reach),
        false => None,
    };
    let (least, gap, exact) = mine.unwrap_or((f64::NAN, f64::NAN, false));
    let all = b.all_gather(vec![least, gap, f64::from(u8::from(exact))]);
    if all.iter().any(|p| p[2] != 1.0) {
        return Ok(None);
    }
    Ok(Some((all.iter().fold(f64::INFINITY, |m, p| m.min(p[0])), all.iter().fold(0.0, |m, p| m.max(p[1])))))
}

/// Over every particle, relative to its own spacing Δx_i: the least distance to another particle
/// (clumping: the tensile instability pulls particles together) and the largest distance to its
/// nearest neighbour (a crack or a particle left alone). Neighbours within 3 Δx_i are searched.
fn spacing_extremes(x: &[[f64; 3]], b: &dyn Reader) -> Result<(f64, f64), BackendError> {
    let Some(dxf) = b.plan().model.field_id("dx") else { return Ok((f64::NAN, f64::NAN)) };
    let Some(column) = b.read(dxf)? else { return Ok((f64::NAN, f64::NAN)) };
    let extremes = spacing_of(x, &column.1, b.plan().dim, f64::INFINITY);
    Ok(extremes.map_or((f64::NAN, f64::NAN), |(least, gap, _)| (least, gap)))
}

/// [`spacing_extremes`] over the first particles of `x`, those of the spacings `dx`, against
/// every particle of `x`, and whether each one's nearest (capped at 3 Δx_i) lies within `reach`;
/// `None` where a spacing is not a number.
fn spacing_of(x: &[[f64; 3]], dx: &[f64], dim: usize, reach: f64) -> Option<(f64, f64, bool)> {
    let cell = 3.0 * max_keeping_nan(0.0, dx.iter().copied());
    if !cell.is_finite() {
        return None;
    }
    let flat: Vec<f64> = x.iter().flat_map(|p| p[..dim].to_vec()).collect();
    let grid = crate::grid::Grid::build(&flat, dim, cell);
    let (mut least, mut gap, mut within) = (f64::INFINITY, 0.0f64, true);
    for (i, dx_i) in dx.iter().enumerate().take(x.len()) {
        let p = x[i];
        let mut nearest = f64::INFINITY;
        grid.for_each_candidate(p, |j| {
            if j as usize != i {
                let r = (0..dim).map(|c| (p[c] - x[j as usize][c]).powi(2)).sum::<f64>().sqrt();
                nearest = nearest.min(r);
            }
        });
        let nearest = nearest.min(3.0 * dx_i);
        within &= nearest <= reach;
        least = least.min(nearest / dx_i);
        gap = gap.max(nearest / dx_i);
    }
    Some((least, gap, within))
}

fn speeds(b: &dyn Reader) -> Result<Vec<f64>, BackendError> {
    let Some(v) = b.plan().model.field_id("v") else { return Ok(vec![]) };
    let Some(column) = b.read(v)? else { return Ok(vec![]) };
    let (c, v) = (column.0, &column.1);
    Ok(v.chunks(c).map(|u| u.iter().map(|x| x * x).sum::<f64>().sqrt()).collect())
}

/// Σ ½ m |v|² over every particle (in an axisymmetric case over its ring: m 2π r).
fn kinetic_energy(scene: &Scene, b: &dyn Reader) -> Result<f64, BackendError> {
    let Some(m) = b.plan().model.field_id("m") else { return Ok(f64::NAN) };
    let Some(column) = b.read(m)? else { return Ok(f64::NAN) };
    let (_, m) = (column.0, &column.1);
    let rings: Vec<f64> = match scene.spec.axisymmetric {
        true => positions(b)?.unwrap_or_default().iter().map(ring).collect(),
        false => vec![1.0; m.len()],
    };
    Ok(speeds(b)?.iter().zip(m).zip(&rings).map(|((s, m), w)| 0.5 * m * w * s * s).sum())
}

/// The impact axis: through the first body's centroid at t = 0, along its initial velocity.
struct Axis {
    origin: [f64; 3],
    dir: [f64; 3],
}

impl Axis {
    fn of(scene: &Scene) -> Option<Axis> {
        let first = scene.bodies.first()?.particles.clone();
        let n = first.len() as f64;
        let mut origin = [0.0; 3];
        let mut dir = [0.0; 3];
        for k in first {
            for c in 0..3 {
                origin[c] += scene.particles.x[k][c] / n;
                dir[c] += scene.particles.v[k][c] / n;
            }
        }
        // A body cut by symmetry planes is centred on them.
        for m in &scene.mirrors {
            origin[m.axis] = m.offset;
        }
        let len = dir.iter().map(|d| d * d).sum::<f64>().sqrt();
        (len > 0.0).then(|| Axis { origin, dir: dir.map(|d| d / len) })
    }
    /// (distance along the axis, distance from it).
    fn coords(&self, p: [f64; 3]) -> (f64, f64) {
        let d: Vec<f64> = (0..3).map(|c| p[c] - self.origin[c]).collect();
        let s: f64 = (0..3).map(|c| d[c] * self.dir[c]).sum();
        let r2: f64 = (0..3).map(|c| (d[c] - s * self.dir[c]).powi(2)).sum();
        (s, r2.max(0.0).sqrt())
    }
}

/// The diameter of the hole the first body makes in the second (a plate across the impact axis).
/// The plate's material is counted in rings of width Δx around the axis, at t = 0 and now, now
/// only within the plate's initial slab widened by its thickness on each side (so that bent or
/// lipped material still counts, and ejected material does not). The crater's radius is where the
/// ring's share of its initial count first reaches one half, interpolated between rings.
/// Given the damage `D` of every particle, only the intact ones (`D < 1`) count: a failed particle
/// carries no tension, so it is loose fragments that a recovered plate would not hold. `x`, `body`,
/// `weight` ([`counted`]) and the damage are this rank's own particles; the rings' counts are
/// summed over the ranks.
fn crater_diameter(
    x: &[[f64; 3]],
    body: &[u32],
    weight: &[f64],
    scene: &Scene,
    damage: Option<&[f64]>,
    b: &dyn Reader,
) -> f64 {
    let (Some(axis), Some(plate)) = (Axis::of(scene), scene.bodies.get(1)) else { return f64::NAN };
    let initial = plate.particles.clone().map(|k| (scene.particles.x[k], counted_weight(scene, k)));
    let Some(rings) = Rings::new(&axis, &initial.collect::<Vec<_>>(), scene.dx) else { return f64::NAN };
    rings.diameter(&summed(b, rings.count(plate_now(x, body, weight, damage))))
}

/// Where the second body's particles are now, with their weights, only the intact ones (`D < 1`)
/// given the damage.
fn plate_now<'a>(
    x: &'a [[f64; 3]],
    body: &'a [u32],
    weight: &'a [f64],
    damage: Option<&'a [f64]>,
) -> impl Iterator<Item = ([f64; 3], f64)> + 'a {
    let intact = move |k: usize| damage.is_none_or(|d| d[k] < 1.0);
    (0..x.len()).filter(move |k| body[*k] == 1 && intact(*k)).map(|k| (x[k], weight[k]))
}

/// What each of this rank's own particles weighs in the crater's and the debris cloud's counts.
fn counted(scene: &Scene, b: &dyn Reader) -> Result<Vec<f64>, BackendError> {
    Ok(b.ids_own()?.iter().map(|id| counted_weight(scene, *id as usize)).collect())
}

/// What the particle with id `k` weighs in the crater's and the debris cloud's counts: in a
/// planar case 1, a particle; in an axisymmetric one its ring's volume at t = 0, V 2π r, the
/// material it stands for, which its ring keeps as it moves in or out (m 2π r is constant, ṁ =
/// −m v_r / r): a particle pushed out from near the axis is a small ring among larger ones.
fn counted_weight(scene: &Scene, k: usize) -> f64 {
    match scene.spec.axisymmetric {
        true => scene.particles.vol[k] * ring(&scene.particles.x[k]),
        false => 1.0,
    }
}

/// The damage `D` of this rank's own particles, or none where the model has no damage (nothing
/// has failed).
fn damage(b: &dyn Reader) -> Result<Option<Vec<f64>>, BackendError> {
    let Some(d) = b.plan().model.field_id("D") else { return Ok(None) };
    Ok(b.read_own(d)?.map(|d| d.1.clone()))
}

/// The rings of [`crater_diameter`]: a plate's slab and its material per ring at t = 0.
struct Rings<'a> {
    axis: &'a Axis,
    width: f64,
    /// The slab along the axis where material counts, the plate's initial one widened by its
    /// thickness on each side.
    slab: (f64, f64),
    r_max: f64,
    before: Vec<f64>,
}

impl<'a> Rings<'a> {
    /// The rings of width `width` of a plate whose particles were at `initial`, each with its
    /// weight; `None` where the plate has no particles.
    fn new(axis: &'a Axis, initial: &[([f64; 3], f64)], width: f64) -> Option<Rings<'a>> {
        let weights: Vec<f64> = initial.iter().map(|p| p.1).collect();
        let initial: Vec<(f64, f64)> = initial.iter().map(|p| axis.coords(p.0)).collect();
        let (lo, hi) = initial.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, p| (a.0.min(p.0), a.1.max(p.0)));
        let r_max = max_keeping_nan(0.0, initial.iter().map(|p| p.1));
        if r_max.is_nan() {
            return None;
        }
        let n = (r_max / width).ceil() as usize + 1;
        let mut before = vec![0.0; n];
        for (p, w) in initial.iter().zip(weights) {
            before[((p.1 / width) as usize).min(n - 1)] += w;
        }
        let t = hi - lo;
        Some(Rings { axis, width, slab: (lo - t, hi + t), r_max, before })
    }

    /// How much of the weighted points `now` lies in each ring, within the slab.
    fn count(&self, now: impl Iterator<Item = ([f64; 3], f64)>) -> Vec<f64> {
        let n = self.before.len();
        let mut after = vec![0.0; n];
        for (p, w) in now {
            let (s, r) = self.axis.coords(p);
            if s >= self.slab.0 && s <= self.slab.1 && r < self.r_max {
                after[((r / self.width) as usize).min(n - 1)] += w;
            }
        }
        after
    }

    /// The hole's diameter, given the count now in each ring.
    fn diameter(&self, after: &[f64]) -> f64 {
        let share: Vec<f64> = self.before.iter().zip(after).map(|(b, a)| if *b > 0.0 { a / b } else { 1.0 }).collect();
        match share.iter().position(|s| *s >= 0.5) {
            Some(0) => 0.0,
            Some(k) => {
                // Ring k − 1 (centre (k − ½)Δx) is below one half, ring k (centre (k + ½)Δx) above.
                let (a, c) = (share[k - 1], share[k]);
                2.0 * self.width * (k as f64 - 0.5 + (0.5 - a) / (c - a))
            }
            None => f64::NAN,
        }
    }
}

/// [`crater_diameter`] of a plate whose particles were at `initial` and are now at `now`, in a
/// run in one piece.
#[cfg(test)]
fn hole_diameter(axis: &Axis, initial: &[[f64; 3]], now: impl Iterator<Item = ([f64; 3], f64)>, ring: f64) -> f64 {
    let initial: Vec<([f64; 3], f64)> = initial.iter().map(|p| (*p, 1.0)).collect();
    Rings::new(axis, &initial, ring).map_or(f64::NAN, |r| r.diameter(&r.count(now)))
}

/// The debris cloud behind the plate: every particle more than Δx beyond the second body's
/// initial rear face (along the impact axis). Its length is how far beyond the rear face it
/// reaches, its width twice its reach from the axis, both as the 99th percentile over its
/// particles so that a few stray particles do not set them; in an axisymmetric case over its
/// rings, each with its `weight` ([`counted`]). `x` and `weight` are this rank's own particles;
/// the ranks' debris particles are gathered (the cloud's, not the whole scene's).
fn debris(x: &[[f64; 3]], weight: &[f64], scene: &Scene, b: &dyn Reader) -> (f64, f64) {
    let (Some(axis), Some(plate)) = (Axis::of(scene), scene.bodies.get(1)) else { return (f64::NAN, f64::NAN) };
    let rear = max_keeping_nan(f64::NEG_INFINITY, plate.particles.clone().map(|k| axis.coords(scene.particles.x[k]).0));
    let behind = |k: &usize| axis.coords(x[*k]).0 > rear + scene.dx;
    let mine = (0..x.len()).filter(behind).flat_map(|k| {
        let (s, r) = axis.coords(x[k]);
        [s - rear, r, weight[k]]
    });
    let cloud: Vec<f64> = b.all_gather(mine.collect()).concat();
    if cloud.len() < 3 * 10 {
        return (f64::NAN, f64::NAN);
    }
    // (value, weight) pairs: along the axis, and from it.
    let mut along: Vec<(f64, f64)> = cloud.chunks(3).map(|p| (p[0], p[2])).collect();
    let mut across: Vec<(f64, f64)> = cloud.chunks(3).map(|p| (p[1], p[2])).collect();
    let quantile = |v: &mut [(f64, f64)]| match scene.spec.axisymmetric {
        true => weighted_percentile(v, 0.99),
        false => percentile(&mut v.iter().map(|p| p.0).collect::<Vec<_>>(), 0.99),
    };
    (quantile(&mut along), 2.0 * quantile(&mut across))
}

/// The `q` quantile of values each with its weight `(value, weight)`: the least value at which
/// the weights summed in order of value reach q of their total.
fn weighted_percentile(v: &mut [(f64, f64)], q: f64) -> f64 {
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = v.iter().map(|p| p.1).sum();
    let mut sum = 0.0;
    for (value, w) in v.iter() {
        sum += w;
        if sum >= q * total {
            return *value;
        }
    }
    v.last().map_or(f64::NAN, |p| p.0)
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// The particles that drive a wave front: those of the first constraint that moves (a piston,
/// a body of its own or a region of the body it drives), else the first body.
fn drivers(scene: &Scene, body: &[u32], b: &dyn Reader) -> Result<Vec<bool>, BackendError> {
    let moving = scene.spec.constraints.iter().find(|c| c.velocity.iter().any(|v| *v != 0.0));
    let first_body = || body.iter().map(|w| *w == 0).collect();
    Ok(match moving.map(|c| c.target) {
        Some(Target::Body(k)) => body.iter().map(|w| *w as usize == k).collect(),
        Some(Target::Part(k)) => match b.plan().model.field_id("part").map(|f| b.read_own(f)).transpose()?.flatten() {
            Some(part) => part.1.iter().map(|p| *p == k as f64).collect(),
            None => first_body(),
        },
        None => first_body(),
    })
}

/// Where a wave front has got to: along the first axis, the position at which the speed falls
/// through half the drivers' mean speed, interpolated linearly between the last particle above
/// and the next one below (particles ordered by position, then by id). `x` and `driving` are this
/// rank's own particles; the drivers' mean, the last particle above and the next one are each
/// found over the ranks (three numbers a rank each).
fn front_position(x: &[[f64; 3]], driving: &[bool], b: &dyn Reader) -> Result<f64, BackendError> {
    let Some(v) = b.plan().model.field_id("v") else { return Ok(f64::NAN) };
    let Some(column) = b.read_own(v)? else { return Ok(f64::NAN) };
    let (c, v) = (column.0, &column.1);
    let ids = b.ids_own()?;
    let speed: Vec<f64> =
        (0..x.len()).map(|k| v[k * c..(k + 1) * c].iter().map(|u| u * u).sum::<f64>().sqrt()).collect();
    let driver: Vec<f64> = (0..x.len()).filter(|k| driving[*k]).map(|k| speed[k]).collect();
    let drivers = summed(b, vec![driver.iter().sum(), driver.len() as f64]);
    let (sum, count) = (drivers[0], drivers[1]);
    if count == 0.0 {
        return Ok(f64::NAN);
    }
    let half = 0.5 * sum / count;
    // A particle as (position, id, speed), ordered by position, then id.
    let row = |k: usize| [x[k][0], ids[k] as f64, speed[k]];
    let order = |p: &[f64], q: &[f64]| p[0].total_cmp(&q[0]).then(p[1].total_cmp(&q[1]));
    let above = (0..x.len()).filter(|k| speed[*k] > half).map(row).max_by(|p, q| order(p, q));
    let Some(a) = greatest(b, above.map(Vec::from), order) else { return Ok(f64::NAN) };
    let after = (0..x.len()).map(row).filter(|r| order(r, &a).is_gt()).min_by(|p, q| order(p, q));
    Ok(match greatest(b, after.map(Vec::from), |p, q| order(q, p)) {
        Some(n) => {
            let t = (a[2] - half) / (a[2] - n[2]);
            a[0] + t * (n[0] - a[0])
        }
        None => a[0],
    })
}

/// [`interbody`] reduced on each rank over its own particles against those near them
/// ([`Reader::nearby`]), then over the ranks: (least distance, particles closer than Δx/2 to the
/// other body). `None` where that may not be what the undivided particles give (the bodies are
/// farther apart than 2 Δx, where [`interbody`] searches them all, or than the reach), and the
/// caller gathers every particle.
fn interbody_near(scene: &Scene, b: &dyn Reader) -> Result<Option<(f64, f64)>, BackendError> {
    let Some(near) = b.nearby()? else { return Ok(None) };
    let (dim, dx) = (b.plan().dim, scene.dx);
    let body = bodies_now(scene, &near.ids);
    let grids: Vec<(Vec<usize>, crate::grid::Grid)> = (0..2)
        .map(|k| {
            let side: Vec<usize> = (0..near.x.len()).filter(|i| body[*i] == k).collect();
            let flat: Vec<f64> = side.iter().flat_map(|i| near.x[*i][..dim].to_vec()).collect();
            let grid = crate::grid::Grid::build(&flat, dim, 2.0 * dx);
            (side, grid)
        })
        .collect();
    let (mut least, mut close) = (f64::INFINITY, 0usize);
    for i in (0..near.own).filter(|i| body[*i] < 2) {
        let (side, grid) = &grids[1 - body[i] as usize];
        let mut touching = false;
        grid.for_each_candidate(near.x[i], |j| {
            let q = near.x[side[j as usize]];
            let r = (0..dim).map(|c| (near.x[i][c] - q[c]).powi(2)).sum::<f64>().sqrt();
            least = least.min(r);
            touching |= r < 0.5 * dx;
        });
        close += usize::from(touching);
    }
    let all = b.all_gather(vec![least, close as f64, near.reach]);
    let least = all.iter().fold(f64::INFINITY, |m, p| m.min(p[0]));
    let reach = all.iter().fold(f64::INFINITY, |m, p| m.min(p[2]));
    let exact = least <= 2.0 * dx && least <= reach && 0.5 * dx <= reach;
    Ok(exact.then(|| (least, all.iter().map(|p| p[1]).sum())))
}

/// (least distance between bodies 0 and 1, number of particles of either closer than Δx/2 to the
/// other body). Neighbours come from a cell list of body 1; if no pair is within two spacings, the
/// distance is found by brute force (bodies still apart).
fn interbody(x: &[[f64; 3]], body: &[u32], dim: usize, dx: f64) -> (f64, usize) {
    let a: Vec<usize> = (0..x.len()).filter(|k| body[*k] == 0).collect();
    let b: Vec<usize> = (0..x.len()).filter(|k| body[*k] == 1).collect();
    if a.is_empty() || b.is_empty() {
        return (f64::NAN, 0);
    }
    let flat: Vec<f64> = b.iter().flat_map(|k| x[*k][..dim].to_vec()).collect();
    let grid = crate::grid::Grid::build(&flat, dim, 2.0 * dx);
    let dist = |p: [f64; 3], q: [f64; 3]| (0..dim).map(|c| (p[c] - q[c]).powi(2)).sum::<f64>().sqrt();
    let mut least = f64::INFINITY;
    let mut close_a = 0;
    let mut close_b = vec![false; b.len()];
    for &i in &a {
        let mut near = false;
        grid.for_each_candidate(x[i], |j| {
            let r = dist(x[i], x[b[j as usize]]);
            least = least.min(r);
            if r < 0.5 * dx {
                near = true;
                close_b[j as usize] = true;
            }
        });
        close_a += usize::from(near);
    }
    if least > 2.0 * dx && a.len().saturating_mul(b.len()) <= 100_000_000 {
        for &i in &a {
            for &j in &b {
                least = least.min(dist(x[i], x[j]));
            }
        }
    }
    (least, close_a + close_b.iter().filter(|c| **c).count())
}

impl History {
    /// A history resumed from a checkpoint: its points so far, the value a relative probe
    /// measures from and the last value sampled.
    pub fn resumed(points: Vec<(f64, f64)>, initial: Option<f64>, last: Option<f64>) -> History {
        History { points, initial, last }
    }

    /// The value a relative probe measures from (its first value), once recorded.
    pub fn initial(&self) -> Option<f64> {
        self.initial
    }

    /// The last value sampled, once recorded (what an integrating probe integrates on from).
    pub fn last(&self) -> Option<f64> {
        self.last
    }

    pub fn record(&mut self, p: &ProbeSpec, t: f64, value: f64) {
        let base = *self.initial.get_or_insert(value);
        let recorded = match p.record {
            Record::Value => value,
            Record::Change => value - base,
            Record::Integral => match (self.points.last(), self.last) {
                (Some(&(t0, sum)), Some(v0)) => sum + 0.5 * (v0 + value) * (t - t0),
                _ => 0.0,
            },
        };
        self.last = Some(value);
        self.points.push((t, recorded));
    }
}

/// NaN when a value of `points` is NaN, otherwise `f(points)`.
fn nan_or(points: &[(f64, f64)], f: impl Fn(&[(f64, f64)]) -> f64) -> f64 {
    if points.iter().any(|p| p.1.is_nan()) {
        f64::NAN
    } else {
        f(points)
    }
}

/// The mean of the values (NaN for none).
fn mean(values: &[(f64, f64)]) -> f64 {
    if values.is_empty() {
        f64::NAN
    } else {
        values.iter().map(|p| p.1).sum::<f64>() / values.len() as f64
    }
}

/// The period of an oscillation: twice the mean spacing of the times at which the history crosses
/// its mean over the window (interpolated linearly); NaN with fewer than three crossings (one
/// whole period) or a NaN in the window.
fn period(window: &[(f64, f64)]) -> f64 {
    let level = mean(window);
    let crossings: Vec<f64> = window
        .windows(2)
        .filter(|w| (w[0].1 - level) * (w[1].1 - level) < 0.0)
        .map(|w| w[0].0 + (w[1].0 - w[0].0) * (w[0].1 - level) / (w[0].1 - w[1].1))
        .collect();
    match crossings.as_slice() {
        [first, .., last] if crossings.len() >= 3 && level.is_finite() => {
            2.0 * (last - first) / (crossings.len() - 1) as f64
        }
        _ => f64::NAN,
    }
}

/// A result from its probe's history.
pub fn result_value(r: &ResultSpec, h: &History) -> f64 {
    let pts = &h.points;
    // The window [from, to] (the whole history by default).
    let (from, to) = (r.from.unwrap_or(f64::NEG_INFINITY), r.to.unwrap_or(f64::INFINITY));
    let window: Vec<(f64, f64)> = pts.iter().copied().filter(|p| p.0 >= from && p.0 <= to).collect();
    let v = match r.at.as_str() {
        // A NaN recorded in the window makes these NaN (`f64::min` and `f64::max` would drop it).
        "min" => -max_keeping_nan(f64::NEG_INFINITY, window.iter().map(|p| -p.1)),
        "max" => max_keeping_nan(f64::NEG_INFINITY, window.iter().map(|p| p.1)),
        "abs_max" => max_keeping_nan(0.0, window.iter().map(|p| p.1.abs())),
        "mean" | "mean_after" => mean(&window),
        "period" => nan_or(&window, period),
        "frequency" => 1.0 / nan_or(&window, period),
        // The least-squares slope of the history between `from` and `to`.
        "slope" => {
            let (from, to) = (r.from.unwrap_or(f64::NEG_INFINITY), r.to.unwrap_or(f64::INFINITY));
            let sel: Vec<(f64, f64)> =
                pts.iter().copied().filter(|p| p.0 >= from && p.0 <= to && p.1.is_finite()).collect();
            let n = sel.len() as f64;
            if sel.len() < 2 {
                f64::NAN
            } else {
                let (mt, mv) = (sel.iter().map(|p| p.0).sum::<f64>() / n, sel.iter().map(|p| p.1).sum::<f64>() / n);
                let cov: f64 = sel.iter().map(|p| (p.0 - mt) * (p.1 - mv)).sum();
                let var: f64 = sel.iter().map(|p| (p.0 - mt).powi(2)).sum();
                cov / var
            }
        }
        // The first time after `from` at which the history changes sign (linear interpolation).
        "zero_crossing" => {
            let from = r.from.unwrap_or(f64::NEG_INFINITY);
            let sel: Vec<(f64, f64)> = pts.iter().copied().filter(|p| p.0 >= from && p.1.is_finite()).collect();
            sel.windows(2)
                .find(|w| w[0].1 != 0.0 && w[0].1.signum() != w[1].1.signum())
                .map(|w| w[0].0 + (w[1].0 - w[0].0) * w[0].1 / (w[0].1 - w[1].1))
                .unwrap_or(f64::NAN)
        }
        // The history at `time`, interpolated linearly (NaN outside the recorded span).
        "at_time" => {
            let t = r.time.unwrap_or(f64::NAN);
            pts.windows(2)
                .find(|w| w[0].0 <= t && t <= w[1].0)
                .map(|w| {
                    if w[1].0 > w[0].0 {
                        w[0].1 + (w[1].1 - w[0].1) * (t - w[0].0) / (w[1].0 - w[0].0)
                    } else {
                        w[0].1
                    }
                })
                .unwrap_or(f64::NAN)
        }
        _ => pts.last().map(|p| p.1).unwrap_or(f64::NAN),
    };
    v * r.scale + r.offset
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_probe_leaves_nan_values_out_and_its_parts_merge_to_the_whole_reduction() {
        let v = [1.0, f64::NAN, -3.0, 2.5, -0.5];
        for (reduce, whole) in [("min", -3.0), ("max", 2.5), ("abs_max", 3.0), ("sum", 0.0), ("mean", 0.0)] {
            assert_eq!(Partial::of(reduce, v).value(), whole, "{reduce}");
            // Split anywhere, the parts merged (through their numbers, as ranks send them) give the same.
            for cut in 0..=v.len() {
                let parts = [Partial::of(reduce, v[..cut].to_vec()), Partial::of(reduce, v[cut..].to_vec())];
                let sent: Vec<Vec<f64>> = parts.iter().map(|p| p.parts().to_vec()).collect();
                assert_eq!(parts[0].merge_all(&sent).value(), whole, "{reduce} cut at {cut}");
            }
            assert!(Partial::of(reduce, [f64::NAN]).value().is_nan(), "{reduce} of no value");
            assert!(Partial::of(reduce, []).merge_all(&[vec![f64::INFINITY, 0.0]]).value().is_nan(), "{reduce}");
        }
        assert_eq!(Partial::of("mean", [1.0, -3.0]).value(), -1.0);
        assert!(max_keeping_nan(0.0, [2.0, f64::NAN, 5.0]).is_nan(), "a NaN speed among finite ones");
        assert_eq!(max_keeping_nan(0.0, [2.0, 5.0]), 5.0);
    }

    fn result(at: &str, time: Option<f64>) -> ResultSpec {
        ResultSpec {
            quantity: "q".into(),
            probe: 0,
            at: at.into(),
            from: None,
            to: None,
            time,
            scale: 1.0,
            offset: 0.0,
            unit: String::new(),
            reference: None,
            source: None,
            tolerance: None,
            tolerance_why: None,
        }
    }

    #[test]
    fn a_result_is_its_value_at_times_scale_plus_offset() {
        // A foot's radius grows by 0.5 mm from 3.2 mm: its diameter is 2 × 0.5 mm + 6.4 mm.
        let h = History { points: vec![(0.0, 0.0), (1.0, 2.5e-4), (2.0, 5e-4)], initial: None, last: None };
        let r = ResultSpec { scale: 2.0, offset: 6.4e-3, ..result("end", None) };
        assert!((result_value(&r, &h) - 7.4e-3).abs() < 1e-15);
        let r = ResultSpec { scale: 2.0, offset: 6.4e-3, ..result("at_time", Some(1.0)) };
        assert!((result_value(&r, &h) - 6.9e-3).abs() < 1e-15);
    }

    #[test]
    fn period_frequency_and_window_extremes_of_a_sampled_damped_oscillation_about_an_offset() {
        // 0.3 + e^(−t/20) sin(2π t / 0.7), sampled every 1e-3 over 0 … 5.
        let points: Vec<(f64, f64)> = (0..=5000)
            .map(|k| {
                let t = k as f64 * 1e-3;
                (t, 0.3 + (-t / 20.0).exp() * (2.0 * std::f64::consts::PI * t / 0.7).sin())
            })
            .collect();
        let h = History { points, initial: None, last: None };
        let window = |at: &str, from: f64, to: f64| {
            let r = ResultSpec { from: Some(from), to: Some(to), ..result(at, None) };
            result_value(&r, &h)
        };
        // The crossings of the window's mean are those of 0.3 to within the slow decay.
        let p = window("period", 1.0, 4.5);
        assert!((p - 0.7).abs() < 1e-3 * 0.7, "period {p}");
        assert!((window("frequency", 1.0, 4.5) - 1.0 / p).abs() < 1e-12);
        // Less than a whole period in the window: no period.
        assert!(window("period", 1.0, 1.3).is_nan());
        // The first quarter period peaks at 0.3 + e^(−0.175/20) = 1.2913; the window keeps the
        // earlier, larger peak out of the later maximum.
        let (early, late) = (window("max", 0.0, 0.35), window("max", 3.0, 5.0));
        assert!((early - (0.3 + (-0.175_f64 / 20.0).exp())).abs() < 1e-5, "max {early}");
        assert!(late < early - 0.1, "max over 3–5 s {late} against {early}");
        let mean = window("mean", 0.0, 4.9);
        assert!((mean - 0.3).abs() < 0.01, "mean over seven periods {mean}");
    }

    fn probe_recording(record: Record) -> ProbeSpec {
        ProbeSpec { name: "e".into(), kind: ProbeKind::Measure(Measure::ALL[0]), record, unit: String::new(), every: 1 }
    }

    #[test]
    fn a_relative_measure_records_its_change_from_the_first_value() {
        for (record, expected) in [(Record::Change, [0.0, 2.5]), (Record::Value, [4.0, 6.5])] {
            let mut h = History::default();
            h.record(&probe_recording(record), 0.0, 4.0);
            h.record(&probe_recording(record), 1.0, 6.5);
            assert_eq!(h.points, vec![(0.0, expected[0]), (1.0, expected[1])], "{record:?}");
        }
    }

    /// A power P(t) = 3 + 2 t sampled at uneven times: the trapezoidal rule integrates a line
    /// exactly, so each point is 3 t + t² from the first sample; a checkpoint's history resumed
    /// with its last value goes on to the same points, and a NaN sampled stays in the sum.
    #[test]
    fn an_integrating_probe_records_the_work_of_a_power_from_its_first_sample_and_resumes_it() {
        let probe = probe_recording(Record::Integral);
        let times = [0.0, 0.5, 0.75, 2.0, 3.5];
        let mut h = History::default();
        for &t in &times {
            h.record(&probe, t, 3.0 + 2.0 * t);
        }
        for (&(t, w), &t_expected) in h.points.iter().zip(&times) {
            assert_eq!(t, t_expected);
            assert!((w - (3.0 * t + t * t)).abs() < 1e-12, "work {w} at t = {t}, expected {}", 3.0 * t + t * t);
        }
        let mut resumed = History::resumed(h.points[..3].to_vec(), h.initial(), Some(3.0 + 2.0 * 0.75));
        for &t in &times[3..] {
            resumed.record(&probe, t, 3.0 + 2.0 * t);
        }
        assert_eq!(resumed.points, h.points);
        h.record(&probe, 4.0, f64::NAN);
        h.record(&probe, 5.0, 1.0);
        assert!(h.points[5].1.is_nan() && h.points[6].1.is_nan(), "{:?}", &h.points[5..]);
    }

    /// A plate 3 particles thick, Δx = 1 mm, 40 mm across, on a square lattice normal to z.
    fn plate() -> Vec<[f64; 3]> {
        let mut p = vec![];
        for i in -20..20 {
            for j in -20..20 {
                for k in 0..3 {
                    p.push([(i as f64 + 0.5) * 1e-3, (j as f64 + 0.5) * 1e-3, -(k as f64 + 0.5) * 1e-3]);
                }
            }
        }
        p
    }

    #[test]
    fn the_crater_of_a_plate_with_a_punched_hole_is_the_hole() {
        let axis = Axis { origin: [0.0; 3], dir: [0.0, 0.0, -1.0] };
        let initial = plate();
        for radius in [3e-3, 5.5e-3, 10e-3] {
            let r = |p: &[f64; 3]| (p[0] * p[0] + p[1] * p[1]).sqrt();
            let punched = initial.iter().filter(|p| r(p) >= radius).map(|p| (*p, 1.0));
            let d = hole_diameter(&axis, &initial, punched, 1e-3);
            // Rings of one spacing: the edge is found within half a spacing on the radius.
            assert!((d - 2.0 * radius).abs() <= 1e-3, "hole of radius {radius}: crater {d}");
            // Material pushed out of the hole and gone (beyond the slab widened by its thickness)
            // does not count; material bent into a lip within it does.
            let ejected = initial.iter().map(|p| (if r(p) < radius { [p[0], p[1], p[2] - 0.1] } else { *p }, 1.0));
            assert!((hole_diameter(&axis, &initial, ejected, 1e-3) - d).abs() < 1e-12);
            let lip = initial.iter().map(|p| (if r(p) < radius { [p[0], p[1], p[2] - 2e-3] } else { *p }, 1.0));
            assert_eq!(hole_diameter(&axis, &initial, lip, 1e-3), 0.0);
        }
        assert_eq!(hole_diameter(&axis, &initial, initial.iter().map(|p| (*p, 1.0)), 1e-3), 0.0, "no hole");
    }

    #[test]
    fn the_intact_crater_leaves_out_the_failed_rim_and_the_crater_keeps_it() {
        let axis = Axis { origin: [0.0; 3], dir: [0.0, 0.0, -1.0] };
        let initial = plate();
        let r = |p: &[f64; 3]| (p[0] * p[0] + p[1] * p[1]).sqrt();
        // A hole of radius 5 mm, its rim failed out to 8 mm.
        let x: Vec<[f64; 3]> = initial.iter().filter(|p| r(p) >= 5e-3).copied().collect();
        let body = vec![1; x.len()];
        let one = vec![1.0; x.len()];
        let damage: Vec<f64> = x.iter().map(|p| if r(p) < 8e-3 { 1.0 } else { 0.3 }).collect();
        let all = hole_diameter(&axis, &initial, plate_now(&x, &body, &one, None), 1e-3);
        let intact = hole_diameter(&axis, &initial, plate_now(&x, &body, &one, Some(&damage)), 1e-3);
        assert!((all - 10e-3).abs() <= 1e-3, "crater {all}");
        assert!((intact - 16e-3).abs() <= 1e-3, "intact crater {intact}");
        // Another body's particles never count.
        let other: Vec<u32> = x.iter().map(|p| u32::from(r(p) >= 8e-3)).collect();
        assert_eq!(hole_diameter(&axis, &initial, plate_now(&x, &other, &one, None), 1e-3), intact);
    }

    /// An axisymmetric plate's rings, each particle weighed by its ring (its radius at t = 0, the
    /// spacing 1 mm): the hole from the axis to 6 mm, with the four particles of the ring nearest
    /// the axis (r0 = 0.5 mm) pushed out into the ring at 5–6 mm. By the rings' material that
    /// ring holds 4 × 0.5 / (4 × 5.5) = 1/11 of its own, and the edge lies between it and the
    /// next, whole ring: 2 (5.5 + (½ − 1/11) / (1 − 1/11)) = 11.9 mm. By count it is whole again
    /// (four particles), and the hole would be 10 mm across.
    #[test]
    fn an_axisymmetric_crater_weighs_a_particle_pushed_outward_as_its_ring() {
        let axis = Axis { origin: [0.0; 3], dir: [0.0, -1.0, 0.0] };
        let initial: Vec<([f64; 3], f64)> = (0..40 * 4)
            .map(|n| [(n / 4) as f64 + 0.5, -((n % 4) as f64 + 0.5), 0.0])
            .map(|p| (p.map(|c| c * 1e-3), p[0]))
            .collect();
        let rings = Rings::new(&axis, &initial, 1e-3).expect("a plate");
        let now = || {
            initial.iter().filter_map(|(p, w)| match p[0] {
                r if r < 1e-3 => Some(([5.5e-3, p[1], 0.0], *w)),
                r if r < 6e-3 => None,
                _ => Some((*p, *w)),
            })
        };
        let by_ring = rings.diameter(&rings.count(now()));
        assert!((by_ring - 11.9e-3).abs() < 1e-12, "weighed by ring: {by_ring}");
        let counted =
            Rings::new(&axis, &initial.iter().map(|(p, _)| (*p, 1.0)).collect::<Vec<_>>(), 1e-3).expect("a plate");
        let by_count = counted.diameter(&counted.count(now().map(|(p, _)| (p, 1.0))));
        assert!((by_count - 10e-3).abs() < 1e-12, "counted: {by_count}");
    }

    #[test]
    fn a_weighted_percentile_is_where_the_weights_reach_the_share() {
        let mut v = [(3.0, 1.0), (1.0, 1.0), (2.0, 1.0), (4.0, 7.0)];
        assert_eq!(weighted_percentile(&mut v, 0.35), 4.0);
        assert_eq!(weighted_percentile(&mut v, 0.25), 3.0);
        assert_eq!(weighted_percentile(&mut v, 0.15), 2.0);
        assert_eq!(weighted_percentile(&mut v, 0.05), 1.0);
    }

    #[test]
    fn interpenetration_is_measured_on_a_constructed_overlap() {
        // Two 5 × 5 × 5 cubes of spacing 1, the second shifted by 5 − overlap along x.
        let cube = |shift: f64| -> Vec<[f64; 3]> {
            (0..125).map(|n| [(n % 5) as f64 + shift, ((n / 5) % 5) as f64, (n / 25) as f64]).collect()
        };
        for (gap, close) in [(1.0, 0), (0.6, 0), (0.3, 50), (-0.2, 50)] {
            // The second cube's first layer is `gap` beyond the first cube's last (x = 4).
            let mut x = cube(0.0);
            x.extend(cube(4.0 + gap));
            let body: Vec<u32> = (0..250).map(|k| u32::from(k >= 125)).collect();
            let (least, n) = interbody(&x, &body, 3, 1.0);
            assert!((least - gap.abs()).abs() < 1e-12, "gap {gap}: least {least}");
            // Within Δx/2: the facing layer of each cube (25 + 25 particles).
            assert_eq!(n, close, "gap {gap}");
        }
    }

    #[test]
    fn at_time_interpolates_the_history_and_is_nan_outside_it() {
        let h = History { points: vec![(0.0, 1.0), (0.1, 3.0), (0.3, -1.0)], ..Default::default() };
        let at = |t: f64| result_value(&result("at_time", Some(t)), &h);
        assert!((at(0.05) - 2.0).abs() < 1e-12);
        assert!((at(0.1) - 3.0).abs() < 1e-12);
        assert!((at(0.25) - 0.0).abs() < 1e-12);
        assert!(at(0.31).is_nan() && at(-0.01).is_nan());
    }
}
