//! The case file (`cases/*.toml`) as written: serde structures that keep the span of every value,
//! so that a wrong unit or an unknown name is reported at its line and column.

use serde::Deserialize;
use std::collections::BTreeMap;
use toml::Spanned;

/// A number, a quantity string (`"490 MPa"`), or a list of them.
pub type Value = Spanned<toml::Value>;

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct CaseFile {
    pub name: Spanned<String>,
    #[serde(default)]
    pub title: Option<String>,
    /// The model: a file relative to the case, or a stdlib module path (`models::elastic_solid`).
    pub model: Spanned<String>,
    pub dim: Spanned<usize>,
    #[serde(default)]
    pub kernel: Option<Spanned<String>>,
    #[serde(default)]
    pub integrator: Option<Spanned<String>>,
    pub end_time: Value,
    #[serde(default)]
    pub dt_max: Option<Value>,
    #[serde(default)]
    pub reorder_every: Option<u64>,
    /// The run stops as unstable when its time step falls below this fraction of the first.
    #[serde(default)]
    pub min_dt_ratio: Option<Spanned<f64>>,
    /// The watchdog's bounds on speed and energy (`[watchdog]`).
    #[serde(default)]
    pub watchdog: Option<Watchdog>,
    /// Named resolutions; each a spacing or a table with `dx` and overrides.
    pub resolutions: Spanned<BTreeMap<String, Spanned<Resolution>>>,
    /// The resolution used when none is asked for.
    #[serde(default)]
    pub default_resolution: Option<Spanned<String>>,
    /// The resolutions `pairsum run --convergence` runs (names or spacings), at least three.
    #[serde(default)]
    pub convergence: Option<Vec<String>>,
    #[serde(default)]
    pub gravity: Option<Value>,
    /// A 2D case about an axis: x is the radius, y the axis, each particle a ring.
    #[serde(default)]
    pub axisymmetric: Option<Spanned<bool>>,
    /// Mass-proportional damping (1/s), to bring a loaded body to rest.
    #[serde(default)]
    pub damping: Option<Value>,
    /// Materials by name: `[materials.steel]` with parameter values.
    #[serde(default)]
    pub materials: BTreeMap<String, BTreeMap<String, Value>>,
    pub bodies: Spanned<Vec<Body>>,
    #[serde(default)]
    pub loads: Vec<Load>,
    #[serde(default)]
    pub constraints: Vec<Constraint>,
    #[serde(default)]
    pub symmetry: Vec<Symmetry>,
    /// `[periodic]`: the axes along which the domain repeats.
    #[serde(default)]
    pub periodic: Option<Periodic>,
    /// How neighbours are found (`[neighbours]`; the cell list when absent).
    #[serde(default)]
    pub neighbours: Option<Neighbours>,
    #[serde(default)]
    pub output: Option<Output>,
    #[serde(default)]
    pub probes: Vec<Probe>,
    #[serde(default)]
    pub results: Vec<ResultSpec>,
    #[serde(default)]
    pub profiles: Vec<Profile>,
    /// Defaults of the case's `${name}` placeholders (already substituted when this is parsed).
    #[serde(default)]
    pub parameters: Option<toml::Table>,
    /// The most particles the scene may hold (default [`super::build::DEFAULT_MAX_PARTICLES`]): a
    /// spacing too fine for the domain is refused before anything is allocated.
    #[serde(default)]
    pub max_particles: Option<Spanned<u64>>,
}

#[derive(Deserialize, Debug)]
#[serde(untagged)]
pub enum Resolution {
    Table(ResolutionTable),
    Spacing(toml::Value),
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct ResolutionTable {
    pub dx: toml::Value,
    #[serde(default)]
    pub end_time: Option<toml::Value>,
    /// Relative tolerance of each result at this resolution (tests use it).
    #[serde(default)]
    pub tolerance: Option<f64>,
    /// Runs the case this much faster in time: end time, load and constraint ramps, output
    /// interval and result windows are multiplied by it, prescribed (constraint) velocities divided
    /// by it, so that a quasi-static load reaches the same forces and displacements sooner.
    #[serde(default)]
    pub time_scale: Option<f64>,
    /// Values of the case's `${name}` parameters at this resolution (a smaller domain for CI, a
    /// different time-step factor); `--set` and studies still override them.
    #[serde(default)]
    pub set: Option<toml::Table>,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct Body {
    pub name: Spanned<String>,
    pub group: Spanned<String>,
    pub material: Spanned<String>,
    pub shape: Spanned<Shape>,
    #[serde(default)]
    pub velocity: Option<Value>,
    /// Initial values of state fields, each an expression of the language (position `x`, the
    /// material's parameters): `initial = { v = "vec(...)" }`.
    #[serde(default)]
    pub initial: std::collections::BTreeMap<String, Spanned<String>>,
    /// Spacing as a multiple of the resolution's dx (default 1).
    #[serde(default)]
    pub spacing_factor: Option<f64>,
    /// A length (`"10 mm"`) the body's spacing must divide: the spacing shrinks to the largest
    /// that fits it a whole number of times, so that the body's edge lies the same way in its
    /// lattice at every resolution; 0 leaves the spacing as it is.
    #[serde(default)]
    pub spacing_divides: Option<Value>,
    /// A finer spacing (a multiple of dx) inside this region of the body.
    #[serde(default)]
    pub refine: Option<Refine>,
    /// Particles at the lattice's cell centres (default), at its cells' corners, or in rings.
    #[serde(default)]
    pub fill: Option<Spanned<FillAt>>,
}

impl Body {
    /// Where the body's particles sit in their cells (cell centres unless `fill` says otherwise).
    pub fn fill_at(&self) -> FillAt {
        self.fill.as_ref().map(|f| *f.get_ref()).unwrap_or_default()
    }
}

/// Where a body's particles sit in the cells of its lattice (`fill = "cells"` or `"nodes"`).
#[derive(Deserialize, Debug, Default, Clone, Copy, PartialEq)]
#[serde(rename_all = "snake_case")]
pub enum FillAt {
    /// At the cell centres: a box `[0, L]` holds `dx/2, 3dx/2, …`.
    #[default]
    Cells,
    /// At the cells' corners, each with its share of the cells around it (EK18's mesh nodes).
    Nodes,
    /// In rings about a cylinder's axis, so that its circular edges lie the same way at every
    /// spacing (`geometry::fill_rings`).
    Rings,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct Refine {
    pub factor: f64,
    pub region: Spanned<Shape>,
}

/// A prescribed velocity (zeros: clamped) on a body or on the part of it inside `region`,
/// reached after `ramp`; with `rotation`, a rigid motion: the body turns about the centre, which
/// moves at `velocity`.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct Constraint {
    pub body: Spanned<String>,
    #[serde(default)]
    pub region: Option<Spanned<Shape>>,
    #[serde(default)]
    pub velocity: Option<Value>,
    #[serde(default)]
    pub ramp: Option<Value>,
    #[serde(default)]
    pub rotation: Option<Spanned<Rotation>>,
}

/// `rotation = { center = [x, y(, z)], omega = "1.5 rad/s", axis = [0, 0, 1] }` (the axis only
/// in 3D: a 2D body turns about z).
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct Rotation {
    pub center: Value,
    pub omega: Value,
    #[serde(default)]
    pub axis: Option<Value>,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields, rename_all = "snake_case")]
pub enum Shape {
    Box {
        min: Value,
        max: Value,
    },
    Sphere {
        center: Value,
        radius: Value,
    },
    Cylinder {
        base: Value,
        axis: Value,
        radius: Value,
        length: Value,
    },
    HollowCylinder {
        base: Value,
        axis: Value,
        inner_radius: Value,
        outer_radius: Value,
        length: Value,
    },
    Plate {
        center: Value,
        normal: Value,
        radius: Value,
        thickness: Value,
    },
    /// 2D only.
    Disc {
        center: Value,
        radius: Value,
    },
    /// 2D only.
    #[serde(alias = "ring")]
    Annulus {
        center: Value,
        inner_radius: Value,
        outer_radius: Value,
    },
    /// 2D only: `vertices = [[x, y], …]`.
    Polygon {
        vertices: Value,
    },
    /// Nodes from a file: `.csv` (x,y,z[,volume]) or an LS-DYNA keyword deck (`*NODE`).
    Nodes {
        file: Spanned<String>,
        #[serde(default)]
        scale: Option<f64>,
    },
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct Load {
    pub body: Spanned<String>,
    /// Only the part of the body inside this region (default: the whole body).
    #[serde(default)]
    pub region: Option<Spanned<Shape>>,
    /// The total force, spread over the target's mass.
    pub force: Value,
    #[serde(default)]
    pub ramp: Option<Value>,
}

/// `[watchdog]`: how far past the case's own scales a run may go before it is stopped as
/// unstable (`inf` turns a bound off).
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct Watchdog {
    /// A particle faster than this many times the case's speed scale stops the run.
    #[serde(default)]
    pub speed_factor: Option<Spanned<f64>>,
    /// The run stops when its energy grows by more than this many times the energy in play at
    /// the start.
    #[serde(default)]
    pub energy_factor: Option<Spanned<f64>>,
}

/// `[periodic]`: per axis, the domain `[min, max)` that repeats along it.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct Periodic {
    #[serde(default)]
    pub x: Option<Spanned<Vec<Value>>>,
    #[serde(default)]
    pub y: Option<Spanned<Vec<Value>>>,
    #[serde(default)]
    pub z: Option<Spanned<Vec<Value>>>,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct Symmetry {
    pub axis: Spanned<String>,
    #[serde(default)]
    pub at: Option<Value>,
    /// `"above"` (the default) or `"below"`: the side of the plane the scene keeps.
    #[serde(default)]
    pub keep: Option<Spanned<String>>,
}

/// `[neighbours]`: `search = "cells" | "verlet" | "adaptive"`, the skin (a fraction of the
/// largest cut-off), and for the adaptive search the field and its threshold.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct Neighbours {
    pub search: Spanned<String>,
    #[serde(default)]
    pub skin: Option<Spanned<f64>>,
    #[serde(default)]
    pub field: Option<Spanned<String>>,
    #[serde(default)]
    pub threshold: Option<Value>,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct Output {
    /// Interval between VTK files (none: only the last state).
    #[serde(default)]
    pub interval: Option<Value>,
    #[serde(default)]
    pub fields: Vec<Spanned<String>>,
}

/// Every selected particle's values of some fields at chosen times, as CSV
/// (`profiles/<name>_<k>.csv`): a shock tube's or a boundary layer's profile.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct Profile {
    pub name: Spanned<String>,
    pub fields: Vec<Spanned<String>>,
    pub times: Spanned<Vec<Value>>,
    /// Only this body's particles.
    #[serde(default)]
    pub body: Option<Spanned<String>>,
    /// Only the particles inside this region when the profile is written.
    #[serde(default)]
    pub region: Option<Spanned<Shape>>,
    /// The axis the rows are sorted along (default: x).
    #[serde(default)]
    pub along: Option<Spanned<String>>,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct Probe {
    pub name: Spanned<String>,
    /// What is measured: `field` (with `component` and `reduce` over a body), or a named measure.
    #[serde(default)]
    pub body: Option<Spanned<String>>,
    /// Only the particles (of `body`, if given) inside this region at t = 0.
    #[serde(default)]
    pub region: Option<Spanned<Shape>>,
    #[serde(default)]
    pub field: Option<Spanned<String>>,
    /// An expression of the particle's fields and its material's parameters, instead of `field`.
    #[serde(default)]
    pub expression: Option<Spanned<String>>,
    #[serde(default)]
    pub component: Option<Spanned<String>>,
    #[serde(default)]
    pub reduce: Option<Spanned<String>>,
    /// Subtract the value at t = 0.
    #[serde(default)]
    pub relative: bool,
    /// Record the integral in time of the sampled values (a power's work).
    #[serde(default)]
    pub integrate: bool,
    /// Report this coordinate (`x`, `y`, `z`) of the particle where `reduce` is reached.
    #[serde(default)]
    pub locate: Option<Spanned<String>>,
    #[serde(default)]
    pub measure: Option<Spanned<String>>,
    #[serde(default)]
    pub unit: Option<String>,
    /// Record every this many steps (default: 1).
    #[serde(default)]
    pub every: Option<u64>,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct ResultSpec {
    pub quantity: Spanned<String>,
    pub probe: Spanned<String>,
    /// `end` (default), `min`, `max`, `abs_max`, `mean` (over `from`–`to`), `mean_after`, `period`,
    /// `frequency`, `slope`, `zero_crossing`, `at_time` (docs/CASE_FILES.md).
    #[serde(default)]
    pub at: Option<Spanned<String>>,
    #[serde(default)]
    pub from: Option<Value>,
    #[serde(default)]
    pub to: Option<Value>,
    /// The time of `at = "at_time"`.
    #[serde(default)]
    pub time: Option<Value>,
    #[serde(default)]
    pub scale: Option<f64>,
    /// Added after `scale`, in the result's unit: a length from the displacement a probe with
    /// `relative = true` records.
    #[serde(default)]
    pub offset: Option<Value>,
    #[serde(default)]
    pub reference: Option<Value>,
    #[serde(default)]
    pub source: Option<String>,
    /// Relative tolerance the CI test asserts at the CI resolution, and why.
    #[serde(default)]
    pub tolerance: Option<f64>,
    #[serde(default)]
    pub tolerance_why: Option<String>,
    #[serde(default)]
    pub unit: Option<String>,
}
