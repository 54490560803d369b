//! Names in the generated WGSL, given out by one helper (as naga's `proc::Namer` does): a DSL name
//! becomes an identifier that is valid, not a WGSL keyword, and unique among what it shares a
//! scope with. Fields and parameters are named once per plan, keyed by id, so every kernel calls
//! the same accessor `ld_<field>`; a kernel's locals are named against everything at module scope.

use crate::ir::{FieldId, Model, ParamId};
use std::collections::HashSet;

/// Prefixes of the accessors generated for each field and parameter.
const ACCESSOR_PREFIXES: [&str; 4] = ["ld_", "ldj_", "st_", "prm_"];

/// Module-scope names of the generated code that are not accessors: bindings and helper
/// functions (`tests/emit_names.rs` checks that every function of every stdlib model's kernels is
/// one of these or an accessor).
pub const HELPERS: &[&str] = &[
    // bindings and module constants
    "data",
    "ints",
    "params",
    "info",
    "grid",
    "cells",
    "globals",
    "G",
    "ClF64",
    "CellWalk",
    // functions
    "main",
    "pinf",
    "nan",
    "in_groups",
    "opaque_s",
    "opaque_v",
    "opaque_m",
    "frob",
    "trace",
    "sym",
    "skew",
    "sel_m",
    "outer",
    "neg_m",
    "min_m",
    "max_m",
    "inv",
    "flip_m",
    "eye",
    "div_m",
    "diag",
    "dev",
    "ddot",
    "abs_m",
    "sorted_particle",
    "pos3",
    "h_of",
    "kernel_w_at",
    "kernel_w",
    "kernel_slope",
    "kernel_shape",
    "kernel_grad",
    "kernel_grad_at",
    "grid_origin",
    "grid_dims",
    "grid_cell_size",
    "cell_start",
    "cell_index",
    "cell_coords",
    "walk_cells",
    "walk_skips",
    "cell_gap",
    "cl_zero",
    "cl_to_f32",
    "cl_sub64",
    "cl_sub",
    "cl_shr_jam",
    "cl_shr",
    "cl_shl",
    "cl_round",
    "cl_recip",
    "cl_mul32",
    "cl_mul",
    "cl_lt64",
    "cl_is_zero",
    "cl_inf",
    "cl_from_f32",
    "cl_from_bits",
    "cl_floor_u32",
    "cl_clz64",
    "cl_bits",
    "cl_axis_cell",
    "cl_add64",
    "cl_add",
];

/// Names the scaffolding of a kernel body uses; a DSL local never takes one (nor a name of
/// [`HELPERS`]).
pub const SCAFFOLDING: &[&str] = &[
    "i",
    "j",
    "t",
    "dt",
    "x_ij",
    "r_ij",
    "h_ij",
    "W_ij",
    "gradW_ij",
    "sgn",
    "first",
    "count",
    "k",
    "wg",
    "nwg",
    "li",
    "G",
    "xi",
    "hi",
    "yi",
    "tr",
    "skip",
    "m",
    "axis",
    "at",
    "wk",
    "n_all",
    "stride",
    "list_start",
    "k_list",
    "entry",
    "x",
    "y",
    "z",
    "cell",
    "s",
    "dxv",
    "r2",
    "rc",
    "mirrors",
    "h_max",
    "n",
    "scratch",
    "best",
    "remaining",
    "R",
];

/// Gives out unique, valid identifiers.
#[derive(Clone, Debug, Default)]
pub struct Namer {
    used: HashSet<String>,
    /// The names are only ever used behind a prefix (`ld_<name>`): keywords need no care.
    prefixed: bool,
}

impl Namer {
    /// A namer that never gives out `taken`.
    pub fn with_taken<'a>(taken: impl IntoIterator<Item = &'a str>) -> Namer {
        Namer { used: taken.into_iter().map(str::to_string).collect(), prefixed: false }
    }

    /// A namer for names that always stand behind a prefix.
    pub fn prefixed() -> Namer {
        Namer { used: HashSet::new(), prefixed: true }
    }

    /// Marks a name as taken.
    pub fn take(&mut self, name: &str) {
        self.used.insert(name.to_string());
    }

    /// A fresh identifier after `base`: non-identifier characters become `_`, a keyword or a name
    /// that starts like an accessor gets a suffix, and a taken name gets `_2`, `_3`, ….
    pub fn call(&mut self, base: &str) -> String {
        let mut base: String =
            base.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' { c } else { '_' }).collect();
        if !self.prefixed {
            // WGSL reserves identifiers that start with two underscores.
            if base.is_empty() || base.starts_with(|c: char| c.is_ascii_digit()) || base.starts_with("__") {
                base.insert(0, 'v');
            }
            let keyword = naga::keywords::wgsl::RESERVED.contains(&base.as_str());
            if keyword || ACCESSOR_PREFIXES.iter().any(|p| base.starts_with(p)) {
                base.push('_');
            }
        }
        let mut name = base.clone();
        let mut k = 2;
        while !self.used.insert(name.clone()) {
            name = format!("{base}_{k}");
            k += 1;
        }
        name
    }
}

/// The identifiers of a model's fields and parameters in generated code, by id.
#[derive(Clone, Debug)]
pub struct Names {
    fields: Vec<String>,
    params: Vec<String>,
}

impl Names {
    /// Names every field and parameter of `model` after its own name, each unique among its kind;
    /// the model's own come first (lowest ids), so a synthetic one (a saved copy `x@0` is `x_0`)
    /// gives way to a user's field of the same name.
    pub fn new(model: &Model) -> Names {
        let mut fields = Namer::prefixed();
        let fields = model.fields.iter().map(|f| fields.call(f.name.rsplit('.').next().unwrap_or(&f.name))).collect();
        let mut params = Namer::prefixed();
        let params = model.params.iter().map(|p| params.call(&p.name)).collect();
        Names { fields, params }
    }

    pub fn field(&self, f: FieldId) -> &str {
        &self.fields[f.index()]
    }

    pub fn param(&self, p: ParamId) -> &str {
        &self.params[p.index()]
    }

    /// Every module-scope name: accessors of every field and parameter, and the helpers.
    pub fn module_scope(&self) -> impl Iterator<Item = String> + '_ {
        let fields = self.fields.iter().flat_map(|n| ["ld_", "ldj_", "st_"].map(|p| format!("{p}{n}")));
        let params = self.params.iter().map(|n| format!("prm_{n}"));
        fields.chain(params).chain(HELPERS.iter().map(|h| h.to_string()))
    }

    /// A namer for a kernel's locals: clear of the scaffolding and of everything at module scope.
    pub fn locals(&self) -> Namer {
        let mut n = Namer::with_taken(SCAFFOLDING.iter().copied());
        for name in self.module_scope() {
            n.take(&name);
        }
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_valid_unique_and_clear_of_keywords_and_accessors() {
        let mut n = Namer::with_taken(["x"]);
        assert_eq!(n.call("x"), "x_2");
        assert_eq!(n.call("x@0"), "x_0");
        assert_eq!(n.call("x_0"), "x_0_2");
        assert_eq!(n.call("filter"), "filter_");
        assert_eq!(n.call("ld_x"), "ld_x_");
        assert_eq!(n.call("__y"), "v__y");
        assert_eq!(n.call("2d"), "v2d");
    }
}
