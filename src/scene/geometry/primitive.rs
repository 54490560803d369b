//! Primitives, and their resolution for one dimension into a [`Shape`]: checked parameters, a
//! bounding box, the exact volume, and the intersection of a lattice row with the shape.

use super::GeometryError;
use std::f64::consts::PI;

/// A solid shape to fill with particles. Points and directions are `[f64; 3]`; in 1D and 2D the
/// unused coordinates are ignored (see the module documentation for the 1D/2D sections).
#[derive(Clone, Debug, PartialEq)]
pub enum Primitive {
    /// An axis-aligned box, `min ≤ x ≤ max` along every axis of the model.
    Box {
        /// The lower corner.
        min: [f64; 3],
        /// The upper corner; `max > min` along every axis of the model.
        max: [f64; 3],
    },
    /// A ball: a disc in 2D, a segment in 1D.
    Sphere {
        /// The centre.
        center: [f64; 3],
        /// The radius, > 0.
        radius: f64,
    },
    /// A solid circular cylinder from `base` to `base + length × axis`.
    Cylinder {
        /// The centre of the base disc.
        base: [f64; 3],
        /// The axis direction (normalised here; must not be zero).
        axis: [f64; 3],
        /// The radius, > 0.
        radius: f64,
        /// The length along the axis, > 0.
        length: f64,
    },
    /// A tube: `inner_radius ≤ distance to the axis ≤ outer_radius`, from `base` to
    /// `base + length × axis`.
    HollowCylinder {
        /// The centre of the base ring.
        base: [f64; 3],
        /// The axis direction (normalised here; must not be zero).
        axis: [f64; 3],
        /// The inner radius, ≥ 0 and < `outer_radius`.
        inner_radius: f64,
        /// The outer radius, > `inner_radius`.
        outer_radius: f64,
        /// The length along the axis, > 0.
        length: f64,
    },
    /// A disc (2D only).
    Disc {
        /// The centre.
        center: [f64; 3],
        /// The radius, > 0.
        radius: f64,
    },
    /// A ring, `inner_radius ≤ |x − center| ≤ outer_radius` (2D only).
    Annulus {
        /// The centre.
        center: [f64; 3],
        /// The inner radius, ≥ 0 and < `outer_radius`.
        inner_radius: f64,
        /// The outer radius, > `inner_radius`.
        outer_radius: f64,
    },
    /// A simple polygon (2D only), its vertices in order, either orientation; at least 3.
    Polygon {
        /// The vertices `(x, y)`.
        vertices: Vec<[f64; 2]>,
    },
    /// A circular plate: a cylinder of length `thickness` along `normal`, centred on `center`.
    Plate {
        /// The centre of the plate (half way through its thickness).
        center: [f64; 3],
        /// The plate's normal (normalised here; must not be zero).
        normal: [f64; 3],
        /// The plate's radius, > 0.
        radius: f64,
        /// The plate's thickness along the normal, > 0.
        thickness: f64,
    },
}

/// An axis component below this (of the unit axis) counts as zero when classifying an axis.
pub(crate) const AXIS_EPS: f64 = 1e-12;

/// The geometric kinds every primitive reduces to, in the model's `dim` axes (unused coordinates 0).
#[derive(Clone, Debug)]
pub(crate) enum Region {
    /// `min ≤ x ≤ max` along the model's axes.
    Box { min: [f64; 3], max: [f64; 3] },
    /// `r_in ≤ |x − center| ≤ r_out` (a ball when `r_in == 0`).
    Shell { center: [f64; 3], r_in: f64, r_out: f64 },
    /// `0 ≤ (x − base)·axis ≤ len` and `r_in ≤ distance to the axis ≤ r_out`; `axis` is a unit vector.
    Tube { base: [f64; 3], axis: [f64; 3], r_in: f64, r_out: f64, len: f64 },
    /// Inside a simple polygon of the (x, y) plane (even–odd rule).
    Polygon { vertices: std::sync::Arc<[[f64; 2]]> },
}

/// A primitive resolved for a dimension: every parameter checked, unused coordinates zeroed.
#[derive(Clone, Debug)]
pub(crate) struct Shape {
    pub region: Region,
    pub dim: usize,
}

/// How an axis sits relative to the model's axes.
enum Orientation {
    /// In the model's axes: the unit axis, unused coordinates 0.
    Along([f64; 3]),
    /// Perpendicular to the model's axes (1D and 2D only).
    Across,
}

/// Checks that `dim` is 1, 2 or 3.
pub(crate) fn check_dim(dim: usize) -> Result<(), GeometryError> {
    if (1..=3).contains(&dim) {
        Ok(())
    } else {
        Err(GeometryError::Dimension(dim))
    }
}

fn param(name: &'static str, message: String) -> GeometryError {
    GeometryError::Parameter { name, message }
}

/// Checks that every coordinate of `p` is finite.
pub(crate) fn finite_point(name: &'static str, p: [f64; 3]) -> Result<[f64; 3], GeometryError> {
    if p.iter().all(|v| v.is_finite()) {
        Ok(p)
    } else {
        Err(param(name, format!("{name} must have finite coordinates, found {p:?}")))
    }
}

/// Checks that `v` is finite and > 0.
pub(crate) fn positive(name: &'static str, v: f64) -> Result<f64, GeometryError> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(param(name, format!("{name} must be positive and finite, found {v}")))
    }
}

/// `p` with the coordinates beyond `dim` set to 0.
pub(crate) fn truncate(mut p: [f64; 3], dim: usize) -> [f64; 3] {
    p.iter_mut().skip(dim).for_each(|v| *v = 0.0);
    p
}

fn norm(p: [f64; 3]) -> f64 {
    (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()
}

pub(crate) fn unit(name: &'static str, a: [f64; 3]) -> Result<[f64; 3], GeometryError> {
    let a = finite_point(name, a)?;
    let big = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if big == 0.0 {
        return Err(param(name, format!("{name} must not be the zero vector")));
    }
    let scaled = a.map(|v| v / big);
    let n = norm(scaled);
    Ok(scaled.map(|v| v / n))
}

fn orient(name: &'static str, a: [f64; 3], dim: usize) -> Result<Orientation, GeometryError> {
    let u = unit(name, a)?;
    let off = u.iter().skip(dim).map(|v| v * v).sum::<f64>().sqrt();
    let on = u.iter().take(dim).map(|v| v * v).sum::<f64>().sqrt();
    if off <= AXIS_EPS {
        let t = truncate(u, dim);
        let n = norm(t);
        Ok(Orientation::Along(t.map(|v| v / n)))
    } else if on <= AXIS_EPS {
        Ok(Orientation::Across)
    } else {
        let msg = format!(
            "{name} {a:?} is oblique to the {dim}D model: it must lie in the model's axes or be perpendicular to them"
        );
        Err(param(name, msg))
    }
}

/// The volume of a `d`-ball of radius `r` (`d` = 0 is a point: 1 when r > 0).
fn ball(d: usize, r: f64) -> f64 {
    match d {
        0 => f64::from(u8::from(r > 0.0)),
        1 => 2.0 * r,
        2 => PI * r * r,
        _ => 4.0 / 3.0 * PI * r * r * r,
    }
}

impl Primitive {
    /// The bounding box of the shape in `dim` dimensions (unused coordinates 0).
    pub fn bbox(&self, dim: usize) -> Result<([f64; 3], [f64; 3]), GeometryError> {
        Shape::resolve(self, dim).map(|s| s.bbox())
    }

    /// The exact volume of the solid the 2D shape's part at x ≥ 0 sweeps about the y axis, where
    /// it is known: a disc or an annulus centred on the axis (a ball or a shell) or wholly off it
    /// (a torus, by Pappus: 2π × its centre's radius × its area). `None` for the others: a box's
    /// lattice sweeps its exact volume where its extents are whole spacings, and the rest keep
    /// their area's scale.
    pub fn revolved_volume(&self) -> Option<f64> {
        let Region::Shell { center, r_in, r_out } = Shape::resolve(self, 2).ok()?.region else { return None };
        let pi = std::f64::consts::PI;
        if center[0] == 0.0 {
            Some(4.0 / 3.0 * pi * (r_out.powi(3) - r_in.powi(3)))
        } else if center[0] >= r_out {
            Some(2.0 * pi * center[0] * pi * (r_out * r_out - r_in * r_in))
        } else {
            None
        }
    }
}

impl Shape {
    /// Checks `p`'s parameters and reduces it to a [`Region`] in `dim` dimensions.
    pub fn resolve(p: &Primitive, dim: usize) -> Result<Shape, GeometryError> {
        check_dim(dim)?;
        let region = match *p {
            Primitive::Disc { center, radius } => {
                plane_only("disc", dim)?;
                Region::Shell {
                    center: truncate(finite_point("center", center)?, 2),
                    r_in: 0.0,
                    r_out: positive("radius", radius)?,
                }
            }
            Primitive::Annulus { center, inner_radius, outer_radius } => {
                plane_only("annulus", dim)?;
                let (r_in, r_out) = radii(inner_radius, outer_radius)?;
                Region::Shell { center: truncate(finite_point("center", center)?, 2), r_in, r_out }
            }
            Primitive::Polygon { ref vertices } => {
                plane_only("polygon", dim)?;
                polygon(vertices)?
            }
            Primitive::Box { min, max } => resolve_box(min, max, dim)?,
            Primitive::Sphere { center, radius } => {
                let center = truncate(finite_point("center", center)?, dim);
                Region::Shell { center, r_in: 0.0, r_out: positive("radius", radius)? }
            }
            Primitive::Cylinder { base, axis, radius, length } => {
                let r = positive("radius", radius)?;
                tube("axis", base, axis, 0.0, r, positive("length", length)?, dim)?
            }
            Primitive::HollowCylinder { base, axis, inner_radius, outer_radius, length } => {
                let (r_in, r_out) = radii(inner_radius, outer_radius)?;
                if r_in > 0.0 && dim == 1 && matches!(orient("axis", axis, 1)?, Orientation::Along(_)) {
                    let msg =
                        "a hollow cylinder along the line of a 1D model is empty (the line runs through the hole)";
                    return Err(param("axis", msg.to_string()));
                }
                tube("axis", base, axis, r_in, r_out, positive("length", length)?, dim)?
            }
            Primitive::Plate { center, normal, radius, thickness } => plate(center, normal, radius, thickness, dim)?,
        };
        Ok(Shape { region, dim })
    }

    /// The exact volume (m³ per the unit slab/bar convention).
    pub fn volume(&self) -> f64 {
        let d = self.dim;
        match self.region {
            Region::Box { min, max } => (0..d).map(|i| max[i] - min[i]).product(),
            Region::Shell { r_in, r_out, .. } => ball(d, r_out) - ball(d, r_in),
            Region::Tube { r_in, r_out, len, .. } => len * (ball(d - 1, r_out) - ball(d - 1, r_in)),
            Region::Polygon { ref vertices } => shoelace(vertices).abs(),
        }
    }

    /// Whether the volumes of this shape's particles are rescaled to its exact volume.
    pub fn rescaled(&self) -> bool {
        !matches!(self.region, Region::Box { .. })
    }

    /// The axis-aligned bounding box `(min, max)` (unused coordinates 0).
    pub fn bbox(&self) -> ([f64; 3], [f64; 3]) {
        let (mut lo, mut hi) = ([0.0; 3], [0.0; 3]);
        for i in 0..self.dim {
            (lo[i], hi[i]) = match self.region {
                Region::Box { min, max } => (min[i], max[i]),
                Region::Shell { center, r_out, .. } => (center[i] - r_out, center[i] + r_out),
                Region::Tube { base, axis, r_out, len, .. } => {
                    let (a, b) = (base[i], base[i] + len * axis[i]);
                    let ext = r_out * (1.0 - axis[i] * axis[i]).max(0.0).sqrt();
                    (a.min(b) - ext, a.max(b) + ext)
                }
                Region::Polygon { ref vertices } => {
                    vertices.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v[i]), hi.max(v[i])))
                }
            };
        }
        (lo, hi)
    }

    /// Whether `p` lies in the shape, boundaries widened by `tol`.
    pub fn contains(&self, p: [f64; 3], tol: f64) -> bool {
        let mut out = Vec::with_capacity(2);
        self.row_intervals(p, 0, tol, &mut out);
        out.iter().any(|&(lo, hi)| lo <= p[0] && p[0] <= hi)
    }

    /// The closed intervals of coordinate `k` where the line through `q` along axis `k` lies in the
    /// shape (boundaries widened by `tol`), appended to `out`; `q[k]` is ignored. Intervals may be
    /// unbounded only where the shape is bounded by the caller's index box anyway.
    pub fn row_intervals(&self, mut q: [f64; 3], k: usize, tol: f64, out: &mut Vec<(f64, f64)>) {
        out.clear();
        q[k] = 0.0;
        match self.region {
            Region::Polygon { ref vertices } => polygon_row(vertices, q, k, tol, out),
            Region::Box { min, max } => self.box_row(min, max, q, k, tol, out),
            Region::Shell { center, r_in, r_out } => self.shell_row(center, r_in, r_out, q, k, tol, out),
            Region::Tube { base, axis, r_in, r_out, len } => {
                let u0 = sub(q, base);
                let s_axis = slab(u0, axis, k, len, tol);
                let around = Around::new(u0, axis, k);
                let outer = around.within(r_out + tol);
                let Some(iv) = intersect(s_axis, outer) else { return };
                let inner = if r_in - tol > 0.0 { around.within(r_in - tol) } else { None };
                subtract(iv, inner, out);
            }
        }
    }

    fn box_row(&self, min: [f64; 3], max: [f64; 3], q: [f64; 3], k: usize, tol: f64, out: &mut Vec<(f64, f64)>) {
        let outside = (0..self.dim).any(|i| i != k && (q[i] < min[i] - tol || q[i] > max[i] + tol));
        if !outside {
            out.push((min[k] - tol, max[k] + tol));
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn shell_row(
        &self,
        c: [f64; 3],
        r_in: f64,
        r_out: f64,
        q: [f64; 3],
        k: usize,
        tol: f64,
        out: &mut Vec<(f64, f64)>,
    ) {
        let d2: f64 = (0..self.dim).filter(|&i| i != k).map(|i| (q[i] - c[i]).powi(2)).sum();
        let ro = r_out + tol;
        if d2 > ro * ro {
            return;
        }
        let w = (ro * ro - d2).sqrt();
        let ri = r_in - tol;
        if r_in > 0.0 && ri > 0.0 && d2 < ri * ri {
            let wi = (ri * ri - d2).sqrt();
            out.push((c[k] - w, c[k] - wi));
            out.push((c[k] + wi, c[k] + w));
        } else {
            out.push((c[k] - w, c[k] + w));
        }
    }
}

/// The 2D shapes (disc, annulus, polygon) exist only in a 2D model.
fn plane_only(shape: &'static str, dim: usize) -> Result<(), GeometryError> {
    if dim == 2 {
        Ok(())
    } else {
        let hint = if dim == 3 { "; in 3D use a cylinder, a hollow cylinder or a plate" } else { "" };
        Err(param("dim", format!("a {shape} is a shape of a 2D case, and this case is {dim}D{hint}")))
    }
}

/// A simple polygon: at least 3 finite vertices, a non-zero area, no edge crossing another.
fn polygon(vertices: &[[f64; 2]]) -> Result<Region, GeometryError> {
    if vertices.len() < 3 {
        return Err(param("vertices", format!("a polygon needs at least 3 vertices, found {}", vertices.len())));
    }
    if let Some(v) = vertices.iter().find(|v| !v.iter().all(|c| c.is_finite())) {
        return Err(param("vertices", format!("polygon vertices must be finite, found {v:?}")));
    }
    let n = vertices.len();
    let edge = |k: usize| (vertices[k], vertices[(k + 1) % n]);
    for a in 0..n {
        for b in a + 2..n {
            if (b + 1) % n == a {
                continue;
            }
            if segments_cross(edge(a), edge(b)) {
                let msg = format!("the polygon crosses itself: edge {} and edge {} intersect", a + 1, b + 1);
                return Err(param("vertices", msg));
            }
        }
    }
    if shoelace(vertices).abs() <= 0.0 {
        return Err(param("vertices", "the polygon has no area (its vertices lie on a line)".to_string()));
    }
    Ok(Region::Polygon { vertices: vertices.into() })
}

/// Twice the signed area, halved: the shoelace formula.
fn shoelace(v: &[[f64; 2]]) -> f64 {
    let n = v.len();
    0.5 * (0..n).map(|k| v[k][0] * v[(k + 1) % n][1] - v[(k + 1) % n][0] * v[k][1]).sum::<f64>()
}

/// Whether two segments properly intersect (touching at an end counts).
fn segments_cross((p1, p2): ([f64; 2], [f64; 2]), (q1, q2): ([f64; 2], [f64; 2])) -> bool {
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
    let (d1, d2) = (cross(q1, q2, p1), cross(q1, q2, p2));
    let (d3, d4) = (cross(p1, p2, q1), cross(p1, p2, q2));
    d1 * d2 <= 0.0 && d3 * d4 <= 0.0 && !(d1 == 0.0 && d2 == 0.0)
}

/// The intervals along axis `k` (0 or 1) of the row through `q` that lie inside the polygon
/// (even–odd rule), each widened by `tol`.
fn polygon_row(v: &[[f64; 2]], q: [f64; 3], k: usize, tol: f64, out: &mut Vec<(f64, f64)>) {
    let other = 1 - k;
    let at = q[other];
    let n = v.len();
    let mut crossings: Vec<f64> = (0..n)
        .filter_map(|e| {
            let (a, b) = (v[e], v[(e + 1) % n]);
            // Half-open in the other coordinate, so a vertex on the row counts once.
            if (a[other] <= at) == (b[other] <= at) {
                return None;
            }
            let t = (at - a[other]) / (b[other] - a[other]);
            Some(a[k] + t * (b[k] - a[k]))
        })
        .collect();
    crossings.sort_by(f64::total_cmp);
    for pair in crossings.chunks_exact(2) {
        out.push((pair[0] - tol, pair[1] + tol));
    }
}

fn resolve_box(min: [f64; 3], max: [f64; 3], dim: usize) -> Result<Region, GeometryError> {
    let (min, max) = (finite_point("min", min)?, finite_point("max", max)?);
    if let Some(i) = (0..dim).find(|&i| max[i] <= min[i]) {
        let msg = format!(
            "box max must exceed min along every axis of the model; along axis {i}: min {}, max {}",
            min[i], max[i]
        );
        return Err(param("max", msg));
    }
    Ok(Region::Box { min: truncate(min, dim), max: truncate(max, dim) })
}

fn radii(inner: f64, outer: f64) -> Result<(f64, f64), GeometryError> {
    let outer = positive("outer_radius", outer)?;
    if !(inner.is_finite() && inner >= 0.0 && inner < outer) {
        let msg = format!("inner_radius must be ≥ 0 and < outer_radius ({outer}), found {inner}");
        return Err(param("inner_radius", msg));
    }
    Ok((inner, outer))
}

fn tube(
    name: &'static str,
    base: [f64; 3],
    axis: [f64; 3],
    r_in: f64,
    r_out: f64,
    len: f64,
    dim: usize,
) -> Result<Region, GeometryError> {
    let base = truncate(finite_point("base", base)?, dim);
    Ok(match orient(name, axis, dim)? {
        Orientation::Along(axis) => Region::Tube { base, axis, r_in, r_out, len },
        Orientation::Across => Region::Shell { center: base, r_in, r_out },
    })
}

fn plate(center: [f64; 3], normal: [f64; 3], radius: f64, thickness: f64, dim: usize) -> Result<Region, GeometryError> {
    let c = finite_point("center", center)?;
    let (r, t) = (positive("radius", radius)?, positive("thickness", thickness)?);
    let n = unit("normal", normal)?;
    let base = [c[0] - 0.5 * t * n[0], c[1] - 0.5 * t * n[1], c[2] - 0.5 * t * n[2]];
    match tube("normal", base, normal, 0.0, r, t, dim)? {
        Region::Shell { r_in, r_out, .. } => Ok(Region::Shell { center: truncate(c, dim), r_in, r_out }),
        region => Ok(region),
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// An interval of the row coordinate; `None` is empty.
type Interval = Option<(f64, f64)>;

const ALL: Interval = Some((f64::NEG_INFINITY, f64::INFINITY));

/// Where `0 − tol ≤ (u0 + t e_k)·axis ≤ len + tol`.
fn slab(u0: [f64; 3], axis: [f64; 3], k: usize, len: f64, tol: f64) -> Interval {
    let s0 = dot(u0, axis);
    let ak = axis[k];
    if ak.abs() > AXIS_EPS {
        let (t1, t2) = ((-tol - s0) / ak, (len + tol - s0) / ak);
        Some((t1.min(t2), t1.max(t2)))
    } else if (-tol..=len + tol).contains(&s0) {
        ALL
    } else {
        None
    }
}

/// The squared distance to the axis along the row, `a t² + 2 b t + c`.
struct Around {
    a: f64,
    b: f64,
    c: f64,
}

impl Around {
    fn new(u0: [f64; 3], axis: [f64; 3], k: usize) -> Around {
        let s0 = dot(u0, axis);
        let p = [u0[0] - s0 * axis[0], u0[1] - s0 * axis[1], u0[2] - s0 * axis[2]];
        let mut d = axis.map(|v| -axis[k] * v);
        d[k] += 1.0;
        Around { a: dot(d, d), b: dot(p, d), c: dot(p, p) }
    }

    /// Where the distance to the axis is ≤ `r` (empty for r ≤ 0 unless on the axis).
    fn within(&self, r: f64) -> Interval {
        let r2 = if r > 0.0 { r * r } else { 0.0 };
        if self.a < 1e-24 {
            return if self.c <= r2 { ALL } else { None };
        }
        let disc = self.b * self.b - self.a * (self.c - r2);
        if disc < 0.0 {
            return None;
        }
        let s = disc.sqrt();
        Some(((-self.b - s) / self.a, (-self.b + s) / self.a))
    }
}

fn intersect(a: Interval, b: Interval) -> Interval {
    let ((a0, a1), (b0, b1)) = (a?, b?);
    let (lo, hi) = (a0.max(b0), a1.min(b1));
    (lo <= hi).then_some((lo, hi))
}

/// Pushes `iv` minus the (open) interval `hole` onto `out`.
fn subtract(iv: (f64, f64), hole: Interval, out: &mut Vec<(f64, f64)>) {
    let Some((h0, h1)) = hole.filter(|h| h.0 < h.1) else {
        out.push(iv);
        return;
    };
    if iv.0 < h0 {
        out.push((iv.0, iv.1.min(h0)));
    }
    if iv.1 > h1 {
        out.push((iv.0.max(h1), iv.1));
    }
}
