//! The tracker's ring of the last frames, shared by the block pass
//! ([`crate::tracker`]) and the live watch ([`crate::live`]), which both read
//! rows of recent frames from it.

use crate::sample::Sample;

/// The last `slots` frames, frame `j` in slot `j % slots`.
///
/// Slots are `stride ≥ frame_len` samples apart: whole 4 KiB pages plus
/// [`SLOT_SKEW`] bytes. Slots a whole number of pages apart (a 1024×768 frame
/// of either type) put the same pixel of every frame at one offset in its
/// page, so the block pass, which reads a few dozen frames at one pixel,
/// evicts its own lines from the first-level cache (whose set is chosen by
/// that offset). Measured on the frog-sized capture (one thread): per frame,
/// 1.35 → 1.1 ms of CPU plain and 3.4 → 2.8 ms normalised with second dips;
/// 1920×1080 `u8`, already a quarter page apart, unchanged. (A skew of one
/// cache line, 512 or 1536 bytes measured slower than a quarter page.)
///
/// Invariants:
/// * `slots ≥ 1` (the tracker's `3W + 2m`) and `samples.len() = stride · slots`;
/// * `frame_len = height · width ≤ stride`, and a slot's `stride · size_of::<T>()` bytes are
///   whole pages plus [`SLOT_SKEW`] (the sample size, 1 or 2 bytes, divides both);
/// * slot `j % slots` holds frame `j` once it is stored, until frame `j + slots` overwrites
///   it; a slot never written holds `T::MIN`. The ring does not know which frames it holds:
///   its owner counts the frames stored and reads only the last `slots` of them
///   ([`row`](Self::row) of an older frame gives the newer frame in its slot).
#[derive(Debug, Clone)]
pub(crate) struct FrameRing<T> {
    samples: Vec<T>,
    width: usize,
    frame_len: usize,
    stride: usize,
    slots: usize,
}

/// Ask Linux to back `samples` (freshly allocated, not yet touched) with huge
/// pages where it can: the ring is written frame by frame, and faulting it in
/// by 4 KiB pages cost about as much CPU as the normalised store itself
/// (a hint: nothing changes if it is refused; no effect elsewhere).
fn advise_huge_pages<T>(samples: &[T]) {
    #[cfg(target_os = "linux")]
    {
        let start = samples.as_ptr() as usize;
        let end = start + std::mem::size_of_val(samples);
        let (first, last) = (start.div_ceil(PAGE) * PAGE, end / PAGE * PAGE);
        if last > first {
            // SAFETY: madvise only hints how the pages of this allocation (whole pages
            // within it) are backed; it does not change their contents or validity.
            unsafe {
                libc::madvise(
                    first as *mut libc::c_void,
                    last - first,
                    libc::MADV_HUGEPAGE,
                );
            }
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = samples;
}

/// Bytes of a memory page, and how many more than whole pages a ring slot
/// takes ([`FrameRing`]).
const PAGE: usize = 4096;
const SLOT_SKEW: usize = 1024;

impl<T: Sample> FrameRing<T> {
    /// An empty ring of `slots ≥ 1` frames of `height × width` samples.
    pub(crate) fn new(height: usize, width: usize, slots: usize) -> Self {
        debug_assert!(slots >= 1, "a ring of no slots");
        let frame_len = height * width;
        let size = std::mem::size_of::<T>();
        // whole 4 KiB pages, plus a quarter page
        let stride = ((frame_len * size).div_ceil(PAGE) * PAGE + SLOT_SKEW) / size;
        let samples = vec![T::MIN; stride * slots];
        advise_huge_pages(&samples);
        FrameRing {
            samples,
            width,
            frame_len,
            stride,
            slots,
        }
    }

    /// The slot of frame `index` (overwriting frame `index − slots`).
    pub(crate) fn slot_mut(&mut self, index: usize) -> &mut [T] {
        let start = (index % self.slots) * self.stride;
        &mut self.samples[start..start + self.frame_len]
    }

    /// How many frames the ring holds.
    pub(crate) fn slots(&self) -> usize {
        self.slots
    }

    /// Row `row < height` of the frame in `frame`'s slot (frame `frame` while it is among
    /// the last `slots` stored).
    #[inline(always)]
    pub(crate) fn row(&self, frame: usize, row: usize) -> &[T] {
        let start = (frame % self.slots) * self.stride + row * self.width;
        &self.samples[start..start + self.width]
    }
}
