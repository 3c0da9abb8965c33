//! The allocator prismap runs with, shared by the `prismap` binary and the benchmarks
//! (included by path: `#[path = …] mod allocator;`), so that the benchmarks measure the
//! memory behaviour the product has.
//!
//! Every pass allocates and frees its photon maps, irradiance cache and image (tens of
//! MB). glibc's allocator handed that memory back to the OS between passes and faulted it
//! in again (a pass's photon tracing took 95–180 ms depending on what the previous pass
//! had freed; up to a quarter of the samples in `clear_page`). mimalloc, told never to
//! purge (`mi_option_purge_delay` = −1, set by [`keep_freed_memory`] first thing in
//! `main`), keeps it: the process holds its peak, which it reaches in the first pass
//! anyway.

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// `mi_option_purge_delay` in `mi_option_e`: 15 in mimalloc 2 and in mimalloc 3 (which
/// libmimalloc-sys 0.1.49 builds by default); the crate names the options around it, 14
/// `eager_commit_delay` and 16 `use_numa_nodes`, but not this one.
const MI_OPTION_PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;

/// Tells mimalloc never to return freed memory to the OS. Call first thing in `main`.
pub fn keep_freed_memory() {
    // SAFETY: sets a process-wide allocator option; mimalloc reads it at each purge.
    unsafe { libmimalloc_sys::mi_option_set(MI_OPTION_PURGE_DELAY, -1) };
}
