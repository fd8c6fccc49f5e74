//! Grey-level sample types the tracker accepts (`u8`, `u16`) and the signed
//! integer lane each one is widened to for frame differences.
//!
//! The lane is the narrowest signed type that holds `a - b` for any two
//! samples, so the tracker's inner loop runs at the widest SIMD lane count:
//! `u8 → i16` (16 lanes per AVX2 register, 32 with AVX-512), `u16 → i32`.

use std::fmt::Debug;
use std::ops::Sub;

mod sealed {
    pub trait Sealed {}
    impl Sealed for u8 {}
    impl Sealed for u16 {}
    impl Sealed for i16 {}
    impl Sealed for i32 {}
}

/// A signed integer lane: frame differences and block-local frame offsets.
pub trait Lane:
    Copy + Ord + Debug + Default + Send + Sync + Sub<Output = Self> + 'static + sealed::Sealed
{
    const ZERO: Self;
    /// Marks "no frame" in block-local offsets.
    const NONE: Self;
    /// The largest block-local offset a lane can hold.
    const MAX_OFFSET: usize;
    /// A block-local frame offset; `k <= MAX_OFFSET` (checked by the caller).
    fn from_offset(k: usize) -> Self;
    /// The offset back; only called on lanes that are not `NONE`.
    fn to_offset(self) -> usize;
}

impl Lane for i16 {
    const ZERO: Self = 0;
    const NONE: Self = -1;
    const MAX_OFFSET: usize = i16::MAX as usize;
    #[inline(always)]
    fn from_offset(k: usize) -> Self {
        debug_assert!(k <= Self::MAX_OFFSET);
        k as i16
    }
    #[inline(always)]
    fn to_offset(self) -> usize {
        debug_assert!(self >= 0);
        self as usize
    }
}

impl Lane for i32 {
    const ZERO: Self = 0;
    const NONE: Self = -1;
    const MAX_OFFSET: usize = i32::MAX as usize;
    #[inline(always)]
    fn from_offset(k: usize) -> Self {
        debug_assert!(k <= Self::MAX_OFFSET);
        k as i32
    }
    #[inline(always)]
    fn to_offset(self) -> usize {
        debug_assert!(self >= 0);
        self as usize
    }
}

/// An unsigned grey-level sample (digital number, DN).
pub trait Sample: Copy + Ord + Debug + Default + Send + Sync + 'static + sealed::Sealed {
    /// The signed lane frame differences are computed in.
    type Lane: Lane;
    /// The darkest and brightest representable values.
    const MIN: Self;
    const MAX: Self;
    /// Length of a decoding LUT indexed by this sample: `MAX + 1`.
    const LUT_LEN: usize;
    /// The numpy dtype name, for messages.
    const DTYPE: &'static str;
    fn widen(self) -> Self::Lane;
    /// The value as a LUT index.
    fn index(self) -> usize;
    fn to_f32(self) -> f32;
}

impl Sample for u8 {
    type Lane = i16;
    const MIN: Self = u8::MIN;
    const MAX: Self = u8::MAX;
    const LUT_LEN: usize = 1 << 8;
    const DTYPE: &'static str = "uint8";
    #[inline(always)]
    fn widen(self) -> i16 {
        i16::from(self)
    }
    #[inline(always)]
    fn index(self) -> usize {
        usize::from(self)
    }
    #[inline(always)]
    fn to_f32(self) -> f32 {
        f32::from(self)
    }
}

impl Sample for u16 {
    type Lane = i32;
    const MIN: Self = u16::MIN;
    const MAX: Self = u16::MAX;
    const LUT_LEN: usize = 1 << 16;
    const DTYPE: &'static str = "uint16";
    #[inline(always)]
    fn widen(self) -> i32 {
        i32::from(self)
    }
    #[inline(always)]
    fn index(self) -> usize {
        usize::from(self)
    }
    #[inline(always)]
    fn to_f32(self) -> f32 {
        f32::from(self)
    }
}
