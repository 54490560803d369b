//! The GPU backend: wgpu device and buffers, the GPU cell list, reductions and reordering.
pub mod cells;
pub mod device;
pub mod lists;
pub mod probe;
pub mod reduce;
pub mod reorder;
pub mod runtime;
pub mod share;
pub mod timing;

pub use runtime::GpuBackend;
