//! The GPU cell list, reductions and device context against the CPU. These tests need a GPU
//! adapter (lavapipe, `apt-get install mesa-vulkan-drivers`, is enough) and FAIL without one:
//! a GPU test is never silently skipped.

use pairsum::backend::gpu::cells::{wgsl_helpers, CellList};
use pairsum::backend::gpu::device::{choose_adapter, choose_adapter_for, dispatch_grid, used_bindings, Gpu, GpuError};
use pairsum::backend::gpu::reduce::{ReduceOp, Reducer, Segment, ALL_FINITE};
use pairsum::grid::Grid;
use std::sync::OnceLock;

/// One device for all tests of this file (device creation and shader compilation on lavapipe
/// take a while). Fails the calling test with the NoAdapter help when there is no adapter.
fn gpu() -> &'static Gpu {
    static GPU: OnceLock<Result<Gpu, String>> = OnceLock::new();
    match GPU.get_or_init(|| Gpu::new().map_err(|e| e.to_string())) {
        Ok(g) => g,
        Err(e) => panic!("GPU tests need a GPU adapter: {e}"),
    }
}

/// SplitMix64: deterministic test data without a dependency.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    fn f(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

#[derive(Clone, Debug)]
struct Cloud {
    name: &'static str,
    dim: usize,
    n: usize,
    seed: u64,
    /// Smoothing lengths vary by a factor 3 (else uniform).
    variable_h: bool,
    /// Moves some particles exactly onto cell faces and one f32 step either side.
    faces: bool,
    /// One particle far away (forces the cell size to double).
    outlier: Option<[f32; 3]>,
    /// A NaN and an infinite coordinate.
    non_finite: bool,
    /// Cells per cut-off of the cell list (1, 2, 4 or 8).
    cells_per_cutoff: u32,
}

const SUPPORT: f32 = 2.0;
/// Words per particle at the head of the query's output.
const HEAD: usize = 7;

fn point(x: &[f32], dim: usize, i: usize) -> [f64; 3] {
    let mut p = [0.0; 3];
    for k in 0..dim {
        p[k] = x[i * dim + k] as f64;
    }
    p
}

fn h_max(h: &[f32]) -> f64 {
    h.iter().fold(0.0f64, |m, &v| m.max(v as f64))
}

/// The cell size the cloud's cell list asks for: the cut-off over the cells per cut-off.
fn cell_request(c: &Cloud, h: &[f32]) -> f64 {
    SUPPORT as f64 * h_max(h) / c.cells_per_cutoff as f64
}

fn build_cloud(c: &Cloud) -> (Vec<f32>, Vec<f32>) {
    let mut rng = Rng(c.seed);
    let (n, dim) = (c.n, c.dim);
    let mut x: Vec<f32> = (0..n * dim).map(|_| rng.f() as f32).collect();
    // About 1.3 mean spacings in the unit box.
    let dx = (1.0 / n as f64).powf(1.0 / dim as f64);
    let h: Vec<f32> =
        (0..n).map(|_| (1.3 * dx * if c.variable_h { 0.5 + 1.0 * rng.f() } else { 1.0 }) as f32).collect();
    if let Some(o) = c.outlier {
        x[(n - 1) * dim..n * dim].copy_from_slice(&o[..dim]);
    }
    if c.faces {
        // The geometry depends only on the bounding box and h_max, which moving interior
        // particles onto interior faces does not change.
        let g = Grid::build(&x, dim, cell_request(c, &h));
        let (origin, cell, counts) = (g.origin(), g.cell_size(), g.cells_per_axis());
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in x.chunks(dim) {
            for k in 0..dim {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        for q in 0..n / 10 {
            let i = rng.below(n - 1);
            if (0..dim).any(|k| x[i * dim + k] == lo[k] || x[i * dim + k] == hi[k]) {
                continue; // it spans the bounding box
            }
            for k in 0..dim {
                if counts[k] < 3 || rng.below(2) == 0 {
                    continue;
                }
                let face = 1 + rng.below(counts[k] - 2);
                let v = (origin[k] + face as f64 * cell) as f32;
                // On the face, or one f32 step below or above it.
                let v = match q % 3 {
                    0 => v,
                    1 => f32::from_bits(v.to_bits() - 1),
                    _ => f32::from_bits(v.to_bits() + 1),
                };
                x[i * dim + k] = v;
            }
        }
        let g2 = Grid::build(&x, dim, cell_request(c, &h));
        assert_eq!((g2.cell_size(), g2.cells_per_axis()), (cell, counts), "{}: faces moved the bbox", c.name);
    }
    if c.non_finite {
        x[3 * dim] = f32::NAN;
        x[7 * dim + dim - 1] = f32::INFINITY;
        x[11 * dim] = f32::NEG_INFINITY;
    }
    (x, h)
}

/// A pass-like kernel that uses the WGSL helpers: for particle i, its cell, the candidates in
/// the 3^d cells around it (z, then y, then x; slots in order) and the neighbours within
/// support * (h_i + h_j) / 2 among them; then the candidates and neighbours of the walk the pass
/// kernels take (`walk_cells`, `walk_skips`).
const QUERY_WGSL: &str = r#"
struct Query {
    n: u32,
    dim: u32,
    x_offset: u32,
    h_offset: u32,
    cap: u32,
    support: f32,
    pad0: u32,
    pad1: u32,
}
@group(0) @binding(0) var<uniform> q: Query;
@group(0) @binding(1) var<storage, read> data: array<f32>;
@group(0) @binding(2) var<storage, read> grid: array<u32>;
@group(0) @binding(3) var<storage, read> cells: array<u32>;
@group(0) @binding(4) var<storage, read_write> out: array<u32>;
// Words per particle at the head of `out`.
const HEAD = 7u;

fn pos(i: u32) -> vec3<f32> {
    var p = vec3<f32>(0.0);
    for (var k = 0u; k < q.dim; k++) {
        p[k] = data[q.x_offset + i * q.dim + k];
    }
    return p;
}

@compute @workgroup_size(64)
fn main(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wg: vec3<u32>,
        @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = (wg.x + wg.y * nwg.x) * 64u + lid;
    if (i >= q.n) { return; }
    let xi = pos(i);
    let hi = data[q.h_offset + i];
    let c = cell_coords(xi);
    let dims = grid_dims();
    let lo = select(c - vec3<u32>(1u), vec3<u32>(0u), c == vec3<u32>(0u));
    let hc = min(c + vec3<u32>(1u), dims - vec3<u32>(1u));
    var k = 0u;
    var nb = 0u;
    let base = HEAD * q.n + i * q.cap;
    for (var z = lo.z; z <= hc.z; z++) {
        for (var y = lo.y; y <= hc.y; y++) {
            for (var x = lo.x; x <= hc.x; x++) {
                let cell = cell_index(vec3<u32>(x, y, z));
                for (var s = cell_start(cell); s < cell_start(cell + 1u); s++) {
                    let j = sorted_particle(s);
                    if (k < q.cap) { out[base + k] = j; }
                    k++;
                    if (j == i) { continue; }
                    let d = xi - pos(j);
                    let r2 = d.x * d.x + d.y * d.y + d.z * d.z;
                    let rc = q.support * (0.5 * (hi + data[q.h_offset + j]));
                    if (r2 < rc * rc) { nb++; }
                }
            }
        }
    }
    // The walk the pass kernels take: the cells within the cut-off of the largest h.
    let wk = walk_cells(xi, q.support * bitcast<f32>(grid[9]));
    var k_walk = 0u;
    var nb_walk = 0u;
    for (var z = wk.lo.z; z <= wk.hi.z; z++) {
        for (var y = wk.lo.y; y <= wk.hi.y; y++) {
            for (var x = wk.lo.x; x <= wk.hi.x; x++) {
                if (walk_skips(wk, vec3<u32>(x, y, z))) { continue; }
                let cell = cell_index(vec3<u32>(x, y, z));
                for (var s = cell_start(cell); s < cell_start(cell + 1u); s++) {
                    let j = sorted_particle(s);
                    k_walk++;
                    if (j == i) { continue; }
                    let d = xi - pos(j);
                    let r2 = d.x * d.x + d.y * d.y + d.z * d.z;
                    let rc = q.support * (0.5 * (hi + data[q.h_offset + j]));
                    if (r2 < rc * rc) { nb_walk++; }
                }
            }
        }
    }
    out[HEAD * i] = c.x;
    out[HEAD * i + 1u] = c.y;
    out[HEAD * i + 2u] = c.z;
    out[HEAD * i + 3u] = k;
    out[HEAD * i + 4u] = nb;
    out[HEAD * i + 5u] = k_walk;
    out[HEAD * i + 6u] = nb_walk;
}
"#;

/// The CPU's neighbour count of particle i among `cands`, in f32 like the kernels.
fn count_within(x: &[f32], h: &[f32], dim: usize, i: usize, cands: impl Iterator<Item = usize>) -> u32 {
    let mut nb = 0;
    for j in cands {
        if j == i {
            continue;
        }
        let mut r2 = 0.0f32;
        for k in 0..dim {
            let d = x[i * dim + k] - x[j * dim + k];
            r2 += d * d;
        }
        let rc = SUPPORT * (0.5 * (h[i] + h[j]));
        if r2 < rc * rc {
            nb += 1;
        }
    }
    nb
}

fn check_cloud(c: &Cloud) {
    check_cloud_on(gpu(), c);
}

fn check_cloud_on(gpu: &Gpu, c: &Cloud) {
    let (x, h) = build_cloud(c);
    let (n, dim) = (c.n, c.dim);
    let cpu = Grid::build(&x, dim, cell_request(c, &h));

    // The caller's data buffer, with the positions and h at odd offsets.
    let x_offset = 5usize;
    let h_offset = x_offset + n * dim + 3;
    let mut data = vec![-7.0f32; h_offset + n + 2];
    data[x_offset..x_offset + n * dim].copy_from_slice(&x);
    data[h_offset..h_offset + n].copy_from_slice(&h);
    let buf = gpu.storage_buffer("test data", 4 * data.len() as u64, wgpu::BufferUsages::empty()).unwrap();
    gpu.upload(&buf, 0, &data).unwrap();

    let cl = CellList::new(gpu, n, dim, c.cells_per_cutoff).unwrap_or_else(|e| panic!("{e}"));
    let mut cap = 0;
    let mut cpu_cands = vec![];
    for i in 0..n {
        let mut v = vec![];
        cpu.for_each_candidate(point(&x, dim, i), |j| v.push(j as usize));
        cap = cap.max(v.len());
        cpu_cands.push(v);
    }
    let cap = cap + 8;
    let query = gpu
        .compile("test: query", &format!("{}{QUERY_WGSL}", wgsl_helpers()), "main")
        .unwrap_or_else(|e| panic!("{e}"));
    let out = gpu.storage_buffer("test out", 4 * (HEAD * n + n * cap) as u64, wgpu::BufferUsages::empty()).unwrap();
    let qp = [n as u32, dim as u32, x_offset as u32, h_offset as u32, cap as u32, SUPPORT.to_bits(), 0, 0];
    let qbuf = gpu.uniform_buffer("test query params", &qp);
    let bind = gpu.bind("test query", &query, &[&qbuf, &buf, cl.grid_buffer(), cl.cells_buffer(), &out]);

    let t = std::time::Instant::now();
    let mut enc = gpu.encoder("test");
    cl.record(gpu, &mut enc, &buf, x_offset as u32, h_offset as u32, SUPPORT);
    gpu.dispatch(&mut enc, "test query", &query, &bind, (n as u32).div_ceil(64));
    gpu.submit(enc);
    gpu.wait().unwrap();
    let elapsed = t.elapsed();

    let g: Vec<u32> = gpu.download(cl.grid_buffer(), 0, 16).unwrap();
    let max_cells = pairsum::grid::max_cells(n);
    let cells: Vec<u32> = gpu.download(cl.cells_buffer(), 0, max_cells + 1 + n).unwrap();
    let res: Vec<u32> = gpu.download(&out, 0, HEAD * n + n * cap).unwrap();
    eprintln!("{}: n = {n}, {} cells, build + query {elapsed:?}", c.name, cpu.num_cells());

    // How many particles a plain f32 computation would put in another cell than the CPU: the
    // faces make sure the exact (software f64) arithmetic is exercised.
    let naive = (0..n)
        .filter(|&i| {
            let p = point(&x, dim, i);
            let (o, inv) = (cpu.origin(), (1.0 / cpu.cell_size()) as f32);
            (0..dim).any(|k| {
                let v = p[k] as f32;
                let c = ((v - o[k] as f32) * inv).floor().clamp(0.0, (cpu.cells_per_axis()[k] - 1) as f32);
                v.is_finite() && c as u32 != cpu.cell_coords(p)[k]
            })
        })
        .count();
    eprintln!("{}: {naive} particles where plain f32 cells differ from the CPU's", c.name);
    if c.faces {
        assert!(naive > 0, "{}: the face particles do not test the exact arithmetic", c.name);
    }

    // Geometry.
    let name = c.name;
    let f = |w: u32| f32::from_bits(w) as f64;
    for k in 0..3 {
        assert_eq!(f(g[k]), cpu.origin()[k], "{name}: origin[{k}]");
        assert_eq!(g[4 + k] as usize, cpu.cells_per_axis()[k], "{name}: cells along axis {k}");
    }
    let cell64 = f64::from_bits(g[12] as u64 | (g[13] as u64) << 32);
    let inv64 = f64::from_bits(g[10] as u64 | (g[11] as u64) << 32);
    assert_eq!(cell64.to_bits(), cpu.cell_size().to_bits(), "{name}: cell size {cell64} vs {}", cpu.cell_size());
    assert_eq!(inv64.to_bits(), (1.0 / cpu.cell_size()).to_bits(), "{name}: inverse cell size");
    assert_eq!(f32::from_bits(g[3]), cpu.cell_size() as f32, "{name}: f32 cell size");
    assert_eq!(g[7] as usize, cpu.num_cells(), "{name}: cells used");
    assert_eq!(g[8] as usize, max_cells + 1, "{name}: offset of the order");
    assert_eq!(f(g[9]), h_max(&h), "{name}: h_max");
    // Cells on each side of a walk: the cells per cut-off, halved by each doubling of the cell.
    let doubled = cpu.cell_size() / (cell_request(c, &h) * (1.0 + pairsum::grid::CELL_MARGIN));
    let walk = if doubled.is_finite() { (c.cells_per_cutoff as f64 / doubled).max(1.0) as u32 } else { 1 };
    assert_eq!(g[14], walk, "{name}: cells walked on each side (cell size {doubled} times the request)");
    assert_eq!(g[15], 0, "{name}: reserved word");

    // The counting sort, entry for entry.
    let ncells = cpu.num_cells();
    assert_eq!(&cells[..=ncells], cpu.cell_start(), "{name}: cell starts");
    assert!(cells[ncells..=max_cells].iter().all(|&s| s as usize == n), "{name}: starts past the last cell");
    assert_eq!(&cells[max_cells + 1..], cpu.order(), "{name}: sorted particle order");

    // Per particle: cell, candidate sequence, neighbour count (and the grid is complete).
    for i in 0..n {
        let p = point(&x, dim, i);
        let head = &res[HEAD * i..HEAD * (i + 1)];
        assert_eq!(&head[..3], &cpu.cell_coords(p), "{name}: cell of particle {i} at {p:?}");
        let k = head[3] as usize;
        let gpu_cands: Vec<usize> =
            res[HEAD * n + i * cap..HEAD * n + i * cap + k.min(cap)].iter().map(|&j| j as usize).collect();
        assert_eq!(k, cpu_cands[i].len(), "{name}: number of candidates of particle {i}");
        assert_eq!(gpu_cands, cpu_cands[i], "{name}: candidates of particle {i}");
        let nb_cpu = count_within(&x, &h, dim, i, cpu_cands[i].iter().copied());
        assert_eq!(head[4], nb_cpu, "{name}: neighbours of particle {i}");
        let all = count_within(&x, &h, dim, i, 0..n);
        if c.cells_per_cutoff == 1 {
            assert_eq!(nb_cpu, all, "{name}: the CPU grid misses neighbours of {i}");
            assert!(head[5] <= head[3], "{name}: the walk of {i} takes more candidates than its 3^d cells");
        }
        assert_eq!(head[6], all, "{name}: the walk finds another number of neighbours of {i} than all pairs");
    }
    let (cands, walked): (u64, u64) = (0..n)
        .map(|i| (res[HEAD * i + 3] as u64, res[HEAD * i + 5] as u64))
        .fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    eprintln!(
        "{name}: candidates per particle {:.1} in 3^d cells, {:.1} walked",
        cands as f64 / n as f64,
        walked as f64 / n as f64
    );
}

#[test]
fn cells_2d_uniform_h() {
    check_cloud(&Cloud {
        name: "2d uniform h",
        dim: 2,
        n: 3000,
        seed: 1,
        variable_h: false,
        faces: false,
        outlier: None,
        non_finite: false,
        cells_per_cutoff: 1,
    });
}

#[test]
fn cells_2d_variable_h_faces() {
    check_cloud(&Cloud {
        name: "2d variable h, faces",
        dim: 2,
        n: 3000,
        seed: 2,
        variable_h: true,
        faces: true,
        outlier: None,
        non_finite: false,
        cells_per_cutoff: 1,
    });
}

#[test]
fn cells_2d_outlier_faces() {
    check_cloud(&Cloud {
        name: "2d outlier (cell size doubled), faces",
        dim: 2,
        n: 3000,
        seed: 3,
        variable_h: true,
        faces: true,
        outlier: Some([40.0, -25.0, 0.0]),
        non_finite: false,
        cells_per_cutoff: 1,
    });
}

#[test]
fn cells_3d_uniform_h_faces() {
    check_cloud(&Cloud {
        name: "3d uniform h, faces",
        dim: 3,
        n: 3000,
        seed: 4,
        variable_h: false,
        faces: true,
        outlier: None,
        non_finite: false,
        cells_per_cutoff: 1,
    });
}

#[test]
fn cells_3d_variable_h_outlier_non_finite() {
    check_cloud(&Cloud {
        name: "3d variable h, outlier, NaN/inf, faces",
        dim: 3,
        n: 4000,
        seed: 5,
        variable_h: true,
        faces: true,
        outlier: Some([3.0, 2.5, -4.0]),
        non_finite: true,
        cells_per_cutoff: 1,
    });
}

#[test]
fn cells_3d_two_per_cutoff_walk_finds_every_neighbour() {
    check_cloud(&Cloud {
        name: "3d uniform h, two cells per cut-off, faces",
        dim: 3,
        n: 4000,
        seed: 11,
        variable_h: false,
        faces: true,
        outlier: None,
        non_finite: false,
        cells_per_cutoff: 2,
    });
}

#[test]
fn cells_3d_two_per_cutoff_variable_h_doubled_non_finite() {
    // The outlier doubles the cell: the walk takes one cell on each side again.
    check_cloud(&Cloud {
        name: "3d variable h, two cells per cut-off, outlier, NaN/inf, faces",
        dim: 3,
        n: 4000,
        seed: 12,
        variable_h: true,
        faces: true,
        outlier: Some([3.0, 2.5, -4.0]),
        non_finite: true,
        cells_per_cutoff: 2,
    });
}

#[test]
fn cells_2d_four_per_cutoff_variable_h_faces() {
    check_cloud(&Cloud {
        name: "2d variable h, four cells per cut-off, faces",
        dim: 2,
        n: 3000,
        seed: 13,
        variable_h: true,
        faces: true,
        outlier: None,
        non_finite: false,
        cells_per_cutoff: 4,
    });
}

#[test]
fn cells_1d_and_three_scan_levels() {
    // 20 000 particles: max_cells + 1 = 80 001 counts, scanned in three levels.
    check_cloud(&Cloud {
        name: "1d, three scan levels",
        dim: 1,
        n: 20000,
        seed: 6,
        variable_h: true,
        faces: true,
        outlier: None,
        non_finite: false,
        cells_per_cutoff: 1,
    });
}

#[test]
fn two_dimensional_dispatch() {
    // A device that pretends to allow only 7 workgroups per dimension: every dispatch above
    // that becomes a 2D grid, which each kernel must index linearly.
    let mut g = Gpu::new().unwrap_or_else(|e| panic!("GPU tests need a GPU adapter: {e}"));
    g.limits.max_compute_workgroups_per_dimension = 7;
    check_cloud_on(
        &g,
        &Cloud {
            name: "2d, 2D dispatch",
            dim: 2,
            n: 3000,
            seed: 7,
            variable_h: true,
            faces: true,
            outlier: None,
            non_finite: true,
            cells_per_cutoff: 1,
        },
    );
    let red = Reducer::new(&g).unwrap();
    let v: Vec<f32> = (0..50_000).map(|i| ((i * 7919) % 10007) as f32 - 5000.0).collect();
    let buf = g.storage_buffer("test values", 4 * v.len() as u64, wgpu::BufferUsages::empty()).unwrap();
    g.upload(&buf, 0, &v).unwrap();
    let out = g.storage_buffer("test out", 16, wgpu::BufferUsages::empty()).unwrap();
    let list = red.segments(&g, &[Segment { offset: 0, first: 0, count: 25_000, comps: 2 }]).unwrap();
    let mut enc = g.encoder("test");
    red.record(&g, &mut enc, ReduceOp::Min, &buf, 0, v.len() as u32, &out, 0);
    red.record(&g, &mut enc, ReduceOp::Max, &buf, 0, v.len() as u32, &out, 1);
    red.record(&g, &mut enc, ReduceOp::Sum, &buf, 0, v.len() as u32, &out, 2);
    red.record_first_non_finite(&g, &mut enc, &buf, &list, &out, 3);
    g.submit(enc);
    let r: Vec<f32> = g.download(&out, 0, 4).unwrap();
    assert_eq!(r[0], v.iter().fold(f32::INFINITY, |a, &b| a.min(b)));
    assert_eq!(r[1], v.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b)));
    assert_eq!(r[2] as f64, v.iter().map(|&x| x as f64).sum::<f64>());
    assert_eq!(r[3].to_bits(), ALL_FINITE);
}

#[test]
fn cells_single_cell_fallback() {
    // h_max = +inf: the CPU grid falls back to one infinite cell; so must the GPU.
    let gpu = gpu();
    let n = 100;
    let mut rng = Rng(9);
    let x: Vec<f32> = (0..n * 2).map(|_| rng.f() as f32).collect();
    let mut h = vec![0.05f32; n];
    h[17] = f32::INFINITY;
    let cpu = Grid::build(&x, 2, SUPPORT as f64 * h_max(&h));
    assert_eq!(cpu.num_cells(), 1);
    let data: Vec<f32> = x.iter().chain(&h).copied().collect();
    let buf = gpu.storage_buffer("test data", 4 * data.len() as u64, wgpu::BufferUsages::empty()).unwrap();
    gpu.upload(&buf, 0, &data).unwrap();
    let cl = CellList::new(gpu, n, 2, 2).unwrap();
    let mut enc = gpu.encoder("test");
    cl.record(gpu, &mut enc, &buf, 0, 2 * n as u32, SUPPORT);
    gpu.submit(enc);
    let g: Vec<u32> = gpu.download(cl.grid_buffer(), 0, 16).unwrap();
    assert_eq!(&g[4..8], &[1, 1, 1, 1]);
    assert_eq!(g[14], 1, "one cell walked on each side of the single cell");
    assert_eq!(f32::from_bits(g[3]), f32::INFINITY);
    assert_eq!(f32::from_bits(g[9]), f32::INFINITY);
    assert_eq!((g[10], g[11]), (0, 0), "inv = 0");
    let cells: Vec<u32> = gpu.download(cl.cells_buffer(), 0, cl.max_cells() + 1 + n).unwrap();
    assert_eq!(&cells[..2], &[0, n as u32]);
    assert_eq!(&cells[cl.max_cells() + 1..], cpu.order());
}

#[test]
fn reductions_match_cpu() {
    let gpu = gpu();
    let red = Reducer::new(gpu).unwrap_or_else(|e| panic!("{e}"));
    let mut rng = Rng(11);
    let len = 100_003usize;
    let mut v: Vec<f32> = (0..len).map(|_| ((rng.f() - 0.3) * 1e3) as f32).collect();
    for k in 0..50 {
        v[rng.below(len)] = f32::NAN;
        if k < 3 {
            v[rng.below(len)] = if k == 0 { f32::INFINITY } else { -1e30 };
        }
    }
    let buf = gpu.storage_buffer("test values", 4 * len as u64, wgpu::BufferUsages::empty()).unwrap();
    gpu.upload(&buf, 0, &v).unwrap();
    // (offset, count, stride): empty, tiny, block boundaries, strided, all.
    let ranges =
        [(0, 0, 1), (5, 1, 1), (7, 255, 1), (7, 256, 1), (9, 257, 1), (3, 1000, 3), (0, len, 1), (1, 70_000, 1)];
    let ops = [ReduceOp::Min, ReduceOp::Max, ReduceOp::Sum];
    let out =
        gpu.storage_buffer("test out", 4 * (ranges.len() * ops.len()) as u64, wgpu::BufferUsages::empty()).unwrap();
    let mut enc = gpu.encoder("test");
    let mut k = 0;
    for &(o, c, s) in &ranges {
        for &op in &ops {
            red.record_strided(gpu, &mut enc, op, &buf, o as u32, c as u32, s as u32, &out, k);
            k += 1;
        }
    }
    gpu.submit(enc);
    let got: Vec<f32> = gpu.download(&out, 0, ranges.len() * ops.len()).unwrap();
    let mut k = 0;
    for &(o, c, s) in &ranges {
        let vals: Vec<f32> = (0..c).map(|i| v[o + i * s]).collect();
        let min = vals.iter().fold(f32::INFINITY, |a, &b| a.min(b));
        let max = vals.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
        let sum: f64 = vals.iter().map(|&b| b as f64).sum();
        let abs: f64 = vals.iter().filter(|b| b.is_finite()).map(|&b| (b as f64).abs()).sum();
        assert_eq!(got[k].to_bits(), min.to_bits(), "min of {c} from {o} stride {s}: {} vs {min}", got[k]);
        assert_eq!(got[k + 1].to_bits(), max.to_bits(), "max of {c} from {o} stride {s}: {} vs {max}", got[k + 1]);
        let g = got[k + 2] as f64;
        if sum.is_nan() {
            assert!(g.is_nan(), "sum of {c} from {o} with NaN: {g}");
        } else if sum.is_infinite() {
            assert_eq!(g, sum, "sum of {c} from {o} with inf");
        } else {
            assert!((g - sum).abs() <= 1e-5 * abs.max(1.0), "sum of {c} from {o} stride {s}: {g} vs {sum}");
        }
        k += 3;
    }
    // Sum of a clean range: check a value, not just NaN propagation.
    let clean: Vec<f32> = (0..5000).map(|i| (i % 7) as f32 - 2.5).collect();
    let cbuf = gpu.storage_buffer("test clean", 4 * clean.len() as u64, wgpu::BufferUsages::empty()).unwrap();
    gpu.upload(&cbuf, 0, &clean).unwrap();
    let mut enc = gpu.encoder("test");
    red.record(gpu, &mut enc, ReduceOp::Sum, &cbuf, 0, clean.len() as u32, &out, 0);
    gpu.submit(enc);
    let s: Vec<f32> = gpu.download(&out, 0, 1).unwrap();
    assert_eq!(s[0], clean.iter().map(|&x| x as f64).sum::<f64>() as f32);
}

#[test]
fn first_non_finite() {
    let gpu = gpu();
    let red = Reducer::new(gpu).unwrap();
    let mut rng = Rng(12);
    // Three fields on two groups: a scalar of particles 0..3000 at 0, a 3-vector of particles
    // 3000..5000 at 3000, a 2-vector of particles 0..3000 at 9000.
    let mut v: Vec<f32> = (0..16000).map(|_| rng.f() as f32).collect();
    let segs = [
        Segment { offset: 0, first: 0, count: 3000, comps: 1 },
        Segment { offset: 3000, first: 3000, count: 2000, comps: 3 },
        Segment { offset: 9000, first: 0, count: 3000, comps: 2 },
    ];
    let list = red.segments(gpu, &segs).unwrap();
    let buf = gpu.storage_buffer("test values", 4 * v.len() as u64, wgpu::BufferUsages::empty()).unwrap();
    let out = gpu.storage_buffer("test out", 16, wgpu::BufferUsages::empty()).unwrap();
    let run = |v: &[f32]| -> u32 {
        gpu.upload(&buf, 0, v).unwrap();
        let mut enc = gpu.encoder("test");
        red.record_first_non_finite(gpu, &mut enc, &buf, &list, &out, 2);
        gpu.submit(enc);
        gpu.download::<u32>(&out, 8, 1).unwrap()[0]
    };
    assert_eq!(run(&v), ALL_FINITE);
    v[3000 + 3 * 1500 + 2] = f32::INFINITY; // particle 4500
    assert_eq!(run(&v), 4500);
    v[9000 + 2 * 2345 + 1] = f32::NAN; // particle 2345
    assert_eq!(run(&v), 2345);
    v[2999] = f32::NEG_INFINITY; // particle 2999: not the smallest
    assert_eq!(run(&v), 2345);
    v[12] = f32::NAN;
    assert_eq!(run(&v), 12);
    // Values outside the segments do not count.
    let mut w = vec![1.0f32; 16000];
    w[15500] = f32::NAN;
    assert_eq!(run(&w), ALL_FINITE);
}

#[test]
fn naga_rejects_before_wgpu() {
    let gpu = gpu();
    let bad = "@compute @workgroup_size(64)\nfn main() {\n    let x: u32 = 1.5;\n}\n";
    match gpu.compile("bad", bad, "main") {
        Err(GpuError::Shader { label, wgsl, message }) => {
            assert_eq!(label, "bad");
            assert_eq!(wgsl, bad);
            assert!(message.contains("error"), "naga's message: {message}");
            assert!(message.contains("let x: u32 = 1.5"), "the message quotes the source: {message}");
            let shown = GpuError::Shader { label, wgsl, message }.to_string();
            assert!(shown.contains("   3 |     let x: u32 = 1.5;"), "{shown}");
        }
        other => panic!("expected a shader error, got {other:?}"),
    }
    // Parses, but the validator rejects it (a read-only storage buffer written to).
    let invalid = "@group(0) @binding(0) var<storage, read> a: array<u32>;\n\
                   @compute @workgroup_size(64)\nfn main() {\n    a[0] = 1u;\n}\n";
    assert!(matches!(gpu.compile("invalid", invalid, "main"), Err(GpuError::Shader { .. })));
    // Which bindings an automatic layout holds: only those the entry point uses.
    let partly = "@group(0) @binding(0) var<storage, read> a: array<u32>;\n\
                  @group(0) @binding(1) var<storage, read> unused: array<u32>;\n\
                  @group(0) @binding(2) var<storage, read_write> b: array<u32>;\n\
                  @compute @workgroup_size(64)\nfn main() {\n    b[0] = a[0];\n}\n";
    assert_eq!(used_bindings("partly", partly, "main").unwrap(), vec![(0, 0), (0, 2)]);
    let p = gpu.compile("partly", partly, "main").unwrap();
    let a = gpu.storage_buffer("test a", 16, wgpu::BufferUsages::empty()).unwrap();
    let b = gpu.storage_buffer("test b", 16, wgpu::BufferUsages::empty()).unwrap();
    let _ = gpu.bind_at("partly", &p, &[(0, &a), (2, &b)]);
    gpu.check().unwrap();
    // naga accepts it, wgpu rejects it (no such entry point): caught by the error scope.
    let ok = "@compute @workgroup_size(64)\nfn main() {\n}\n";
    assert!(gpu.compile("ok", ok, "main").is_ok());
    match gpu.compile("ok", ok, "missing") {
        Err(GpuError::Shader { message, .. }) => assert!(message.contains("wgpu"), "{message}"),
        other => panic!("expected a shader error, got {other:?}"),
    }
    gpu.check().unwrap();
}

#[test]
fn too_large_buffers() {
    let gpu = gpu();
    let limit = gpu.max_storage_bytes();
    match gpu.storage_buffer("huge", limit + 4, wgpu::BufferUsages::empty()) {
        Err(GpuError::TooLarge { what, needed, limit: l }) => {
            assert_eq!((what.as_str(), needed, l), ("huge", limit + 4, limit));
        }
        other => panic!("expected TooLarge, got {other:?}"),
    }
    assert!(gpu.estimate_fits(&[("a", 16), ("b", limit)]).is_ok());
    match gpu.estimate_fits(&[("a", 16), ("positions", limit + 1), ("c", limit + 9)]) {
        Err(e @ GpuError::TooLarge { .. }) => assert!(e.to_string().contains("`positions`"), "{e}"),
        other => panic!("expected TooLarge, got {other:?}"),
    }
    // A cell list too large for the device is refused before anything is allocated.
    let n = (limit / 4) as usize;
    assert!(matches!(CellList::new(gpu, n, 3, 1), Err(GpuError::TooLarge { .. })));
    assert!(matches!(
        gpu.download::<u32>(&gpu.storage_buffer("small", 8, wgpu::BufferUsages::empty()).unwrap(), 4, 4),
        Err(GpuError::Map(_))
    ));
    assert!(gpu
        .download::<u32>(&gpu.storage_buffer("small", 8, wgpu::BufferUsages::empty()).unwrap(), 4, 0)
        .unwrap()
        .is_empty());
}

#[test]
fn adapter_choice_and_messages() {
    let base = gpu().adapter_info.clone();
    let info = |name: &str, t: wgpu::DeviceType, b: wgpu::Backend| wgpu::AdapterInfo {
        name: name.to_string(),
        device_type: t,
        backend: b,
        ..base.clone()
    };
    let infos = [
        info("llvmpipe", wgpu::DeviceType::Cpu, wgpu::Backend::Vulkan),
        info("Intel Iris GL", wgpu::DeviceType::IntegratedGpu, wgpu::Backend::Gl),
        info("Intel Iris", wgpu::DeviceType::IntegratedGpu, wgpu::Backend::Vulkan),
        info("NVIDIA RTX", wgpu::DeviceType::DiscreteGpu, wgpu::Backend::Vulkan),
    ];
    assert_eq!(choose_adapter(&infos, None).unwrap(), 3);
    assert_eq!(choose_adapter(&infos[..3], None).unwrap(), 2);
    assert_eq!(choose_adapter(&infos[..2], None).unwrap(), 1);
    assert_eq!(choose_adapter(&infos, Some("LLVMPIPE")).unwrap(), 0);
    match choose_adapter(&infos, Some("radeon")) {
        Err(e @ GpuError::NoMatchingAdapter { .. }) => assert!(e.to_string().contains("NVIDIA RTX"), "{e}"),
        other => panic!("{other:?}"),
    }
    // The ranks on a machine share its best adapters out, cyclically.
    let mut two = infos.to_vec();
    two.push(info("NVIDIA RTX", wgpu::DeviceType::DiscreteGpu, wgpu::Backend::Vulkan));
    two.push(info("NVIDIA RTX GL", wgpu::DeviceType::DiscreteGpu, wgpu::Backend::Gl));
    let ranks: Vec<usize> = (0..3).map(|r| choose_adapter_for(&two, None, r).unwrap()).collect();
    assert_eq!(ranks, [3, 4, 3]);
    assert_eq!(choose_adapter_for(&two, Some("iris"), 1).unwrap(), 2);
    let none = choose_adapter(&[], None).unwrap_err().to_string();
    assert!(none.contains("mesa-vulkan-drivers") && none.contains("lavapipe"), "{none}");
    assert_eq!(dispatch_grid(10, 65535), (10, 1));
    let (x, y) = dispatch_grid(200_000, 65535);
    assert!(x <= 65535 && x as u64 * y as u64 >= 200_000 && (x as u64 * y as u64) < 200_000 + y as u64 + x as u64);
}

#[test]
fn device_loss_is_reported() {
    let g = Gpu::new().unwrap_or_else(|e| panic!("GPU tests need a GPU adapter: {e}"));
    assert!(g.check_lost().is_ok());
    g.device.destroy();
    let _ = g.device.poll(wgpu::PollType::wait_indefinitely());
    match g.check_lost() {
        Err(GpuError::Lost(m)) => assert!(!m.is_empty()),
        other => panic!("expected Lost, got {other:?}"),
    }
}

/// The software f64 of the WGSL helpers against the CPU's f64, bit for bit.
const SOFT_F64_TEST_WGSL: &str = r#"
@group(0) @binding(0) var<storage, read> cases: array<vec4<u32>>;
@group(0) @binding(1) var<storage, read_write> res: array<u32>;
// Declared for the helpers that read the cell list; unused here.
@group(1) @binding(0) var<storage, read> grid: array<u32>;
@group(1) @binding(1) var<storage, read> cells: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = gid.x;
    if (k >= arrayLength(&cases)) { return; }
    let a = cl_from_bits(cases[k].xy);
    let b = cl_from_bits(cases[k].zw);
    let add = cl_bits(cl_add(a, b));
    let sub = cl_bits(cl_sub(a, b));
    let mul = cl_bits(cl_mul(a, b));
    let rcp = cl_bits(cl_recip(a));
    res[10u * k] = add.x;
    res[10u * k + 1u] = add.y;
    res[10u * k + 2u] = sub.x;
    res[10u * k + 3u] = sub.y;
    res[10u * k + 4u] = mul.x;
    res[10u * k + 5u] = mul.y;
    res[10u * k + 6u] = rcp.x;
    res[10u * k + 7u] = rcp.y;
    res[10u * k + 8u] = cl_floor_u32(a);
    res[10u * k + 9u] = bitcast<u32>(cl_to_f32(a));
}
"#;

#[test]
fn soft_f64_matches_cpu() {
    let gpu = gpu();
    let mut rng = Rng(21);
    let mut cases: Vec<(f64, f64)> = vec![];
    let pow2 = |e: i32| 2f64.powi(e);
    let full = |u: f64, e: i32| (1.0 + u) * pow2(e);
    for k in 0..4000 {
        let a = match k % 8 {
            // Full random mantissas over a wide exponent range.
            0 | 1 => full(rng.f(), rng.below(120) as i32 - 60),
            // Short mantissas: exact products and ties.
            2 => ((rng.next() >> 40) | 1) as f64 * pow2(rng.below(40) as i32 - 30),
            // f32 values, subnormal ones included.
            3 => f32::from_bits((rng.next() as u32) & 0x7fff_ffff).min(f32::MAX) as f64,
            // Near integers (the floor) and powers of two.
            4 => {
                let i = (rng.next() >> 31) as f64;
                [i, i + i * f64::EPSILON, i - i * f64::EPSILON / 2.0, pow2(rng.below(40) as i32)][rng.below(4)]
            }
            5 => f64::from_bits(((1023 + rng.below(34) as u64) << 52) | ((1u64 << 52) - 1 - rng.below(3) as u64)),
            6 => 0.0,
            _ => full(rng.f(), rng.below(8) as i32),
        };
        let a = if rng.below(4) == 0 { -a } else { a };
        let b = match k % 5 {
            0 => -a,                                                                      // exact cancellation
            1 => -f64::from_bits(a.to_bits() + 1 + rng.below(4) as u64),                  // near cancellation
            2 => full(rng.f(), a.abs().max(1e-300).log2() as i32 - rng.below(70) as i32), // shifted
            3 => ((rng.next() >> 11) | 1) as f64 * pow2(-52) * if rng.below(2) == 0 { 1.0 } else { -1.0 },
            _ => (1.0 + pow2(-52)) * pow2(rng.below(6) as i32),
        };
        cases.push((a, b));
    }
    // The domain: normal values and zero (subnormal f64 never arise from f32 positions).
    cases.retain(|&(a, b)| [a, b, a + b, a - b, a * b].iter().all(|v| *v == 0.0 || v.is_normal()));
    assert!(cases.len() > 3500);
    cases.push((1.0 + pow2(-52), 1.5)); // a tie in the product
    cases.push((3.0, 1.0 / 3.0));
    cases.push((1.0 + 1e-5, 0.1));
    let words: Vec<u32> = cases
        .iter()
        .flat_map(|&(a, b)| {
            [a.to_bits() as u32, (a.to_bits() >> 32) as u32, b.to_bits() as u32, (b.to_bits() >> 32) as u32]
        })
        .collect();
    let input = gpu.storage_buffer("test cases", 4 * words.len() as u64, wgpu::BufferUsages::empty()).unwrap();
    gpu.upload(&input, 0, &words).unwrap();
    let out = gpu.storage_buffer("test out", 40 * cases.len() as u64, wgpu::BufferUsages::empty()).unwrap();
    let wgsl = format!("{}{SOFT_F64_TEST_WGSL}", wgsl_helpers());
    let pipeline = gpu.compile("test: soft f64", &wgsl, "main").unwrap_or_else(|e| panic!("{e}"));
    let bind = gpu.bind("test", &pipeline, &[&input, &out]);
    let mut enc = gpu.encoder("test");
    gpu.dispatch(&mut enc, "test", &pipeline, &bind, (cases.len() as u32).div_ceil(64));
    gpu.submit(enc);
    let r: Vec<u32> = gpu.download(&out, 0, 10 * cases.len()).unwrap();
    let f64_of = |lo: u32, hi: u32| f64::from_bits(lo as u64 | (hi as u64) << 32);
    // Zero has no sign here; the grid never depends on it.
    let same = |g: f64, c: f64| g.to_bits() == c.to_bits() || (g == 0.0 && c == 0.0);
    for (k, &(a, b)) in cases.iter().enumerate() {
        let w = &r[10 * k..10 * k + 10];
        let ctx = format!("a = {a:e} ({:#x}), b = {b:e} ({:#x})", a.to_bits(), b.to_bits());
        assert!(same(f64_of(w[0], w[1]), a + b), "add: {} vs {}, {ctx}", f64_of(w[0], w[1]), a + b);
        assert!(same(f64_of(w[2], w[3]), a - b), "sub: {} vs {}, {ctx}", f64_of(w[2], w[3]), a - b);
        assert!(same(f64_of(w[4], w[5]), a * b), "mul: {} vs {}, {ctx}", f64_of(w[4], w[5]), a * b);
        assert!(same(f64_of(w[6], w[7]), 1.0 / a), "recip: {} vs {}, {ctx}", f64_of(w[6], w[7]), 1.0 / a);
        let floor = if a.is_nan() || a < 1.0 {
            0
        } else if a >= 4294967296.0 {
            u32::MAX
        } else {
            a.floor() as u32
        };
        assert_eq!(w[8], floor, "floor, {ctx}");
        if a == 0.0 || (a.abs() >= pow2(-126) && a.abs() < pow2(120)) {
            assert!(same(f32::from_bits(w[9]) as f64, a as f32 as f64), "to f32, {ctx}");
        }
    }
}

/// A cubic (or square) lattice of `side` particles per axis at unit spacing.
fn lattice(side: usize, dim: usize) -> Vec<f32> {
    let n = side.pow(dim as u32);
    (0..n).flat_map(|i| (0..dim).map(move |k| ((i / side.pow(k as u32)) % side) as f32)).collect()
}

#[test]
fn two_cells_per_cutoff_only_where_half_a_cutoff_holds_five_particles() {
    use pairsum::backend::gpu::runtime::cells_per_cutoff;
    // PySPH's impact3d (3 h, h = 1.3 dx): 7.4 particles per half cell in the bulk.
    assert_eq!(cells_per_cutoff(&lattice(24, 3), 3, 3.9), 2);
    // The 3D dam break (2 h, h = 1.5 dx): 3.4.
    assert_eq!(cells_per_cutoff(&lattice(24, 3), 3, 3.0), 1);
    // The 2D dam break: 2.25; twice the cut-off: 9.
    assert_eq!(cells_per_cutoff(&lattice(60, 2), 2, 3.0), 1);
    assert_eq!(cells_per_cutoff(&lattice(60, 2), 2, 6.0), 2);
    // No particles, or no finite cut-off: one cell.
    assert_eq!(cells_per_cutoff(&[], 3, 3.9), 1);
    assert_eq!(cells_per_cutoff(&lattice(8, 3), 3, f64::NAN), 1);
}
