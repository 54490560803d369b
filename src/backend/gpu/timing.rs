//! Where a GPU run's time goes (`pairsum run --timing`): each kernel's device time from timestamp
//! queries written around its dispatch (where the adapter has `TIMESTAMP_QUERY`), and every
//! submission and read-back, with the bytes read and the host's wait for them.
//!
//! Timing changes what it measures a little: a submission that carries timestamps waits for
//! them, so the host and the device no longer overlap across submissions. The kernels' device
//! times are unaffected.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::sync::Mutex;
use std::time::Duration;

/// Timestamps one submission can carry (two per dispatch); past these a dispatch runs untimed.
const QUERIES: u32 = 2048;

struct Timestamps {
    set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    read: wgpu::Buffer,
    /// Nanoseconds per timestamp tick.
    period_ns: f64,
}

#[derive(Default)]
struct Tally {
    /// The kernels timed in the submission being recorded, in order (two queries each).
    pending: Vec<String>,
    /// Per kernel: dispatches, device nanoseconds (NaN where untimed).
    kernels: BTreeMap<String, (u64, f64)>,
    untimed: u64,
    submissions: u64,
    readbacks: u64,
    readback_bytes: u64,
    readback_wait: Duration,
}

pub struct Timing {
    timestamps: Option<Timestamps>,
    tally: Mutex<Tally>,
}

impl Timing {
    /// A timing of `device`; with `timestamps` (the device was created with `TIMESTAMP_QUERY`),
    /// kernels are timed on the device too.
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, timestamps: bool) -> Timing {
        let timestamps = timestamps.then(|| {
            let bytes = QUERIES as u64 * wgpu::QUERY_SIZE as u64;
            Timestamps {
                set: device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("timing"),
                    ty: wgpu::QueryType::Timestamp,
                    count: QUERIES,
                }),
                resolve: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("timing resolve"),
                    size: bytes,
                    usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
                read: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("timing read"),
                    size: bytes,
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }),
                period_ns: queue.get_timestamp_period() as f64,
            }
        });
        Timing { timestamps, tally: Mutex::new(Tally::default()) }
    }

    fn tally(&self) -> std::sync::MutexGuard<'_, Tally> {
        self.tally.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The timestamp writes of the next dispatch, `label`'s (None: it runs untimed).
    pub fn dispatch(&self, label: &str) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        let mut t = self.tally();
        let Some(ts) = &self.timestamps else {
            t.kernels.entry(label.to_string()).or_insert((0, f64::NAN)).0 += 1;
            t.untimed += 1;
            return None;
        };
        let k = t.pending.len() as u32;
        if 2 * k + 2 > QUERIES {
            t.untimed += 1;
            return None;
        }
        t.pending.push(label.to_string());
        Some(wgpu::ComputePassTimestampWrites {
            query_set: &ts.set,
            beginning_of_pass_write_index: Some(2 * k),
            end_of_pass_write_index: Some(2 * k + 1),
        })
    }

    /// Submits `encoder` and, when it carries timestamps, waits for them and adds them up.
    pub fn submit(&self, device: &wgpu::Device, queue: &wgpu::Queue, mut encoder: wgpu::CommandEncoder) {
        let pending = std::mem::take(&mut self.tally().pending);
        self.tally().submissions += 1;
        let Some(ts) = self.timestamps.as_ref().filter(|_| !pending.is_empty()) else {
            queue.submit([encoder.finish()]);
            return;
        };
        let queries = 2 * pending.len() as u32;
        let bytes = queries as u64 * wgpu::QUERY_SIZE as u64;
        encoder.resolve_query_set(&ts.set, 0..queries, &ts.resolve, 0);
        encoder.copy_buffer_to_buffer(&ts.resolve, 0, &ts.read, 0, bytes);
        queue.submit([encoder.finish()]);
        let slice = ts.read.slice(0..bytes);
        slice.map_async(wgpu::MapMode::Read, |_| {});
        // A failure here leaves these dispatches untimed; the run's own wait reports the error.
        if device.poll(wgpu::PollType::wait_indefinitely()).is_err() {
            self.tally().untimed += pending.len() as u64;
            return;
        }
        let ticks: Vec<u64> = match slice.get_mapped_range() {
            Ok(view) => bytemuck::cast_slice(&view).to_vec(),
            Err(_) => vec![],
        };
        ts.read.unmap();
        let mut t = self.tally();
        for (k, label) in pending.into_iter().enumerate() {
            let ns = match (ticks.get(2 * k), ticks.get(2 * k + 1)) {
                (Some(a), Some(b)) => b.saturating_sub(*a) as f64 * ts.period_ns,
                _ => f64::NAN,
            };
            let e = t.kernels.entry(label).or_insert((0, 0.0));
            e.0 += 1;
            e.1 += ns;
        }
    }

    /// A read-back of `bytes` that kept the host waiting `wait`.
    pub fn readback(&self, bytes: u64, wait: Duration) {
        let mut t = self.tally();
        t.readbacks += 1;
        t.readback_bytes += bytes;
        t.readback_wait += wait;
    }

    /// The table: kernels by device time, then the submissions and read-backs, per step over
    /// `steps` steps.
    pub fn report(&self, steps: u64) -> String {
        let t = self.tally();
        let per = |x: f64| x / steps.max(1) as f64;
        let mut s = String::new();
        let total: f64 = t.kernels.values().map(|(_, ns)| ns).filter(|ns| ns.is_finite()).sum();
        if self.timestamps.is_some() {
            let _ = writeln!(s, "device time by kernel (timestamp queries), over the whole run including set-up:");
            let _ = writeln!(
                s,
                "  {:<40} {:>10} {:>12} {:>10} {:>7}",
                "kernel", "dispatches", "total ms", "mean us", "share"
            );
            let mut rows: Vec<_> = t.kernels.iter().collect();
            rows.sort_by(|a, b| b.1 .1.total_cmp(&a.1 .1));
            for (name, (n, ns)) in rows {
                let _ = writeln!(
                    s,
                    "  {:<40} {:>10} {:>12.3} {:>10.2} {:>6.1}%",
                    name,
                    n,
                    ns * 1e-6,
                    ns * 1e-3 / *n as f64,
                    100.0 * ns / total
                );
            }
            let _ = writeln!(s, "  all kernels: {:.3} ms, {:.3} ms per step", total * 1e-6, per(total) * 1e-6);
            if t.untimed > 0 {
                let _ = writeln!(s, "  ({} dispatches past {} per submission ran untimed)", t.untimed, QUERIES / 2);
            }
        } else {
            let dispatches: u64 = t.kernels.values().map(|(n, _)| n).sum();
            let _ = writeln!(
                s,
                "the adapter has no timestamp queries: {dispatches} dispatches ({:.1} per step), not timed",
                per(dispatches as f64)
            );
        }
        let _ = writeln!(
            s,
            "submissions: {} ({:.2} per step); blocking read-backs: {} ({:.2} per step), {:.3} MB ({:.3} MB per step), \
             host waited {:.3} s ({:.3} ms per step)",
            t.submissions,
            per(t.submissions as f64),
            t.readbacks,
            per(t.readbacks as f64),
            t.readback_bytes as f64 * 1e-6,
            per(t.readback_bytes as f64) * 1e-6,
            t.readback_wait.as_secs_f64(),
            per(t.readback_wait.as_secs_f64()) * 1e3
        );
        s
    }
}
