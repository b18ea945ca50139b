//! Transparent huge pages for the large arrays a ray walks (tree nodes, triangle packs,
//! shading records).
//!
//! At 10⁶ triangles these arrays hold about 150 MB, and a ray visits them at scattered
//! addresses: with 4 KiB pages nearly every node, pack or record load also misses the TLB and
//! waits on a page-table walk. Backed by 2 MiB pages, all of them fit in about 75 TLB entries.
//! Linux madvise(2) (man-pages 6.x): `MADV_HUGEPAGE` marks a range for transparent huge pages
//! (needed when `/sys/kernel/mm/transparent_hugepage/enabled` is `madvise`), and
//! `MADV_COLLAPSE` (Linux ≥ 6.1) moves the pages already written there into huge pages
//! synchronously (a copy in the kernel, which at 10⁶ triangles took about 0.8 s of system time,
//! so the arrays are advised before they are written and collapsed only where that failed). Both are advice: where the kernel declines (an older kernel, THP
//! disabled, no free huge page) nothing changes, and the bytes are the same either way, so
//! results never depend on it.

/// Bytes in a huge page (x86-64 and the usual aarch64 configuration).
const HUGE_PAGE_BYTES: usize = 2 << 20;

/// Arrays smaller than this are left alone (they span at most one whole huge page).
const MIN_BYTES: usize = 2 * HUGE_PAGE_BYTES;

/// The whole huge pages inside the `bytes` bytes at address `addr`: (first, end) addresses,
/// both multiples of [`HUGE_PAGE_BYTES`]; None when the range is too small to hold one.
fn whole_huge_pages(addr: usize, bytes: usize) -> Option<(usize, usize)> {
    if bytes < MIN_BYTES {
        return None;
    }
    let first = addr.checked_next_multiple_of(HUGE_PAGE_BYTES)?;
    let end = addr.checked_add(bytes)? / HUGE_PAGE_BYTES * HUGE_PAGE_BYTES;
    (end > first).then_some((first, end))
}

/// `MADV_HUGEPAGE`: pages first written after this come as huge pages where whole ones fit.
const MADV_HUGEPAGE: i32 = 14;
/// `MADV_COLLAPSE`: the pages already written are moved into huge pages now (a copy).
const MADV_COLLAPSE: i32 = 25;

/// madvise(2) on the whole huge pages inside the `bytes` bytes at `addr` (a no-op off Linux,
/// for small ranges, and wherever the kernel declines).
fn advise_range(addr: usize, bytes: usize, advice: i32) {
    let Some((first, end)) = whole_huge_pages(addr, bytes) else {
        return;
    };
    #[cfg(target_os = "linux")]
    {
        // (the advice values are those of <asm-generic/mman-common.h>, the same on every
        // Linux architecture)
        extern "C" {
            fn madvise(addr: *mut std::ffi::c_void, len: usize, advice: i32) -> i32;
        }
        // SAFETY: [first, end) lies inside one live allocation; these advices change how its
        // pages are backed, never their contents (the return value is ignored: the advice is
        // optional)
        unsafe {
            madvise(first as *mut std::ffi::c_void, end - first, advice);
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = (first, end, advice);
}

/// An empty vector with room for `n` elements whose memory is advised for huge pages before
/// anything is written to it (so the page faults that fill it take huge pages, without the
/// copy `MADV_COLLAPSE` makes); call [`finish`] after filling it.
pub(crate) fn with_capacity<T>(n: usize) -> Vec<T> {
    let v = Vec::<T>::with_capacity(n);
    advise_range(
        v.as_ptr() as usize,
        v.capacity() * std::mem::size_of::<T>(),
        MADV_HUGEPAGE,
    );
    v
}

/// After filling a vector of [`with_capacity`]: collapse whatever still sits in small pages
/// (memory the allocator had already used before, which took no fault; free where the faults
/// already took huge pages).
pub(crate) fn finish<T>(v: &[T]) {
    advise_range(v.as_ptr() as usize, std::mem::size_of_val(v), MADV_COLLAPSE);
}

/// `v` copied into huge pages (the arrays the tree builders grow by pushing).
pub(crate) fn copy<T: Copy>(v: &[T]) -> Vec<T> {
    let mut h = with_capacity(v.len());
    h.extend_from_slice(v);
    finish(&h);
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_whole_huge_pages_inside_the_range_are_advised() {
        const H: usize = HUGE_PAGE_BYTES;
        // aligned start: every whole page, not the partial one at the end
        assert_eq!(whole_huge_pages(4 * H, 3 * H + 100), Some((4 * H, 7 * H)));
        // unaligned start: from the next boundary
        assert_eq!(whole_huge_pages(4 * H + 64, 3 * H), Some((5 * H, 7 * H)));
        // exactly aligned end
        assert_eq!(
            whole_huge_pages(4 * H + 64, 3 * H - 64),
            Some((5 * H, 7 * H))
        );
        // small arrays and ranges without a whole page
        assert_eq!(whole_huge_pages(4 * H, H), None);
        assert_eq!(whole_huge_pages(4 * H + 1, 2 * H - 2), None);
        // no overflow at the top of the address space
        assert_eq!(whole_huge_pages(usize::MAX - H, 2 * H), None);
    }

    #[test]
    fn advice_keeps_the_contents() {
        let v: Vec<u64> = (0..(3 * HUGE_PAGE_BYTES / 8) as u64)
            .map(|i| i * 7 + 3)
            .collect();
        let h = copy(&v);
        finish(&v);
        assert_eq!(h, v);
        assert!(v.iter().enumerate().all(|(i, &x)| x == i as u64 * 7 + 3));
    }
}
