//! Explicit SIMD vectors of samples for the tracker's hot loops, and the
//! choice of instruction set at run time.
//!
//! The kernel is built for the baseline of its target (SSE2 on x86-64, NEON
//! on aarch64): no `target-cpu` flag, so one build runs everywhere. The hot
//! loops are written once, generic over [`Vector`], and instantiated per
//! instruction set:
//!
//! * [`SimdPath::Avx2`]: 256-bit vectors, compiled inside
//!   `#[target_feature(enable = "avx2")]` entry points and chosen at run time
//!   when the CPU has AVX2 (`is_x86_feature_detected!`);
//! * [`SimdPath::Sse2`]: 128-bit vectors, the x86-64 baseline;
//! * [`SimdPath::Portable`]: 16-lane arrays folded lane by lane, which the
//!   compiler vectorises for the target's baseline (NEON on aarch64).
//!
//! Every path computes exactly the same integers (only saturating
//! subtraction, max/min, comparisons and selects), so results do not depend
//! on the path; the tests check it.
//!
//! The path is detected once; the environment variable `GNOMON_SIMD`
//! (`avx2`, `sse2`, `portable`) forces a lower one, for benchmarks and tests.
//!
//! The vectors are generic over [`Lane`], the scalar arithmetic they fold
//! (defined here); [`crate::sample::Sample`] builds on it and names each
//! sample type's vectors, so this module depends on no other of the crate.

use std::sync::OnceLock;

/// An instruction set the tracker's hot loops can run on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum SimdPath {
    /// Lane-by-lane loops left to the compiler's auto-vectoriser (baseline of the target).
    Portable,
    /// 128-bit SSE2 intrinsics (x86-64 baseline).
    Sse2,
    /// 256-bit AVX2 intrinsics (x86-64, detected at run time).
    Avx2,
}

impl SimdPath {
    /// Lower-case name: `"avx2"`, `"sse2"` or `"portable"`.
    pub fn name(self) -> &'static str {
        match self {
            SimdPath::Portable => "portable",
            SimdPath::Sse2 => "sse2",
            SimdPath::Avx2 => "avx2",
        }
    }

    /// The path named `name` (as [`name`](Self::name)), if any.
    pub fn from_name(name: &str) -> Option<Self> {
        match name.trim().to_ascii_lowercase().as_str() {
            "portable" => Some(SimdPath::Portable),
            "sse2" => Some(SimdPath::Sse2),
            "avx2" => Some(SimdPath::Avx2),
            _ => None,
        }
    }

    /// Whether this CPU can run the path.
    pub fn is_supported(self) -> bool {
        match self {
            SimdPath::Portable => true,
            #[cfg(target_arch = "x86_64")]
            SimdPath::Sse2 => true,
            #[cfg(target_arch = "x86_64")]
            SimdPath::Avx2 => std::is_x86_feature_detected!("avx2"),
            #[cfg(not(target_arch = "x86_64"))]
            _ => false,
        }
    }

    /// The best path this CPU supports.
    pub fn detect() -> Self {
        [SimdPath::Avx2, SimdPath::Sse2]
            .into_iter()
            .find(|p| p.is_supported())
            .unwrap_or(SimdPath::Portable)
    }

    /// Every path this CPU supports, best first.
    pub fn supported() -> Vec<Self> {
        [SimdPath::Avx2, SimdPath::Sse2, SimdPath::Portable]
            .into_iter()
            .filter(|p| p.is_supported())
            .collect()
    }

    /// The path new trackers use: [`detect`](Self::detect)ed once, lowered by
    /// `GNOMON_SIMD` when that names a supported path no better than it
    /// (an unknown or unsupported name is ignored).
    pub fn active() -> Self {
        static ACTIVE: OnceLock<SimdPath> = OnceLock::new();
        *ACTIVE.get_or_init(|| {
            let best = Self::detect();
            std::env::var("GNOMON_SIMD")
                .ok()
                .and_then(|name| Self::from_name(&name))
                .filter(|p| p.is_supported() && *p <= best)
                .unwrap_or(best)
        })
    }
}

mod sealed {
    pub trait Sealed {}
    impl Sealed for u8 {}
    impl Sealed for u16 {}
}

/// The scalar in each lane of a [`Vector`]: an unsigned integer with
/// saturating arithmetic, `u8` or `u16` (sealed). [`crate::sample::Sample`]
/// is a `Lane` with what the tracker needs besides.
///
/// Invariants the masks rely on: `MIN` is 0 (no bit set) and `MAX` has every
/// bit set, so that a mask's lane (all ones or zero) is `MAX` or `MIN`, and
/// [`Portable`]'s lane-by-lane masks equal the intrinsics' bitwise ones.
pub trait Lane: Copy + Ord + Send + Sync + 'static + sealed::Sealed {
    /// The darkest and brightest representable values.
    const MIN: Self;
    const MAX: Self;
    /// `self − other`, or 0 if negative.
    fn saturating_sub(self, other: Self) -> Self;
    /// `self + other`, or `MAX` if larger.
    fn saturating_add(self, other: Self) -> Self;
}

/// The two lane types differ only in width: one implementation for both.
macro_rules! impl_lane {
    ($($t:ty),+) => {$(
        impl Lane for $t {
            const MIN: Self = <$t>::MIN;
            const MAX: Self = <$t>::MAX;
            #[inline(always)]
            fn saturating_sub(self, other: Self) -> Self {
                <$t>::saturating_sub(self, other)
            }
            #[inline(always)]
            fn saturating_add(self, other: Self) -> Self {
                <$t>::saturating_add(self, other)
            }
        }
    )+};
}

impl_lane!(u8, u16);

/// A vector of `LANES` samples. Comparisons return masks: all bits set in
/// the lanes where they hold, zero elsewhere.
///
/// # Safety
/// Implementations for an instruction set may only be used on a CPU that has
/// it (see [`SimdPath::is_supported`]); the loads and stores read and write
/// `LANES` samples from the pointer.
pub trait Vector<T: Lane>: Copy {
    const LANES: usize;
    /// `LANES` samples from `ptr` (no alignment needed).
    ///
    /// # Safety
    /// `ptr` must point to `LANES` readable samples.
    unsafe fn load(ptr: *const T) -> Self;
    /// Store `LANES` samples at `ptr` (no alignment needed).
    ///
    /// # Safety
    /// `ptr` must point to `LANES` writable samples.
    unsafe fn store(self, ptr: *mut T);
    fn splat(v: T) -> Self;
    fn max(self, o: Self) -> Self;
    fn min(self, o: Self) -> Self;
    /// `max(self − o, 0)` lane by lane.
    fn sub_sat(self, o: Self) -> Self;
    /// `min(self + o, MAX)` lane by lane.
    fn add_sat(self, o: Self) -> Self;
    /// Mask of `self > o` (unsigned).
    fn gt(self, o: Self) -> Self;
    /// Mask of `self ≤ o` (unsigned): one operation fewer than [`gt`](Self::gt) on x86.
    fn le(self, o: Self) -> Self;
    /// `if mask { a } else { b }` lane by lane (mask lanes all-ones or zero).
    fn select(mask: Self, a: Self, b: Self) -> Self;
    /// Mask of `self != o`.
    fn ne(self, o: Self) -> Self;
    /// Bitwise or (of masks).
    fn or(self, o: Self) -> Self;
    /// Bitwise and (of masks).
    fn and(self, o: Self) -> Self;
    /// Whether any bit is set.
    fn any(self) -> bool;
}

/// `LANES` samples in an array, folded lane by lane: left to the
/// auto-vectoriser of the target's baseline.
#[derive(Clone, Copy)]
pub struct Portable<T, const N: usize>([T; N]);

impl<T: Lane, const N: usize> Portable<T, N> {
    #[inline(always)]
    fn map2(self, o: Self, f: impl Fn(T, T) -> T) -> Self {
        let mut out = self.0;
        for (r, &b) in out.iter_mut().zip(&o.0) {
            *r = f(*r, b);
        }
        Portable(out)
    }
}

impl<T: Lane, const N: usize> Vector<T> for Portable<T, N> {
    const LANES: usize = N;
    #[inline(always)]
    unsafe fn load(ptr: *const T) -> Self {
        // SAFETY: the caller guarantees N readable samples at ptr.
        Portable(unsafe { std::ptr::read_unaligned(ptr.cast::<[T; N]>()) })
    }
    #[inline(always)]
    unsafe fn store(self, ptr: *mut T) {
        // SAFETY: the caller guarantees N writable samples at ptr.
        unsafe { std::ptr::write_unaligned(ptr.cast::<[T; N]>(), self.0) }
    }
    #[inline(always)]
    fn splat(v: T) -> Self {
        Portable([v; N])
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        self.map2(o, |a, b| a.max(b))
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        self.map2(o, |a, b| a.min(b))
    }
    #[inline(always)]
    fn sub_sat(self, o: Self) -> Self {
        self.map2(o, |a, b| a.saturating_sub(b))
    }
    #[inline(always)]
    fn add_sat(self, o: Self) -> Self {
        self.map2(o, |a, b| a.saturating_add(b))
    }
    #[inline(always)]
    fn gt(self, o: Self) -> Self {
        self.map2(o, |a, b| if a > b { T::MAX } else { T::MIN })
    }
    #[inline(always)]
    fn le(self, o: Self) -> Self {
        self.map2(o, |a, b| if a <= b { T::MAX } else { T::MIN })
    }
    #[inline(always)]
    fn and(self, o: Self) -> Self {
        self.map2(o, |a, b| {
            if a != T::MIN && b != T::MIN {
                T::MAX
            } else {
                T::MIN
            }
        })
    }
    #[inline(always)]
    fn select(mask: Self, a: Self, b: Self) -> Self {
        let mut out = b.0;
        for ((r, &m), &x) in out.iter_mut().zip(&mask.0).zip(&a.0) {
            *r = if m != T::MIN { x } else { *r };
        }
        Portable(out)
    }
    #[inline(always)]
    fn ne(self, o: Self) -> Self {
        self.map2(o, |a, b| if a != b { T::MAX } else { T::MIN })
    }
    #[inline(always)]
    fn or(self, o: Self) -> Self {
        self.map2(o, |a, b| {
            if a != T::MIN || b != T::MIN {
                T::MAX
            } else {
                T::MIN
            }
        })
    }
    #[inline(always)]
    fn any(self) -> bool {
        self.0.iter().fold(false, |any, &v| any | (v != T::MIN))
    }
}

#[cfg(target_arch = "x86_64")]
pub use x86::{Avx2U16, Avx2U8, Sse2U16, Sse2U8};

#[cfg(target_arch = "x86_64")]
mod x86 {
    //! SSE2 and AVX2 vectors of `u8` and `u16`. The AVX2 methods are
    //! `#[inline(always)]` and only called from `#[target_feature(enable =
    //! "avx2")]` entry points, into which they (and the intrinsics) inline.
    //! SSE2 has no unsigned 16-bit max/min: they are built from saturating
    //! subtraction, `max(a, b) = (a ⊖ b) + b`, `min(a, b) = a − (a ⊖ b)`.
    //! Unsigned `a > b` is `(a ⊖ b) ≠ 0` for both widths.

    use std::arch::x86_64::*;

    use super::Vector;

    macro_rules! common {
        ($zero:ident, $cmpeq:ident, $or:ident, $xor:ident, $and:ident, $movemask:ident, $setones:expr) => {
            #[inline(always)]
            fn gt(self, o: Self) -> Self {
                let d = self.sub_sat(o);
                // SAFETY: the vector type exists only on CPUs with its instruction set.
                unsafe { Self($xor($cmpeq(d.0, $zero()), $setones)) }
            }
            #[inline(always)]
            fn le(self, o: Self) -> Self {
                let d = self.sub_sat(o);
                unsafe { Self($cmpeq(d.0, $zero())) }
            }
            #[inline(always)]
            fn ne(self, o: Self) -> Self {
                unsafe { Self($xor($cmpeq(self.0, o.0), $setones)) }
            }
            #[inline(always)]
            fn or(self, o: Self) -> Self {
                unsafe { Self($or(self.0, o.0)) }
            }
            #[inline(always)]
            fn and(self, o: Self) -> Self {
                unsafe { Self($and(self.0, o.0)) }
            }
            #[inline(always)]
            fn any(self) -> bool {
                unsafe { $movemask(self.0) != 0 }
            }
        };
    }

    /// `if mask { a } else { b }` with SSE2's bit operations.
    macro_rules! select_sse2 {
        () => {
            #[inline(always)]
            fn select(mask: Self, a: Self, b: Self) -> Self {
                unsafe {
                    Self(_mm_xor_si128(
                        b.0,
                        _mm_and_si128(_mm_xor_si128(a.0, b.0), mask.0),
                    ))
                }
            }
        };
    }

    /// `if mask { a } else { b }` in one AVX2 blend (the mask's lanes are
    /// all-ones or zero, so blending bytes blends lanes of either width).
    macro_rules! select_avx2 {
        () => {
            #[inline(always)]
            fn select(mask: Self, a: Self, b: Self) -> Self {
                unsafe { Self(_mm256_blendv_epi8(b.0, a.0, mask.0)) }
            }
        };
    }

    #[derive(Clone, Copy)]
    pub struct Sse2U8(__m128i);
    #[derive(Clone, Copy)]
    pub struct Sse2U16(__m128i);
    #[derive(Clone, Copy)]
    pub struct Avx2U8(__m256i);
    #[derive(Clone, Copy)]
    pub struct Avx2U16(__m256i);

    impl Vector<u8> for Sse2U8 {
        const LANES: usize = 16;
        #[inline(always)]
        unsafe fn load(ptr: *const u8) -> Self {
            unsafe { Self(_mm_loadu_si128(ptr.cast())) }
        }
        #[inline(always)]
        unsafe fn store(self, ptr: *mut u8) {
            unsafe { _mm_storeu_si128(ptr.cast(), self.0) }
        }
        #[inline(always)]
        fn splat(v: u8) -> Self {
            unsafe { Self(_mm_set1_epi8(v as i8)) }
        }
        #[inline(always)]
        fn max(self, o: Self) -> Self {
            unsafe { Self(_mm_max_epu8(self.0, o.0)) }
        }
        #[inline(always)]
        fn min(self, o: Self) -> Self {
            unsafe { Self(_mm_min_epu8(self.0, o.0)) }
        }
        #[inline(always)]
        fn sub_sat(self, o: Self) -> Self {
            unsafe { Self(_mm_subs_epu8(self.0, o.0)) }
        }
        #[inline(always)]
        fn add_sat(self, o: Self) -> Self {
            unsafe { Self(_mm_adds_epu8(self.0, o.0)) }
        }
        select_sse2!();
        common!(
            _mm_setzero_si128,
            _mm_cmpeq_epi8,
            _mm_or_si128,
            _mm_xor_si128,
            _mm_and_si128,
            _mm_movemask_epi8,
            _mm_set1_epi8(-1)
        );
    }

    impl Vector<u16> for Sse2U16 {
        const LANES: usize = 8;
        #[inline(always)]
        unsafe fn load(ptr: *const u16) -> Self {
            unsafe { Self(_mm_loadu_si128(ptr.cast())) }
        }
        #[inline(always)]
        unsafe fn store(self, ptr: *mut u16) {
            unsafe { _mm_storeu_si128(ptr.cast(), self.0) }
        }
        #[inline(always)]
        fn splat(v: u16) -> Self {
            unsafe { Self(_mm_set1_epi16(v as i16)) }
        }
        #[inline(always)]
        fn max(self, o: Self) -> Self {
            unsafe { Self(_mm_add_epi16(_mm_subs_epu16(self.0, o.0), o.0)) }
        }
        #[inline(always)]
        fn min(self, o: Self) -> Self {
            unsafe { Self(_mm_sub_epi16(self.0, _mm_subs_epu16(self.0, o.0))) }
        }
        #[inline(always)]
        fn sub_sat(self, o: Self) -> Self {
            unsafe { Self(_mm_subs_epu16(self.0, o.0)) }
        }
        #[inline(always)]
        fn add_sat(self, o: Self) -> Self {
            unsafe { Self(_mm_adds_epu16(self.0, o.0)) }
        }
        select_sse2!();
        common!(
            _mm_setzero_si128,
            _mm_cmpeq_epi16,
            _mm_or_si128,
            _mm_xor_si128,
            _mm_and_si128,
            _mm_movemask_epi8,
            _mm_set1_epi8(-1)
        );
    }

    impl Vector<u8> for Avx2U8 {
        const LANES: usize = 32;
        #[inline(always)]
        unsafe fn load(ptr: *const u8) -> Self {
            unsafe { Self(_mm256_loadu_si256(ptr.cast())) }
        }
        #[inline(always)]
        unsafe fn store(self, ptr: *mut u8) {
            unsafe { _mm256_storeu_si256(ptr.cast(), self.0) }
        }
        #[inline(always)]
        fn splat(v: u8) -> Self {
            unsafe { Self(_mm256_set1_epi8(v as i8)) }
        }
        #[inline(always)]
        fn max(self, o: Self) -> Self {
            unsafe { Self(_mm256_max_epu8(self.0, o.0)) }
        }
        #[inline(always)]
        fn min(self, o: Self) -> Self {
            unsafe { Self(_mm256_min_epu8(self.0, o.0)) }
        }
        #[inline(always)]
        fn sub_sat(self, o: Self) -> Self {
            unsafe { Self(_mm256_subs_epu8(self.0, o.0)) }
        }
        #[inline(always)]
        fn add_sat(self, o: Self) -> Self {
            unsafe { Self(_mm256_adds_epu8(self.0, o.0)) }
        }
        select_avx2!();
        common!(
            _mm256_setzero_si256,
            _mm256_cmpeq_epi8,
            _mm256_or_si256,
            _mm256_xor_si256,
            _mm256_and_si256,
            _mm256_movemask_epi8,
            _mm256_set1_epi8(-1)
        );
    }

    impl Vector<u16> for Avx2U16 {
        const LANES: usize = 16;
        #[inline(always)]
        unsafe fn load(ptr: *const u16) -> Self {
            unsafe { Self(_mm256_loadu_si256(ptr.cast())) }
        }
        #[inline(always)]
        unsafe fn store(self, ptr: *mut u16) {
            unsafe { _mm256_storeu_si256(ptr.cast(), self.0) }
        }
        #[inline(always)]
        fn splat(v: u16) -> Self {
            unsafe { Self(_mm256_set1_epi16(v as i16)) }
        }
        #[inline(always)]
        fn max(self, o: Self) -> Self {
            unsafe { Self(_mm256_max_epu16(self.0, o.0)) }
        }
        #[inline(always)]
        fn min(self, o: Self) -> Self {
            unsafe { Self(_mm256_min_epu16(self.0, o.0)) }
        }
        #[inline(always)]
        fn sub_sat(self, o: Self) -> Self {
            unsafe { Self(_mm256_subs_epu16(self.0, o.0)) }
        }
        #[inline(always)]
        fn add_sat(self, o: Self) -> Self {
            unsafe { Self(_mm256_adds_epu16(self.0, o.0)) }
        }
        select_avx2!();
        common!(
            _mm256_setzero_si256,
            _mm256_cmpeq_epi16,
            _mm256_or_si256,
            _mm256_xor_si256,
            _mm256_and_si256,
            _mm256_movemask_epi8,
            _mm256_set1_epi8(-1)
        );
    }
}
