//! The particle store: one struct-of-arrays column per live field of the plan, stored only on
//! the groups that use it, and the table of material parameters.
//!
//! Particles are kept group-major (each group a contiguous range) and, within a group, in the
//! order the engine chooses (Morton order after a reorder). A column holds the rows of its groups
//! one after another; `base[g]` maps particle index i of group g to its row, `i + base[g]`.
//! Components of a row are interleaved (`row * comps + c`).

use crate::ir::{FieldId, GroupId, Model, ParamId};
use crate::schedule::Plan;
use std::ops::{Add, Div, Mul, Neg, Range, Sub};

/// The floating-point type a run computes in (`to_f64` comes from `grid::Coord`).
pub trait Real:
    Copy
    + Send
    + Sync
    + Default
    + PartialOrd
    + std::fmt::Debug
    + std::fmt::Display
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + bytemuck::Pod
    + crate::grid::Coord
{
    const BYTES: usize;
    const NAME: &'static str;
    fn from_f64(x: f64) -> Self;
    fn sqrt(self) -> Self;
    fn exp(self) -> Self;
    fn ln(self) -> Self;
    /// The elementary function `e` in this precision (`ir::ELEMENTARY`).
    fn elementary(e: crate::ir::Elementary) -> fn(Self) -> Self;
    fn powf(self, e: Self) -> Self;
    fn abs(self) -> Self;
    fn min(self, o: Self) -> Self;
    fn max(self, o: Self) -> Self;
    fn is_finite(self) -> bool;
    /// exp by the CPU backend's vectorisable recipe (`backend::cpu::math`), not libm.
    fn lane_exp(self) -> Self;
    /// ln and pow by the same module's recipes.
    fn lane_ln(self) -> Self;
    fn lane_pow(self, e: Self) -> Self;
    /// The constants of those recipes in this precision.
    const EXP: &'static crate::backend::cpu::math::ExpConsts;
    const LN: &'static crate::backend::cpu::math::LnConsts;
    fn zero() -> Self {
        Self::from_f64(0.0)
    }
    fn one() -> Self {
        Self::from_f64(1.0)
    }
}

macro_rules! real {
    ($t:ty, $elementary:ident, $name:expr, $exp:path, $ln:path, $pow:path, $consts:path, $ln_consts:path) => {
        impl Real for $t {
            const BYTES: usize = std::mem::size_of::<$t>();
            const NAME: &'static str = $name;
            const EXP: &'static crate::backend::cpu::math::ExpConsts = &$consts;
            const LN: &'static crate::backend::cpu::math::LnConsts = &$ln_consts;
            #[inline(always)]
            fn lane_exp(self) -> Self {
                $exp(self)
            }
            #[inline(always)]
            fn lane_ln(self) -> Self {
                $ln(self)
            }
            #[inline(always)]
            fn lane_pow(self, e: Self) -> Self {
                $pow(self, e)
            }
            #[inline(always)]
            fn from_f64(x: f64) -> Self {
                x as $t
            }
            #[inline(always)]
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            #[inline(always)]
            fn exp(self) -> Self {
                <$t>::exp(self)
            }
            #[inline(always)]
            fn ln(self) -> Self {
                <$t>::ln(self)
            }
            fn elementary(e: crate::ir::Elementary) -> fn(Self) -> Self {
                e.row().$elementary
            }
            #[inline(always)]
            fn powf(self, e: Self) -> Self {
                <$t>::powf(self, e)
            }
            #[inline(always)]
            fn abs(self) -> Self {
                <$t>::abs(self)
            }
            #[inline(always)]
            fn min(self, o: Self) -> Self {
                <$t>::min(self, o)
            }
            #[inline(always)]
            fn max(self, o: Self) -> Self {
                <$t>::max(self, o)
            }
            #[inline(always)]
            fn is_finite(self) -> bool {
                <$t>::is_finite(self)
            }
        }
    };
}
real!(
    f32,
    f32,
    "f32",
    crate::backend::cpu::math::exp_f32,
    crate::backend::cpu::math::ln_f32,
    crate::backend::cpu::math::pow_f32,
    crate::backend::cpu::math::EXP_F32,
    crate::backend::cpu::math::LN_F32
);
real!(
    f64,
    f64,
    "f64",
    crate::backend::cpu::math::exp_f64,
    crate::backend::cpu::math::ln_f64,
    crate::backend::cpu::math::pow_f64,
    crate::backend::cpu::math::EXP_F64,
    crate::backend::cpu::math::LN_F64
);

/// Where a column has no row for a group.
pub const ABSENT: isize = isize::MIN;

#[derive(Clone, Debug)]
pub struct Column<T> {
    pub comps: usize,
    pub data: Vec<T>,
    /// Per model group: row offset (`row = i + base[g]`), or `ABSENT`.
    pub base: Vec<isize>,
}

impl<T: Real> Column<T> {
    #[inline(always)]
    pub fn row(&self, i: usize, g: usize) -> usize {
        (i as isize + self.base[g]) as usize
    }
    pub fn has(&self, g: usize) -> bool {
        self.base[g] != ABSENT
    }
}

/// Material parameters: one row of values per material, each parameter at a fixed offset.
#[derive(Clone, Debug, Default)]
pub struct ParamTable<T> {
    pub offset: Vec<usize>,
    pub comps: Vec<usize>,
    pub stride: usize,
    pub values: Vec<T>,
}

impl<T: Real> ParamTable<T> {
    pub fn new(model: &Model, dim: usize, materials: usize) -> ParamTable<T> {
        let mut offset = vec![];
        let mut comps = vec![];
        let mut stride = 0;
        for p in &model.params {
            let c = crate::ir::components(p.ty.shape, dim);
            offset.push(stride);
            comps.push(c);
            stride += c;
        }
        ParamTable { offset, comps, stride, values: vec![T::zero(); stride * materials] }
    }
    pub fn set(&mut self, material: usize, p: ParamId, value: &[f64]) {
        let o = material * self.stride + self.offset[p.index()];
        for (k, v) in value.iter().take(self.comps[p.index()]).enumerate() {
            self.values[o + k] = T::from_f64(*v);
        }
    }
    #[inline(always)]
    pub fn get(&self, material: usize, p: ParamId, comp: usize) -> T {
        self.values[material * self.stride + self.offset[p.index()] + comp]
    }
    pub fn materials(&self) -> usize {
        self.values.len().checked_div(self.stride).unwrap_or(0)
    }
}

#[derive(Clone, Debug)]
pub struct Store<T> {
    pub dim: usize,
    pub n: usize,
    /// Each present group's particle range, in group order.
    pub ranges: Vec<(GroupId, Range<usize>)>,
    /// Per particle: its group (model group index) and material index.
    pub group: Vec<u32>,
    pub material: Vec<u32>,
    /// Per particle: its index when the scene created it (stable across reorders).
    pub id: Vec<u32>,
    /// Indexed by field id; `None` for fields the plan does not store.
    pub columns: Vec<Option<Column<T>>>,
    pub params: ParamTable<T>,
}

impl<T: Real> Store<T> {
    /// An empty-valued store for particles already sorted group-major: `group[i]` must be
    /// non-decreasing in group order.
    pub fn new(plan: &Plan, group: Vec<u32>, material: Vec<u32>, materials: usize) -> Store<T> {
        let n = group.len();
        let n_groups = plan.model.groups.len();
        let mut ranges: Vec<(GroupId, Range<usize>)> = vec![];
        for (i, g) in group.iter().enumerate() {
            match ranges.last_mut() {
                Some((last, r)) if last.0 == *g => r.end = i + 1,
                _ => ranges.push((GroupId(*g), i..i + 1)),
            }
        }
        let mut columns: Vec<Option<Column<T>>> = vec![None; plan.model.fields.len()];
        for l in &plan.layout {
            let mut base = vec![ABSENT; n_groups];
            let mut rows = 0usize;
            for (g, r) in &ranges {
                if l.groups.contains(*g) {
                    base[g.index()] = rows as isize - r.start as isize;
                    rows += r.len();
                }
            }
            columns[l.field.index()] = Some(Column { comps: l.comps, data: vec![T::zero(); rows * l.comps], base });
        }
        Store {
            dim: plan.dim,
            n,
            ranges,
            group,
            material,
            id: (0..n as u32).collect(),
            columns,
            params: ParamTable::new(&plan.model, plan.dim, materials),
        }
    }

    /// The same particles with their values in precision `U`.
    pub fn converted<U: Real>(&self) -> Store<U> {
        let convert = |v: &[T]| v.iter().map(|x| U::from_f64(x.to_f64())).collect();
        let column = |c: &Column<T>| Column { comps: c.comps, data: convert(&c.data), base: c.base.clone() };
        Store {
            dim: self.dim,
            n: self.n,
            ranges: self.ranges.clone(),
            group: self.group.clone(),
            material: self.material.clone(),
            id: self.id.clone(),
            columns: self.columns.iter().map(|c| c.as_ref().map(column)).collect(),
            params: ParamTable {
                offset: self.params.offset.clone(),
                comps: self.params.comps.clone(),
                stride: self.params.stride,
                values: convert(&self.params.values),
            },
        }
    }

    pub fn column(&self, f: FieldId) -> Option<&Column<T>> {
        self.columns.get(f.index()).and_then(|c| c.as_ref())
    }

    pub fn column_mut(&mut self, f: FieldId) -> Option<&mut Column<T>> {
        self.columns.get_mut(f.index()).and_then(|c| c.as_mut())
    }

    /// A field's values for every particle as f64 (`n × comps`); NaN where the field is not stored.
    pub fn read_f64(&self, f: FieldId) -> Option<(usize, Vec<f64>)> {
        let c = self.column(f)?;
        self.read_f64_from(f, &c.data)
    }

    /// Like `read_f64`, from column data held elsewhere (e.g. downloaded from a device) that has
    /// this store's layout.
    pub fn read_f64_from(&self, f: FieldId, data: &[T]) -> Option<(usize, Vec<f64>)> {
        let c = self.column(f)?;
        let mut out = vec![f64::NAN; self.n * c.comps];
        // Group by group: a group's rows are contiguous, in the column as in the output.
        for (g, r) in &self.ranges {
            if c.has(g.index()) && !r.is_empty() {
                let first = c.row(r.start, g.index()) * c.comps;
                let from = &data[first..first + r.len() * c.comps];
                for (o, v) in out[r.start * c.comps..r.end * c.comps].iter_mut().zip(from) {
                    *o = v.to_f64();
                }
            }
        }
        Some((c.comps, out))
    }

    /// Sets a field for every particle that stores it, from `n × comps` values (extra components
    /// of the input beyond the column's are ignored; `in_comps` is the input's stride).
    pub fn write_f64(&mut self, f: FieldId, values: &[f64], in_comps: usize) {
        let (group, n) = (&self.group, self.n);
        let Some(c) = self.columns.get_mut(f.index()).and_then(|c| c.as_mut()) else { return };
        for i in 0..n {
            let g = group[i] as usize;
            if c.has(g) {
                let row = c.row(i, g);
                for k in 0..c.comps.min(in_comps) {
                    c.data[row * c.comps + k] = T::from_f64(values[i * in_comps + k]);
                }
            }
        }
    }

    /// Reorders the particles: particle `perm[k]` moves to position k. `perm` must keep every
    /// group's particles inside the group's range.
    pub fn permute(&mut self, perm: &[u32]) {
        let gather = |v: &Vec<u32>| perm.iter().map(|&p| v[p as usize]).collect::<Vec<u32>>();
        let group = gather(&self.group);
        debug_assert!(group == self.group, "a reorder must keep particles in their group");
        self.material = gather(&self.material);
        self.id = gather(&self.id);
        let old_group = self.group.clone();
        for c in self.columns.iter_mut().flatten() {
            let mut data = c.data.clone();
            for (k, &p) in perm.iter().enumerate() {
                let g = old_group[k] as usize;
                if !c.has(g) {
                    continue;
                }
                let (dst, src) = (c.row(k, g), c.row(p as usize, g));
                data[dst * c.comps..(dst + 1) * c.comps].copy_from_slice(&c.data[src * c.comps..(src + 1) * c.comps]);
            }
            c.data = data;
        }
    }

    /// A store of particles taken from other stores of the same plan: `rows[k]` = (store, particle)
    /// becomes particle k, with its whole state. The rows must be group-major; `params` is the
    /// material table of them all.
    pub fn gather(plan: &Plan, params: &ParamTable<T>, rows: &[(&Store<T>, usize)]) -> Store<T> {
        let group: Vec<u32> = rows.iter().map(|(s, i)| s.group[*i]).collect();
        let material: Vec<u32> = rows.iter().map(|(s, i)| s.material[*i]).collect();
        debug_assert!(group.windows(2).all(|w| w[0] <= w[1]), "rows must be group-major");
        let mut out = Store::new(plan, group, material, params.materials());
        out.params = params.clone();
        out.id = rows.iter().map(|(s, i)| s.id[*i]).collect();
        for (k, (src, i)) in rows.iter().enumerate() {
            out.copy_state(k, src, *i);
        }
        out
    }

    /// Copies every field of particle `i` of `src` (a store of the same plan, the same group)
    /// into particle k.
    pub fn copy_state(&mut self, k: usize, src: &Store<T>, i: usize) {
        let g = src.group[i] as usize;
        for (dst, from) in self.columns.iter_mut().zip(&src.columns) {
            let (Some(dst), Some(from)) = (dst.as_mut(), from.as_ref()) else { continue };
            if dst.has(g) {
                let (a, b) = (from.row(i, g) * from.comps, dst.row(k, g) * dst.comps);
                dst.data[b..b + dst.comps].copy_from_slice(&from.data[a..a + from.comps]);
            }
        }
    }

    /// Bytes of all columns.
    pub fn bytes(&self) -> usize {
        self.columns.iter().flatten().map(|c| c.data.len() * T::BYTES).sum()
    }
}
