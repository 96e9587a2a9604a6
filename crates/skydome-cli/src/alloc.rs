//! The process's allocator: the system allocator for ordinary blocks, and on Linux whole
//! anonymous mappings backed by transparent huge pages for large ones.
//!
//! A run holds a few large buffers (decoded frames, the radiance, the preview, the encoded
//! files) that are each written once from start to end. With 4 KiB pages every first write is a
//! page fault: on the 6 MP bracket of `scripts/bench.sh` those faults were about a quarter of the
//! run's CPU time. A block of [`LARGE`] bytes or more therefore gets its own `mmap`, advised
//! `MADV_HUGEPAGE` so the kernel can back it with 2 MiB pages (when its transparent-huge-page
//! mode is `always` or `madvise`, the common defaults); it shrinks and grows with `mremap` and
//! goes back to the system with `munmap` the moment it is freed or truncated.
//!
//! Why by hand: glibc does the advice itself only when started with
//! `GLIBC_TUNABLES=glibc.malloc.hugetlb=1`, which a program cannot set for itself, and then it
//! also serves blocks up to 32 MiB from its heap once a large block has been freed, where the
//! huge pages cost 12–20 % more peak memory (measured on 9-frame brackets). mimalloc measured
//! slower here. Elsewhere than Linux this is the system allocator unchanged.

use std::alloc::{GlobalAlloc, Layout, System};

/// Blocks at least this large (bytes) get their own mapping on Linux.
#[cfg(target_os = "linux")]
const LARGE: usize = 4 << 20;

/// See the module documentation.
pub struct HugePageAlloc;

#[cfg(target_os = "linux")]
mod large {
    /// Base page size the mapping lengths are rounded to (4 KiB on x86-64 and on most arm64
    /// kernels; a larger real page size only makes the rounding conservative for `mremap`).
    const PAGE: usize = 4096;

    fn len(size: usize) -> usize {
        size.next_multiple_of(PAGE)
    }

    /// A fresh zeroed mapping of `size` bytes advised for huge pages, or null.
    pub fn map(size: usize) -> *mut u8 {
        // SAFETY: an anonymous private mapping at an address of the kernel's choosing touches
        // no existing memory.
        let p = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len(size),
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_PRIVATE | libc::MAP_ANONYMOUS,
                -1,
                0,
            )
        };
        if p == libc::MAP_FAILED {
            return std::ptr::null_mut();
        }
        advise(p.cast(), size);
        p.cast()
    }

    /// `MADV_HUGEPAGE` on `[p, p + size)`; a kernel without transparent huge pages refuses,
    /// which changes nothing.
    fn advise(p: *mut u8, size: usize) {
        // SAFETY: the range is a mapping this module made; the advice changes only how the
        // kernel backs it, never its contents.
        unsafe {
            libc::madvise(p.cast(), len(size), libc::MADV_HUGEPAGE);
        }
    }

    /// Unmaps a block from [`map`] or [`remap`] of `size` bytes.
    ///
    /// # Safety
    /// `p` and `size` describe a live block from this module.
    pub unsafe fn unmap(p: *mut u8, size: usize) {
        // SAFETY: per the caller, the range is exactly one of our mappings.
        unsafe {
            libc::munmap(p.cast(), len(size));
        }
    }

    /// Resizes a block from this module, moving it if needed; null on failure (the block is
    /// then unchanged).
    ///
    /// # Safety
    /// `p` and `old` describe a live block from this module.
    pub unsafe fn remap(p: *mut u8, old: usize, new: usize) -> *mut u8 {
        // SAFETY: per the caller, the old range is exactly one of our mappings; MAYMOVE lets
        // the kernel pick a new address instead of overwriting a neighbour.
        let q = unsafe { libc::mremap(p.cast(), len(old), len(new), libc::MREMAP_MAYMOVE) };
        if q == libc::MAP_FAILED {
            return std::ptr::null_mut();
        }
        if new > old {
            advise(q.cast(), new);
        }
        q.cast()
    }
}

#[cfg(target_os = "linux")]
impl HugePageAlloc {
    /// Whether a block of `layout` is (or would be) one of our own mappings. Mappings are
    /// page-aligned, so larger alignments stay with the system allocator.
    fn is_large(layout: &Layout) -> bool {
        layout.size() >= LARGE && layout.align() <= 4096
    }
}

// SAFETY: every block is either the system allocator's (calls forwarded unchanged) or a whole
// mapping of our own, told apart by its layout's size, which the caller passes back unchanged
// (`GlobalAlloc`'s contract); mappings are zeroed, page-aligned and at least `size` long.
#[cfg(target_os = "linux")]
unsafe impl GlobalAlloc for HugePageAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if Self::is_large(&layout) {
            return large::map(layout.size());
        }
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if Self::is_large(&layout) {
            // Fresh anonymous mappings read as zeros.
            return large::map(layout.size());
        }
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        if Self::is_large(&layout) {
            // SAFETY: a large layout means the block is one of our mappings.
            return unsafe { large::unmap(ptr, layout.size()) };
        }
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: `GlobalAlloc::realloc`'s contract makes this a valid layout.
        let new_layout = unsafe { Layout::from_size_align_unchecked(new_size, layout.align()) };
        match (Self::is_large(&layout), Self::is_large(&new_layout)) {
            // SAFETY: both are our mappings.
            (true, true) => unsafe { large::remap(ptr, layout.size(), new_size) },
            // SAFETY: both are the system allocator's.
            (false, false) => unsafe { System.realloc(ptr, layout, new_size) },
            _ => {
                // Crossing the threshold: a new block of the other kind, then a copy.
                // SAFETY: `new_layout` has a non-zero size (it was or becomes large, or is the
                // caller's), and the copy stays within both blocks.
                unsafe {
                    let q = self.alloc(new_layout);
                    if !q.is_null() {
                        std::ptr::copy_nonoverlapping(ptr, q, layout.size().min(new_size));
                        self.dealloc(ptr, layout);
                    }
                    q
                }
            }
        }
    }
}

// SAFETY: forwarded unchanged.
#[cfg(not(target_os = "linux"))]
unsafe impl GlobalAlloc for HugePageAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn large_blocks_are_zeroed_keep_their_contents_and_cross_the_threshold_both_ways() {
        let a = HugePageAlloc;
        let mb = 1 << 20;
        // SAFETY: each block is used within its size and freed with its own layout.
        unsafe {
            let big = Layout::from_size_align(9 * mb + 5, 16).unwrap();
            let p = a.alloc_zeroed(big);
            assert!(!p.is_null());
            assert!(std::slice::from_raw_parts(p, big.size())
                .iter()
                .all(|&b| b == 0));
            // Grow large → larger, shrink large → large, then large → small → large.
            for (i, b) in std::slice::from_raw_parts_mut(p, big.size())
                .iter_mut()
                .enumerate()
            {
                *b = (i % 251) as u8;
            }
            let check = |p: *mut u8, n: usize| {
                std::slice::from_raw_parts(p, n)
                    .iter()
                    .enumerate()
                    .all(|(i, &b)| b == (i % 251) as u8)
            };
            let p = a.realloc(p, big, 20 * mb);
            assert!(check(p, big.size()));
            let p = a.realloc(p, Layout::from_size_align(20 * mb, 16).unwrap(), 5 * mb);
            assert!(check(p, 5 * mb));
            let p = a.realloc(p, Layout::from_size_align(5 * mb, 16).unwrap(), 1000);
            assert!(check(p, 1000));
            let p = a.realloc(p, Layout::from_size_align(1000, 16).unwrap(), 6 * mb);
            assert!(check(p, 1000));
            a.dealloc(p, Layout::from_size_align(6 * mb, 16).unwrap());
            // An alignment beyond a page stays with the system allocator.
            let odd = Layout::from_size_align(8 * mb, 1 << 16).unwrap();
            let q = a.alloc(odd);
            assert_eq!(q as usize % (1 << 16), 0);
            a.dealloc(q, odd);
        }
    }

    #[test]
    fn vectors_grow_and_shrink_through_the_large_path() {
        // The process allocator of this test binary is `HugePageAlloc` (see `main.rs`).
        let mut v: Vec<u32> = Vec::new();
        for i in 0..3_000_000u32 {
            v.push(i);
        }
        v.truncate(1_500_000);
        v.shrink_to_fit();
        assert!(v.iter().enumerate().all(|(i, &x)| x == i as u32));
        v.truncate(10);
        v.shrink_to_fit();
        assert_eq!(v, (0..10).collect::<Vec<_>>());
    }
}
