//! A rank's neighbour passes on its own GPU (issue 42, `--backend gpu` on a split run). The
//! rank's particles stay on the host, where its domain migrates them, exchanges their halos and
//! its CPU backend (in f32) integrates them; the passes run on the device. Each evaluation writes
//! the state to the device before its first pass, a halo's refreshed fields
//! before a later one, and reads back what each pass writes. The device's buffers are built again
//! over each new halo (the kernels are compiled once per device: `Gpu::compile` keeps them).
//!
//! The copies cost the state's bytes and those the passes write, per evaluation, which on a
//! discrete GPU may outweigh the passes; keeping the state on the device and copying only the halo's rows
//! is not built.

use super::device::Gpu;
use super::runtime::GpuBackend;
use crate::backend::{BackendError, Globals, Mirror};
use crate::ir::FieldId;
use crate::particles::{Real, Store};
use crate::schedule::{search::Search, Plan};

/// The device of one rank and its buffers over the rank's current particles.
pub struct DevicePasses {
    plan: Plan,
    mirrors: Vec<Mirror>,
    /// The device when no buffers are built on it (between two stores).
    idle: Option<Gpu>,
    built: Option<GpuBackend>,
    describe: String,
    /// Per model group, the seconds of its particles in passes since the last
    /// [`take_pass_time`](Self::take_pass_time): each pass's time shared by the own particles.
    pass_time: Vec<f64>,
    /// Per model group: how many particles of the current store are this rank's own.
    owned: Vec<(usize, usize)>,
}

impl DevicePasses {
    /// The passes of `plan` on `gpu`, unless [`refuses`](Self::refuses) them.
    pub fn new(gpu: Gpu, plan: &Plan, mirrors: &[Mirror]) -> Result<DevicePasses, BackendError> {
        if let Some(e) = Self::refuses(plan) {
            return Err(e);
        }
        Ok(DevicePasses {
            describe: gpu.describe(),
            plan: plan.clone(),
            mirrors: mirrors.to_vec(),
            idle: Some(gpu),
            built: None,
            pass_time: vec![0.0; plan.model.groups.len()],
            owned: vec![],
        })
    }

    /// Why the ranks' GPUs cannot run `plan`'s passes, if they cannot: the adaptive search keeps
    /// a pair in its lists after it moved apart (it counts again if the two come back), so a split
    /// run carries the lists from rank to rank, on the CPU; a device's lists would start again
    /// at each new halo, and the run would not be the undivided one.
    pub fn refuses(plan: &Plan) -> Option<BackendError> {
        matches!(plan.search, Search::Adaptive { .. }).then(|| {
            BackendError(
                "a run split into domains keeps the adaptive search's lists on the CPU only: run it with \
                 `--backend cpu`, or on the GPU in one process (without `mpirun` or `--domains`)"
                    .into(),
            )
        })
    }

    /// "llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan, Cpu)".
    pub fn describe(&self) -> &str {
        &self.describe
    }

    /// Drops the buffers: the rank's particles changed (migration, a new halo, a reordering).
    pub fn forget(&mut self) {
        if let Some(b) = self.built.take() {
            self.idle = Some(b.into_gpu());
        }
    }

    /// Neighbour pass `k` of `store`, whose first `owned[r]` particles of its r-th group range
    /// are the rank's own (the rest, its halo, are read as neighbours only): the fields the host
    /// changed since the last pass (`changed`; every one at the first pass of an evaluation, when
    /// the search runs) go to the device, and what the pass writes comes back. Buffers built
    /// for this pass are searched whatever `first` says.
    pub fn run_pass<T: Real>(
        &mut self,
        k: usize,
        g: Globals,
        store: &mut Store<T>,
        owned: &[usize],
        changed: &[FieldId],
        first: bool,
    ) -> Result<(), BackendError> {
        let started = std::time::Instant::now();
        let search = first || self.built.is_none();
        let b = match self.built.take() {
            // The whole state at the first pass, whether a pass reads a field or not: the host's
            // updates may have changed any, and no list of what the kernels read is kept beside
            // them (`Pass::reads` leaves out `x` and `h`, which the plan's report adds: uploading
            // only those, the impact's time step went 0.24 % off within 40 steps).
            Some(b) => {
                if first {
                    b.upload_state(store)?;
                } else {
                    b.upload_fields(store, changed)?;
                }
                b
            }
            None => {
                let gpu = self.idle.take().ok_or_else(|| BackendError("the rank's GPU was lost".into()))?;
                let mut b = GpuBackend::new(gpu, self.plan.clone(), store.converted::<f32>(), &self.mirrors)?;
                b.activate_only(owned)?;
                self.owned = store.ranges.iter().zip(owned).map(|((g, _), n)| (g.index(), *n)).collect();
                b
            }
        };
        let b = self.built.insert(b);
        b.run_pass(k, g, search)?;
        b.download_fields(store, &self.plan.passes[k].writes)?;
        let secs = started.elapsed().as_secs_f64();
        let total: usize = self.owned.iter().map(|(_, n)| n).sum();
        for (g, n) in &self.owned {
            self.pass_time[*g] += secs * *n as f64 / total.max(1) as f64;
        }
        Ok(())
    }

    /// Per model group, the seconds spent in passes since the last call.
    pub fn take_pass_time(&mut self) -> Vec<f64> {
        std::mem::replace(&mut self.pass_time, vec![0.0; self.plan.model.groups.len()])
    }
}
