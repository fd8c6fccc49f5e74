//! A compressed video's shadow times between its codec blocks' centres (see `gnomon.capture.deblock`).

use rayon::prelude::*;

use crate::error::KernelError;

/// The codec block grid a time map is interpolated on: `size` pixels, the first whole block at
/// column `u0` and row `v0`, `blocks_x` × `blocks_y` whole blocks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlockLayout {
    pub size: usize,
    pub u0: usize,
    pub v0: usize,
    pub blocks_x: usize,
    pub blocks_y: usize,
}

/// Each pixel's time interpolated bilinearly between the four block centres around it.
///
/// * `times`: `H·W` shadow times (frames, NaN = none), row-major, `width` W;
/// * `value`: `blocks_y·blocks_x` each block's time (NaN: the block does not count);
/// * `span_max`: the largest spread of four block centres interpolated between.
///
/// A pixel at column `u` sits at `((u − u0) − (size − 1)/2)/size` in block-centre units (its
/// row likewise); it is interpolated when that position has a block centre on both sides in both
/// directions, its four corners are finite and span at most `span_max` (`max − min`), and its own
/// time is finite: `c00·(1 − fu)·(1 − fv) + c01·fu·(1 − fv) + c10·(1 − fu)·fv + c11·fu·fv` in
/// f64, in that order, rounded to f32; every other pixel keeps its time. Element for element
/// `gnomon.capture.deblock._interpolate_numpy`. Rows in parallel.
pub fn deblock_interpolate(
    times: &[f32],
    width: usize,
    value: &[f64],
    layout: BlockLayout,
    span_max: f64,
) -> Result<Vec<f32>, KernelError> {
    let n = times.len();
    let BlockLayout {
        size,
        u0,
        v0,
        blocks_x,
        blocks_y,
    } = layout;
    KernelError::check_image(
        n,
        width,
        &[("value (one per block)", blocks_x * blocks_y, value.len())],
    )?;
    if size == 0 || blocks_x < 2 || blocks_y < 2 {
        return Err(KernelError::parameter(
            "layout",
            format!("{size}-pixel blocks, {blocks_x} × {blocks_y}: at least 2 × 2 blocks of at least 1 pixel"),
        ));
    }
    let half = (size - 1) as f64 / 2.0;
    let b = size as f64;
    // a pixel's place between block centres along one axis: (first centre, fraction, between two centres)
    let place = |p: usize, origin: usize, blocks: usize| -> (usize, f64, bool) {
        let x = ((p as i64 - origin as i64) as f64 - half) / b;
        let j = x.floor();
        let inside = j >= 0.0 && j + 1.0 < blocks as f64;
        (j.clamp(0.0, (blocks - 2) as f64) as usize, x - j, inside)
    };
    let columns: Vec<(usize, f64, bool)> = (0..width).map(|u| place(u, u0, blocks_x)).collect();
    let mut out = times.to_vec();
    out.par_chunks_mut(width.max(1))
        .enumerate()
        .for_each(|(v, row)| {
            let (i, fv, inside_v) = place(v, v0, blocks_y);
            if !inside_v {
                return;
            }
            for (o, &(j, fu, inside_u)) in row.iter_mut().zip(&columns) {
                if !inside_u || !o.is_finite() {
                    continue;
                }
                let (c00, c01) = (value[i * blocks_x + j], value[i * blocks_x + j + 1]);
                let (c10, c11) = (
                    value[(i + 1) * blocks_x + j],
                    value[(i + 1) * blocks_x + j + 1],
                );
                let corners = [c00, c01, c10, c11];
                if !corners.iter().all(|c| c.is_finite()) {
                    continue;
                }
                let hi = corners.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                let lo = corners.iter().copied().fold(f64::INFINITY, f64::min);
                let within = hi - lo <= span_max; // false for a NaN span_max too
                if !within {
                    continue;
                }
                let interp = c00 * (1.0 - fu) * (1.0 - fv)
                    + c01 * fu * (1.0 - fv)
                    + c10 * (1.0 - fu) * fv
                    + c11 * fu * fv;
                *o = interp as f32;
            }
        });
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ramp_of_block_times_is_interpolated_and_the_rest_kept() {
        // 4 × 4 blocks of 2 px over an 8 × 8 map; block (i, j) has time 10·i + j; pixel (v, u) sits at
        // ((v − 0.5)/2, (u − 0.5)/2) in block-centre units, so inside it gets 10·(v − 0.5)/2 + (u − 0.5)/2
        let layout = BlockLayout {
            size: 2,
            u0: 0,
            v0: 0,
            blocks_x: 4,
            blocks_y: 4,
        };
        let value: Vec<f64> = (0..16).map(|k| f64::from(10 * (k / 4) + k % 4)).collect();
        let mut times = vec![1.0f32; 64];
        times[3 * 8 + 3] = f32::NAN;
        let got = deblock_interpolate(&times, 8, &value, layout, 100.0).unwrap();
        for v in 0..8 {
            for u in 0..8 {
                let (x, y) = ((u as f64 - 0.5) / 2.0, (v as f64 - 0.5) / 2.0);
                let inside = (0.0..3.0).contains(&x) && (0.0..3.0).contains(&y);
                let t = got[v * 8 + u];
                if v == 3 && u == 3 {
                    assert!(t.is_nan()); // no time of its own: none given
                } else if inside {
                    assert!((f64::from(t) - (10.0 * y + x)).abs() < 1e-5, "{v} {u} {t}");
                } else {
                    assert_eq!(t, 1.0); // outside the centres: its own time
                }
            }
        }
        // a spread beyond span_max, or a block that does not count, keeps the pixels' own times
        assert!(deblock_interpolate(&times, 8, &value, layout, 5.0).unwrap()[2 * 8 + 2] == 1.0);
        let mut holed = value.clone();
        holed[5] = f64::NAN;
        assert_eq!(
            deblock_interpolate(&times, 8, &holed, layout, 100.0).unwrap()[2 * 8 + 2],
            1.0
        );
        assert!(deblock_interpolate(&times, 8, &value[..15], layout, 100.0).is_err());
    }
}
