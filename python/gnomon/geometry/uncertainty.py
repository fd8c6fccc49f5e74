"""Per-pixel depth uncertainty σZ by first-order propagation (Bouguet & Perona §5).

Every error source is expressed as an equivalent error of the pixel's shadow
time, then mapped to depth through the local sensitivity ∂Z/∂ts:

* the pixel's own shadow time: ``σt = σI / |dI/dt|`` at the crossing, with
  σI the image noise (estimated from the data) carried into the linear
  irradiance units of the threshold, and |dI/dt| the measured slope;
* the sampling of the edge: linear interpolation between two frames of an
  S-shaped edge errs by an amount that grows quickly as the edge's
  transition shortens (:func:`interpolation_time_sigma`);
* the reference line of the frame: its fitted position has an error
  ``rms / sqrt(n)`` across the line (plus the tilt error ``rms / sqrt(Σ s²)``
  at the typical distance along it), which is a time error once divided by
  how fast the line moves across the plane (world units per frame).

Independent sources add in quadrature: ``σZ = |∂Z/∂t| · sqrt(σt_pixel² + σt_line²)``.
∂Z/∂t comes from triangulating each pixel again at ``ts ± h`` (at ``ts ± h / FINE_STEP_DIVISOR``
where neither gives a depth).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gnomon import _kernel
from gnomon.geometry.reference_lines import ReferenceLines
from gnomon.geometry.triangulation import MIN_RAY_PLANE_COS, triangulate

DERIVATIVE_STEP_FRAMES = 0.25
# Where neither ts + h nor ts − h gives a depth (the ray lies in the shadow planes there, or
# behind the camera), ∂Z/∂t is taken again with h / FINE_STEP_DIVISOR, within the pixel's own
# pair of plane rows: such a depth has a large σ, not the typical one a missing σ gets (the
# kernel's own FINE_STEP_DIVISOR: the two must agree, tests/test_depth_sigma.py compares them).
FINE_STEP_DIVISOR = 64.0
# A transition sampled by fewer than this many frames (steepest single-frame
# step larger than contrast / this) is under-sampled: linear interpolation
# between the two samples is then biased by the edge's shape.
MIN_FRAMES_PER_TRANSITION = 2.0
def linear_noise_at_threshold(sigma_dn: float, threshold_lin: np.ndarray, lut: np.ndarray) -> np.ndarray:
    """σI carried to linear irradiance units at each pixel's threshold: σ_DN · dL/dDN.

    A float32 map and table go to the kernel (``_kernel.lut_lookup``, pixels in parallel: the code's
    binary search, element for element numpy's ``searchsorted``); :func:`_linear_noise_at_threshold_numpy`
    is the definition."""
    values = np.asarray(threshold_lin)
    table = np.asarray(lut)
    if (values.dtype == np.float32 and table.dtype == np.float32 and table.ndim == 1 and table.size
            and not np.any(table[1:] < table[:-1]) and not np.isnan(table).any()):
        slope = np.gradient(table.astype(np.float64))  # linear units per DN, at every code value
        flat = _kernel.lut_lookup(table, slope, float(sigma_dn), np.ascontiguousarray(values).reshape(-1))
        return flat.reshape(values.shape)
    return _linear_noise_at_threshold_numpy(sigma_dn, threshold_lin, lut)


def _linear_noise_at_threshold_numpy(sigma_dn: float, threshold_lin: np.ndarray, lut: np.ndarray) -> np.ndarray:
    """:func:`linear_noise_at_threshold` in numpy (the kernel's ``lut_lookup`` gives the same on float32)."""
    slope = np.gradient(lut.astype(np.float64))  # linear units per DN, at every code value
    code = np.searchsorted(lut, threshold_lin).clip(0, len(lut) - 1)
    return (sigma_dn * slope[code]).astype(np.float32)


def undersampled(slope_lin: np.ndarray, imax_lin: np.ndarray, imin_lin: np.ndarray) -> np.ndarray:
    """Pixels whose edge crossed them in fewer than ``MIN_FRAMES_PER_TRANSITION`` frames."""
    contrast = imax_lin - imin_lin
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.isfinite(slope_lin) & (slope_lin * MIN_FRAMES_PER_TRANSITION > contrast)


def interpolation_time_sigma(contrast_lin: np.ndarray, slope_lin: np.ndarray) -> np.ndarray:
    """Error (frames) of locating a sampled edge by linear interpolation.

    A shadow edge is S-shaped in time (a disc light's penumbra, blurred);
    interpolating linearly between the two samples around the half-way level
    misses its centre by an amount that depends on where the samples fall.
    For an edge whose transition lasts ``w = contrast / slope`` frames, the RMS
    of that error over sampling phases is ≈ 0.035·(1.5/w)³ frames (measured on
    the penumbra profile: 0.12 at w = 1, 0.035 at 1.5, 0.008 at 2.5). It is an
    independent error per pixel (each pixel has its own phase).
    """
    with np.errstate(invalid="ignore", divide="ignore"):
        # np.where(slope > 0, contrast / slope, NaN), then 0.035·(1.5 / max(w, 0.5))³, each step in place in
        # one new array (the same operations: a 1080p map's σ without five fresh whole-image temporaries)
        w = np.divide(contrast_lin, slope_lin)
        np.copyto(w, np.nan, where=~(slope_lin > 0))
        np.maximum(w, 0.5, out=w)
        np.divide(1.5, w, out=w)
        np.power(w, 3, out=w)
        np.multiply(0.035, w, out=w)
    return w if w.dtype == np.float32 else w.astype(np.float32)


def line_time_sigma(lines: ReferenceLines) -> np.ndarray:
    """Per-frame equivalent time error (frames) of a plane's fitted shadow line.

    The position error of the fit across the line, ``rms / sqrt(n)``, plus the
    tilt error seen at the RMS distance along the line, divided by the line's
    speed across the plane (from its neighbours in time).
    """
    sigma = np.full(len(lines.point), np.nan)
    speed = lines.speeds()
    with np.errstate(invalid="ignore"):
        ok = lines.found & (lines.count >= 3) & (speed > 0)
    # A line fit to n points spread uniformly has var(tilt)·Σs² = var(offset)·n,
    # so the tilt term at the RMS along-line distance equals the offset term.
    sigma_across = lines.rms[ok] * np.sqrt(2.0 / lines.count[ok])
    sigma[ok] = sigma_across / speed[ok]
    return sigma


@dataclass
class DepthUncertainty:
    """σZ (H, W) float32 in world units (NaN where no depth) and its parts."""

    sigma_z: np.ndarray
    dz_dt: np.ndarray  # world units per frame
    sigma_t_pixel: np.ndarray  # frames
    sigma_t_line: np.ndarray  # frames


def completion_depth_sigma(ray_map: np.ndarray, times: np.ndarray, depth: np.ndarray, planes: np.ndarray,
                           line_point: np.ndarray, line_direction: np.ndarray, sigma_rad: float) -> np.ndarray:
    """(H, W) σZ (world units, camera Z) a completed plane's own error adds at each point.

    A frame whose shadow crossed one reference plane only gets the plane containing that
    line and the located light (:func:`gnomon.light.shadow_planes.complete_from_light`). If the
    light is off, the plane is still exact along the line and turned about it: by an angle
    of 1σ ``sigma_rad`` (the completion's measured error) a point at distance ``d`` from the
    line moves by ``sigma_rad·d`` along the plane's normal, which its ray, at angle cosine
    ``|n·r|`` to that normal, turns into ``sigma_rad·d·r_z/|n·r|`` of camera Z. A pixel's
    plane is interpolated between rows ``floor(t)`` and ``floor(t) + 1`` with weights
    ``1 − f`` and ``f``, and the two rows' errors come from one light (fully correlated), so
    their terms add linearly with those weights; a measured row adds nothing.

    ``ray_map`` (H, W, 3) unit camera rays; ``times`` (H, W) plane rows; ``depth`` (H, W)
    camera Z (NaN: no point); ``planes`` (N, 4); ``line_point``, ``line_direction`` (N, 3) the
    completing line of each completed row (NaN rows: measured; direction a unit vector,
    :func:`gnomon.light.shadow_planes.completing_lines`). 0 where no completed row is involved.
    Computed by the kernel (``_kernel.completion_sigma``: chunks of pixels in parallel, the
    arithmetic of :func:`_completion_depth_sigma_numpy`, value for value).
    """
    return _kernel.completion_sigma(
        np.ascontiguousarray(ray_map, dtype=np.float64), np.ascontiguousarray(times, dtype=np.float64),
        np.ascontiguousarray(depth, dtype=np.float64), np.ascontiguousarray(planes, dtype=np.float64),
        np.ascontiguousarray(line_point, dtype=np.float64), np.ascontiguousarray(line_direction, dtype=np.float64),
        float(sigma_rad), MIN_RAY_PLANE_COS)


def _completion_depth_sigma_numpy(ray_map: np.ndarray, times: np.ndarray, depth: np.ndarray, planes: np.ndarray,
                                  line_point: np.ndarray, line_direction: np.ndarray, sigma_rad: float) -> np.ndarray:
    """The definition of :func:`completion_depth_sigma` in numpy (the kernel's reference in the tests)."""
    n = len(planes)
    sigma = np.zeros(depth.shape, dtype=np.float64)
    ok = np.isfinite(depth) & np.isfinite(times)
    completed = np.isfinite(line_point[:, 0])
    if not completed.any() or not ok.any() or sigma_rad <= 0:
        return sigma.astype(np.float32)
    t = times[ok].astype(np.float64)
    ray = ray_map[ok].astype(np.float64)
    x = ray * (depth[ok] / ray[:, 2])[:, None]
    k0 = np.clip(np.floor(t).astype(np.int64), 0, n - 1)
    frac = t - k0
    total = np.zeros(len(t))
    for k, w in ((k0, 1.0 - frac), (np.minimum(k0 + 1, n - 1), frac)):
        use = completed[k] & (w > 0)
        if not use.any():
            continue
        kk = k[use]
        dist = np.linalg.norm(np.cross(x[use] - line_point[kk], line_direction[kk]), axis=1)
        normal = planes[kk, :3] / np.linalg.norm(planes[kk, :3], axis=1)[:, None]
        cos = np.maximum(np.abs(np.sum(normal * ray[use], axis=1)), MIN_RAY_PLANE_COS)
        total[use] += w[use] * sigma_rad * dist * np.abs(ray[use, 2]) / cos
    sigma[ok] = total
    return sigma.astype(np.float32)


def depth_sigma(ray_map: np.ndarray, times: np.ndarray, planes: np.ndarray, depth: np.ndarray,
                sigma_t_pixel: np.ndarray, sigma_t_line_per_frame: np.ndarray) -> DepthUncertainty:
    """First-order σZ for every pixel with a depth.

    ``ray_map`` (H, W, 3) camera rays, ``times`` (H, W) frames (NaN = none), ``planes`` (N, 4) as
    :func:`~gnomon.geometry.triangulation.triangulate` takes them; ``depth`` (H, W) camera Z at ``times``
    (world units, NaN = none); ``sigma_t_pixel`` (H, W) each time's σ (frames);
    ``sigma_t_line_per_frame`` (N,) the σ (frames) each plane's line adds. On float32 maps the
    kernel computes it per pixel (``_kernel.depth_sigma``, chunks of pixels in parallel, the
    same arithmetic); :func:`_depth_sigma_numpy` is the definition.
    """
    line = np.asarray(sigma_t_line_per_frame, dtype=np.float64)
    maps = (times, depth, sigma_t_pixel)
    if (all(isinstance(m, np.ndarray) and m.dtype == np.float32 and m.ndim == 2 for m in maps)
            and times.shape == depth.shape == sigma_t_pixel.shape and len(line)
            and np.shape(ray_map) == (*times.shape, 3)):
        finite = line[np.isfinite(line)]
        fill = float(np.median(finite)) if finite.size else 0.0
        sigma_z, dz_dt, st_line = _kernel.depth_sigma(
            np.ascontiguousarray(ray_map, dtype=np.float64), np.ascontiguousarray(times),
            np.ascontiguousarray(planes, dtype=np.float64), np.ascontiguousarray(depth),
            np.ascontiguousarray(sigma_t_pixel), np.ascontiguousarray(line), fill,
            DERIVATIVE_STEP_FRAMES, MIN_RAY_PLANE_COS)
        return DepthUncertainty(sigma_z, dz_dt, sigma_t_pixel, st_line)
    return _depth_sigma_numpy(ray_map, times, planes, depth, sigma_t_pixel, sigma_t_line_per_frame)


def _depth_sigma_numpy(ray_map: np.ndarray, times: np.ndarray, planes: np.ndarray, depth: np.ndarray,
                       sigma_t_pixel: np.ndarray, sigma_t_line_per_frame: np.ndarray) -> DepthUncertainty:
    """:func:`depth_sigma` in numpy (the kernel's ``depth_sigma`` gives the same on float32 maps)."""
    def derivative(h: float) -> np.ndarray:
        plus = triangulate(ray_map, times + h, planes).depth
        minus = triangulate(ray_map, times - h, planes).depth
        with np.errstate(invalid="ignore"):
            central = (plus - minus) / (2 * h)
            forward = (plus - depth) / h
            backward = (depth - minus) / h
        return np.where(np.isfinite(central), central, np.where(np.isfinite(forward), forward, backward))

    dz_dt = derivative(DERIVATIVE_STEP_FRAMES)
    retry = ~np.isfinite(dz_dt) & np.isfinite(depth)
    if retry.any():
        dz_dt = np.where(retry, derivative(DERIVATIVE_STEP_FRAMES / FINE_STEP_DIVISOR), dz_dt)

    n = len(sigma_t_line_per_frame)
    line_sigma = np.where(np.isfinite(sigma_t_line_per_frame), sigma_t_line_per_frame, np.nan)
    idx = np.clip(np.nan_to_num(np.floor(times), nan=0).astype(np.int64), 0, n - 1)
    nxt = np.clip(idx + 1, 0, n - 1)
    frac = np.nan_to_num(times - np.floor(times))
    with np.errstate(invalid="ignore"):
        st_line = (1 - frac) * line_sigma[idx] + frac * line_sigma[nxt]
    st_line = np.where(np.isfinite(st_line), st_line,
                       np.nanmedian(line_sigma) if np.isfinite(line_sigma).any() else 0.0)
    total_t = np.sqrt(np.square(sigma_t_pixel) + np.square(st_line))
    sigma_z = (np.abs(dz_dt) * total_t).astype(np.float32)
    sigma_z[~np.isfinite(depth)] = np.nan
    return DepthUncertainty(sigma_z, dz_dt.astype(np.float32), sigma_t_pixel.astype(np.float32),
                            st_line.astype(np.float32))
