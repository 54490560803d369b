//! Checkpoints: the whole particle state and the clock, so that a killed run resumes and gives
//! the same result bit for bit. Format: a JSON header line, then every stored column as raw
//! little-endian f64, then ids and materials as u32.

use super::Engine;
use crate::backend::{Backend, Snapshot};
use serde::{Deserialize, Serialize};
use std::io::{Read, Write};
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
}

const FORMAT: &str = "pairsum-checkpoint-1";

pub fn write<B: Backend>(engine: &Engine<B>, path: &Path) -> std::io::Result<()> {
    let s = engine.backend.snapshot().map_err(backend_failed)?;
    let header = Header {
        format: FORMAT.into(),
        time: engine.time,
        step: engine.step,
        dt: engine.dt,
        particles: s.id.len(),
        columns: s.columns.iter().map(|c| c.as_ref().map(Vec::len)).collect(),
    };
    let tmp = path.with_extension("tmp");
    {
        let mut f = std::io::BufWriter::new(std::fs::File::create(&tmp)?);
        serde_json::to_writer(&mut f, &header)?;
        f.write_all(b"\n")?;
        for c in s.columns.iter().flatten() {
            for v in c {
                f.write_all(&v.to_le_bytes())?;
            }
        }
        for v in s.id.iter().chain(&s.material) {
            f.write_all(&v.to_le_bytes())?;
        }
        f.flush()?;
    }
    // Replace atomically, so a run killed while writing keeps the previous checkpoint.
    std::fs::rename(tmp, path)
}

fn backend_failed(e: crate::backend::BackendError) -> std::io::Error {
    std::io::Error::other(e.0)
}

fn bad(msg: impl Into<String>) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidData, msg.into())
}

/// Restores a checkpoint into an engine built from the same case.
pub fn read<B: Backend>(engine: &mut Engine<B>, path: &Path) -> std::io::Result<()> {
    let mut data = vec![];
    std::fs::File::open(path)?.read_to_end(&mut data)?;
    let nl = data.iter().position(|b| *b == b'\n').ok_or_else(|| bad("no checkpoint header"))?;
    let header: Header = serde_json::from_slice(&data[..nl]).map_err(|e| bad(format!("bad checkpoint header: {e}")))?;
    if header.format != FORMAT {
        return Err(bad(format!("unknown checkpoint format `{}`", header.format)));
    }
    let current = engine.backend.snapshot().map_err(backend_failed)?;
    let shapes: Vec<Option<usize>> = current.columns.iter().map(|c| c.as_ref().map(Vec::len)).collect();
    if shapes != header.columns || current.id.len() != header.particles {
        return Err(bad("the checkpoint was written by a different case or plan"));
    }
    let mut at = nl + 1;
    let mut f64s = |n: usize| -> std::io::Result<Vec<f64>> {
        let end = at + n * 8;
        let bytes = data.get(at..end).ok_or_else(|| bad("truncated checkpoint"))?;
        at = end;
        Ok(bytes.chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes"))).collect())
    };
    let mut columns = vec![];
    for c in &header.columns {
        columns.push(match c {
            Some(n) => Some(f64s(*n)?),
            None => None,
        });
    }
    let n = header.particles;
    let u32s = data.get(at..at + 8 * n).ok_or_else(|| bad("truncated checkpoint"))?;
    let all: Vec<u32> = u32s.chunks_exact(4).map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes"))).collect();
    let snapshot = Snapshot { columns, id: all[..n].to_vec(), material: all[n..].to_vec() };
    engine.backend.restore(&snapshot).map_err(backend_failed)?;
    engine.time = header.time;
    engine.step = header.step;
    engine.dt = header.dt;
    Ok(())
}
