//! Grey-level sample types the tracker accepts: `u8` and `u16`.
//!
//! The tracker's hot loop runs entirely in the sample's own lane width (32
//! `u8` lanes per AVX2 register, 16 with SSE2; half that for `u16`): dip
//! depths `min(L, R) − I` with saturating subtraction (0 when the sample is
//! not below both contexts), running maxima, and the block-local frame offset
//! of a new deepest dip, stored in the same type (offsets stay below
//! [`Sample::NO_OFFSET`] = `MAX`; the tracker bounds the block accordingly).

use std::fmt::Debug;

use crate::simd::{Lane, Portable, Vector};

/// An unsigned grey-level sample (digital number, DN): a [`Lane`] (whence
/// `MIN`, `MAX` and the saturating arithmetic; sealed through it: `u8`, `u16`).
pub trait Sample: Lane + Debug + Default {
    /// Marks "no offset" among block-local frame offsets.
    const NO_OFFSET: Self;
    /// Length of a decoding LUT indexed by this sample: `MAX + 1`.
    const LUT_LEN: usize;
    /// The numpy dtype name, for messages.
    const DTYPE: &'static str;
    /// A block-local frame offset `k < NO_OFFSET` (checked by the caller).
    fn from_offset(k: usize) -> Self;
    /// The value as an offset or a LUT index.
    fn index(self) -> usize;
    fn to_f32(self) -> f32;
    /// 128-bit SSE2 vector of this sample type.
    #[cfg(target_arch = "x86_64")]
    type Sse2: Vector<Self>;
    /// 256-bit AVX2 vector of this sample type.
    #[cfg(target_arch = "x86_64")]
    type Avx2: Vector<Self>;
    /// 16 lanes folded lane by lane (left to the auto-vectoriser).
    type Portable: Vector<Self>;
}

/// The two sample types differ only in width: one implementation for both.
macro_rules! impl_sample {
    ($t:ty, $bits:expr, $dtype:expr, $sse2:ty, $avx2:ty) => {
        impl Sample for $t {
            #[cfg(target_arch = "x86_64")]
            type Sse2 = $sse2;
            #[cfg(target_arch = "x86_64")]
            type Avx2 = $avx2;
            type Portable = Portable<$t, 16>;
            const NO_OFFSET: Self = <$t>::MAX;
            const LUT_LEN: usize = 1 << $bits;
            const DTYPE: &'static str = $dtype;
            #[inline(always)]
            fn from_offset(k: usize) -> Self {
                debug_assert!(k < usize::from(Self::NO_OFFSET));
                k as $t
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
    };
}

#[cfg(target_arch = "x86_64")]
impl_sample!(u8, 8, "uint8", crate::simd::Sse2U8, crate::simd::Avx2U8);
#[cfg(target_arch = "x86_64")]
impl_sample!(
    u16,
    16,
    "uint16",
    crate::simd::Sse2U16,
    crate::simd::Avx2U16
);
#[cfg(not(target_arch = "x86_64"))]
impl_sample!(u8, 8, "uint8", (), ());
#[cfg(not(target_arch = "x86_64"))]
impl_sample!(u16, 16, "uint16", (), ());
