//! WGSL helper functions shared by every generated kernel: the tensor algebra the language has
//! and WGSL lacks (outer products, sym/skew/dev, element-wise min/max/abs on matrices, inverse,
//! selecting a matrix), per dimension.

/// The helpers for `dim` (1, 2 or 3).
pub fn helpers(dim: usize) -> String {
    match dim {
        1 => HELPERS_1D.to_string(),
        2 => mat_helpers(2),
        _ => mat_helpers(3),
    }
}

const HELPERS_1D: &str = "
// In 1D every vec and tensor is a single f32.
fn frob(a: f32) -> f32 { return abs(a); }
";

fn mat_helpers(d: usize) -> String {
    let m = format!("mat{d}x{d}<f32>");
    let v = format!("vec{d}<f32>");
    let cols = |f: &dyn Fn(usize) -> String| (0..d).map(f).collect::<Vec<_>>().join(", ");
    let mut s = String::new();
    s.push_str(&format!(
        "fn eye() -> {m} {{ return {m}({}); }}\n",
        cols(&|c| format!(
            "{v}({})",
            (0..d).map(|r| if r == c { "1.0" } else { "0.0" }).collect::<Vec<_>>().join(", ")
        ))
    ));
    s.push_str(&format!("fn outer(a: {v}, b: {v}) -> {m} {{ return {m}({}); }}\n", cols(&|c| format!("a * b[{c}]"))));
    s.push_str(&format!("fn sym(a: {m}) -> {m} {{ return 0.5 * (a + transpose(a)); }}\n"));
    s.push_str(&format!("fn skew(a: {m}) -> {m} {{ return 0.5 * (a - transpose(a)); }}\n"));
    s.push_str(&format!(
        "fn trace(a: {m}) -> f32 {{ return {}; }}\n",
        (0..d).map(|k| format!("a[{k}][{k}]")).collect::<Vec<_>>().join(" + ")
    ));
    s.push_str(&format!("fn dev(a: {m}) -> {m} {{ return a - (trace(a) / 3.0) * eye(); }}\n"));
    s.push_str(&format!(
        "fn ddot(a: {m}, b: {m}) -> f32 {{ return {}; }}\n",
        (0..d).map(|k| format!("dot(a[{k}], b[{k}])")).collect::<Vec<_>>().join(" + ")
    ));
    s.push_str(&format!("fn frob(a: {m}) -> f32 {{ return sqrt(ddot(a, a)); }}\n"));
    s.push_str(&format!(
        "fn diag(v: {v}) -> {m} {{ return {m}({}); }}\n",
        cols(&|c| format!(
            "{v}({})",
            (0..d).map(|r| if r == c { format!("v[{c}]") } else { "0.0".into() }).collect::<Vec<_>>().join(", ")
        ))
    ));
    s.push_str(&format!("fn neg_m(a: {m}) -> {m} {{ return -1.0 * a; }}\n"));
    s.push_str(&format!("fn abs_m(a: {m}) -> {m} {{ return {m}({}); }}\n", cols(&|c| format!("abs(a[{c}])"))));
    s.push_str(&format!(
        "fn min_m(a: {m}, b: {m}) -> {m} {{ return {m}({}); }}\n",
        cols(&|c| format!("min(a[{c}], b[{c}])"))
    ));
    s.push_str(&format!(
        "fn max_m(a: {m}, b: {m}) -> {m} {{ return {m}({}); }}\n",
        cols(&|c| format!("max(a[{c}], b[{c}])"))
    ));
    s.push_str(&format!(
        "fn sel_m(f: {m}, t: {m}, c: bool) -> {m} {{ return {m}({}); }}\n",
        cols(&|c| format!("select(f[{c}], t[{c}], c)"))
    ));
    s.push_str(&format!("fn div_m(a: {m}, s: f32) -> {m} {{ return (1.0 / s) * a; }}\n"));
    // Mirror images: a tensor's (r, c) component flips with the signs of both axes.
    s.push_str(&format!(
        "fn flip_m(a: {m}, s: {v}) -> {m} {{ return {m}({}); }}\n",
        cols(&|c| format!("a[{c}] * s * s[{c}]"))
    ));
    if d == 2 {
        s.push_str(&format!(
            "fn inv(a: {m}) -> {m} {{ return (1.0 / determinant(a)) * {m}(a[1][1], -a[0][1], -a[1][0], a[0][0]); }}\n"
        ));
    } else {
        s.push_str(&format!(
            "fn inv(a: {m}) -> {m} {{
    // adjugate / determinant; columns of the inverse are cross products of the rows' complements
    let r0 = cross(a[1], a[2]);
    let r1 = cross(a[2], a[0]);
    let r2 = cross(a[0], a[1]);
    let det = dot(a[0], r0);
    return (1.0 / det) * transpose({m}(r0, r1, r2));
}}\n"
        ));
    }
    s
}
