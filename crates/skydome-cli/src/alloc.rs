//! The process's allocator: the system allocator, asking Linux for transparent huge pages on
//! large blocks.
//!
//! A run holds a few large buffers (decoded frames, the radiance, the preview) that are each
//! written once from start to end. With 4 KiB pages every first write is a page fault: on the
//! 6 MP bracket of `scripts/bench.sh` those faults cost about a quarter of the run's CPU time.
//! `madvise(MADV_HUGEPAGE)` on a fresh large block lets the kernel back it with 2 MiB pages
//! (when its transparent-huge-page mode is `always` or `madvise`, the common defaults), which
//! measured 0.46 → 0.37 s for `skydome merge --preview` and 0.25 → 0.17 s for `skydome tonemap`.
//! glibc does the same when started with `GLIBC_TUNABLES=glibc.malloc.hugetlb=1`, but a program
//! cannot set that for itself, and no allocator crate measured as well (mimalloc: 0.43 s and
//! 0.20 s, more CPU time), hence this small wrapper. Elsewhere than Linux it is the system
//! allocator unchanged.

use std::alloc::{GlobalAlloc, Layout, System};

/// Blocks at least this large (bytes) are advised.
#[cfg(target_os = "linux")]
const HUGE_FROM: usize = 4 << 20;
/// The huge page size the advice is aligned to (x86-64 and arm64 with 4 KiB base pages).
#[cfg(target_os = "linux")]
const HUGE_PAGE: usize = 2 << 20;

/// [`System`], advising huge pages for blocks of [`HUGE_FROM`] bytes or more.
pub struct HugePageAlloc;

/// Advises transparent huge pages for the whole 2 MiB pages inside `[p, p + size)`.
#[cfg(target_os = "linux")]
fn advise(p: *mut u8, size: usize) {
    if p.is_null() || size < HUGE_FROM {
        return;
    }
    let start = (p as usize).next_multiple_of(HUGE_PAGE);
    let end = (p as usize + size) / HUGE_PAGE * HUGE_PAGE;
    if end > start {
        // SAFETY: the range lies inside a block the allocator just handed out, and
        // MADV_HUGEPAGE changes only how the kernel backs it, never its contents. A failure
        // (e.g. a kernel without transparent huge pages) leaves the block as it was.
        unsafe {
            libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE);
        }
    }
}

#[cfg(not(target_os = "linux"))]
fn advise(_: *mut u8, _: usize) {}

// SAFETY: every call is forwarded to `System` unchanged; `advise` only adds a hint.
unsafe impl GlobalAlloc for HugePageAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded with the caller's guarantees.
        let p = unsafe { System.alloc(layout) };
        advise(p, layout.size());
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded with the caller's guarantees.
        let p = unsafe { System.alloc_zeroed(layout) };
        advise(p, layout.size());
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: forwarded with the caller's guarantees.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if new_size > layout.size() {
            advise(p, new_size);
        }
        p
    }
}
