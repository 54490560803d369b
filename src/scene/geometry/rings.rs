//! Filling a cylinder in rings about its axis ([`fill_rings`]): a body whose edges are circles
//! about one axis (a projectile, the plate it strikes) then meets them the same way at every
//! spacing, where a Cartesian lattice cuts a circle at a phase that changes from one spacing to
//! the next.
//!
//! The cylinder is cut into layers along its axis, each layer into rings, each ring into `4 n`
//! equal sectors: one particle at the middle of each sector's arc at the ring's middle radius,
//! with the sector's exact volume. `n` is the whole number of spacings nearest a quarter of the
//! ring's middle circumference (at least 1), and the sectors' middles lie at `(j + 1/2) 2π / 4n`,
//! so that every ring is symmetric about both planes through the axis along the model's other two
//! axes (a quarter or half model cut by them keeps whole sectors, none on a plane). The volumes
//! sum to the cylinder's exactly, with no rescaling.

use super::primitive::{positive, unit, Primitive, Shape, AXIS_EPS};
use super::{GeometryError, Particles};
use std::f64::consts::PI;

/// How to fill a cylinder in rings.
#[derive(Clone, Debug, PartialEq)]
pub struct Rings {
    /// The spacing along the axis and around each ring (m), > 0.
    pub spacing: f64,
    /// The rings' radial width (m), > 0: `spacing`, or that fitted to a radius so that the radius
    /// falls on a boundary between rings.
    pub width: f64,
    /// A finer fill out to a radius: rings of its own width and spacing there, whole rings only,
    /// then rings of `width` and `spacing` out to the cylinder's radius.
    pub core: Option<Core>,
}

/// The finer rings about the axis of a graded ring fill.
#[derive(Clone, Debug, PartialEq)]
pub struct Core {
    /// The radius out to which the fine rings reach (the last whole fine ring ends at or inside it).
    pub radius: f64,
    /// The spacing along the axis and around the fine rings (m).
    pub spacing: f64,
    /// The fine rings' radial width (m).
    pub width: f64,
}

/// A ring of one band: inner and outer radius, and the spacing along the axis and around it.
type Ring = (f64, f64, f64);

/// The axis a cylinder lies along (its index among x, y, z) and the other two, in order; `None`
/// when its axis is zero, not finite, or oblique to the model's axes.
pub(crate) fn axis_index(axis: [f64; 3]) -> Option<(usize, [usize; 2])> {
    let u = unit("axis", axis).ok()?;
    let k = (0..3).find(|&k| u[k].abs() >= 1.0 - AXIS_EPS)?;
    let others = match k {
        0 => [1, 2],
        1 => [0, 2],
        _ => [0, 1],
    };
    Some((k, others))
}

/// Fills a cylinder along one of the model's axes in rings about that axis (3D only; see the
/// module documentation), failing beyond `limit` particles before anything is allocated.
pub fn fill_rings(shape: &Primitive, how: &Rings, dim: usize, limit: u64) -> Result<Particles, GeometryError> {
    let Primitive::Cylinder { base, axis, radius, length } = shape else {
        return Err(param("a ring fill takes a `cylinder`".into()));
    };
    if dim != 3 {
        return Err(param(format!("a ring fill is for 3D cylinders; this model is {dim}D")));
    }
    Shape::resolve(shape, dim)?; // the cylinder's own parameters, checked as for any fill
    let Some((k, [u, v])) = axis_index(*axis) else {
        return Err(param(format!("a ring fill needs a cylinder along x, y or z; its axis is {axis:?}")));
    };
    let (radius, length) = (*radius, *length);
    let (spacing, width) = (positive("spacing", how.spacing)?, positive("width", how.width)?);
    let rings = rings(radius, spacing, width, how.core.as_ref())?;
    let layers = |s: f64| ((length / s).round() as u64).max(1);
    let count: u64 = rings.iter().map(|&(a, b, s)| 4 * per_quarter(a, b, s) * layers(s)).sum();
    if count > limit {
        return Err(GeometryError::TooManyParticles { count, estimated: false, limit });
    }
    let sign = axis[k].signum();
    let mut out = Particles { volume_scale: 1.0, ..Particles::default() };
    for &(a, b, s) in &rings {
        let (n, m) = (4 * per_quarter(a, b, s), layers(s));
        let dz = length / m as f64;
        let (r, volume) = (0.5 * (a + b), PI * (b * b - a * a) / n as f64 * dz);
        for layer in 0..m {
            for j in 0..n {
                let theta = (j as f64 + 0.5) * 2.0 * PI / n as f64;
                let mut p = *base;
                p[k] += sign * (layer as f64 + 0.5) * dz;
                p[u] += r * theta.cos();
                p[v] += r * theta.sin();
                out.positions.push(p);
                out.volumes.push(volume);
                out.spacing.push(s);
            }
        }
    }
    Ok(out)
}

/// Sectors a quarter of a ring from `a` to `b` holds at spacing `s`: the whole spacings nearest a
/// quarter of its middle circumference, at least one.
fn per_quarter(a: f64, b: f64, s: f64) -> u64 {
    ((0.25 * PI * (a + b) / s).round() as u64).max(1)
}

/// The rings from the axis out to `radius`: the core's whole rings first (when it has one), then
/// rings of `width` out to `radius`, the last one widened to take a remainder under half a width
/// or made of a remainder of half a width or more.
fn rings(radius: f64, spacing: f64, width: f64, core: Option<&Core>) -> Result<Vec<Ring>, GeometryError> {
    let mut out = vec![];
    let mut from = 0.0;
    if let Some(c) = core {
        let (fine, s) = (positive("core width", c.width)?, positive("core spacing", c.spacing)?);
        let whole = (c.radius.min(radius) / fine * (1.0 + 1e-9)).floor() as u64;
        out.extend((0..whole).map(|i| (i as f64 * fine, (i + 1) as f64 * fine, s)));
        from = whole as f64 * fine;
    }
    let span = radius - from;
    if span <= 1e-9 * radius {
        return Ok(out);
    }
    let whole = (span / width * (1.0 + 1e-9)).floor() as u64;
    let rest = span - whole as f64 * width;
    let mut edges: Vec<f64> = (0..=whole).map(|i| from + i as f64 * width).collect();
    if rest >= 0.5 * width || whole == 0 {
        edges.push(radius);
    } else {
        *edges.last_mut().expect("one edge at least") = radius;
    }
    out.extend(edges.windows(2).map(|w| (w[0], w[1], spacing)));
    Ok(out)
}

fn param(message: String) -> GeometryError {
    GeometryError::Parameter { name: "fill", message }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cylinder(radius: f64, length: f64) -> Primitive {
        Primitive::Cylinder { base: [0.0, 0.0, -length], axis: [0.0, 0.0, 1.0], radius, length }
    }

    #[test]
    fn the_rings_volumes_sum_to_the_cylinders_exactly() {
        let how = Rings { spacing: 1.0, width: 1.25, core: None };
        let p = fill_rings(&cylinder(10.0, 8.0), &how, 3, u64::MAX).expect("fill");
        let exact = PI * 100.0 * 8.0;
        assert!((p.total_volume() - exact).abs() < 1e-12 * exact, "{} against {exact}", p.total_volume());
    }

    #[test]
    fn a_radius_the_width_divides_falls_between_rings_at_every_spacing() {
        for n in [7u32, 8, 10, 13, 15, 18] {
            let width = 10.0 / n as f64;
            let how = Rings { spacing: width, width, core: None };
            let p = fill_rings(&cylinder(20.0, 2.0), &how, 3, u64::MAX).expect("fill");
            let mut radii: Vec<f64> = p.positions.iter().map(|x| x[0].hypot(x[1])).collect();
            radii.sort_by(f64::total_cmp);
            radii.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
            let below = radii.iter().rev().find(|&&r| r < 10.0).expect("a ring inside");
            let above = radii.iter().find(|&&r| r > 10.0).expect("a ring outside");
            assert!((10.0 - below - 0.5 * width).abs() < 1e-9 && (above - 10.0 - 0.5 * width).abs() < 1e-9);
        }
    }

    #[test]
    fn every_ring_is_symmetric_about_both_planes_through_the_axis_with_no_particle_on_them() {
        let how = Rings { spacing: 0.8, width: 0.8, core: None };
        let p = fill_rings(&cylinder(5.0, 0.8), &how, 3, u64::MAX).expect("fill");
        let has = |x: f64, y: f64| p.positions.iter().any(|q| (q[0] - x).abs() < 1e-9 && (q[1] - y).abs() < 1e-9);
        for q in &p.positions {
            assert!(has(-q[0], q[1]) && has(q[0], -q[1]), "{q:?} has no mirror image");
            assert!(
                q[0].abs() > 0.25 * 0.8 && q[1].abs() > 0.25 * 0.8,
                "{q:?} lies within a quarter spacing of a plane"
            );
        }
    }

    #[test]
    fn a_core_gives_whole_fine_rings_then_coarse_ones_out_to_the_radius() {
        let core = Core { radius: 24.0, spacing: 4.0 / 3.0, width: 1.25 };
        let how = Rings { spacing: 4.0, width: 4.0, core: Some(core) };
        let r = rings(256.0, 4.0, 4.0, how.core.as_ref()).expect("rings");
        let fine: Vec<_> = r.iter().filter(|x| x.2 < 2.0).collect();
        assert_eq!(fine.len(), 19);
        assert!((fine[18].1 - 23.75).abs() < 1e-12);
        assert!((r.last().expect("a ring").1 - 256.0).abs() < 1e-12);
        assert!(r.windows(2).all(|w| (w[0].1 - w[1].0).abs() < 1e-12), "the rings leave a gap");
        let p = fill_rings(&cylinder(256.0, 8.0), &how, 3, u64::MAX).expect("fill");
        let exact = PI * 256.0 * 256.0 * 8.0;
        assert!((p.total_volume() - exact).abs() < 1e-12 * exact);
        // Fine particles within 23.75 mm in 6 layers through the 8 mm, coarse ones beyond in 2.
        let layers = |fine: bool| {
            let mut z: Vec<f64> =
                (0..p.len()).filter(|&i| (p.spacing[i] < 2.0) == fine).map(|i| p.positions[i][2]).collect();
            z.sort_by(f64::total_cmp);
            z.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
            z.len()
        };
        assert_eq!((layers(true), layers(false)), (6, 2));
        let within = |i: usize| p.positions[i][0].hypot(p.positions[i][1]) < 23.75;
        assert!((0..p.len()).all(|i| within(i) == (p.spacing[i] < 2.0)));
    }

    #[test]
    fn a_fill_over_the_limit_is_refused_before_it_is_built() {
        let how = Rings { spacing: 0.01, width: 0.01, core: None };
        match fill_rings(&cylinder(10.0, 8.0), &how, 3, 1000) {
            Err(GeometryError::TooManyParticles { estimated: false, limit: 1000, .. }) => {}
            other => panic!("{other:?}"),
        }
    }
}
