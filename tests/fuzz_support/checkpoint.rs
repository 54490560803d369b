//! Checkpoint files: a valid checkpoint of a small bundled case (`standing_wave`, 206 particles,
//! after a few steps), mutated byte by byte (flips, insertions, deletions, truncation, ranges
//! copied or zeroed), in its JSON header (each field given another type or an extreme value,
//! fields dropped or added), and in its data (values made NaN or infinite, particle ids and
//! materials changed, the caller's record lengthened); in half the inputs the trailing CRC-32 is
//! computed again, so that the reader behind the checksum is reached. Each is decoded into the
//! engine (`pairsum::engine::checkpoint::decode`): an error is fine, and must leave the engine as it
//! was; a checkpoint that decodes is followed by the valid one again.

use super::{label, Kind, Outcome, Rng};
use pairsum::backend::cpu::CpuBackend;
use pairsum::backend::Backend;
use pairsum::engine::{checkpoint, setup, Engine};
use std::path::Path;

type CpuEngine = Engine<CpuBackend<f64>>;

pub struct Checkpoints {
    engine: CpuEngine,
    /// Valid checkpoints of the engine's state, with records of different lengths.
    valid: Vec<Vec<u8>>,
    /// The engine's state they hold.
    state: State,
}

/// An engine's state: the clock (as bits), columns as bits, ids, materials.
type State = ([u64; 3], Vec<Option<Vec<u64>>>, Vec<u32>, Vec<u32>);

fn state_of(e: &CpuEngine) -> State {
    let s = e.backend.snapshot().expect("a snapshot");
    let bits = s.columns.iter().map(|c| c.as_ref().map(|c| c.iter().map(|v| v.to_bits()).collect())).collect();
    ([e.time.to_bits(), e.step, e.dt.to_bits()], bits, s.id, s.material)
}

impl Checkpoints {
    pub fn new() -> Checkpoints {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("cases/standing_wave.toml");
        let (scene, plan) = pairsum::runner::prepare(&path, &Default::default()).unwrap_or_else(|e| panic!("{e}"));
        let store = setup::build_store::<f64>(&plan, &scene.particles, &scene.materials).expect("a store");
        let backend = CpuBackend::new(plan, store, scene.mirrors.clone()).expect("a backend");
        let mut engine = Engine::new(backend, scene.config.clone());
        engine.initialise().expect("initialise");
        for _ in 0..3 {
            engine.step().expect("a step");
        }
        let records: [&[u8]; 3] = [b"", b"probe histories \x00\xff", &[7u8; 300]];
        let valid = records.iter().map(|r| checkpoint::encode(&engine, r).expect("encode")).collect();
        let state = state_of(&engine);
        Checkpoints { engine, valid, state }
    }
}

/// Values for the header's fields: other types and extremes.
const JSON_VALUES: &[&str] = &[
    "null",
    "true",
    "0",
    "-1",
    "1",
    "1.5",
    "-0.0",
    "1e308",
    "-1e308",
    "1e-320",
    "4294967295",
    "4294967296",
    "9223372036854775807",
    "18446744073709551615",
    "18446744073709551616",
    "-9223372036854775809",
    "\"\"",
    "\"pairsum-checkpoint-1\"",
    "\"pairsum-checkpoint-2\"",
    "\"NaN\"",
    "[]",
    "[null]",
    "[1, 2, 3]",
    "{}",
    "[18446744073709551615]",
    "[0, null, 0]",
];

/// One edit of the JSON header (the bytes up to the first newline).
fn mutate_header(rng: &mut Rng, data: &mut Vec<u8>) {
    let Some(nl) = data.iter().position(|b| *b == b'\n') else { return };
    let Ok(mut header) = serde_json::from_slice::<serde_json::Value>(&data[..nl]) else { return };
    let Some(obj) = header.as_object_mut() else { return };
    let keys: Vec<String> = obj.keys().cloned().collect();
    let key = rng.pick(&keys).clone();
    let new: serde_json::Value = serde_json::from_str(rng.word(JSON_VALUES)).unwrap_or(serde_json::Value::Null);
    match rng.below(6) {
        0 => {
            obj.remove(&key);
        }
        1 => {
            obj.insert("extra".into(), new);
        }
        2 => {
            // A column's length, or a column dropped or added.
            if let Some(serde_json::Value::Array(cols)) = obj.get_mut("columns") {
                let k = rng.below(cols.len().max(1));
                match rng.below(3) {
                    0 if k < cols.len() => cols[k] = new,
                    1 if k < cols.len() => {
                        cols.remove(k);
                    }
                    _ => cols.push(serde_json::json!(rng.below(1000))),
                }
            }
        }
        3 => {
            // A count off by a little.
            if let Some(v) = obj.get(&key).and_then(|v| v.as_u64()) {
                let d = rng.below(5) as u64;
                obj.insert(key, serde_json::json!(if rng.chance(50) { v.wrapping_add(d) } else { v.wrapping_sub(d) }));
            }
        }
        _ => {
            obj.insert(key, new);
        }
    }
    let mut out = serde_json::to_vec(&header).unwrap_or_default();
    out.extend_from_slice(&data[nl..]);
    *data = out;
}

/// One edit of the data after the header: a value made NaN or infinite, an id or material changed.
fn mutate_data(rng: &mut Rng, data: &mut [u8]) {
    let Some(nl) = data.iter().position(|b| *b == b'\n') else { return };
    let body = data.len().saturating_sub(4);
    if body <= nl + 9 {
        return;
    }
    let span = body - nl - 1;
    match rng.below(3) {
        0 => {
            // An f64 somewhere in the data (aligned to the columns' start).
            let k = nl + 1 + 8 * rng.below(span / 8);
            let v = *rng.pick(&[f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 0.0, -0.0, 1e308, f64::MIN_POSITIVE / 2.0]);
            if k + 8 <= body {
                data[k..k + 8].copy_from_slice(&v.to_le_bytes());
            }
        }
        _ => {
            // A u32 (an id or a material near the end of the data), given an extreme value.
            let k = body - 4 * (1 + rng.below((span / 4).min(600)));
            let v = *rng.pick(&[0u32, 1, 2, 205, 206, 207, u32::MAX, 0x8000_0000, 12345]);
            if k > nl {
                data[k..k + 4].copy_from_slice(&v.to_le_bytes());
            }
        }
    }
}

/// One edit of the bytes.
fn mutate_bytes(rng: &mut Rng, data: &mut Vec<u8>) {
    if data.is_empty() {
        data.push(rng.next() as u8);
        return;
    }
    let n = data.len();
    let k = rng.below(n);
    match rng.below(8) {
        0 => data[k] ^= 1 << rng.below(8),
        1 => data[k] = rng.next() as u8,
        2 => data.insert(k, rng.next() as u8),
        3 => {
            data.remove(k);
        }
        4 => data.truncate(k),
        5 => {
            let extra: Vec<u8> = (0..1 + rng.below(64)).map(|_| rng.next() as u8).collect();
            data.extend(extra);
        }
        6 => {
            let len = (1 + rng.below(64)).min(n - k);
            let copy = data[k..k + len].to_vec();
            let to = rng.below(n);
            data.splice(to..to, copy);
        }
        _ => {
            let len = (1 + rng.below(256)).min(n - k);
            data[k..k + len].fill(0);
        }
    }
}

/// The last four bytes made the CRC-32 of the rest again.
fn fix_crc(data: &mut Vec<u8>) {
    if data.len() < 4 {
        let crc = crc32fast::hash(data);
        data.extend_from_slice(&crc.to_le_bytes());
        return;
    }
    let n = data.len() - 4;
    let crc = crc32fast::hash(&data[..n]);
    data[n..].copy_from_slice(&crc.to_le_bytes());
}

impl Kind for Checkpoints {
    fn name(&self) -> &'static str {
        "checkpoints"
    }
    fn extension(&self) -> &'static str {
        "bin"
    }
    fn generate(&mut self, index: u64, rng: &mut Rng) -> Vec<u8> {
        if let Some(v) = self.valid.get(index as usize) {
            return v.clone();
        }
        let mut data = rng.pick(&self.valid).clone();
        for _ in 0..1 + rng.below(3) {
            match rng.below(10) {
                0..=2 => mutate_header(rng, &mut data),
                3..=4 => mutate_data(rng, &mut data),
                _ => mutate_bytes(rng, &mut data),
            }
        }
        if rng.chance(50) {
            fix_crc(&mut data);
        }
        data
    }
    fn run(&mut self, input: &[u8]) -> Outcome {
        match checkpoint::decode(&mut self.engine, input) {
            Ok(_) => {
                // Back to the valid state for the next input.
                let valid = self.valid[0].clone();
                if let Err(e) = checkpoint::decode(&mut self.engine, &valid) {
                    return Outcome::Bad(format!("the valid checkpoint no longer decodes: {e}"));
                }
                Outcome::Accepted("restored".into())
            }
            Err(e) => {
                if e.to_string().is_empty() {
                    return Outcome::Bad("an error without a message".into());
                }
                if state_of(&self.engine) != self.state {
                    return Outcome::Bad(format!("a refused checkpoint changed the engine: {e}"));
                }
                Outcome::Refused(label(&e.to_string()))
            }
        }
    }
}
