//! The GPU backend: wgpu device and buffers, the GPU cell list and reductions.
pub mod cells;
pub mod device;
pub mod reduce;
pub mod runtime;

pub use runtime::GpuBackend;
