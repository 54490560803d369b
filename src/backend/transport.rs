//! How the domains of a split run talk: every exchange is collective (each rank calls it, in the
//! same order), so a run's control flow is the same on every rank. Two transports: threads of one
//! process ([`Threads`], what the tests use) and MPI processes (`mpi` feature, [`mpi::Mpi`]).
//! Values travel as f64 (an f32 run's values convert exactly).

use crate::ir::Reduce;
use std::sync::{Arc, Condvar, Mutex};

/// One rank's end of a transport.
pub trait Transport: Send {
    fn rank(&self) -> usize;
    fn size(&self) -> usize;
    /// All to all: `out[d]` goes to rank d; returns what each rank sent this one, by rank.
    fn exchange(&mut self, out: Vec<Vec<f64>>) -> Vec<Vec<f64>>;
    /// Every rank's `mine`, by rank.
    fn all_gather(&mut self, mine: Vec<f64>) -> Vec<Vec<f64>> {
        let out = vec![mine; self.size()];
        self.exchange(out)
    }
    /// `values` combined over the ranks element by element, in rank order (the same result on
    /// every rank and every transport).
    fn all_reduce(&mut self, values: &[f64], reduce: &[Reduce]) -> Vec<f64> {
        let all = self.all_gather(values.to_vec());
        let mut out: Vec<f64> = reduce.iter().map(|r| r.identity()).collect();
        for v in all {
            for (k, r) in reduce.iter().enumerate() {
                out[k] = match r {
                    Reduce::Sum => out[k] + v[k],
                    Reduce::Min => out[k].min(v[k]),
                    Reduce::Max => out[k].max(v[k]),
                };
            }
        }
        out
    }
}

/// The ranks as threads of one process, exchanging through shared mailboxes. A rank that stops
/// (returns or panics) while the others still exchange makes them panic instead of waiting for
/// it forever.
pub struct Threads {
    rank: usize,
    size: usize,
    shared: Arc<Mailboxes>,
}

struct Mailboxes {
    state: Mutex<Exchange>,
    turned: Condvar,
}

struct Exchange {
    /// `slots[to][from]`.
    slots: Vec<Vec<Vec<f64>>>,
    /// Ranks waiting for the others in this round, and the rounds completed.
    arrived: usize,
    round: u64,
    /// A rank has stopped: no round can complete.
    broken: bool,
}

impl Threads {
    /// The `size` ends of one transport, one per thread.
    pub fn ranks(size: usize) -> Vec<Threads> {
        let state = Exchange { slots: vec![vec![vec![]; size]; size], arrived: 0, round: 0, broken: false };
        let shared = Arc::new(Mailboxes { state: Mutex::new(state), turned: Condvar::new() });
        (0..size).map(|rank| Threads { rank, size, shared: shared.clone() }).collect()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Exchange> {
        self.shared.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Waits until every rank has arrived here.
    fn wait_for_all<'a>(
        &'a self,
        mut state: std::sync::MutexGuard<'a, Exchange>,
    ) -> std::sync::MutexGuard<'a, Exchange> {
        let round = state.round;
        state.arrived += 1;
        if state.arrived == self.size {
            state.arrived = 0;
            state.round += 1;
            self.shared.turned.notify_all();
            return state;
        }
        while state.round == round {
            assert!(!state.broken, "another rank of this split run stopped before this exchange");
            state = self.shared.turned.wait(state).unwrap_or_else(|e| e.into_inner());
        }
        state
    }
}

impl Drop for Threads {
    fn drop(&mut self) {
        self.lock().broken = true;
        self.shared.turned.notify_all();
    }
}

impl Transport for Threads {
    fn rank(&self) -> usize {
        self.rank
    }

    fn size(&self) -> usize {
        self.size
    }

    fn exchange(&mut self, out: Vec<Vec<f64>>) -> Vec<Vec<f64>> {
        let mut state = self.lock();
        assert!(!state.broken, "another rank of this split run stopped before this exchange");
        for (to, v) in out.into_iter().enumerate() {
            state.slots[to][self.rank] = v;
        }
        let mut state = self.wait_for_all(state);
        let got = std::mem::replace(&mut state.slots[self.rank], vec![vec![]; self.size]);
        // No rank writes the next round's messages before every rank has taken this one's.
        drop(self.wait_for_all(state));
        got
    }
}

/// The number of ranks `mpirun` (Open MPI's or MPICH's) started this process among, if it did.
pub fn launched_ranks() -> Option<usize> {
    ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE"].iter().find_map(|v| std::env::var(v).ok()?.parse().ok())
}

/// This process's rank among those `mpirun` (Open MPI's or MPICH's) started on this machine,
/// if it did.
pub fn local_rank() -> Option<usize> {
    ["OMPI_COMM_WORLD_LOCAL_RANK", "MPI_LOCALRANKID"].iter().find_map(|v| std::env::var(v).ok()?.parse().ok())
}

/// This process's rank among those `mpirun` started (initialising MPI on first use); `None`
/// where it was not started by `mpirun` on more than one rank.
pub fn launched_rank() -> Result<Option<usize>, super::BackendError> {
    Ok(world()?.map(|w| w.rank()))
}

/// The ranks `mpirun` started, as a transport (MPI is initialised on the first call and
/// finalised by [`finalise`]); `None` where this process was not started by `mpirun` on more
/// than one rank. An error where it was but this build has no MPI.
pub fn world() -> Result<Option<Box<dyn Transport>>, super::BackendError> {
    match launched_ranks() {
        Some(n) if n > 1 => launched_world(n),
        _ => Ok(None),
    }
}

#[cfg(feature = "mpi")]
fn launched_world(_: usize) -> Result<Option<Box<dyn Transport>>, super::BackendError> {
    mpi_ranks::World::get().map(|w| Some(Box::new(w) as Box<dyn Transport>))
}

#[cfg(not(feature = "mpi"))]
fn launched_world(n: usize) -> Result<Option<Box<dyn Transport>>, super::BackendError> {
    Err(super::BackendError(format!(
        "this pairsum was started by mpirun as one of {n} ranks but was built without MPI: build it with \
         `cargo build --release --features mpi` (which needs Open MPI, Debian's libopenmpi-dev, and libclang-dev)"
    )))
}

/// Finalises MPI if this process initialised it (at the end of `main`, on the thread that
/// initialised it).
pub fn finalise() {
    #[cfg(feature = "mpi")]
    mpi_ranks::finalise();
}

/// Stops every rank after an error on this one, which the others cannot know of and would wait
/// for; returns where this process is not one of several MPI ranks.
pub fn abort_ranks(code: i32) {
    #[cfg(feature = "mpi")]
    mpi_ranks::abort(code);
    let _ = code;
}

/// MPI: the processes `mpirun` started, one rank each (the `mpi` feature).
#[cfg(feature = "mpi")]
pub mod mpi_ranks {
    use super::super::BackendError;
    use super::Transport;
    use mpi::datatype::{Partition, PartitionMut};
    use mpi::topology::{Communicator, SimpleCommunicator};
    use mpi::traits::*;
    use mpi::Count;
    use std::sync::Mutex;

    pub struct Mpi {
        world: SimpleCommunicator,
        rank: usize,
        size: usize,
        // Finalises MPI when the run is done.
        _universe: mpi::environment::Universe,
    }

    // SAFETY: MPI is initialised with `Threading::Serialized` and every call goes through the
    // transport's mutex, one at a time.
    unsafe impl Send for Mpi {}

    /// MPI, once initialised; taken (and finalised) by [`finalise`].
    static MPI: Mutex<Option<Mpi>> = Mutex::new(None);
    static STARTED: std::sync::Once = std::sync::Once::new();

    fn lock() -> std::sync::MutexGuard<'static, Option<Mpi>> {
        MPI.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// This process's end of MPI's world, shared by every run it makes (a study's).
    pub struct World {
        rank: usize,
        size: usize,
    }

    impl World {
        pub fn get() -> Result<World, BackendError> {
            STARTED.call_once(|| {
                if let Some((universe, _)) = mpi::initialize_with_threading(mpi::Threading::Serialized) {
                    let world = universe.world();
                    let (rank, size) = (world.rank() as usize, world.size() as usize);
                    *lock() = Some(Mpi { world, rank, size, _universe: universe });
                }
            });
            let mpi = lock();
            let m =
                mpi.as_ref().ok_or_else(|| BackendError("MPI could not be initialised (or was finalised)".into()))?;
            Ok(World { rank: m.rank, size: m.size })
        }
    }

    impl Transport for World {
        fn rank(&self) -> usize {
            self.rank
        }
        fn size(&self) -> usize {
            self.size
        }
        fn exchange(&mut self, out: Vec<Vec<f64>>) -> Vec<Vec<f64>> {
            match lock().as_mut() {
                Some(m) => m.exchange(out),
                None => panic!("MPI was finalised before the run ended"),
            }
        }
    }

    pub fn finalise() {
        drop(lock().take());
    }

    pub fn abort(code: i32) {
        if let Some(m) = lock().as_ref() {
            if m.size > 1 {
                m.world.abort(code)
            }
        }
    }

    fn displacements(counts: &[Count]) -> Vec<Count> {
        counts
            .iter()
            .scan(0, |at, c| {
                let d = *at;
                *at += c;
                Some(d)
            })
            .collect()
    }

    impl Transport for Mpi {
        fn rank(&self) -> usize {
            self.rank
        }

        fn size(&self) -> usize {
            self.size
        }

        fn exchange(&mut self, out: Vec<Vec<f64>>) -> Vec<Vec<f64>> {
            let counts: Vec<Count> = out.iter().map(|v| v.len() as Count).collect();
            let mut incoming: Vec<Count> = vec![0; self.size];
            self.world.all_to_all_into(&counts[..], &mut incoming[..]);
            let send: Vec<f64> = out.concat();
            let mut recv = vec![0.0f64; incoming.iter().map(|c| *c as usize).sum()];
            let (out_at, in_at) = (displacements(&counts), displacements(&incoming));
            {
                let sent = Partition::new(&send[..], &counts[..], &out_at[..]);
                let mut got = PartitionMut::new(&mut recv[..], &incoming[..], &in_at[..]);
                self.world.all_to_all_varcount_into(&sent, &mut got);
            }
            incoming.iter().zip(&in_at).map(|(c, d)| recv[*d as usize..(*d + *c) as usize].to_vec()).collect()
        }
    }
}
