//! One intensity representation, from the input's DN to the threshold.
//!
//! The frames reach the tracker as they were decoded from the files: digital
//! numbers (DN, `u8` or `u16`). The capture's one decoding table `L` (its
//! gamma: DN → linear irradiance, finite and non-decreasing) is held by the
//! tracker, which uses it for every linear quantity: the mid-level threshold,
//! the interpolated crossings, the slopes. `min_contrast` is a number of DN of
//! the input and is applied by the tracker, in every mode.
//!
//! Two modes ([`Intensity`]):
//!
//! * **DN**: the tracker's samples are the input's DN. Its levels `imax`,
//!   `imin`, the contrast and the rival dip's depth are DN.
//! * **normalised** (a changing light: the sun through a day): every frame
//!   comes with a *gain* `g_f`, the level of its light relative to the first
//!   frame's. The tracker must compare samples across frames in one light,
//!   so it stores each sample as its normalised irradiance `L(DN) / g_f`, as
//!   a fixed-point `u16` code `min(⌊L(DN) · S / g_f⌋, 65535)`
//!   ([`NORMALISED_SCALE`] `S` = 32768: the first frame's full scale is half
//!   the code range, headroom for a light twice as bright; a step of `1/S`
//!   is finer than one 8-bit DN anywhere above `L = 0.0001`). This code is
//!   internal: it never leaves the kernel. Each dip is reported in the light
//!   it was seen in: its levels are carried back by the gain at the dip
//!   `g` (the frames' gains interpolated at the middle of its enter and
//!   leave times) to linear irradiance `x = g · c / S`, and to DN of the
//!   input through `L⁻¹` (interpolated between the table's entries, so a
//!   fractional DN; `L(L⁻¹(x)) = x` within `f32`). The contrast and the
//!   `min_contrast` test are in those DN, the threshold and slopes in that
//!   light.
//!
//! Depths, the rival dip and the ambiguity ratio are compared in the
//! tracker's samples (DN, or normalised codes); only what is reported is
//! converted.

use crate::error::KernelError;
use crate::sample::Sample;

/// Normalised code of the first frame's full-scale irradiance (`L = 1`).
pub const NORMALISED_SCALE: f32 = 32768.0;

/// Largest normalised code.
const CODE_MAX: f32 = u16::MAX as f32;

/// Check a decoding table for an input of `dtype` with `len` values:
/// `len` finite, non-decreasing entries.
pub(crate) fn check_table(table: &[f32], len: usize, dtype: &str) -> Result<(), KernelError> {
    if table.len() != len {
        return Err(KernelError::InvalidLut {
            reason: format!("a {dtype} LUT needs {len} entries, got {}", table.len()),
        });
    }
    if let Some(i) = table.iter().position(|v| !v.is_finite()) {
        return Err(KernelError::InvalidLut {
            reason: format!("entry {i} is {}", table[i]),
        });
    }
    if let Some(i) = table.windows(2).position(|w| w[1] < w[0]) {
        return Err(KernelError::InvalidLut {
            reason: format!(
                "must be non-decreasing, but entry {} ({}) < entry {i} ({})",
                i + 1,
                table[i + 1],
                table[i]
            ),
        });
    }
    Ok(())
}

/// `L⁻¹(x)`: the DN whose decoded value is `x`, interpolated linearly between
/// the table's entries (the first of equal entries); clamped to `[0, len − 1]`.
pub(crate) fn undecode(table: &[f32], x: f32) -> f32 {
    let top = table.len() - 1;
    // first entry ≥ x
    let i = table.partition_point(|&v| v < x);
    if i == 0 {
        return 0.0;
    }
    if i > top {
        return top as f32;
    }
    let (a, b) = (table[i - 1], table[i]);
    if b > a {
        (i - 1) as f32 + (x - a) / (b - a)
    } else {
        i as f32
    }
}

/// What the tracker's samples are, and how they become reported values.
#[derive(Debug, Clone)]
pub(crate) enum Intensity {
    /// The samples are the input's DN; `decode` is the capture's table `L`.
    Dn { decode: Vec<f32> },
    /// The samples are normalised codes (see the module docs).
    Normalised {
        /// `L`, indexed by the input's DN (256 or 65536 entries).
        input: Vec<f32>,
        /// `decode[c] = c / S`: a code's normalised irradiance.
        decode: Vec<f32>,
        /// `g_f` of every frame given so far.
        gains: Vec<f64>,
        /// The code of the input's largest DN in every frame given so far
        /// (`L(top) · S / g_f`, as encoded): a sample at or above it was
        /// clipped in the input.
        full_scale: Vec<u16>,
    },
}

/// One dip's values as reported (see [`Intensity::report`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Reported {
    pub imax: f32,
    pub imin: f32,
    pub rival: f32,
    /// Multiplies the linear values (threshold, slopes): the gain at the dip.
    pub gain: f32,
}

impl Intensity {
    /// DN samples decoded by `table` (`None`: the identity, DN as linear).
    pub(crate) fn dn<T: Sample>(table: Option<&[f32]>) -> Result<Self, KernelError> {
        let decode = match table {
            Some(table) => {
                check_table(table, T::LUT_LEN, T::DTYPE)?;
                table.to_vec()
            }
            None => (0..T::LUT_LEN).map(|v| v as f32).collect(),
        };
        Ok(Intensity::Dn { decode })
    }

    /// Normalised codes of an input decoded by `table` (256 entries for
    /// `uint8` input, 65536 for `uint16`).
    pub(crate) fn normalised(table: &[f32]) -> Result<Self, KernelError> {
        let (len, dtype) = match table.len() {
            256 => (u8::LUT_LEN, u8::DTYPE),
            _ => (u16::LUT_LEN, u16::DTYPE),
        };
        check_table(table, len, dtype)?;
        Ok(Intensity::Normalised {
            input: table.to_vec(),
            decode: (0..=u16::MAX)
                .map(|c| (f64::from(c) / f64::from(NORMALISED_SCALE)) as f32)
                .collect(),
            gains: Vec::new(),
            full_scale: Vec::new(),
        })
    }

    /// The samples' decoding table: sample → linear.
    pub(crate) fn decode(&self) -> &[f32] {
        match self {
            Intensity::Dn { decode } | Intensity::Normalised { decode, .. } => decode,
        }
    }

    pub(crate) fn is_normalised(&self) -> bool {
        matches!(self, Intensity::Normalised { .. })
    }

    /// Length of the input's table (its dtype's number of values).
    pub(crate) fn input_len(&self) -> usize {
        match self {
            Intensity::Dn { decode } => decode.len(),
            Intensity::Normalised { input, .. } => input.len(),
        }
    }

    /// The code table of one frame of gain `gain` (normalised mode):
    /// `code[DN] = min(⌊L(DN) · (S / gain)⌋, 65535)`, and remember the gain.
    pub(crate) fn encoder(&mut self, gain: f64) -> Result<Vec<u16>, KernelError> {
        let Intensity::Normalised {
            input,
            gains,
            full_scale,
            ..
        } = self
        else {
            return Err(not_normalised());
        };
        check_gain(gain)?;
        let factor = (f64::from(NORMALISED_SCALE) / gain) as f32;
        // (the product is ≥ 0: clamped, then truncated towards zero)
        let code = |l: f32| (l * factor).clamp(0.0, CODE_MAX) as u16;
        let table: Vec<u16> = input.iter().map(|&l| code(l)).collect();
        gains.push(gain);
        full_scale.push(table[table.len() - 1]);
        Ok(table)
    }

    /// The input's decoding table `L` (normalised mode; the samples' table otherwise).
    pub(crate) fn input_table(&self) -> &[f32] {
        match self {
            Intensity::Dn { decode } => decode,
            Intensity::Normalised { input, .. } => input,
        }
    }

    /// Remember the gain of a frame stored with per-pixel levels (normalised
    /// mode): its clipped samples are stored as the largest code, which is
    /// then its full scale.
    pub(crate) fn encoder_levelled(&mut self, gain: f64) -> Result<(), KernelError> {
        let Intensity::Normalised {
            gains, full_scale, ..
        } = self
        else {
            return Err(not_normalised());
        };
        check_gain(gain)?;
        gains.push(gain);
        full_scale.push(u16::MAX);
        Ok(())
    }

    /// Whether the sample `v` of frame `frame` is clipped (0 or the input's
    /// maximum, or the end of the code range).
    #[inline]
    pub(crate) fn clipped<T: Sample>(&self, v: T, frame: usize) -> bool {
        if v == T::MIN || v == T::MAX {
            return true;
        }
        match self {
            Intensity::Dn { .. } => false,
            Intensity::Normalised { full_scale, .. } => {
                // (a window clamped at the newest frame repeats it)
                let f = frame.min(full_scale.len().saturating_sub(1));
                full_scale
                    .get(f)
                    .is_some_and(|&top| v.index() >= usize::from(top))
            }
        }
    }

    /// The time of a dip whose light is wanted: the middle of its enter and
    /// leave times, or the one that exists (NaN without).
    pub(crate) fn dip_time(enter: f32, leave: f32) -> f32 {
        match (enter.is_finite(), leave.is_finite()) {
            (true, true) => 0.5 * (enter + leave),
            (true, false) => enter,
            (false, true) => leave,
            (false, false) => f32::NAN,
        }
    }

    /// Gain at time `centre` (frames): the frames' gains interpolated
    /// linearly (clamped to the first and last); `fallback` when `centre` is
    /// NaN. 1 in DN mode.
    pub(crate) fn gain_at(&self, centre: f32, fallback: f64) -> f64 {
        let Intensity::Normalised { gains, .. } = self else {
            return 1.0;
        };
        if !centre.is_finite() || gains.is_empty() {
            return fallback;
        }
        let t = f64::from(centre);
        let last = gains.len() - 1;
        if t <= 0.0 {
            return gains[0];
        }
        if t >= last as f64 {
            return gains[last];
        }
        let i = t.floor() as usize;
        let w = t - i as f64;
        gains[i] + w * (gains[(i + 1).min(last)] - gains[i])
    }

    /// The median of the frames' gains (1 in DN mode or before any frame):
    /// the gain of a dip without times.
    pub(crate) fn median_gain(&self) -> f64 {
        let Intensity::Normalised { gains, .. } = self else {
            return 1.0;
        };
        if gains.is_empty() {
            return 1.0;
        }
        let mut sorted = gains.clone();
        sorted.sort_by(f64::total_cmp);
        let n = sorted.len();
        if n % 2 == 1 {
            sorted[n / 2]
        } else {
            0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
        }
    }

    /// A dip's lit level `hi`, darkest sample `lo` and rival depth `d2`
    /// (samples) as reported at gain `gain`: DN of the input (fractional in
    /// normalised mode) and the factor of its linear values.
    pub(crate) fn report<T: Sample>(&self, hi: T, lo: T, d2: T, gain: f64) -> Reported {
        match self {
            Intensity::Dn { .. } => Reported {
                imax: hi.to_f32(),
                imin: lo.to_f32(),
                rival: d2.to_f32(),
                gain: 1.0,
            },
            Intensity::Normalised { input, decode, .. } => {
                let g = gain as f32;
                let dn = |v: usize| undecode(input, decode[v] * g);
                let imax = dn(hi.index());
                Reported {
                    imax,
                    imin: dn(lo.index()),
                    rival: if d2 == T::MIN {
                        0.0
                    } else {
                        imax - dn(hi.index().saturating_sub(d2.index()))
                    },
                    gain: g,
                }
            }
        }
    }

    /// A contrast of `min_contrast` DN of the input in the samples' units,
    /// for the live watch: itself in DN mode; in normalised mode the step it
    /// spans around the input's mid-grey, at the first frame's light.
    pub(crate) fn contrast_in_samples(&self, min_contrast: f32) -> f32 {
        match self {
            Intensity::Dn { .. } => min_contrast,
            Intensity::Normalised { input, .. } => {
                let top = input.len() - 1;
                let mid = top / 2;
                let half = (f64::from(min_contrast) / 2.0).max(0.5);
                let lo = (mid as f64 - half).max(0.0) as usize;
                let hi = ((mid as f64 + half).min(top as f64)) as usize;
                let step = f64::from(input[hi] - input[lo]) * f64::from(NORMALISED_SCALE);
                step.max(1.0) as f32
            }
        }
    }
}

/// A frame's gain must be a positive finite number.
fn check_gain(gain: f64) -> Result<(), KernelError> {
    if gain.is_finite() && gain > 0.0 {
        Ok(())
    } else {
        Err(KernelError::parameter(
            "gain",
            format!("must be a positive number, got {gain}"),
        ))
    }
}

/// A gain given to a tracker that is not normalised.
fn not_normalised() -> KernelError {
    KernelError::parameter(
        "gain",
        "only a normalised tracker takes a gain with each frame",
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn undecode_inverts_the_table() {
        let table: Vec<f32> = (0..256).map(|v| (v as f32 / 255.0).powf(2.2)).collect();
        for dn in [0usize, 1, 17, 128, 254, 255] {
            assert_eq!(undecode(&table, table[dn]), dn as f32);
        }
        let mid = 0.5 * (table[100] + table[101]);
        let x = undecode(&table, mid);
        assert!((x - 100.5).abs() < 1e-3, "{x}");
        assert_eq!(undecode(&table, -1.0), 0.0);
        assert_eq!(undecode(&table, 2.0), 255.0);
    }

    #[test]
    fn gains_are_interpolated_and_clamped() {
        let table: Vec<f32> = (0..256).map(|v| v as f32 / 255.0).collect();
        let mut n = Intensity::normalised(&table).unwrap();
        for g in [1.0, 2.0, 4.0] {
            n.encoder(g).unwrap();
        }
        assert_eq!(n.gain_at(0.5, 9.0), 1.5);
        assert_eq!(n.gain_at(1.25, 9.0), 2.5);
        assert_eq!(n.gain_at(-3.0, 9.0), 1.0);
        assert_eq!(n.gain_at(7.0, 9.0), 4.0);
        assert_eq!(n.gain_at(f32::NAN, 9.0), 9.0);
        assert_eq!(n.median_gain(), 2.0);
        assert!(n.encoder(0.0).is_err());
        assert!(n.encoder(f64::NAN).is_err());
        assert!(Intensity::dn::<u8>(None).unwrap().encoder(1.0).is_err());
    }

    #[test]
    fn a_code_reports_the_dn_it_was_encoded_from() {
        let table: Vec<f32> = (0..256)
            .map(|v| ((v as f64 / 255.0).powf(2.2)) as f32)
            .collect();
        let mut n = Intensity::normalised(&table).unwrap();
        let code = n.encoder(0.6).unwrap();
        for dn in [30usize, 90, 200, 255] {
            let r = n.report(code[dn], code[dn], 0u16, 0.6);
            // the code truncates L·S/g: at most one code (1/S of irradiance) below
            assert!(
                r.imax <= dn as f32 && r.imax > dn as f32 - 0.05,
                "{dn}: {}",
                r.imax
            );
        }
    }
}
