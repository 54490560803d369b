//! Particle placement: primitive fills (counts, positions, exact volumes, 1D/2D sections, errors),
//! graded fills (minimum pair distance, coverage, total volume), node-list readers (CSV, LS-DYNA,
//! positioned errors, fuzzing) and spacing estimation (regular and graded lattices).

use pairsum::scene::geometry::{
    at_corners, estimate_spacing, fill, fill_graded, fill_with, read_csv_nodes, read_lsdyna_nodes, Fill, GeometryError,
    NodeList, Particles, Primitive, MAX_PARTICLES,
};
use std::f64::consts::PI;

struct XorShift(u64);

impl XorShift {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * b.abs().max(1e-300)
}

/// The smallest distance between two particles, by brute force.
fn min_pair_distance(p: &[[f64; 3]]) -> f64 {
    let mut m = f64::INFINITY;
    for i in 0..p.len() {
        for j in i + 1..p.len() {
            m = m.min(dist(p[i], p[j]));
        }
    }
    m
}

fn centroid(p: &Particles) -> [f64; 3] {
    let mut c = [0.0; 3];
    for x in &p.positions {
        for a in 0..3 {
            c[a] += x[a] / p.len() as f64;
        }
    }
    c
}

fn check_consistent(p: &Particles, dim: usize) {
    assert_eq!(p.positions.len(), p.volumes.len());
    assert_eq!(p.positions.len(), p.spacing.len());
    for (x, (v, s)) in p.positions.iter().zip(p.volumes.iter().zip(&p.spacing)) {
        assert!(x[dim..].iter().all(|&c| c == 0.0), "unused coordinates must be 0: {x:?}");
        assert!(close(*v, s.powi(dim as i32) * p.volume_scale, 1e-12));
    }
}

// ---------------------------------------------------------------- primitives

#[test]
fn box_nodes_sit_at_cell_centres_in_every_dimension() {
    let b = Primitive::Box { min: [0.0, 0.0, 0.0], max: [1.0, 0.5, 0.3] };
    for (dim, n) in [(1, 10), (2, 50), (3, 150)] {
        let p = fill(&b, 0.1, dim).unwrap();
        check_consistent(&p, dim);
        assert_eq!(p.len(), n, "dim {dim}");
        assert_eq!(p.volume_scale, 1.0);
        assert!(p.volumes.iter().all(|&v| close(v, 0.1f64.powi(dim as i32), 1e-12)));
        for x in &p.positions {
            for a in 0..dim {
                let k = x[a] / 0.1 - 0.5;
                assert!((k - k.round()).abs() < 1e-9, "node off the cell centres: {x:?}");
                assert!(x[a] > 0.0, "no particle on a face: {x:?}");
            }
        }
        let xs: Vec<f64> = p.positions.iter().map(|x| x[0]).collect();
        let (lo, hi) = pairsum::compare::extremes(&xs).unwrap_or_else(|e| panic!("the particles' x: {e}"));
        assert!(close(lo, 0.05, 1e-12) && close(hi, 0.95, 1e-12));
    }
}

#[test]
fn box_ignores_unused_coordinates() {
    let b = Primitive::Box { min: [0.0, 0.0, 7.0], max: [1.0, 1.0, 7.0] };
    let p = fill(&b, 0.25, 2).unwrap();
    assert_eq!(p.len(), 16);
    assert!(p.positions.iter().all(|x| x[2] == 0.0));
}

#[test]
fn sphere_volume_is_exact_and_nodes_inside_and_symmetric() {
    let c = [1.0, -2.0, 0.5];
    let r = 0.5;
    for (dim, exact) in [(1, 2.0 * r), (2, PI * r * r), (3, 4.0 / 3.0 * PI * r.powi(3))] {
        let p = fill(&Primitive::Sphere { center: c, radius: r }, 0.05, dim).unwrap();
        check_consistent(&p, dim);
        assert!(close(p.total_volume(), exact, 1e-12), "dim {dim}: {} vs {exact}", p.total_volume());
        let lattice = p.len() as f64 * 0.05f64.powi(dim as i32);
        assert!(close(lattice, exact, 0.05), "dim {dim}: lattice volume {lattice} vs {exact}");
        assert!((p.volume_scale - exact / lattice).abs() < 1e-12);
        let mut cc = c;
        cc[dim..].iter_mut().for_each(|v| *v = 0.0);
        assert!(p.positions.iter().all(|x| dist(*x, cc) <= r * (1.0 + 1e-9)));
        let g = centroid(&p);
        assert!(dist(g, cc) < 1e-9, "dim {dim}: centroid {g:?}");
    }
}

#[test]
fn oblique_cylinder_holds_only_inside_nodes_and_exact_volume() {
    let axis = [1.0, 2.0, 2.0];
    let base = [0.1, 0.2, 0.3];
    let (radius, length) = (0.3, 1.2);
    let p = fill(&Primitive::Cylinder { base, axis, radius, length }, 0.04, 3).unwrap();
    check_consistent(&p, 3);
    assert!(close(p.total_volume(), PI * radius * radius * length, 1e-12));
    let lattice = p.len() as f64 * 0.04f64.powi(3);
    assert!(close(lattice, PI * radius * radius * length, 0.03), "{lattice}");
    let a = [1.0 / 3.0, 2.0 / 3.0, 2.0 / 3.0];
    for x in &p.positions {
        let u = [x[0] - base[0], x[1] - base[1], x[2] - base[2]];
        let s = u[0] * a[0] + u[1] * a[1] + u[2] * a[2];
        let perp = dist(u, [s * a[0], s * a[1], s * a[2]]);
        assert!((-1e-9..=length + 1e-9).contains(&s) && perp <= radius + 1e-9, "{x:?}");
    }
}

#[test]
fn cylinder_along_z_matches_a_count_by_membership() {
    let dx = 0.1;
    let p =
        fill(&Primitive::Cylinder { base: [0.0; 3], axis: [0.0, 0.0, 3.0], radius: 1.0, length: 1.0 }, dx, 3).unwrap();
    // Default anchor: bbox min + dx/2 = (-0.95, -0.95, 0.05); count the nodes inside by brute force.
    let mut n = 0;
    for i in 0..20 {
        for j in 0..20 {
            let (x, y) = (-0.95 + i as f64 * dx, -0.95 + j as f64 * dx);
            if x * x + y * y <= 1.0 {
                n += 10;
            }
        }
    }
    assert_eq!(p.len(), n);
}

#[test]
fn hollow_cylinder_in_3d_2d_and_1d() {
    let (ri, ro, len) = (0.3, 0.5, 1.0);
    let tube =
        |axis| Primitive::HollowCylinder { base: [0.0; 3], axis, inner_radius: ri, outer_radius: ro, length: len };
    let p3 = fill(&tube([1.0, 0.0, 0.0]), 0.02, 3).unwrap();
    assert!(close(p3.total_volume(), PI * (ro * ro - ri * ri) * len, 1e-12));
    for x in &p3.positions {
        let r = (x[1] * x[1] + x[2] * x[2]).sqrt();
        assert!(r >= ri - 1e-9 && r <= ro + 1e-9 && x[0] >= -1e-9 && x[0] <= len + 1e-9);
    }
    // 2D, axis in the plane: two strips.
    let strips = fill(&tube([1.0, 0.0, 0.0]), 0.02, 2).unwrap();
    assert!(close(strips.total_volume(), 2.0 * (ro - ri) * len, 1e-12));
    assert!(strips.positions.iter().all(|x| x[1].abs() >= ri - 1e-9 && x[1].abs() <= ro + 1e-9));
    // 2D, axis across the plane: an annulus.
    let ring = fill(&tube([0.0, 0.0, 1.0]), 0.02, 2).unwrap();
    assert!(close(ring.total_volume(), PI * (ro * ro - ri * ri), 1e-12));
    let lattice = ring.len() as f64 * 0.02 * 0.02;
    assert!(close(lattice, PI * (ro * ro - ri * ri), 0.03));
    // 1D: across the line, two segments; along it, empty and rejected.
    let segs = fill(&tube([0.0, 1.0, 0.0]), 0.01, 1).unwrap();
    assert!(close(segs.total_volume(), 2.0 * (ro - ri), 1e-12));
    assert_eq!(segs.len(), 40);
    assert!(matches!(fill(&tube([1.0, 0.0, 0.0]), 0.01, 1), Err(GeometryError::Parameter { name: "axis", .. })));
}

#[test]
fn plate_volume_layers_and_sections() {
    let plate = |normal| Primitive::Plate { center: [0.0, 0.0, 0.0], normal, radius: 1.0, thickness: 0.1 };
    let p = fill(&plate([0.0, 0.0, 1.0]), 0.025, 3).unwrap();
    assert!(close(p.total_volume(), PI * 0.1, 1e-12));
    let mut zs: Vec<f64> = p.positions.iter().map(|x| (x[2] * 1e6).round() / 1e6).collect();
    zs.sort_by(f64::total_cmp);
    zs.dedup();
    assert_eq!(zs, vec![-0.0375, -0.0125, 0.0125, 0.0375], "four layers, none on the faces");
    // 2D with the normal in the plane: a 0.1 × 2 rectangle; across: a unit disc.
    let rect = fill(&plate([0.0, 1.0, 0.0]), 0.025, 2).unwrap();
    assert!(close(rect.total_volume(), 0.2, 1e-12));
    assert_eq!(rect.len(), 4 * 80);
    let disc = fill(&plate([0.0, 0.0, -2.0]), 0.025, 2).unwrap();
    assert!(close(disc.total_volume(), PI, 1e-12));
    // 1D along the normal: a segment of the plate's thickness.
    let seg = fill(&plate([1.0, 0.0, 0.0]), 0.025, 1).unwrap();
    assert_eq!(seg.len(), 4);
    assert!(close(seg.total_volume(), 0.1, 1e-12));
}

#[test]
fn explicit_origin_anchors_the_lattice() {
    let b = Primitive::Box { min: [0.0; 3], max: [1.0, 1.0, 0.0] };
    let p = fill_with(&b, &Fill { spacing: 0.25, origin: Some([0.0, 0.0, 0.0]) }, 2).unwrap();
    assert_eq!(p.len(), 25, "nodes on the faces count as inside");
    assert!(p.positions.contains(&[0.0, 0.0, 0.0]) && p.positions.contains(&[1.0, 1.0, 0.0]));
}

#[test]
fn bad_parameters_are_errors_not_panics() {
    let s = Primitive::Sphere { center: [0.0; 3], radius: 1.0 };
    for dx in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(matches!(fill(&s, dx, 3), Err(GeometryError::Parameter { name: "spacing", .. })), "{dx}");
    }
    assert_eq!(fill(&s, 0.1, 0), Err(GeometryError::Dimension(0)));
    assert_eq!(fill(&s, 0.1, 4), Err(GeometryError::Dimension(4)));
    let bad = [
        (Primitive::Sphere { center: [0.0; 3], radius: 0.0 }, "radius"),
        (Primitive::Sphere { center: [f64::NAN, 0.0, 0.0], radius: 1.0 }, "center"),
        (Primitive::Box { min: [0.0; 3], max: [1.0, 0.0, 1.0] }, "max"),
        (Primitive::Cylinder { base: [0.0; 3], axis: [0.0; 3], radius: 1.0, length: 1.0 }, "axis"),
        (Primitive::Cylinder { base: [0.0; 3], axis: [1.0, f64::NAN, 0.0], radius: 1.0, length: 1.0 }, "axis"),
        (Primitive::Cylinder { base: [0.0; 3], axis: [1.0, 0.0, 0.0], radius: 1.0, length: -1.0 }, "length"),
        (
            Primitive::HollowCylinder {
                base: [0.0; 3],
                axis: [1.0, 0.0, 0.0],
                inner_radius: 2.0,
                outer_radius: 1.0,
                length: 1.0,
            },
            "inner_radius",
        ),
        (Primitive::Plate { center: [0.0; 3], normal: [0.0, 0.0, 1.0], radius: 1.0, thickness: 0.0 }, "thickness"),
    ];
    for (shape, name) in bad {
        match fill(&shape, 0.1, 3) {
            Err(GeometryError::Parameter { name: n, message }) => {
                assert_eq!(n, name, "{message}");
                assert!(!message.is_empty());
            }
            other => panic!("{shape:?}: expected a {name} error, got {other:?}"),
        }
    }
    // An oblique axis has no 2D section.
    let oblique = Primitive::Cylinder { base: [0.0; 3], axis: [1.0, 0.0, 1.0], radius: 1.0, length: 1.0 };
    let e = fill(&oblique, 0.1, 2).unwrap_err();
    assert!(e.to_string().contains("oblique"), "{e}");
}

#[test]
fn too_many_particles_and_empty_shapes_are_reported() {
    let b = Primitive::Box { min: [0.0; 3], max: [1.0; 3] };
    let e = fill(&b, 1e-3, 3).unwrap_err();
    assert!(matches!(e, GeometryError::TooManyParticles { count: 1_000_000_000, estimated: true, .. }), "{e:?}");
    assert!(e.to_string().contains("1000000000"), "{e}");
    // Just above the limit: counted exactly.
    let n = 7072; // 7072² = 50_013_184 > 50M
    let b2 = Primitive::Box { min: [0.0; 3], max: [n as f64, n as f64, 0.0] };
    match fill(&b2, 1.0, 2).unwrap_err() {
        GeometryError::TooManyParticles { count, estimated: false, limit } => {
            assert_eq!((count, limit), ((n * n) as u64, MAX_PARTICLES));
        }
        other => panic!("{other:?}"),
    }
    let tiny = Primitive::Sphere { center: [0.0; 3], radius: 0.01 };
    assert!(matches!(fill(&tiny, 1.0, 3), Err(GeometryError::Empty { .. })));
    let huge = Primitive::Sphere { center: [0.0; 3], radius: 1e300 };
    assert!(matches!(fill(&huge, 1.0, 3), Err(GeometryError::TooManyParticles { .. })));
}

// ---------------------------------------------------------------- graded fills

fn check_graded(p: &Particles, fine: f64, coarse: f64, exact: f64, dim: usize) {
    check_consistent(p, dim);
    assert!(close(p.total_volume(), exact, 1e-12), "{} vs {exact}", p.total_volume());
    assert!(p.spacing.iter().all(|&s| s == fine || s == coarse));
    assert!(p.spacing.contains(&fine) && p.spacing.contains(&coarse));
    let bound = if (coarse / fine).fract() == 0.0 { fine } else { fine.min(coarse / 2.0) };
    let m = min_pair_distance(&p.positions);
    assert!(m >= bound * (1.0 - 1e-9), "minimum pair distance {m} < {bound}");
}

#[test]
fn graded_box_with_a_fine_disc() {
    let shape = Primitive::Box { min: [0.0; 3], max: [2.0, 1.0, 0.0] };
    let region = Primitive::Sphere { center: [0.7, 0.5, 0.0], radius: 0.25 };
    let (f, c) = (0.025, 0.1);
    let p = fill_graded(&shape, f, c, &region, 2, None).unwrap();
    check_graded(&p, f, c, 2.0, 2);
    // Integer ratio and a box: the cells tile exactly, no rescaling needed.
    assert!((p.volume_scale - 1.0).abs() < 1e-12);
    // Every fine node of the region is present.
    let inside = |x: &[f64; 3]| dist(*x, [0.7, 0.5, 0.0]) <= 0.25;
    let fine_in = p.positions.iter().zip(&p.spacing).filter(|(x, &s)| s == f && inside(x)).count();
    let uniform = fill(&region, f, 2).unwrap();
    assert!(fine_in >= uniform.len() * 9 / 10, "{fine_in} vs {}", uniform.len());
    // Coverage: every point of the box is within half a coarse cell diagonal of a particle.
    let mut rng = XorShift(7);
    for _ in 0..2000 {
        let q = [2.0 * rng.unit(), rng.unit(), 0.0];
        let distances: Vec<f64> = p.positions.iter().map(|x| dist(*x, q)).collect();
        let d = pairsum::compare::extremes(&distances).unwrap_or_else(|e| panic!("distances to {q:?}: {e}")).0;
        assert!(d <= c * 2f64.sqrt() / 2.0 + 1e-9, "gap of {d} at {q:?}");
    }
}

#[test]
fn graded_sphere_with_a_fine_box_and_a_non_integer_ratio() {
    let shape = Primitive::Sphere { center: [0.0; 3], radius: 0.5 };
    let region = Primitive::Box { min: [0.0, -0.1, -0.1], max: [0.5, 0.1, 0.1] };
    for (f, c) in [(0.04, 0.08), (0.03, 0.08)] {
        let p = fill_graded(&shape, f, c, &region, 3, None).unwrap();
        check_graded(&p, f, c, 4.0 / 3.0 * PI * 0.125, 3);
        for (x, s) in p.positions.iter().zip(&p.spacing) {
            assert!(dist(*x, [0.0; 3]) <= 0.5 + 1e-9);
            if *s == f {
                assert!(
                    x[0] > -c && x[1].abs() < 0.1 + c && x[2].abs() < 0.1 + c,
                    "fine particle far from the region: {x:?}"
                );
            }
        }
    }
}

// ---------------------------------------------------------------- node-centred fills

/// Node-centred fills: one volume and spacing per particle, unused coordinates 0, volumes positive.
fn check_nodes(p: &Particles, dim: usize) {
    assert_eq!(p.positions.len(), p.volumes.len());
    assert_eq!(p.positions.len(), p.spacing.len());
    assert!(p.positions.iter().all(|x| x[dim..].iter().all(|&c| c == 0.0)));
    assert!(p.volumes.iter().all(|&v| v > 0.0));
}

/// The volume-weighted centroid of a fill.
fn volume_centroid(p: &Particles) -> [f64; 3] {
    let mut c = [0.0; 3];
    for (x, v) in p.positions.iter().zip(&p.volumes) {
        for a in 0..3 {
            c[a] += x[a] * v;
        }
    }
    c.map(|s| s / p.total_volume())
}

#[test]
fn node_centred_box_has_particles_on_its_faces_with_lumped_volumes() {
    // EK18 §4's uniform plate: 200 × 200 × 10 mm at 5 mm is 41 × 41 × 3 = 5,043 nodes.
    let dx = 0.005;
    let plate = Primitive::Box { min: [-0.1, -0.1, -0.01], max: [0.1, 0.1, 0.0] };
    let p = at_corners(&fill(&plate, dx, 3).unwrap(), 3);
    assert_eq!(p.len(), 5043);
    check_nodes(&p, 3);
    assert!(close(p.total_volume(), 0.2 * 0.2 * 0.01, 1e-12));
    for (x, (v, s)) in p.positions.iter().zip(p.volumes.iter().zip(&p.spacing)) {
        // On the lattice of the box's corners, and inside the box.
        let on_face = |a: usize, lo: f64, hi: f64| {
            let k = (x[a] - lo) / dx;
            assert!((k - k.round()).abs() < 1e-9 && x[a] >= lo - 1e-12 && x[a] <= hi + 1e-12, "{x:?}");
            (x[a] - lo).abs() < 1e-12 || (x[a] - hi).abs() < 1e-12
        };
        let faces = [on_face(0, -0.1, 0.1), on_face(1, -0.1, 0.1), on_face(2, -0.01, 0.0)];
        // A half on a face, a quarter on an edge, an eighth at a corner.
        let expect = dx.powi(3) * 0.5f64.powi(faces.iter().filter(|f| **f).count() as i32);
        assert!(close(*v, expect, 1e-12), "volume {v} at {x:?}");
        assert_eq!(*s, dx);
    }
    // Three layers through the thickness, where the cell-centred fill has two.
    let mut layers: Vec<i64> = p.positions.iter().map(|x| (x[2] / dx).round() as i64).collect();
    layers.sort_unstable();
    layers.dedup();
    assert_eq!(layers, vec![-2, -1, 0]);
    // 2D: a rectangle of 4 × 2 cells has 5 × 3 nodes; 1D: a bar of 4 cells has 5.
    let rect = Primitive::Box { min: [0.0; 3], max: [0.4, 0.2, 0.0] };
    let p2 = at_corners(&fill(&rect, 0.1, 2).unwrap(), 2);
    assert_eq!(p2.len(), 15);
    assert!(close(p2.total_volume(), 0.08, 1e-12));
    let bar = Primitive::Box { min: [0.0; 3], max: [0.4, 0.0, 0.0] };
    let p1 = at_corners(&fill(&bar, 0.1, 1).unwrap(), 1);
    assert_eq!(p1.volumes, vec![0.05, 0.1, 0.1, 0.1, 0.05]);
}

#[test]
fn node_centred_graded_plate_keeps_two_layers_where_coarse() {
    // EK18 §4's graded plate: 5 mm within 40 mm of the axis, 10 mm beyond, 10 mm thick.
    let plate = Primitive::Box { min: [-0.1, -0.1, -0.01], max: [0.1, 0.1, 0.0] };
    let region = Primitive::Cylinder { base: [0.0, 0.0, -0.02], axis: [0.0, 0.0, 1.0], radius: 0.04, length: 0.04 };
    let (f, c) = (0.005, 0.01);
    let cells = fill_graded(&plate, f, c, &region, 3, None).unwrap();
    let p = at_corners(&cells, 3);
    check_nodes(&p, 3);
    assert!(close(p.total_volume(), 0.2 * 0.2 * 0.01, 1e-12));
    // The corners share each cell's volume equally, so the volume's centroid is the cells'.
    let (a, b) = (volume_centroid(&p), volume_centroid(&cells));
    assert!((0..3).all(|k| (a[k] - b[k]).abs() < 1e-12), "{a:?} vs {b:?}");
    assert!(min_pair_distance(&p.positions) >= f * (1.0 - 1e-9));
    // Layers through the thickness: three in the fine part, two (both faces) in the coarse one.
    let layers_at = |r_lo: f64, r_hi: f64| {
        let mut z: Vec<i64> = p
            .positions
            .iter()
            .filter(|x| (r_lo..r_hi).contains(&x[0].hypot(x[1])))
            .map(|x| (x[2] / f).round() as i64)
            .collect();
        z.sort_unstable();
        z.dedup();
        z
    };
    assert_eq!(layers_at(0.0, 0.03), vec![-2, -1, 0]);
    assert_eq!(layers_at(0.07, 0.09), vec![-2, 0]);
    // Spacings: fine inside, coarse outside, their mean where a node joins both.
    assert!(p.spacing.iter().all(|&s| (f - 1e-15..=c + 1e-15).contains(&s)));
    assert!(p.spacing.iter().any(|&s| s > f && s < c));
}

#[test]
fn graded_fill_in_1d_and_degenerate_cases() {
    let bar = Primitive::Box { min: [0.0; 3], max: [1.0, 0.0, 0.0] };
    let region = Primitive::Box { min: [0.4, 0.0, 0.0], max: [0.6, 0.0, 0.0] };
    let p = fill_graded(&bar, 0.01, 0.05, &region, 1, None).unwrap();
    check_graded(&p, 0.01, 0.05, 1.0, 1);
    assert_eq!(p.spacing.iter().filter(|&&s| s == 0.01).count(), 20);
    assert_eq!(p.spacing.iter().filter(|&&s| s == 0.05).count(), 16);
    // A fine region outside the shape: a plain coarse fill.
    let away = Primitive::Sphere { center: [5.0, 0.0, 0.0], radius: 0.1 };
    let q = fill_graded(&bar, 0.01, 0.05, &away, 1, None).unwrap();
    assert_eq!(q.len(), 20);
    // coarse < fine is an error.
    assert!(matches!(
        fill_graded(&bar, 0.05, 0.01, &region, 1, None),
        Err(GeometryError::Parameter { name: "coarse", .. })
    ));
    // Too fine a region.
    let cube = Primitive::Box { min: [0.0; 3], max: [1.0; 3] };
    assert!(matches!(fill_graded(&cube, 1e-3, 0.1, &cube, 3, None), Err(GeometryError::TooManyParticles { .. })));
}

// ---------------------------------------------------------------- CSV

#[test]
fn csv_with_header_comments_and_volumes() {
    let text = "\u{feff}# nodes\nx, y, z, volume\n\n0, 0, 0, 1e-3  # first\n1.5,-2,3E2,0.5\n";
    let n = read_csv_nodes(text, "n.csv").unwrap();
    assert_eq!(n.positions, vec![[0.0, 0.0, 0.0], [1.5, -2.0, 300.0]]);
    assert_eq!(n.volumes, Some(vec![1e-3, 0.5]));
    let n = read_csv_nodes("1,2,3\n4,5,6", "n.csv").unwrap();
    assert_eq!(n.positions.len(), 2);
    assert_eq!(n.volumes, None);
}

#[test]
fn csv_errors_point_at_line_and_column() {
    let cases = [
        ("x,y,z\n1,2,3\n4, abc,6\n", 3, 4, "expected a number, found `abc`"),
        ("1,2,3\n1,2,3,4\n", 2, 7, "expected 3 fields like line 1, found 4"),
        ("1,2\n", 1, 4, "expected 3 fields (x,y,z) or 4 (x,y,z,volume), found 2"),
        ("1,2,3,-1\n", 1, 7, "expected a positive volume, found `-1`"),
        ("1,,3\n", 1, 3, "expected a number, found nothing"),
        ("1,2,inf\n", 1, 5, "expected a number, found `inf`"),
        ("x,y,z\nx,y,z\n", 2, 1, "expected a number, found `x`"),
        ("# nothing\n\n", 2, 1, "no nodes"),
    ];
    for (text, line, column, message) in cases {
        let e = read_csv_nodes(text, "nodes.csv").unwrap_err();
        assert_eq!((e.line, e.column), (line, column), "{text:?}: {e}");
        assert!(e.message.starts_with(message), "{text:?}: {e}");
        assert_eq!(e.to_string(), format!("nodes.csv:{line}:{column}: {}", e.message));
    }
}

// ---------------------------------------------------------------- LS-DYNA

const DECK: &str = "\
*KEYWORD
*TITLE
plate $ not a comment here
$#   nid               x               y               z      tc      rc
*NODE
       1             0.0             0.0             0.0       0       0
       2          1.0E-3        -2.5e+00            1.50
$ a comment inside the section
       3            1.-3           2.5+1              -4
*ELEMENT_SOLID
       1       1       1       2       3       3       3       3       3       3
*NODE_RIGID_SURFACE
       9             9.0             9.0             9.0
*NODE
4, 1.0, 2.0, 3.0
5,-1.5D-2,0,7, 0, 0
*END
";

#[test]
fn lsdyna_fixed_and_free_format_sections() {
    let n = read_lsdyna_nodes(DECK, "deck.k").unwrap();
    assert_eq!(n.volumes, None);
    let expect = [[0.0, 0.0, 0.0], [1.0e-3, -2.5, 1.5], [1.0e-3, 25.0, -4.0], [1.0, 2.0, 3.0], [-1.5e-2, 0.0, 7.0]];
    assert_eq!(n.positions.len(), expect.len());
    for (a, b) in n.positions.iter().zip(expect) {
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() <= 1e-12 * b[k].abs().max(1.0), "{a:?} vs {b:?}");
        }
    }
}

#[test]
fn lsdyna_wide_and_long_layouts() {
    let wide = "*NODE %\n1234567890             1.0             2.0             3.0\n";
    assert_eq!(read_lsdyna_nodes(wide, "w.k").unwrap().positions, vec![[1.0, 2.0, 3.0]]);
    let long = format!("*KEYWORD LONG=Y\n*NODE\n{:>20}{:>20}{:>20}{:>20}\n", 7, "1.5", "-2", "0.25");
    assert_eq!(read_lsdyna_nodes(&long, "l.k").unwrap().positions, vec![[1.5, -2.0, 0.25]]);
    let plus = format!("*node +\n{:>20}{:>20}{:>20}{:>20}{:>20}{:>20}\n", 7, "1", "2", "3", "0", "0");
    assert_eq!(read_lsdyna_nodes(&plus, "p.k").unwrap().positions, vec![[1.0, 2.0, 3.0]]);
}

#[test]
fn lsdyna_errors_point_at_line_and_column() {
    let cases = [
        ("*NODE\n       1             abc             0.0             0.0\n", 2, 22, "expected a number, found `abc`"),
        (
            "*NODE\n     1.5             0.0             0.0             0.0\n",
            2,
            6,
            "expected an integer node id, found `1.5`",
        ),
        ("*NODE\n1 0.5 0.5 0.5\n", 2, 1, "expected an integer node id, found `1 0.5 0.`"),
        ("*NODE\n1, 0.5\n", 2, 7, "expected 4 to 6 comma-separated fields"),
        ("*NODE\n1, 0.5, x, 0\n", 2, 9, "expected a number, found `x`"),
        (
            "*NODE\n       1             0.0             0.0             0.0       0       0 extra\n",
            2,
            74,
            "unexpected text after the last field",
        ),
        ("*KEYWORD\n*END\n", 2, 1, "no *NODE section"),
        ("*NODE\n$ only a comment\n*END\n", 3, 1, "no nodes in the *NODE sections"),
    ];
    for (text, line, column, message) in cases {
        let e = read_lsdyna_nodes(text, "deck.k").unwrap_err();
        assert_eq!((e.line, e.column), (line, column), "{text:?}: {e}");
        assert!(e.message.starts_with(message), "{text:?}: {e}");
        assert_eq!(e.to_string(), format!("deck.k:{line}:{column}: {}", e.message));
    }
}

#[test]
fn readers_never_panic_on_garbage_or_truncation() {
    let mut rng = XorShift(0x9e37_79b9_7f4a_7c15);
    let alphabet: Vec<char> = "0123456789 ,.-+eEdD*$#\n\tNODEnodxyz%é\u{feff}".chars().collect();
    let csv = "x,y,z,volume\n0,0,0,1\n1.5,2,3e-2,0.5\n";
    for round in 0..3000 {
        let text: String = match round % 3 {
            0 => (0..rng.below(200)).map(|_| alphabet[rng.below(alphabet.len())]).collect(),
            1 => DECK.chars().take(rng.below(DECK.chars().count())).collect(),
            _ => {
                let mut s: Vec<char> = if rng.below(2) == 0 { DECK.chars().collect() } else { csv.chars().collect() };
                for _ in 0..1 + rng.below(4) {
                    let i = rng.below(s.len());
                    s[i] = alphabet[rng.below(alphabet.len())];
                }
                s.into_iter().collect()
            }
        };
        for result in [read_csv_nodes(&text, "f"), read_lsdyna_nodes(&text, "f")] {
            match result {
                Ok(n) => {
                    assert!(!n.positions.is_empty());
                    assert!(n.positions.iter().flatten().all(|v| v.is_finite()));
                }
                Err(e) => {
                    assert!(e.line >= 1 && e.column >= 1 && e.line <= text.lines().count().max(1), "{e} in {text:?}");
                }
            }
        }
    }
    // Truncating every line of the deck at every column.
    let lines: Vec<&str> = DECK.lines().collect();
    for (i, l) in lines.iter().enumerate() {
        for cut in 0..=l.len() {
            let mut t: Vec<String> = lines.iter().map(|s| s.to_string()).collect();
            t[i] = l[..cut].to_string();
            let _ = read_lsdyna_nodes(&t.join("\n"), "t");
        }
    }
}

// ---------------------------------------------------------------- spacing

fn lattice(n: [usize; 3], dx: f64, offset: [f64; 3]) -> Vec<[f64; 3]> {
    let mut out = Vec::new();
    for k in 0..n[2] {
        for j in 0..n[1] {
            for i in 0..n[0] {
                out.push([offset[0] + i as f64 * dx, offset[1] + j as f64 * dx, offset[2] + k as f64 * dx]);
            }
        }
    }
    out
}

#[test]
fn spacing_of_regular_lattices() {
    for (dim, n) in [(1, [200, 1, 1]), (2, [40, 30, 1]), (3, [20, 20, 20])] {
        let dx = 0.013;
        let mut rng = XorShift(3);
        let mut pts = lattice(n, dx, [-0.2, 0.1, 5.0]);
        pts.iter_mut().for_each(|p| p[dim..].iter_mut().for_each(|v| *v = 0.0));
        // Shuffle so that file order does not matter.
        for i in (1..pts.len()).rev() {
            pts.swap(i, rng.below(i + 1));
        }
        let s = estimate_spacing(&pts, dim);
        let lo = [-0.2, 0.1, 5.0];
        for (p, s) in pts.iter().zip(&s) {
            let interior = (0..dim).all(|a| {
                let k = ((p[a] - lo[a]) / dx).round() as usize;
                k > 0 && k + 1 < n[a]
            });
            if interior {
                assert!(close(*s, dx, 0.01), "dim {dim}: spacing {s} at {p:?}");
            } else {
                assert!(*s >= dx * (1.0 - 1e-9) && *s <= dx * 1.5 + 1e-12, "dim {dim}: boundary spacing {s}");
            }
        }
    }
}

#[test]
fn spacing_of_a_graded_lattice() {
    // Fine half x < 0 at 0.01, coarse half x > 0 at 0.04, in 2D.
    let mut pts = lattice([100, 80, 1], 0.01, [-1.0 + 0.005, 0.005, 0.0]);
    pts.extend(lattice([25, 20, 1], 0.04, [0.02, 0.02, 0.0]));
    pts.iter_mut().for_each(|p| p[2] = 0.0);
    let s = estimate_spacing(&pts, 2);
    for (p, s) in pts.iter().zip(&s) {
        let inner_y = p[1] > 0.05 && p[1] < 0.75;
        if p[0] < -0.1 && p[0] > -0.95 && inner_y {
            assert!(close(*s, 0.01, 0.01), "fine {s} at {p:?}");
        }
        if p[0] > 0.1 && p[0] < 0.95 && inner_y {
            assert!(close(*s, 0.04, 0.01), "coarse {s} at {p:?}");
        }
        assert!(*s > 0.009 && *s < 0.06, "{s} at {p:?}");
    }
}

#[test]
fn spacing_edge_cases() {
    assert!(estimate_spacing(&[], 3).is_empty());
    assert_eq!(estimate_spacing(&[[1.0, 2.0, 3.0]], 3), vec![0.0]);
    let s = estimate_spacing(&[[0.0; 3], [3.0, 4.0, 0.0]], 2);
    assert_eq!(s, vec![5.0, 5.0]);
    let s = estimate_spacing(&[[0.0; 3], [1.0, 0.0, 0.0], [f64::NAN, 0.0, 0.0], [0.0; 3]], 1);
    assert!(s[2].is_nan() && s[0] == 0.5 && s[1] == 1.0);
    // A far outlier does not break the search.
    let mut pts = lattice([10, 10, 10], 1.0, [0.0; 3]);
    pts.push([1e9, 0.0, 0.0]);
    let s = estimate_spacing(&pts, 3);
    assert!(s[..1000].iter().all(|&v| (1.0..1.35).contains(&v)));
    assert!(s[1000] > 1e8);
}

#[test]
fn spacing_of_a_large_cloud_is_fast_enough() {
    let pts = lattice([50, 50, 40], 0.1, [0.0; 3]);
    let t = std::time::Instant::now();
    let s = estimate_spacing(&pts, 3);
    assert_eq!(s.len(), 100_000);
    assert!(t.elapsed().as_secs_f64() < 20.0, "{:?}", t.elapsed());
    // Strong grading (8:1) and a far outlier: neither a dense grid nor an O(n²) cell.
    let mut pts = lattice([40, 40, 40], 0.01, [0.0; 3]);
    pts.extend(lattice([10, 10, 10], 0.08, [1.0, 0.0, 0.0]));
    pts.push([1e6, -1e6, 3.0]);
    let t = std::time::Instant::now();
    let s = estimate_spacing(&pts, 3);
    assert!(t.elapsed().as_secs_f64() < 20.0, "{:?}", t.elapsed());
    assert!(s[..64_000].iter().all(|&v| (0.01 - 1e-12..0.0136).contains(&v)));
    assert!(s[64_000..65_000].iter().all(|&v| (0.08 - 1e-12..0.11).contains(&v)));
}

#[test]
fn node_lists_become_particles() {
    let nodes = NodeList { positions: lattice([10, 10, 1], 0.5, [0.0, 0.0, 2.0]), volumes: None };
    let p = nodes.to_particles(2).unwrap();
    assert!(p.positions.iter().all(|x| x[2] == 0.0));
    let interior = p.spacing.iter().filter(|&&s| close(s, 0.5, 1e-9)).count();
    assert!(interior >= 64);
    check_consistent(&p, 2);
    // Nodes off the model plane.
    let mut off = nodes.clone();
    off.positions[3][2] = 2.5;
    assert!(matches!(off.to_particles(2), Err(GeometryError::Nodes(_))));
    // Given volumes are kept.
    let csv = read_csv_nodes("0,0,0,2\n1,0,0,8\n", "v.csv").unwrap();
    let p = csv.to_particles(3).unwrap();
    assert_eq!(p.volumes, vec![2.0, 8.0]);
    assert!(close(p.spacing[1], 2.0, 1e-12));
    // Coincident nodes and a lone node cannot get a volume.
    let dup = NodeList { positions: vec![[1.0; 3]; 5], volumes: None };
    assert!(matches!(dup.to_particles(3), Err(GeometryError::Nodes(_))));
    let one = NodeList { positions: vec![[1.0; 3]], volumes: None };
    assert!(one.to_particles(3).unwrap_err().to_string().contains("single node"));
}

/// Timing of a ~1M particle fill; run with `cargo test --release --test geometry -- --ignored --nocapture`.
#[test]
#[ignore]
fn time_a_million_particle_fill() {
    let sphere = Primitive::Sphere { center: [0.0; 3], radius: 1.0 };
    let dx = (4.0 / 3.0 * PI / 1e6f64).cbrt();
    let t = std::time::Instant::now();
    let p = fill(&sphere, dx, 3).unwrap();
    println!("sphere: {} particles in {:?}", p.len(), t.elapsed());
    let cyl = Primitive::Cylinder { base: [0.0; 3], axis: [1.0, 1.0, 1.0], radius: 0.5, length: 4.0 };
    let dx = (PI / 4.0 * 4.0 / 1e6f64).cbrt();
    let t = std::time::Instant::now();
    let p = fill(&cyl, dx, 3).unwrap();
    println!("oblique cylinder: {} particles in {:?}", p.len(), t.elapsed());
    let cube = Primitive::Box { min: [0.0; 3], max: [1.0; 3] };
    let t = std::time::Instant::now();
    let p = fill_graded(&cube, 0.005, 0.02, &Primitive::Sphere { center: [0.5; 3], radius: 0.3 }, 3, None).unwrap();
    println!("graded cube: {} particles in {:?}", p.len(), t.elapsed());
    let t = std::time::Instant::now();
    let s = estimate_spacing(&p.positions, 3);
    println!("estimate_spacing on {} nodes: {:?}", s.len(), t.elapsed());
}

/// Lattice count × dx² against the exact area: the lattice misses or adds at most a band of
/// width about dx along the boundary.
fn area_within_a_boundary_band(p: &Particles, dx: f64, area: f64, perimeter: f64) {
    let lattice = p.len() as f64 * dx * dx;
    assert!((lattice - area).abs() <= perimeter * dx, "lattice area {lattice} vs exact {area}");
    assert!(close(p.total_volume(), area, 1e-9), "volumes sum to {} vs {area}", p.total_volume());
}

#[test]
fn disc_annulus_and_polygon_fill_their_areas_in_2d() {
    let dx = 0.01;
    let disc = fill(&Primitive::Disc { center: [0.1, -0.2, 0.0], radius: 0.25 }, dx, 2).unwrap();
    area_within_a_boundary_band(&disc, dx, PI * 0.0625, 2.0 * PI * 0.25);
    assert!(disc.positions.iter().all(|x| dist(*x, [0.1, -0.2, 0.0]) <= 0.25 + 1e-9));

    let (ri, ro) = (0.03, 0.04);
    let ring = Primitive::Annulus { center: [0.0; 3], inner_radius: ri, outer_radius: ro };
    let ring = fill(&ring, 0.001, 2).unwrap();
    area_within_a_boundary_band(&ring, 0.001, PI * (ro * ro - ri * ri), 2.0 * PI * (ri + ro));
    assert!(ring.positions.iter().all(|x| (ri - 1e-9..=ro + 1e-9).contains(&dist(*x, [0.0; 3]))));

    // An L: the unit square less its upper right quarter, given clockwise.
    let l = vec![[0.0, 0.0], [0.0, 1.0], [0.5, 1.0], [0.5, 0.5], [1.0, 0.5], [1.0, 0.0]];
    let filled = fill(&Primitive::Polygon { vertices: l }, 0.02, 2).unwrap();
    area_within_a_boundary_band(&filled, 0.02, 0.75, 4.0);
    assert!(filled.positions.iter().all(|x| !(x[0] > 0.5 + 1e-9 && x[1] > 0.5 + 1e-9)), "a node in the notch");
    assert!(filled
        .positions
        .iter()
        .all(|x| (-1e-9..=1.0 + 1e-9).contains(&x[0]) && (-1e-9..=1.0 + 1e-9).contains(&x[1])));
    let triangle = vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
    area_within_a_boundary_band(&fill(&Primitive::Polygon { vertices: triangle }, 0.01, 2).unwrap(), 0.01, 0.5, 3.5);
}

#[test]
fn the_2d_shapes_are_refused_elsewhere_and_checked() {
    let disc = Primitive::Disc { center: [0.0; 3], radius: 1.0 };
    for dim in [1, 3] {
        assert!(matches!(fill(&disc, 0.1, dim), Err(GeometryError::Parameter { name: "dim", .. })), "{dim}D");
    }
    let bow_tie = vec![[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]];
    let e = fill(&Primitive::Polygon { vertices: bow_tie }, 0.1, 2).unwrap_err();
    assert!(e.to_string().contains("crosses itself"), "{e}");
    let flat = vec![[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]];
    assert!(fill(&Primitive::Polygon { vertices: flat }, 0.1, 2).is_err());
    assert!(fill(&Primitive::Polygon { vertices: vec![[0.0, 0.0], [1.0, 0.0]] }, 0.1, 2).is_err());
    let ring = Primitive::Annulus { center: [0.0; 3], inner_radius: 1.0, outer_radius: 0.5 };
    assert!(fill(&ring, 0.1, 2).is_err());
}
