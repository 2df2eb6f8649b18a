//! Large read-mostly arrays (BVH nodes, triangle blocks) in memory that
//! the kernel is asked to back with transparent huge pages.
//!
//! A random ray touches a few nodes and triangle blocks scattered over tens
//! of megabytes; with 4 KiB pages nearly every one of those loads also
//! misses the TLB. Embree's allocator asks Linux for huge pages
//! (`madvise(MADV_HUGEPAGE)`) for its BVH for this reason. [`HugeArray`] does
//! the same through an anonymous `memmap2` mapping viewed as `[T]` by
//! `bytemuck` (no `unsafe` here). Small arrays, other systems, and any
//! mapping or advice that fails fall back to an ordinary `Vec`: huge pages
//! only change speed, never results.

use bytemuck::Pod;
use rayon::prelude::*;
use std::fmt;
use std::ops::{Deref, DerefMut};

/// Below this many bytes an array stays on the heap: a huge page is 2 MiB.
const MIN_BYTES: usize = 4 << 20;

/// A fixed-length array of `T`, zero-initialised, in huge-page-advised
/// memory when it is large enough (see the module documentation).
pub struct HugeArray<T: Pod> {
    store: Store<T>,
    len: usize,
}

enum Store<T> {
    Heap(Vec<T>),
    Mapped(memmap2::MmapMut),
}

impl<T: Pod> HugeArray<T> {
    /// `len` zeroed values.
    pub fn zeroed(len: usize) -> Self {
        let bytes = len.saturating_mul(size_of::<T>());
        let store = if bytes >= MIN_BYTES && size_of::<T>() > 0 {
            map(bytes).map_or_else(|| Store::Heap(vec![T::zeroed(); len]), Store::Mapped)
        } else {
            Store::Heap(vec![T::zeroed(); len])
        };
        Self { store, len }
    }

    /// A copy of `data` (copied in parallel when it is large).
    pub fn from_slice(data: &[T]) -> Self
    where
        T: Send + Sync,
    {
        let mut a = Self::zeroed(data.len());
        const CHUNK: usize = 1 << 16;
        if data.len() > CHUNK {
            a.par_chunks_mut(CHUNK)
                .zip(data.par_chunks(CHUNK))
                .for_each(|(d, s)| d.copy_from_slice(s));
        } else {
            a.copy_from_slice(data);
        }
        a
    }

    /// Whether the array lives in a huge-page-advised mapping.
    pub fn is_mapped(&self) -> bool {
        matches!(self.store, Store::Mapped(_))
    }
}

/// An anonymous mapping of `bytes` advised for huge pages, or `None`.
#[cfg(target_os = "linux")]
fn map(bytes: usize) -> Option<memmap2::MmapMut> {
    let m = memmap2::MmapOptions::new().len(bytes).map_anon().ok()?;
    // Advice is a hint: a kernel without THP refuses it and the mapping
    // still works with ordinary pages.
    let _ = m.advise(memmap2::Advice::HugePage);
    Some(m)
}

#[cfg(not(target_os = "linux"))]
fn map(_bytes: usize) -> Option<memmap2::MmapMut> {
    None
}

impl<T: Pod> Deref for HugeArray<T> {
    type Target = [T];

    #[inline]
    fn deref(&self) -> &[T] {
        match &self.store {
            Store::Heap(v) => v,
            Store::Mapped(m) => &bytemuck::cast_slice(&m[..])[..self.len],
        }
    }
}

impl<T: Pod> DerefMut for HugeArray<T> {
    #[inline]
    fn deref_mut(&mut self) -> &mut [T] {
        match &mut self.store {
            Store::Heap(v) => v,
            Store::Mapped(m) => &mut bytemuck::cast_slice_mut(&mut m[..])[..self.len],
        }
    }
}

impl<T: Pod + Send + Sync> Clone for HugeArray<T> {
    fn clone(&self) -> Self {
        Self::from_slice(self)
    }
}

impl<T: Pod> Default for HugeArray<T> {
    fn default() -> Self {
        Self {
            store: Store::Heap(Vec::new()),
            len: 0,
        }
    }
}

impl<T: Pod + fmt::Debug> fmt::Debug for HugeArray<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("HugeArray")
            .field("len", &self.len)
            .field("mapped", &self.is_mapped())
            .finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_arrays_stay_on_the_heap_and_large_ones_map() {
        let small = HugeArray::<u32>::zeroed(10);
        assert!(!small.is_mapped());
        assert_eq!(&small[..], &[0u32; 10]);
        let n = MIN_BYTES / 4 + 3;
        let mut big = HugeArray::<u32>::zeroed(n);
        assert_eq!(big.len(), n);
        assert!(big.iter().all(|&x| x == 0));
        big[n - 1] = 7;
        big[0] = 5;
        let copy = big.clone();
        assert_eq!(copy.len(), n);
        assert_eq!((copy[0], copy[n - 1]), (5, 7));
        #[cfg(target_os = "linux")]
        assert!(big.is_mapped());
    }

    #[test]
    fn empty_and_default_arrays_are_empty() {
        assert!(HugeArray::<f32>::default().is_empty());
        assert!(HugeArray::<f32>::zeroed(0).is_empty());
        assert!(HugeArray::<f32>::from_slice(&[]).is_empty());
    }
}
