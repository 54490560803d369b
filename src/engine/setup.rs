//! From the scene's particles and materials to a particle store: particles sorted by group,
//! the scene-set fields written, every material's parameters resolved (defaults included) and
//! checked against what the plan reads.

use crate::host_eval;
use crate::ir::{self, Expr, FieldId, GroupId, GroupSet, Model, ParamId};
use crate::particles::{Real, Store};
use crate::schedule::Plan;
use std::collections::{BTreeMap, BTreeSet};

/// Particles as the scene places them (any order).
#[derive(Clone, Debug, Default)]
pub struct ParticleInput {
    pub x: Vec<[f64; 3]>,
    pub v: Vec<[f64; 3]>,
    pub vol: Vec<f64>,
    pub dx: Vec<f64>,
    pub body: Vec<u32>,
    /// The load/constraint region each particle lies in, −1 for none.
    pub part: Vec<i32>,
    pub group: Vec<u32>,
    pub material: Vec<u32>,
    /// Initial values the case gives per body, evaluated for each of its particles after the
    /// model's own (which they replace).
    pub initial: Vec<InitialValue>,
}

/// `initial = { field = "expression" }` of one body.
#[derive(Clone, Debug)]
pub struct InitialValue {
    pub field: FieldId,
    pub body: u32,
    pub value: Expr,
}

impl ParticleInput {
    pub fn len(&self) -> usize {
        self.x.len()
    }
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }
    /// The groups that have particles.
    pub fn groups(&self) -> GroupSet {
        self.group.iter().fold(GroupSet::default(), |s, g| s.with(GroupId(*g)))
    }

    /// The particles at `keep` (indices into these), in that order.
    pub fn subset(&self, keep: &[usize]) -> ParticleInput {
        fn pick<V: Clone>(v: &[V], keep: &[usize]) -> Vec<V> {
            keep.iter().map(|k| v[*k].clone()).collect()
        }
        ParticleInput {
            x: pick(&self.x, keep),
            v: pick(&self.v, keep),
            vol: pick(&self.vol, keep),
            dx: pick(&self.dx, keep),
            body: pick(&self.body, keep),
            part: keep.iter().map(|k| self.part.get(*k).copied().unwrap_or(-1)).collect(),
            group: pick(&self.group, keep),
            material: pick(&self.material, keep),
            initial: self.initial.clone(),
        }
    }
}

/// The values a material binds, by parameter (others take their defaults).
#[derive(Clone, Debug, Default)]
pub struct MaterialInput {
    pub name: String,
    pub values: BTreeMap<ParamId, Vec<f64>>,
}

/// A scene that cannot be set up: a code of `docs/ERRORS.md` and what is wrong, naming the
/// material, body or field of the case.
#[derive(Debug, Clone)]
pub struct SetupError {
    pub code: &'static str,
    pub message: String,
}

impl SetupError {
    fn new(code: &'static str, message: impl Into<String>) -> Self {
        SetupError { code, message: message.into() }
    }
}

impl std::fmt::Display for SetupError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "error[{}]: {}", self.code, self.message)
    }
}

/// Every parameter's value for one material: bound, else its default (which may read the
/// material's other parameters), else missing.
pub fn resolve_material(model: &Model, dim: usize, m: &MaterialInput) -> Vec<Option<Vec<f64>>> {
    let mut out: Vec<Option<Vec<f64>>> = vec![None; model.params.len()];
    for (p, v) in &m.values {
        out[p.index()] = Some(v.clone());
    }
    for k in 0..model.params.len() {
        let mut busy = BTreeSet::new();
        resolve(model, dim, ParamId(k as u32), &mut out, &mut busy);
    }
    out
}

/// Every material's parameters, defaults resolved, with the scene's own constants (gravity, loads,
/// prescribed velocities), which are the same for all.
pub fn resolved_materials(plan: &Plan, materials: &[MaterialInput]) -> Vec<Vec<Option<Vec<f64>>>> {
    let mut resolved: Vec<Vec<Option<Vec<f64>>>> =
        materials.iter().map(|m| resolve_material(&plan.model, plan.dim, m)).collect();
    for values in &mut resolved {
        for sp in &plan.scene_params {
            values[sp.param.index()] = Some(sp.value.clone());
        }
    }
    resolved
}

/// The value of a case's expression for particle `k` of `fields` (a probe's `expression`), with
/// its material's parameters `params`.
pub fn particle_value(
    plan: &Plan,
    e: &Expr,
    params: &mut Vec<Option<Vec<f64>>>,
    fields: &HostFields,
    k: usize,
) -> Result<Vec<f64>, String> {
    eval(&plan.model, plan.dim, e, params, &mut BTreeSet::new(), Some((fields, k)))
}

fn resolve(
    model: &Model,
    dim: usize,
    p: ParamId,
    out: &mut Vec<Option<Vec<f64>>>,
    busy: &mut BTreeSet<ParamId>,
) -> Option<Vec<f64>> {
    if let Some(v) = &out[p.index()] {
        return Some(v.clone());
    }
    let default = model.params[p.index()].default.clone()?;
    if !busy.insert(p) {
        return None;
    }
    let v = eval(model, dim, &default, out, busy, None).ok()?;
    out[p.index()] = Some(v.clone());
    Some(v)
}

/// Per-particle values known on the host (scene fields and computed initial values), `n × comps`
/// in the scene's order.
pub type HostFields = BTreeMap<FieldId, (usize, Vec<f64>)>;

/// The leaves of a parameter default or an initial value: the material's parameters (resolved
/// in turn) and, for an initial value, the fields the scene set on one particle.
struct HostLeaves<'a> {
    model: &'a Model,
    dim: usize,
    params: &'a mut Vec<Option<Vec<f64>>>,
    busy: &'a mut BTreeSet<ParamId>,
    particle: Option<(&'a HostFields, usize)>,
}

impl host_eval::Leaves for HostLeaves<'_> {
    fn field(&mut self, f: FieldId) -> Result<Vec<f64>, String> {
        let not_set = || format!("it reads `{}`, which the scene does not set", self.model.field(f).name);
        let (fields, k) = self.particle.ok_or_else(not_set)?;
        let (comps, values) = fields.get(&f).ok_or_else(not_set)?;
        Ok(values[k * comps..(k + 1) * comps].to_vec())
    }
    fn param(&mut self, p: ParamId) -> Result<Vec<f64>, String> {
        resolve(self.model, self.dim, p, self.params, self.busy).ok_or_else(|| {
            format!("it reads `{}`, which the material does not bind", self.model.params[p.index()].name)
        })
    }
    fn global(&mut self, g: ir::Global) -> Result<f64, String> {
        let name = match g {
            ir::Global::Dim => return Ok(self.dim as f64),
            ir::Global::Time => "t",
            ir::Global::Dt => "dt",
        };
        Err(format!("it reads `{name}`, which has no value before the run"))
    }
    fn reduction(&mut self, _: ir::Reduce, _: &Expr) -> Result<f64, String> {
        Err("it takes a reduction over particles".into())
    }
}

/// Evaluates a parameter default or an initial value on the host (`host_eval`); `Err` says what
/// it reads that has no value here.
fn eval(
    model: &Model,
    dim: usize,
    e: &Expr,
    params: &mut Vec<Option<Vec<f64>>>,
    busy: &mut BTreeSet<ParamId>,
    particle: Option<(&HostFields, usize)>,
) -> Result<Vec<f64>, String> {
    host_eval::eval(e, dim, &mut HostLeaves { model, dim, params, busy, particle })
}

/// Sorts particles group-major (stable) and returns the permutation: new index k holds input
/// particle `perm[k]`.
pub fn group_order(input: &ParticleInput) -> Vec<u32> {
    let mut perm: Vec<u32> = (0..input.len() as u32).collect();
    perm.sort_by_key(|&i| input.group[i as usize]);
    perm
}

/// [`build_store`] of the particles at `keep` (ascending indices into `input`) only: a rank's
/// share of a run split into domains, which never holds the others'. Each particle keeps its index
/// in `input` as its id. A parameter left unbound is found only where a particle needs it.
pub fn build_store_of<T: Real>(
    plan: &Plan,
    input: &ParticleInput,
    materials: &[MaterialInput],
    keep: &[usize],
) -> Result<Store<T>, SetupError> {
    let mut store = build_store(plan, &input.subset(keep), materials)?;
    for id in &mut store.id {
        *id = keep[*id as usize] as u32;
    }
    Ok(store)
}

/// Builds the store: particles in group order, scene fields set, parameters resolved.
pub fn build_store<T: Real>(
    plan: &Plan,
    input: &ParticleInput,
    materials: &[MaterialInput],
) -> Result<Store<T>, SetupError> {
    if input.is_empty() {
        return Err(SetupError::new("C0011", "the scene has no particles"));
    }
    let perm = group_order(input);
    let pick = |k: usize| perm[k] as usize;
    let group: Vec<u32> = (0..input.len()).map(|k| input.group[pick(k)]).collect();
    let material: Vec<u32> = (0..input.len()).map(|k| input.material[pick(k)]).collect();
    let mut store: Store<T> = Store::new(plan, group, material, materials.len());
    store.id = perm.clone();
    let resolved = resolved_materials(plan, materials);
    let host = host_fields(plan, input, &resolved)?;
    for (f, (comps, values)) in &host {
        let ordered: Vec<f64> =
            (0..input.len()).flat_map(|k| values[pick(k) * comps..(pick(k) + 1) * comps].to_vec()).collect();
        store.write_f64(*f, &ordered, *comps);
    }
    // Parameters: every material its values; a parameter the plan reads on a group must be
    // bound (or defaulted) for every material with particles on that group.
    if let Some((_, e)) = unbound_parameter(plan, input, materials, &resolved) {
        return Err(e);
    }
    for (mi, values) in resolved.iter().enumerate() {
        for (p, v) in values.iter().enumerate() {
            if let Some(v) = v {
                store.params.set(mi, ParamId(p as u32), v);
            }
        }
    }
    check_requirements(plan, input, materials, &resolved)?;
    Ok(store)
}

/// The first parameter that the plan reads on a group where a material has particles but that
/// the material neither binds nor defaults (error C0046), with the material's index.
pub fn unbound_parameter(
    plan: &Plan,
    input: &ParticleInput,
    materials: &[MaterialInput],
    resolved: &[Vec<Option<Vec<f64>>>],
) -> Option<(usize, SetupError)> {
    let model = &plan.model;
    let used = plan.params_read();
    for (mi, (m, values)) in materials.iter().zip(resolved).enumerate() {
        let groups = material_groups(input, mi);
        for (p, _) in values.iter().enumerate().filter(|(_, v)| v.is_none()) {
            let need = used.get(&ParamId(p as u32)).copied().unwrap_or_default().intersect(groups);
            if !need.is_empty() {
                let message = unbound_message(model, &m.name, ParamId(p as u32), values, &model.group_names(need));
                return Some((mi, SetupError::new("C0046", message)));
            }
        }
    }
    None
}

/// C0046's text for parameter `p`, which material `material` leaves unbound: where `p` has a
/// default that reads parameters the material leaves unbound too (`G = E / (2 (1 + ν))` without
/// `E`), it names those, which are what the user left out, and says that `p` defaults from them.
fn unbound_message(model: &Model, material: &str, p: ParamId, values: &[Option<Vec<f64>>], groups: &str) -> String {
    let param = &model.params[p.index()];
    let sources = unbound_sources(model, p, values);
    if sources.is_empty() {
        return format!(
            "material `{material}` does not bind parameter `{}` ({}), which the model reads on {groups}: give it a value in `[materials.{material}]`",
            param.name, param.ty
        );
    }
    let named: Vec<String> = sources
        .iter()
        .map(|q| format!("`{}` ({})", model.params[q.index()].name, model.params[q.index()].ty))
        .collect();
    let (noun, them) = if named.len() == 1 { ("parameter", "it a value") } else { ("parameters", "them values") };
    format!(
        "material `{material}` does not bind {noun} {}, from which `{}` defaults, which the model reads on {groups}: give {them} in `[materials.{material}]` (or give `{}` one)",
        named.join(" and "),
        param.name,
        param.name
    )
}

/// The parameters without a default that `p`'s default reads, directly or through other
/// defaults, and that `values` (a material's, resolved) leaves unbound, in declaration order.
fn unbound_sources(model: &Model, p: ParamId, values: &[Option<Vec<f64>>]) -> Vec<ParamId> {
    let mut sources = BTreeSet::new();
    let mut seen = BTreeSet::from([p]);
    let mut todo = vec![p];
    while let Some(q) = todo.pop() {
        let Some(default) = &model.params[q.index()].default else { continue };
        ir::walk_expr(default, &mut |e| {
            if let ir::ExprKind::Param(r, _) = e.kind {
                if values[r.index()].is_none() && seen.insert(r) {
                    if model.params[r.index()].default.is_some() {
                        todo.push(r);
                    } else {
                        sources.insert(r);
                    }
                }
            }
        });
    }
    sources.into_iter().collect()
}

/// The groups that material `mi` has particles on.
pub fn material_groups(input: &ParticleInput, mi: usize) -> GroupSet {
    input
        .material
        .iter()
        .zip(&input.group)
        .filter(|(mat, _)| **mat as usize == mi)
        .fold(GroupSet::default(), |s, (_, g)| s.with(GroupId(*g)))
}

/// Every `require` of the model holds for every material with particles where it applies.
fn check_requirements(
    plan: &Plan,
    input: &ParticleInput,
    materials: &[MaterialInput],
    resolved: &[Vec<Option<Vec<f64>>>],
) -> Result<(), SetupError> {
    match broken_requirement(&plan.model, plan.dim, input, materials, resolved) {
        Some(broken) => Err(broken.error),
        None => Ok(()),
    }
}

/// A `require` of the model that a material breaks (or that cannot be checked): the error, the
/// material's index and the parameters the condition reads, for the case file to point at.
pub struct BrokenRequirement {
    pub error: SetupError,
    pub material: usize,
    pub reads: Vec<ParamId>,
    /// Whether the condition could be evaluated (false: a parameter it reads is unbound).
    pub evaluated: bool,
}

/// The first `require` of the model that a material with particles where it applies breaks, or
/// cannot be checked for, with `resolved` its parameters' values (error C0048).
pub fn broken_requirement(
    model: &Model,
    dim: usize,
    input: &ParticleInput,
    materials: &[MaterialInput],
    resolved: &[Vec<Option<Vec<f64>>>],
) -> Option<BrokenRequirement> {
    for r in &model.requirements {
        let mut reads = BTreeSet::new();
        ir::walk_expr(&r.cond, &mut |e| {
            if let ir::ExprKind::Param(p, _) = e.kind {
                reads.insert(p);
            }
        });
        for (mi, m) in materials.iter().enumerate() {
            if material_groups(input, mi).intersect(r.groups).is_empty() {
                continue;
            }
            let mut params = resolved[mi].clone();
            let holds = eval(model, dim, &r.cond, &mut params, &mut BTreeSet::new(), None);
            let values = || {
                let shown: Vec<String> = reads
                    .iter()
                    .map(|p| {
                        let value = params[p.index()].as_ref().map_or("unbound".to_string(), |v| format!("{}", v[0]));
                        let param = &model.params[p.index()];
                        format!("{} = {value} {}", param.name, param.ty.unit.label()).trim_end().to_string()
                    })
                    .collect();
                shown.join(", ")
            };
            let message = match &holds {
                Ok(v) if v[0] != 0.0 => continue,
                Ok(_) => format!("material `{}` breaks a requirement of the model: {} ({})", m.name, r.why, values()),
                Err(what) => {
                    format!("cannot check a requirement of the model (`{}`) for material `{}`: {what}", r.why, m.name)
                }
            };
            return Some(BrokenRequirement {
                error: SetupError::new("C0048", message),
                material: mi,
                reads: reads.into_iter().collect(),
                evaluated: holds.is_ok(),
            });
        }
    }
    None
}

/// The scene's fields (x, v, vol, dx, body) and the initial values computed from them, per
/// particle in the scene's order. Fields used only to compute initial values are never stored.
pub fn host_fields(
    plan: &Plan,
    input: &ParticleInput,
    materials: &[Vec<Option<Vec<f64>>>],
) -> Result<HostFields, SetupError> {
    let model = &plan.model;
    let dim = plan.dim;
    let n = input.len();
    let mut fields: HostFields = BTreeMap::new();
    let vec3 = |v: &Vec<[f64; 3]>| -> Vec<f64> { v.iter().flat_map(|p| p[..dim].to_vec()).collect() };
    let body: Vec<f64> = input.body.iter().map(|b| *b as f64).collect();
    let part: Vec<f64> = (0..n).map(|k| input.part.get(k).map(|p| *p as f64).unwrap_or(-1.0)).collect();
    for (name, values, comps) in [
        ("x", vec3(&input.x), dim),
        ("v", vec3(&input.v), dim),
        ("vol", input.vol.clone(), 1),
        ("dx", input.dx.clone(), 1),
        ("body", body, 1),
        ("part", part, 1),
    ] {
        if let Some(f) = model.field_id(name) {
            fields.insert(f, (comps, values));
        }
    }
    for f in &plan.initial {
        let field = model.field(*f);
        let Some(init) = &field.init else { continue };
        let comps = ir::components(field.ty.shape, dim);
        let mut values = vec![0.0; n * comps];
        let mut params = materials.to_vec();
        for k in 0..n {
            let params = &mut params[input.material[k] as usize];
            let v = eval(model, dim, init, params, &mut BTreeSet::new(), Some((&fields, k))).map_err(|what| {
                SetupError::new(
                    "C0045",
                    format!("cannot compute the model's initial value of `{}`: {what}", field.name),
                )
            })?;
            values[k * comps..(k + 1) * comps].copy_from_slice(&v[..comps]);
        }
        fields.insert(*f, (comps, values));
    }
    for iv in &input.initial {
        let comps = ir::components(model.field(iv.field).ty.shape, dim);
        let mut params = materials.to_vec();
        let mut values = fields.get(&iv.field).map(|f| f.1.clone()).unwrap_or_else(|| vec![0.0; n * comps]);
        for k in (0..n).filter(|k| input.body[*k] == iv.body) {
            let params = &mut params[input.material[k] as usize];
            let v = eval(model, dim, &iv.value, params, &mut BTreeSet::new(), Some((&fields, k))).map_err(|what| {
                SetupError::new(
                    "C0045",
                    format!("cannot compute the case's initial value of `{}`: {what}", model.field(iv.field).name),
                )
            })?;
            values[k * comps..(k + 1) * comps].copy_from_slice(&v[..comps]);
        }
        fields.insert(iv.field, (comps, values));
    }
    Ok(fields)
}
