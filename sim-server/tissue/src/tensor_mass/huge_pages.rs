//! Buffers the hot step streams, backed by transparent huge pages where the
//! kernel offers them.
//!
//! A 1M-tetrahedron step streams about 70 MB: with 4 KiB pages that is some
//! 18,000 TLB misses per step and, worse, the hardware prefetchers stop at
//! every 4 KiB page boundary. On Linux in the default `madvise` THP mode a
//! buffer is only backed by 2 MiB pages if it asks, before its pages are
//! first touched: these helpers reserve the capacity, ask (`MADV_HUGEPAGE`),
//! then fill. Elsewhere, or when THP is off, the advice is a no-op and the
//! buffers are plain vectors.

/// Below this a buffer cannot hold a whole aligned huge page worth asking for.
const MIN_BYTES: usize = 4 << 20;
/// The x86-64 and aarch64 (4 KiB base) huge page size.
const HUGE_PAGE_BYTES: usize = 2 << 20;

/// Collects `items` (at most `len` of them) into a vector whose storage was
/// advised for huge pages before it was written.
pub fn collect_huge<T>(len: usize, items: impl IntoIterator<Item = T>) -> Vec<T> {
    let mut v = Vec::with_capacity(len);
    advise(v.as_ptr() as usize, len * std::mem::size_of::<T>());
    v.extend(items);
    v
}

/// `len` copies of `value`, in storage advised for huge pages.
pub fn huge_vec<T: Clone>(len: usize, value: T) -> Vec<T> {
    collect_huge(len, std::iter::repeat_n(value, len))
}

/// Asks for huge pages on the 2 MiB-aligned interior of `[addr, addr + bytes)`.
/// Advice only: failure (THP compiled out or disabled) changes nothing.
fn advise(addr: usize, bytes: usize) {
    if bytes < MIN_BYTES {
        return;
    }
    let start = addr.next_multiple_of(HUGE_PAGE_BYTES);
    let end = (addr + bytes) / HUGE_PAGE_BYTES * HUGE_PAGE_BYTES;
    if end <= start {
        return;
    }
    #[cfg(target_os = "linux")]
    // SAFETY: the range lies inside one live allocation of ours (a vector's
    // reserved capacity); MADV_HUGEPAGE changes only how its pages are
    // backed, never their contents or validity.
    unsafe {
        libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn huge_buffers_hold_what_was_asked() {
        let big = huge_vec(3 << 20, 7u32);
        assert_eq!(big.len(), 3 << 20);
        assert!(big.iter().all(|&x| x == 7));
        let small = collect_huge(5, (0..5u8).map(|x| x * 2));
        assert_eq!(small, vec![0, 2, 4, 6, 8]);
        let short = collect_huge(10, 0..3u64);
        assert_eq!(short, vec![0, 1, 2]);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_large_buffer_is_advised_for_huge_pages() {
        // The advice is visible in smaps as the `hg` VmFlag of the mapping
        // holding the buffer, whatever the system's THP mode (a kernel built
        // without THP has no such directory and refuses the advice).
        if !std::path::Path::new("/sys/kernel/mm/transparent_hugepage").exists() {
            return;
        }
        let big = huge_vec(16 << 20, 1u8);
        let addr = big.as_ptr() as usize + (8 << 20);
        let smaps = std::fs::read_to_string("/proc/self/smaps").expect("smaps");
        let mut inside = false;
        let mut flags = None;
        for line in smaps.lines() {
            if let Some((range, _)) = line.split_once(' ')
                && let Some((a, b)) = range.split_once('-')
                && let (Ok(a), Ok(b)) = (usize::from_str_radix(a, 16), usize::from_str_radix(b, 16))
            {
                inside = a <= addr && addr < b;
            } else if inside && let Some(f) = line.strip_prefix("VmFlags:") {
                flags = Some(f.to_string());
            }
        }
        let flags = flags.expect("the buffer's mapping is in smaps");
        assert!(
            flags.split_whitespace().any(|f| f == "hg"),
            "VmFlags: {flags}"
        );
    }
}
