//! Memory that the kernel is asked to back with 2 MiB pages: read-only arrays for the BVH,
//! and advice for large fresh outputs.
//!
//! Incoherent rays touch the nodes and triangle blocks of a BVH all over its few megabytes:
//! with 4 KiB pages nearly every step needs a TLB entry that is not in the first-level TLB,
//! and a miss there costs a page walk, a two-dimensional one under a hypervisor. A handful of
//! 2 MiB pages cover the whole structure. Linux backs an anonymous range with such pages when
//! it is 2 MiB aligned and advised `MADV_HUGEPAGE` before it is first touched (transparent
//! huge pages, in their default `madvise` mode). Measured with 1M incoherent rays on the
//! bunny's BVH (6 MiB in huge pages): 2-6% less time per process in paired runs
//! (docs/benchmarks.md). Elsewhere, or when the kernel declines, the array is an ordinary
//! aligned allocation.

use std::alloc::Layout;
use std::fmt;
use std::ops::Deref;
use std::ptr::NonNull;

/// Arrays smaller than this are allocated as usual: rounding them up to a huge page would
/// waste more memory than their few TLB entries cost.
const MIN_BYTES: usize = 1 << 20;
const HUGE_PAGE: usize = 2 << 20;

/// A fixed array of `T`, built once from a slice, read as a slice.
pub struct HugePageArray<T: Copy> {
    ptr: NonNull<T>,
    len: usize,
    /// The allocation's layout; `None` for an empty array, which allocates nothing.
    layout: Option<Layout>,
}

// SAFETY: the array owns its elements and hands out only shared references to them.
unsafe impl<T: Copy + Send> Send for HugePageArray<T> {}
// SAFETY: as above; there is no interior mutability.
unsafe impl<T: Copy + Sync> Sync for HugePageArray<T> {}

impl<T: Copy> HugePageArray<T> {
    pub fn from_slice(items: &[T]) -> HugePageArray<T> {
        let bytes = std::mem::size_of_val(items);
        if bytes == 0 {
            return HugePageArray {
                ptr: NonNull::dangling(),
                len: items.len(),
                layout: None,
            };
        }
        let huge = bytes >= MIN_BYTES;
        let (size, align) = if huge {
            (bytes.next_multiple_of(HUGE_PAGE), HUGE_PAGE)
        } else {
            (bytes, std::mem::align_of::<T>())
        };
        let layout = Layout::from_size_align(size, align).expect("a slice's size fits a layout");
        // SAFETY: `layout` has a non-zero size.
        let raw = unsafe { std::alloc::alloc(layout) };
        let Some(ptr) = NonNull::new(raw as *mut T) else {
            std::alloc::handle_alloc_error(layout)
        };
        if huge {
            advise_huge_pages(raw, size);
        }
        // SAFETY: the allocation holds `size >= bytes` bytes, aligned for `T`, and does not
        // overlap `items`. The copy is the first touch of its pages, after the advice.
        unsafe { std::ptr::copy_nonoverlapping(items.as_ptr(), ptr.as_ptr(), items.len()) };
        HugePageArray {
            ptr,
            len: items.len(),
            layout: Some(layout),
        }
    }
}

/// Asks for huge pages on the 2 MiB-aligned part of `v` not yet touched (a fresh `vec![0; n]`
/// is: the allocator maps it zeroed and leaves it alone). Large outputs are then faulted in
/// 512 times less often: a page fault costs more than clearing its page.
pub fn advise_huge_pages_within<T>(v: &mut [T]) {
    let start = (v.as_mut_ptr() as usize).next_multiple_of(HUGE_PAGE);
    let end = (v.as_mut_ptr() as usize + std::mem::size_of_val(v)) & !(HUGE_PAGE - 1);
    if end > start {
        advise_huge_pages(start as *mut u8, end - start);
    }
}

/// Asks for huge pages on `[at, at + len)`; only a hint, so a refusal changes nothing but speed.
#[cfg(target_os = "linux")]
fn advise_huge_pages(at: *mut u8, len: usize) {
    // SAFETY: the range is one live allocation of ours; MADV_HUGEPAGE changes how it is backed,
    // never its contents.
    unsafe { libc::madvise(at as *mut libc::c_void, len, libc::MADV_HUGEPAGE) };
}

#[cfg(not(target_os = "linux"))]
fn advise_huge_pages(_at: *mut u8, _len: usize) {}

impl<T: Copy> Deref for HugePageArray<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        // SAFETY: `ptr` holds `len` initialised elements (or is dangling with `len * size == 0`).
        unsafe { std::slice::from_raw_parts(self.ptr.as_ptr(), self.len) }
    }
}

impl<T: Copy> Drop for HugePageArray<T> {
    fn drop(&mut self) {
        if let Some(layout) = self.layout {
            // SAFETY: allocated in `from_slice` with this layout.
            unsafe { std::alloc::dealloc(self.ptr.as_ptr() as *mut u8, layout) };
        }
    }
}

impl<T: Copy> Clone for HugePageArray<T> {
    fn clone(&self) -> Self {
        HugePageArray::from_slice(self)
    }
}

impl<T: Copy + fmt::Debug> fmt::Debug for HugePageArray<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Advising a fresh vector (empty, smaller than a huge page, or spanning several) keeps
    /// it zeroed and writable to its ends.
    #[test]
    fn advised_vectors_stay_zeroed_and_writable() {
        for n in [0usize, 10, (5 << 20) / 4 + 3] {
            let mut v = vec![0u32; n];
            advise_huge_pages_within(&mut v);
            assert!(v.iter().all(|&x| x == 0), "n = {n}: zeroed");
            for (i, x) in v.iter_mut().enumerate() {
                *x = i as u32;
            }
            assert!(v.iter().enumerate().all(|(i, &x)| x == i as u32), "n = {n}: written");
        }
    }

    /// The array reads back what it was built from, at every size class: empty, small, and
    /// huge-page backed (with a tail that does not fill its last page); clones too.
    #[test]
    fn holds_its_elements() {
        for n in [0usize, 1, 1000, (3 << 20) / 12 + 7] {
            let items: Vec<[u32; 3]> = (0..n as u32).map(|i| [i, i ^ 0x5555, i.wrapping_mul(7)]).collect();
            let a = HugePageArray::from_slice(&items);
            assert_eq!(&a[..], &items[..], "n = {n}");
            let b = a.clone();
            drop(a);
            assert_eq!(&b[..], &items[..], "n = {n}, clone");
            if std::mem::size_of_val(&items[..]) >= MIN_BYTES {
                assert_eq!(b.as_ptr() as usize % HUGE_PAGE, 0, "n = {n}: huge-page aligned");
            }
        }
    }
}
