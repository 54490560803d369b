//! Checkpoints: the whole particle state and the clock, so that a killed run resumes and gives
//! the same result bit for bit. Format: a JSON header line, then every stored column as raw
//! little-endian f64, then ids and materials as u32, then the caller's record of the run so far
//! (the runner's probe histories and outputs: bytes the engine does not read), then the CRC-32 of
//! everything before it (little-endian u32), so that a flipped or lost byte anywhere is refused
//! rather than restored.
//!
//! A checkpoint is written to a temporary file, synced to the disk, and renamed over the previous
//! one (and the folder synced), so a run killed or a disk filled while writing keeps the last good
//! checkpoint.

use super::Engine;
use crate::backend::{Backend, Snapshot};
use serde::{Deserialize, Serialize};
use std::path::Path;

#[derive(Serialize, Deserialize)]
struct Header {
    format: String,
    time: f64,
    step: u64,
    dt: f64,
    particles: usize,
    /// Per field id: the number of values stored (None: not stored).
    columns: Vec<Option<usize>>,
    /// The length of the caller's record, the last thing before the checksum.
    record: usize,
}

const FORMAT: &str = "pairsum-checkpoint-2";

/// The bytes of a checkpoint of `engine`'s current state, with `record` (the caller's own state).
pub fn encode<B: Backend>(engine: &Engine<B>, record: &[u8]) -> std::io::Result<Vec<u8>> {
    let s = engine.backend.snapshot().map_err(backend_failed)?;
    let header = Header {
        format: FORMAT.into(),
        time: engine.time,
        step: engine.step,
        dt: engine.dt,
        particles: s.id.len(),
        columns: s.columns.iter().map(|c| c.as_ref().map(Vec::len)).collect(),
        record: record.len(),
    };
    let mut out = serde_json::to_vec(&header)?;
    out.push(b'\n');
    for c in s.columns.iter().flatten() {
        for v in c {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    for v in s.id.iter().chain(&s.material) {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(record);
    let crc = crc32fast::hash(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    Ok(out)
}

/// Writes a checkpoint of `engine` and `record` to `path` durably (`output_dir::write_atomic`): on
/// any error `path` is as it was.
pub fn write<B: Backend>(engine: &Engine<B>, record: &[u8], path: &Path) -> std::io::Result<()> {
    crate::output_dir::write_atomic(path, &encode(engine, record)?)
}

fn backend_failed(e: crate::backend::BackendError) -> std::io::Error {
    std::io::Error::other(e.0)
}

fn bad(msg: impl Into<String>) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidData, msg.into())
}

/// Restores a checkpoint into an engine built from the same case; returns the caller's record.
pub fn read<B: Backend>(engine: &mut Engine<B>, path: &Path) -> std::io::Result<Vec<u8>> {
    // Not a device or a pipe, which could be read without end.
    if !std::fs::metadata(path)?.is_file() {
        return Err(bad("not a regular file"));
    }
    let data = std::fs::read(path)?;
    decode(engine, &data)
}

/// Restores the bytes of a checkpoint into an engine built from the same case and returns the
/// caller's record. Whatever the bytes, either the whole state is restored or an error says why
/// and the engine is left as it was.
pub fn decode<B: Backend>(engine: &mut Engine<B>, data: &[u8]) -> std::io::Result<Vec<u8>> {
    let body = verified_body(data)?;
    let nl = body.iter().position(|b| *b == b'\n').ok_or_else(|| bad("no checkpoint header"))?;
    let header: Header = serde_json::from_slice(&body[..nl]).map_err(|e| bad(format!("bad checkpoint header: {e}")))?;
    if header.format != FORMAT {
        return Err(bad(format!("unknown checkpoint format `{}` (this pairsum reads `{FORMAT}`)", header.format)));
    }
    if !(header.time.is_finite() && header.time >= 0.0 && header.dt.is_finite() && header.dt > 0.0) {
        return Err(bad(format!("the checkpoint's clock is t = {} s, dt = {} s", header.time, header.dt)));
    }
    let current = engine.backend.snapshot().map_err(backend_failed)?;
    let shapes: Vec<Option<usize>> = current.columns.iter().map(|c| c.as_ref().map(Vec::len)).collect();
    if shapes != header.columns || current.id.len() != header.particles {
        return Err(bad("the checkpoint was written by a different case or plan"));
    }
    // The shapes are the current ones, so the sizes below cannot overflow.
    let n = header.particles;
    let values: usize = shapes.iter().flatten().sum();
    let rest = &body[nl + 1..];
    let expected = (8 * (values + n)).checked_add(header.record);
    if expected != Some(rest.len()) {
        return Err(bad(format!(
            "the checkpoint holds {} bytes of data where its header says {}",
            rest.len(),
            8 * (values + n) as u128 + header.record as u128
        )));
    }
    let (floats, rest) = rest.split_at(8 * values);
    let (ints, record) = rest.split_at(8 * n);
    let mut floats = floats.chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")));
    let columns = shapes.iter().map(|c| c.map(|len| floats.by_ref().take(len).collect())).collect();
    let all: Vec<u32> = ints.chunks_exact(4).map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes"))).collect();
    let snapshot = Snapshot { columns, id: all[..n].to_vec(), material: all[n..].to_vec() };
    same_particles(&snapshot, &current, &engine.backend.groups())?;
    engine.backend.restore(&snapshot).map_err(backend_failed)?;
    engine.time = header.time;
    engine.step = header.step;
    engine.dt = header.dt;
    Ok(record.to_vec())
}

/// The checkpoint without its checksum, once the checksum matches.
fn verified_body(data: &[u8]) -> std::io::Result<&[u8]> {
    let Some(split) = data.len().checked_sub(4) else {
        return Err(bad(format!("a checkpoint of {} bytes is too short to be one", data.len())));
    };
    let (body, crc) = data.split_at(split);
    let stored = u32::from_le_bytes(crc.try_into().expect("4 bytes"));
    let computed = crc32fast::hash(body);
    if stored != computed {
        return Err(bad(format!(
            "the checkpoint is corrupted: its CRC-32 is {computed:08x}, it was written as {stored:08x} (a changed, \
             lost or added byte; or a checkpoint of an older pairsum, without a checksum)"
        )));
    }
    Ok(body)
}

/// The checkpoint holds the particles the engine holds: each id once, each in a row of its own
/// group and with its own material (a particle keeps both for life; only rows are reordered).
fn same_particles(saved: &Snapshot, current: &Snapshot, groups: &[u32]) -> std::io::Result<()> {
    let n = current.id.len();
    let mut by_id = vec![None; n];
    for (row, id) in current.id.iter().enumerate() {
        if let Some(slot) = by_id.get_mut(*id as usize) {
            *slot = Some((groups.get(row).copied(), current.material[row]));
        }
    }
    let mut seen = vec![false; n];
    for (row, (id, material)) in saved.id.iter().zip(&saved.material).enumerate() {
        let Some(Some((group, own_material))) = by_id.get(*id as usize).copied() else {
            return Err(bad(format!("row {row} of the checkpoint holds particle {id}, which this case does not have")));
        };
        if std::mem::replace(&mut seen[*id as usize], true) {
            return Err(bad(format!("particle {id} appears twice in the checkpoint")));
        }
        if group != groups.get(row).copied() || *material != own_material {
            return Err(bad(format!(
                "row {row} of the checkpoint holds particle {id} with material {material}, in another group or with \
                 another material than this case gives it"
            )));
        }
    }
    Ok(())
}
