//! VTK output that ParaView opens: particle snapshots as XML unstructured grids (`.vtu`) and a
//! `.pvd` collection for time series.
//!
//! # Format choice: hand-written XML with base64 binary arrays
//!
//! The files are written by hand rather than with the `vtkio` crate. vtkio 0.6.3 (features `xml`
//! only, which keeps the C compression libraries out) was tried first and rejected because:
//! - its XML output for an empty particle set leaves out the `NumberOfCells` attribute, which
//!   VTK's `vtkXMLUnstructuredGridReader` (the reader ParaView uses) rejects with "Piece 0 is
//!   missing its NumberOfCells attribute";
//! - it depends on `nom` 3 and `quick-xml` 0.22, both of which trigger Rust's future-incompatibility
//!   warnings ("will become a hard error in a future release").
//!
//! The format is small. Every data array is written inline as `format="binary"`: the base64
//! encoding of a UInt64 byte count followed by the little-endian values, as one base64 stream.
//! Points and fields are `Float64` (so values round-trip exactly), connectivity and offsets are
//! `Int64`, and cell types are `UInt8`. The output was checked by hand against VTK 9.7's
//! `vtkXMLUnstructuredGridReader` (points, cells, every field, the active attributes, and an empty
//! particle set). The tests read files back with [`read_vtu`], a minimal reader for exactly this
//! layout.
//!
//! Each particle is one `VTK_VERTEX` cell, so ParaView shows the particles without a glyph filter.
//! Point fields keep their number of components: 1 (scalar; the first one is the active scalars),
//! 3 (vector; the first one is the active vectors), 6 (symmetric tensor, in VTK's order
//! `XX YY ZZ XY YZ XZ`, with those component names), 9 (full tensor, row major, named
//! `XX XY XZ YX ..`; the first one is the active tensors). Any other count is written as a plain
//! array with that many components.
//!
//! The `.pvd` collection is written by hand as well. [`Series`] rewrites it after every snapshot
//! (through a temporary file and a rename, like every file here), so a run that is killed still
//! leaves a valid collection of the snapshots written so far.

use std::io::{self, Write};
use std::path::{Path, PathBuf};

use crate::output_dir::{write_atomic, write_atomic_with};

/// One per-particle (point) data array: `data` holds `n * comps` values, interleaved per particle
/// (`[p0c0, p0c1, .., p1c0, ..]`).
#[derive(Clone, Debug, PartialEq)]
pub struct PointField {
    pub name: String,
    pub comps: usize,
    pub data: Vec<f64>,
}

impl PointField {
    pub fn new(name: impl Into<String>, comps: usize, data: Vec<f64>) -> Self {
        PointField { name: name.into(), comps, data }
    }

    /// A one-component field.
    pub fn scalar(name: impl Into<String>, data: Vec<f64>) -> Self {
        Self::new(name, 1, data)
    }

    /// A three-component field from per-particle vectors.
    pub fn vector(name: impl Into<String>, data: &[[f64; 3]]) -> Self {
        Self::new(name, 3, data.iter().flatten().copied().collect())
    }
}

fn invalid(msg: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, msg)
}

fn check_fields(n: usize, fields: &[PointField]) -> io::Result<()> {
    for (i, f) in fields.iter().enumerate() {
        if f.comps == 0 {
            return Err(invalid(format!("point field `{}` has zero components", f.name)));
        }
        if f.data.len() != n * f.comps {
            return Err(invalid(format!(
                "point field `{}` has {} values, expected {} particles x {} components = {}",
                f.name,
                f.data.len(),
                n,
                f.comps,
                n * f.comps
            )));
        }
        if f.name.is_empty() {
            return Err(invalid("point field with an empty name".into()));
        }
        if fields[..i].iter().any(|g| g.name == f.name) {
            return Err(invalid(format!("point field `{}` given twice", f.name)));
        }
    }
    Ok(())
}

const SYM_TENSOR_NAMES: [&str; 6] = ["XX", "YY", "ZZ", "XY", "YZ", "XZ"];
const TENSOR_NAMES: [&str; 9] = ["XX", "XY", "XZ", "YX", "YY", "YZ", "ZX", "ZY", "ZZ"];
const VTK_VERTEX: u8 = 1;

/// The point data's active attributes: the first field of one, three and nine components as
/// ` Scalars="…" Vectors="…" Tensors="…"`.
fn active_attributes(fields: &[PointField]) -> String {
    let first = |comps: usize| fields.iter().find(|f| f.comps == comps);
    [("Scalars", 1), ("Vectors", 3), ("Tensors", 9)]
        .into_iter()
        .filter_map(|(attr, comps)| first(comps).map(|f| format!(" {attr}=\"{}\"", xml_escape(&f.name))))
        .collect()
}

/// The names of a field's components, by their count: a symmetric or a full tensor's.
fn component_names(comps: usize) -> &'static [&'static str] {
    match comps {
        6 => &SYM_TENSOR_NAMES,
        9 => &TENSOR_NAMES,
        _ => &[],
    }
}

/// Writes one snapshot as a VTK XML unstructured grid (`.vtu`): one `VTK_VERTEX` cell per
/// particle, with `fields` as point data. Fails with `InvalidInput` (and writes nothing) if a
/// field's length is not `positions.len() * comps`, a field has zero components or an empty name,
/// or two fields share a name.
///
/// The file is written to a temporary name and renamed into place.
pub fn write_vtu(path: &Path, positions: &[[f64; 3]], fields: &[PointField]) -> io::Result<()> {
    let n = positions.len();
    check_fields(n, fields)?;
    write_atomic_with(path, |w| write_vtu_to(w, positions, fields))
}

fn write_vtu_to(w: &mut dyn Write, positions: &[[f64; 3]], fields: &[PointField]) -> io::Result<()> {
    let n = positions.len();
    writeln!(w, "<?xml version=\"1.0\"?>")?;
    writeln!(
        w,
        "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">"
    )?;
    writeln!(w, "  <UnstructuredGrid>")?;
    writeln!(w, "    <Piece NumberOfPoints=\"{n}\" NumberOfCells=\"{n}\">")?;

    writeln!(w, "      <PointData{}>", active_attributes(fields))?;
    for f in fields {
        write_f64_array(w, &f.name, f.comps, component_names(f.comps), &f.data)?;
    }
    writeln!(w, "      </PointData>")?;
    writeln!(w, "      <CellData>\n      </CellData>")?;

    writeln!(w, "      <Points>")?;
    let points: Vec<f64> = positions.iter().flatten().copied().collect();
    write_f64_array(w, "Points", 3, &[], &points)?;
    writeln!(w, "      </Points>")?;

    writeln!(w, "      <Cells>")?;
    write_array(w, "Int64", "connectivity", 1, &[], n * 8, |enc| {
        (0..n as i64).try_for_each(|i| enc.write_all(&i.to_le_bytes()))
    })?;
    write_array(w, "Int64", "offsets", 1, &[], n * 8, |enc| {
        (1..=n as i64).try_for_each(|i| enc.write_all(&i.to_le_bytes()))
    })?;
    write_array(w, "UInt8", "types", 1, &[], n, |enc| enc.write_all(&vec![VTK_VERTEX; n]))?;
    writeln!(w, "      </Cells>")?;

    writeln!(w, "    </Piece>")?;
    writeln!(w, "  </UnstructuredGrid>")?;
    writeln!(w, "</VTKFile>")
}

fn write_f64_array<W: Write + ?Sized>(
    w: &mut W,
    name: &str,
    comps: usize,
    comp_names: &[&str],
    data: &[f64],
) -> io::Result<()> {
    write_array(w, "Float64", name, comps, comp_names, data.len() * 8, |enc| {
        data.iter().try_for_each(|v| enc.write_all(&v.to_le_bytes()))
    })
}

/// One inline binary `DataArray`: base64 of (UInt64 byte count, little-endian values).
fn write_array<W: Write + ?Sized>(
    w: &mut W,
    ty: &str,
    name: &str,
    comps: usize,
    comp_names: &[&str],
    nbytes: usize,
    values: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> io::Result<()> {
    write!(w, "        <DataArray type=\"{ty}\" Name=\"{}\" NumberOfComponents=\"{comps}\"", xml_escape(name))?;
    for (i, c) in comp_names.iter().enumerate() {
        write!(w, " ComponentName{i}=\"{c}\"")?;
    }
    write!(w, " format=\"binary\">\n          ")?;
    let mut enc = Base64Writer::new(&mut *w);
    enc.write_all(&(nbytes as u64).to_le_bytes())?;
    values(&mut enc)?;
    enc.finish()?;
    writeln!(w, "\n        </DataArray>")
}

const B64: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

/// A streaming base64 encoder (standard alphabet, padded, no line breaks).
struct Base64Writer<W: Write> {
    out: W,
    carry: [u8; 3],
    ncarry: usize,
    buf: Vec<u8>,
}

impl<W: Write> Base64Writer<W> {
    fn new(out: W) -> Self {
        Base64Writer { out, carry: [0; 3], ncarry: 0, buf: Vec::with_capacity(4096) }
    }

    fn push_triple(&mut self, t: [u8; 3]) {
        let v = u32::from(t[0]) << 16 | u32::from(t[1]) << 8 | u32::from(t[2]);
        for shift in [18, 12, 6, 0] {
            self.buf.push(B64[(v >> shift & 63) as usize]);
        }
    }

    fn flush_buf(&mut self) -> io::Result<()> {
        self.out.write_all(&self.buf)?;
        self.buf.clear();
        Ok(())
    }

    /// Writes the last partial group with padding.
    fn finish(mut self) -> io::Result<()> {
        if self.ncarry > 0 {
            let mut t = [0u8; 3];
            t[..self.ncarry].copy_from_slice(&self.carry[..self.ncarry]);
            self.push_triple(t);
            let len = self.buf.len();
            for b in &mut self.buf[len - (3 - self.ncarry)..] {
                *b = b'=';
            }
        }
        self.flush_buf()
    }
}

impl<W: Write> Write for Base64Writer<W> {
    fn write(&mut self, mut data: &[u8]) -> io::Result<usize> {
        let len = data.len();
        if self.ncarry > 0 {
            while self.ncarry < 3 && !data.is_empty() {
                self.carry[self.ncarry] = data[0];
                self.ncarry += 1;
                data = &data[1..];
            }
            if self.ncarry < 3 {
                return Ok(len);
            }
            self.push_triple(self.carry);
            self.ncarry = 0;
        }
        let mut chunks = data.chunks_exact(3);
        for t in &mut chunks {
            self.push_triple([t[0], t[1], t[2]]);
            if self.buf.len() >= 4096 {
                self.flush_buf()?;
            }
        }
        let rest = chunks.remainder();
        self.carry[..rest.len()].copy_from_slice(rest);
        self.ncarry = rest.len();
        Ok(len)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.flush_buf()?;
        self.out.flush()
    }
}

/// A `.vtu` file read back by [`read_vtu`].
#[derive(Clone, Debug, PartialEq)]
pub struct VtuData {
    pub positions: Vec<[f64; 3]>,
    /// The point data arrays, in file order.
    pub fields: Vec<PointField>,
    pub cell_types: Vec<u8>,
    pub connectivity: Vec<i64>,
    pub offsets: Vec<i64>,
}

/// Reads back a file written by [`write_vtu`]. This is a minimal reader for exactly that layout
/// (inline base64 `binary` arrays, UInt64 headers, little endian), not a general VTK reader.
pub fn read_vtu(path: &Path) -> io::Result<VtuData> {
    let text = std::fs::read_to_string(path)?;
    let bad = |msg: &str| io::Error::new(io::ErrorKind::InvalidData, format!("{}: {msg}", path.display()));
    let piece_at = text.find("<Piece ").ok_or_else(|| bad("no <Piece>"))?;
    let piece_tag = &text[piece_at..piece_at + text[piece_at..].find('>').ok_or_else(|| bad("unclosed <Piece"))?];
    let count = |key: &str| -> io::Result<usize> {
        attr(piece_tag, key).and_then(|v| v.parse().ok()).ok_or_else(|| bad(&format!("no {key}")))
    };
    let (npoints, ncells) = (count("NumberOfPoints")?, count("NumberOfCells")?);

    let section = |open: &str, close: &str| -> &str {
        match (text.find(open), text.find(close)) {
            (Some(a), Some(b)) if a < b => &text[a..b],
            _ => "",
        }
    };
    let mut fields = Vec::new();
    for (tag, body) in data_arrays(section("<PointData", "</PointData>")) {
        let name = attr(tag, "Name").ok_or_else(|| bad("DataArray without a Name"))?;
        let comps = attr(tag, "NumberOfComponents").and_then(|c| c.parse().ok()).unwrap_or(1);
        let data = f64s(&decode_array(body).ok_or_else(|| bad(&format!("bad data in `{name}`")))?);
        if data.len() != npoints * comps {
            return Err(bad(&format!("`{name}` has {} values, expected {}", data.len(), npoints * comps)));
        }
        fields.push(PointField::new(name, comps, data));
    }
    let points = data_arrays(section("<Points>", "</Points>"));
    let (_, body) = points.first().ok_or_else(|| bad("no points"))?;
    let coords = f64s(&decode_array(body).ok_or_else(|| bad("bad points"))?);
    if coords.len() != 3 * npoints {
        return Err(bad("wrong number of point coordinates"));
    }
    let positions = coords.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();

    let (mut connectivity, mut offsets, mut cell_types) = (Vec::new(), Vec::new(), Vec::new());
    for (tag, body) in data_arrays(section("<Cells>", "</Cells>")) {
        let bytes = decode_array(body).ok_or_else(|| bad("bad cell data"))?;
        let ints = || bytes.chunks_exact(8).map(|c| i64::from_le_bytes(c.try_into().unwrap())).collect();
        match attr(tag, "Name").as_deref() {
            Some("connectivity") => connectivity = ints(),
            Some("offsets") => offsets = ints(),
            Some("types") => cell_types = bytes,
            _ => {}
        }
    }
    if cell_types.len() != ncells || offsets.len() != ncells {
        return Err(bad("wrong number of cells"));
    }
    Ok(VtuData { positions, fields, cell_types, connectivity, offsets })
}

/// `(opening tag, body)` of every `<DataArray ...>body</DataArray>` in `xml`.
fn data_arrays(xml: &str) -> Vec<(&str, &str)> {
    let mut out = Vec::new();
    let mut rest = xml;
    while let Some(start) = rest.find("<DataArray") {
        rest = &rest[start..];
        let Some(tag_end) = rest.find('>') else { break };
        let Some(end) = rest.find("</DataArray>") else { break };
        out.push((&rest[..tag_end], &rest[tag_end + 1..end]));
        rest = &rest[end..];
    }
    out
}

/// The unescaped value of attribute `key` in an opening tag.
fn attr(tag: &str, key: &str) -> Option<String> {
    let pat = format!(" {key}=\"");
    let start = tag.find(&pat)? + pat.len();
    let len = tag[start..].find('"')?;
    Some(xml_unescape(&tag[start..start + len]))
}

/// The values of one binary array: base64 of a UInt64 byte count and the bytes.
fn decode_array(body: &str) -> Option<Vec<u8>> {
    let bytes = base64_decode(body)?;
    let (head, data) = bytes.split_at_checked(8)?;
    let n = u64::from_le_bytes(head.try_into().ok()?) as usize;
    (data.len() == n).then(|| data.to_vec())
}

fn f64s(bytes: &[u8]) -> Vec<f64> {
    bytes.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect()
}

fn base64_decode(text: &str) -> Option<Vec<u8>> {
    let digits: Vec<u8> = text.bytes().filter(|b| !b.is_ascii_whitespace()).collect();
    if !digits.len().is_multiple_of(4) {
        return None;
    }
    let mut out = Vec::with_capacity(digits.len() / 4 * 3);
    for group in digits.chunks_exact(4) {
        let mut v = 0u32;
        let mut pad = 0;
        for &c in group {
            let d = match c {
                b'=' => {
                    pad += 1;
                    0
                }
                _ if pad > 0 => return None,
                _ => B64.iter().position(|&b| b == c)? as u32,
            };
            v = v << 6 | d;
        }
        out.extend_from_slice(&v.to_be_bytes()[1..4 - pad]);
    }
    Some(out)
}

/// A time series of `.vtu` snapshots in `dir`, named `basename_000000.vtu`,
/// `basename_000001.vtu`, …, listed in `dir/basename.pvd` (rewritten after every snapshot).
#[derive(Clone, Debug)]
pub struct Series {
    dir: PathBuf,
    basename: String,
    entries: Vec<(f64, String)>,
}

impl Series {
    /// Starts an empty series; creates `dir` if needed. Nothing is written until the first
    /// [`Series::add`] (or [`Series::finish`]).
    pub fn new(dir: impl Into<PathBuf>, basename: impl Into<String>) -> io::Result<Self> {
        let dir = dir.into();
        std::fs::create_dir_all(&dir)?;
        Ok(Series { dir, basename: basename.into(), entries: Vec::new() })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Continues a series a restarted run had written `entries` of: the next snapshot is numbered
    /// after them, and the `.pvd` lists them all.
    pub fn continue_after(&mut self, entries: Vec<(f64, String)>) {
        self.entries = entries;
    }

    pub fn basename(&self) -> &str {
        &self.basename
    }

    /// The snapshots written so far: (time, file name relative to [`Series::dir`]).
    pub fn entries(&self) -> &[(f64, String)] {
        &self.entries
    }

    /// `dir/basename.pvd`.
    pub fn pvd_path(&self) -> PathBuf {
        self.dir.join(format!("{}.pvd", self.basename))
    }

    /// Writes snapshot number `entries().len()` at `time` as `basename_NNNNNN.vtu`, then rewrites
    /// the `.pvd`. Returns the path of the `.vtu`. A non-finite `time` is refused.
    pub fn add(&mut self, time: f64, positions: &[[f64; 3]], fields: &[PointField]) -> io::Result<PathBuf> {
        if !time.is_finite() {
            return Err(invalid(format!("snapshot time {time} is not finite")));
        }
        let name = format!("{}_{:06}.vtu", self.basename, self.entries.len());
        let path = self.dir.join(&name);
        write_vtu(&path, positions, fields)?;
        self.entries.push((time, name));
        self.finish()?;
        Ok(path)
    }

    /// Writes snapshot number `entries().len()` at `time` of a run split into `ranks` domains:
    /// this rank's particles as the piece `basename_NNNNNN_RANK.vtu`, and on rank 0 the
    /// `basename_NNNNNN.pvtu` that joins the pieces into one data set, then the `.pvd`. Every rank
    /// calls it with its own particles; the series' entries name the `.pvtu`. Returns the path of
    /// the piece.
    pub fn add_piece(
        &mut self,
        time: f64,
        (rank, ranks): (usize, usize),
        positions: &[[f64; 3]],
        fields: &[PointField],
    ) -> io::Result<PathBuf> {
        if !time.is_finite() {
            return Err(invalid(format!("snapshot time {time} is not finite")));
        }
        let frame = format!("{}_{:06}", self.basename, self.entries.len());
        let piece = |r: usize| format!("{frame}_{r}.vtu");
        let path = self.dir.join(piece(rank));
        write_vtu(&path, positions, fields)?;
        let name = format!("{frame}.pvtu");
        if rank == 0 {
            let pieces: Vec<String> = (0..ranks).map(piece).collect();
            write_atomic(&self.dir.join(&name), pvtu_text(fields, &pieces).as_bytes())?;
        }
        self.entries.push((time, name));
        if rank == 0 {
            self.finish()?;
        }
        Ok(path)
    }

    /// (Re)writes the `.pvd` collection listing every snapshot so far; returns its path.
    pub fn finish(&self) -> io::Result<PathBuf> {
        let path = self.pvd_path();
        write_atomic(&path, pvd_text(&self.entries).as_bytes())?;
        Ok(path)
    }
}

/// The text of a `.pvtu` file joining `pieces` (`.vtu` files beside it, each written by
/// [`write_vtu`] with `fields`, in that order) into one data set.
fn pvtu_text(fields: &[PointField], pieces: &[String]) -> String {
    let mut s = String::from(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"PUnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" \
         header_type=\"UInt64\">\n  <PUnstructuredGrid GhostLevel=\"0\">\n    <PPointData",
    );
    s.push_str(&active_attributes(fields));
    s.push_str(">\n");
    for f in fields {
        s.push_str(&format!(
            "      <PDataArray type=\"Float64\" Name=\"{}\" NumberOfComponents=\"{}\"",
            xml_escape(&f.name),
            f.comps
        ));
        for (i, c) in component_names(f.comps).iter().enumerate() {
            s.push_str(&format!(" ComponentName{i}=\"{c}\""));
        }
        s.push_str("/>\n");
    }
    s.push_str("    </PPointData>\n    <PPoints>\n      <PDataArray type=\"Float64\" Name=\"Points\" NumberOfComponents=\"3\"/>\n    </PPoints>\n");
    s.push_str("    <PCells>\n      <PDataArray type=\"Int64\" Name=\"connectivity\"/>\n      <PDataArray type=\"Int64\" Name=\"offsets\"/>\n      <PDataArray type=\"UInt8\" Name=\"types\"/>\n    </PCells>\n");
    for p in pieces {
        s.push_str(&format!("    <Piece Source=\"{}\"/>\n", xml_escape(p)));
    }
    s.push_str("  </PUnstructuredGrid>\n</VTKFile>\n");
    s
}

/// The pieces a `.pvtu` file names (its `<Piece Source=...>`), in order.
pub fn pvtu_pieces(text: &str) -> Vec<String> {
    text.split("<Piece ").skip(1).filter_map(|tag| attr(&format!(" {}", &tag[..tag.find('>')?]), "Source")).collect()
}

/// Reads back a `.pvtu` file written by [`Series::add_piece`]: its pieces joined in order.
pub fn read_pvtu(path: &Path) -> io::Result<VtuData> {
    let text = std::fs::read_to_string(path)?;
    let dir = path.parent().unwrap_or(Path::new(""));
    let mut all: Option<VtuData> = None;
    for piece in pvtu_pieces(&text) {
        let p = read_vtu(&dir.join(&piece))?;
        let Some(a) = all.as_mut() else {
            all = Some(p);
            continue;
        };
        let points = a.positions.len() as i64;
        if p.fields.len() != a.fields.len() || p.fields.iter().zip(&a.fields).any(|(f, g)| f.name != g.name) {
            let bad = format!("{}: piece `{piece}` holds other fields than the first piece", path.display());
            return Err(io::Error::new(io::ErrorKind::InvalidData, bad));
        }
        a.positions.extend(p.positions);
        for (f, g) in a.fields.iter_mut().zip(p.fields) {
            f.data.extend(g.data);
        }
        a.cell_types.extend(p.cell_types);
        a.connectivity.extend(p.connectivity.iter().map(|c| c + points));
        let end = a.offsets.last().copied().unwrap_or(0);
        a.offsets.extend(p.offsets.iter().map(|o| o + end));
    }
    all.ok_or_else(|| io::Error::new(io::ErrorKind::InvalidData, format!("{}: no pieces", path.display())))
}

/// The text of a `.pvd` collection of `(time, file)` entries.
pub fn pvd_text(entries: &[(f64, String)]) -> String {
    let mut s = String::from(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n  <Collection>\n",
    );
    for (t, file) in entries {
        s.push_str(&format!(
            "    <DataSet timestep=\"{}\" group=\"\" part=\"0\" file=\"{}\"/>\n",
            fmt_time(*t),
            xml_escape(file)
        ));
    }
    s.push_str("  </Collection>\n</VTKFile>\n");
    s
}

/// Shortest round-trip decimal, in exponent form for very small or large magnitudes.
fn fmt_time(t: f64) -> String {
    let a = t.abs();
    if a != 0.0 && !(1e-4..1e15).contains(&a) {
        format!("{t:e}")
    } else {
        format!("{t}")
    }
}

fn xml_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            '\n' => out.push_str("&#10;"),
            '\t' => out.push_str("&#9;"),
            c if c.is_control() => out.push(' '),
            c => out.push(c),
        }
    }
    out
}

fn xml_unescape(s: &str) -> String {
    s.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&apos;", "'")
        .replace("&#10;", "\n")
        .replace("&#9;", "\t")
        .replace("&amp;", "&")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmpdir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("pairsum-report-vtk-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn sample() -> (Vec<[f64; 3]>, Vec<PointField>) {
        let pos = vec![[0.0, 0.0, 0.0], [1.5, -2.25, 1e-300], [0.1, 0.2, 0.3]];
        let fields = vec![
            PointField::scalar("rho", vec![1000.0, 1000.5, std::f64::consts::PI]),
            PointField::vector("v", &[[1.0, 2.0, 3.0], [-1.0, -2.0, -3.0], [0.0, 1e-12, f64::NAN]]),
            PointField::new("sym", 6, (0..18).map(|i| i as f64 * 0.5).collect()),
            PointField::new("sigma", 9, (0..27).map(|i| -(i as f64) / 3.0).collect()),
            PointField::new("pair", 2, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]),
        ];
        (pos, fields)
    }

    /// Bitwise equality, so NaN compares equal to itself.
    fn same(a: &[f64], b: &[f64]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
    }

    #[test]
    fn base64_matches_reference_vectors() {
        for (raw, enc) in
            [("", ""), ("f", "Zg=="), ("fo", "Zm8="), ("foo", "Zm9v"), ("foob", "Zm9vYg=="), ("foobar", "Zm9vYmFy")]
        {
            let mut out = Vec::new();
            let mut w = Base64Writer::new(&mut out);
            // Feed byte by byte to exercise the carry.
            for b in raw.bytes() {
                w.write_all(&[b]).unwrap();
            }
            w.finish().unwrap();
            assert_eq!(String::from_utf8(out).unwrap(), enc);
            assert_eq!(base64_decode(enc).unwrap(), raw.as_bytes());
        }
        let big: Vec<u8> = (0..10_000u32).map(|i| (i * 7 % 251) as u8).collect();
        let mut out = Vec::new();
        let mut w = Base64Writer::new(&mut out);
        w.write_all(&big[..5]).unwrap();
        w.write_all(&big[5..]).unwrap();
        w.finish().unwrap();
        assert_eq!(base64_decode(std::str::from_utf8(&out).unwrap()).unwrap(), big);
    }

    #[test]
    fn vtu_round_trip() {
        let dir = tmpdir("roundtrip");
        let path = dir.join("snap.vtu");
        let (pos, fields) = sample();
        write_vtu(&path, &pos, &fields).unwrap();

        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("<VTKFile type=\"UnstructuredGrid\""), "{text}");
        assert!(text.contains("<Piece NumberOfPoints=\"3\" NumberOfCells=\"3\">"));
        assert!(text.contains("<PointData Scalars=\"rho\" Vectors=\"v\" Tensors=\"sigma\">"));
        assert!(text.contains("Name=\"sigma\" NumberOfComponents=\"9\""));
        assert!(text.contains("Name=\"sym\" NumberOfComponents=\"6\" ComponentName0=\"XX\""));

        let back = read_vtu(&path).unwrap();
        assert_eq!(back.positions, pos);
        assert_eq!(back.cell_types, vec![VTK_VERTEX; 3]);
        assert_eq!(back.connectivity, vec![0, 1, 2]);
        assert_eq!(back.offsets, vec![1, 2, 3]);
        assert_eq!(back.fields.len(), fields.len());
        for (f, g) in fields.iter().zip(&back.fields) {
            assert_eq!((&f.name, f.comps), (&g.name, g.comps));
            assert!(same(&f.data, &g.data), "{}: {:?} != {:?}", f.name, f.data, g.data);
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn vtu_empty_and_bad_input() {
        let dir = tmpdir("empty");
        let path = dir.join("empty.vtu");
        write_vtu(&path, &[], &[PointField::scalar("rho", vec![])]).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("<Piece NumberOfPoints=\"0\" NumberOfCells=\"0\">"));
        let back = read_vtu(&path).unwrap();
        assert!(back.positions.is_empty() && back.cell_types.is_empty());
        assert_eq!(back.fields, vec![PointField::scalar("rho", vec![])]);

        let bad = dir.join("bad.vtu");
        for fields in [
            vec![PointField::new("v", 3, vec![1.0])],
            vec![PointField::new("z", 0, vec![])],
            vec![PointField::scalar("", vec![1.0])],
            vec![PointField::scalar("a", vec![1.0]), PointField::scalar("a", vec![2.0])],
        ] {
            let err = write_vtu(&bad, &[[0.0; 3]], &fields).unwrap_err();
            assert_eq!(err.kind(), io::ErrorKind::InvalidInput);
        }
        assert!(!bad.exists());
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn special_characters_in_names_are_escaped() {
        let dir = tmpdir("names");
        let path = dir.join("names.vtu");
        let name = "a<b> & \"c\" 'd'";
        write_vtu(&path, &[[1.0, 2.0, 3.0]], &[PointField::scalar(name, vec![4.0])]).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("Name=\"a&lt;b&gt; &amp; &quot;c&quot; &apos;d&apos;\""), "{text}");
        assert_eq!(read_vtu(&path).unwrap().fields, vec![PointField::scalar(name, vec![4.0])]);
        std::fs::remove_dir_all(&dir).ok();
    }

    /// Two ranks' pieces (one of them empty) join through the `.pvtu` into the particles of both,
    /// in rank order, with the cells renumbered; only rank 0 writes the `.pvtu` and the `.pvd`.
    #[test]
    fn pieces_of_two_ranks_read_back_through_the_pvtu_as_one_data_set() {
        let dir = tmpdir("pieces");
        let (pos, fields) = sample();
        let mut ranks: Vec<Series> = (0..2).map(|_| Series::new(&dir, "plate").unwrap()).collect();
        let part = |f: &PointField, r: std::ops::Range<usize>| {
            PointField::new(f.name.clone(), f.comps, f.data[r.start * f.comps..r.end * f.comps].to_vec())
        };
        for (time, split) in [(0.0, 1), (0.5, 3)] {
            for (rank, series) in ranks.iter_mut().enumerate().rev() {
                let mine = if rank == 0 { 0..split } else { split..pos.len() };
                let f: Vec<PointField> = fields.iter().map(|f| part(f, mine.clone())).collect();
                series.add_piece(time, (rank, 2), &pos[mine], &f).unwrap();
            }
        }
        assert_eq!(ranks[0].entries(), ranks[1].entries());
        let pvd = std::fs::read_to_string(ranks[0].pvd_path()).unwrap();
        assert!(pvd.contains("file=\"plate_000001.pvtu\""), "{pvd}");
        let pvtu = dir.join("plate_000001.pvtu");
        assert_eq!(pvtu_pieces(&std::fs::read_to_string(&pvtu).unwrap()), ["plate_000001_0.vtu", "plate_000001_1.vtu"]);
        for frame in ["plate_000000.pvtu", "plate_000001.pvtu"] {
            let whole = read_pvtu(&dir.join(frame)).unwrap();
            assert_eq!(whole.positions, pos, "{frame}");
            for (a, b) in whole.fields.iter().zip(&fields) {
                assert!(a.name == b.name && a.comps == b.comps && same(&a.data, &b.data), "{frame}: {}", a.name);
            }
            assert_eq!(whole.connectivity, [0, 1, 2]);
            assert_eq!(whole.offsets, [1, 2, 3]);
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn series_writes_pvd_after_every_add() {
        let dir = tmpdir("series");
        let mut s = Series::new(dir.join("out"), "fluid").unwrap();
        let (pos, fields) = sample();
        let p0 = s.add(0.0, &pos, &fields).unwrap();
        assert_eq!(p0, dir.join("out").join("fluid_000000.vtu"));
        // The collection is valid after the first snapshot already.
        let pvd = std::fs::read_to_string(s.pvd_path()).unwrap();
        assert!(pvd.contains("file=\"fluid_000000.vtu\""), "{pvd}");
        assert!(pvd.trim_end().ends_with("</VTKFile>"));
        assert!(!pvd.contains("fluid_000001"));

        let p1 = s.add(0.25, &pos, &fields).unwrap();
        let p2 = s.add(1e-7, &pos[..1], &[]).unwrap();
        assert!(p1.ends_with("fluid_000001.vtu") && p2.ends_with("fluid_000002.vtu"));
        assert!(s.add(f64::NAN, &pos, &fields).is_err());
        let pvd_path = s.finish().unwrap();
        let pvd = std::fs::read_to_string(&pvd_path).unwrap();
        assert!(pvd.starts_with("<?xml"));
        assert!(pvd.contains("<VTKFile type=\"Collection\""));
        assert!(pvd.contains("timestep=\"0\" group=\"\" part=\"0\" file=\"fluid_000000.vtu\""), "{pvd}");
        assert!(pvd.contains("timestep=\"0.25\" group=\"\" part=\"0\" file=\"fluid_000001.vtu\""), "{pvd}");
        assert!(pvd.contains("timestep=\"1e-7\" group=\"\" part=\"0\" file=\"fluid_000002.vtu\""), "{pvd}");
        assert_eq!(pvd.matches("<DataSet ").count(), 3);
        assert_eq!(s.entries().len(), 3);
        // Every listed file exists and reads back.
        for (_, f) in s.entries() {
            read_vtu(&s.dir().join(f)).unwrap();
        }
        // No temporary files left behind.
        let leftovers: Vec<_> = std::fs::read_dir(s.dir())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".tmp"))
            .collect();
        assert!(leftovers.is_empty(), "{leftovers:?}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn pvd_escapes_file_names() {
        let t = pvd_text(&[(1.0, "a&b.vtu".into())]);
        assert!(t.contains("file=\"a&amp;b.vtu\""));
    }
}
