"""Type stub of ``gnomon._kernel``, the Rust kernel (crates gnomon-core, gnomon-py).

Arrays are borrowed without copying when C-contiguous (otherwise copied);
the GIL is released during every kernel call. Errors are the classes of
:mod:`gnomon.errors` (``GnomonError`` and ``ValueError`` subclasses), one per
kernel error, each naming what was expected and what was given: a bad array
``KernelArrayError``, a bad parameter ``KernelParameterError``, a bad decoding
table ``KernelLutError``, no (or too many) frames ``KernelFramesError``.
"""

from typing import Literal, overload

import numpy as np
import numpy.typing as npt

__version__: str

def simd_path() -> Literal["avx2", "sse2", "portable"]:
    """The instruction set new trackers' hot loops run on: the best this CPU has
    (detected at run time), or a lower one forced by the ``GNOMON_SIMD`` environment
    variable. Results do not depend on it."""

def simd_paths() -> list[Literal["avx2", "sse2", "portable"]]:
    """Every instruction set this CPU can run the hot loops on, best first."""

class ShadowTimes:
    """The tracker's per-pixel results; read-only, every array (H, W).

    ``imax``, ``imin``, ``contrast`` (DN of the input: the deepest dip's lit level,
    darkest sample and depth, 0 = no dip; fractional for a normalised tracker, whose
    levels are carried back to the light the dip was seen in), ``threshold`` (linear
    irradiance, the decoding table's units, in that light), ``enter``, ``leave``
    (frames, NaN = none or invalid), ``enter_slope``, ``leave_slope`` (linear units
    per frame), ``rival`` (DN, the deepest other dip): float32; ``valid`` (a dip,
    ``contrast >= min_contrast``, not ambiguous), ``ambiguous`` (``contrast >=
    min_contrast`` and the other dip at least ``ambiguity`` times as deep),
    ``clipped`` (the dip's levels or an interpolated sample at 0 or the input's
    maximum): bool.
    """

    @property
    def imax(self) -> npt.NDArray[np.float32]: ...
    @property
    def imin(self) -> npt.NDArray[np.float32]: ...
    @property
    def contrast(self) -> npt.NDArray[np.float32]: ...
    @property
    def threshold(self) -> npt.NDArray[np.float32]: ...
    @property
    def enter(self) -> npt.NDArray[np.float32]: ...
    @property
    def leave(self) -> npt.NDArray[np.float32]: ...
    @property
    def enter_slope(self) -> npt.NDArray[np.float32]: ...
    @property
    def leave_slope(self) -> npt.NDArray[np.float32]: ...
    @property
    def rival(self) -> npt.NDArray[np.float32]: ...
    @property
    def valid(self) -> npt.NDArray[np.bool_]: ...
    @property
    def ambiguous(self) -> npt.NDArray[np.bool_]: ...
    @property
    def clipped(self) -> npt.NDArray[np.bool_]: ...
    @property
    def shape(self) -> tuple[int, int]: ...

class SecondDips:
    """Every pixel's second candidate dip (the event whose depth is ``ShadowTimes.rival``);
    read-only float32 arrays (H, W) with ``ShadowTimes``' meanings (0 levels, NaN times where
    there is none), and the best dip's ``best_*`` times and slopes wherever it exists."""

    @property
    def imax(self) -> npt.NDArray[np.float32]: ...
    @property
    def imin(self) -> npt.NDArray[np.float32]: ...
    @property
    def contrast(self) -> npt.NDArray[np.float32]: ...
    @property
    def threshold(self) -> npt.NDArray[np.float32]: ...
    @property
    def enter(self) -> npt.NDArray[np.float32]: ...
    @property
    def leave(self) -> npt.NDArray[np.float32]: ...
    @property
    def enter_slope(self) -> npt.NDArray[np.float32]: ...
    @property
    def leave_slope(self) -> npt.NDArray[np.float32]: ...
    @property
    def best_enter(self) -> npt.NDArray[np.float32]: ...
    @property
    def best_leave(self) -> npt.NDArray[np.float32]: ...
    @property
    def best_enter_slope(self) -> npt.NDArray[np.float32]: ...
    @property
    def best_leave_slope(self) -> npt.NDArray[np.float32]: ...

class FinishedPixels:
    """Pixels whose dip ended (the live watch of :meth:`TemporalTracker.watch`); read-only
    1-D arrays, one entry per pixel, in row order.

    ``index`` (row-major ``y * width + x``) and ``frame`` (the frame whose sample
    confirmed the recovery): int64. ``imax`` (the lit level before the dip), ``imin``
    (the dip's darkest sample): DN of the input; ``threshold``: linear irradiance,
    ``(L(imax) + L(imin)) / 2`` (in the light of the dip); ``enter``, ``leave``:
    provisional sub-frame times (frames, NaN when the crossing has left the tracker's
    ring); ``enter_slope``, ``leave_slope``: linear units per frame: float32.
    """

    @property
    def index(self) -> npt.NDArray[np.int64]: ...
    @property
    def frame(self) -> npt.NDArray[np.int64]: ...
    @property
    def imax(self) -> npt.NDArray[np.float32]: ...
    @property
    def imin(self) -> npt.NDArray[np.float32]: ...
    @property
    def threshold(self) -> npt.NDArray[np.float32]: ...
    @property
    def enter(self) -> npt.NDArray[np.float32]: ...
    @property
    def leave(self) -> npt.NDArray[np.float32]: ...
    @property
    def enter_slope(self) -> npt.NDArray[np.float32]: ...
    @property
    def leave_slope(self) -> npt.NDArray[np.float32]: ...
    def __len__(self) -> int: ...

class TemporalTracker:
    """Streaming per-pixel shadow tracker: one shadow event (the deepest dip) per
    pixel; memory independent of the number of frames (see :mod:`gnomon.capture.tracking`).

    ``dtype``: the frames' dtype, ``"uint8"`` or ``"uint16"``. ``window``: half-width
    ``m`` (1..min(64, max_width)) of the sample windows kept around the enter and
    leave crossings. ``max_width``: ``W`` (2..128 frames), the widest dip always
    found and the separation of distinct dips; the ring holds ``3W + 2m`` frames.
    ``ambiguity``: in (0, 1]; a pixel whose second dip is at least this fraction of
    the deepest is ambiguous. ``lut``: the capture's decoding table, float32 DN →
    linear irradiance (256 or 65536 finite, non-decreasing entries; the identity if
    None), used for every linear value. ``normalise``: the light changes (the sun):
    every frame comes with its gain, the tracker compares the samples' decoded values
    divided by it and reports each dip in its own light (``lut`` required).
    ``second_dips``: also keep every pixel's second candidate dip for :meth:`finish_second`
    (off: the block pass is compiled without it, about a third cheaper per frame; the
    ``rival`` depth is tracked either way).
    """

    def __init__(
        self,
        height: int,
        width: int,
        dtype: Literal["uint8", "uint16"] = "uint8",
        window: int = 4,
        max_width: int = 32,
        ambiguity: float = 0.6,
        lut: npt.NDArray[np.float32] | None = None,
        normalise: bool = False,
        second_dips: bool = False,
    ) -> None: ...
    def update(self, frame: npt.NDArray[np.uint8] | npt.NDArray[np.uint16], gain: float | None = None,
               levels: npt.NDArray[np.float32] | None = None) -> None:
        """Add the next frame: a (height, width) array of the tracker's dtype, as decoded
        from its file (DN); with a normalised tracker, ``gain`` (> 0): the frame's light
        relative to the first frame's (required), otherwise None; ``levels`` (normalised
        tracker only): (height, width) float32 per-pixel factors (finite, > 0) on top of the
        gain, a sample stored as ``L(DN)/(gain·level)`` (a cloud frame levelled pixel by pixel,
        :mod:`gnomon.capture.cloud_levels`); a sample at the input's largest DN stays clipped."""
    def finish(self, min_contrast: float) -> ShadowTimes:
        """Per-pixel results for the frames seen so far (see :class:`ShadowTimes`); the tracker is unchanged.

        ``min_contrast``: DN of the input, in every mode.
        """
    def finish_second(self) -> SecondDips:
        """Every pixel's second candidate dip for the frames seen so far (see :class:`SecondDips`),
        in :meth:`finish`'s units; the tracker is unchanged. ``KernelParameterError`` unless the
        tracker was built with ``second_dips=True``."""
    def watch(self, min_contrast: float, recover: int = 3) -> None:
        """Start the live watch from the next frame on (replacing an earlier one).

        Per pixel: a sample ``min_contrast`` DN of the input (> 0) below the brightest so far
        opens a dip (normalised: the step that many DN span at mid-grey); ``recover``
        (1..255) consecutive samples at or above the mid-level between that lit level and
        the dip's minimum end it, and the pixel is *finished* (one dip per pixel). Its
        provisional times follow :meth:`finish`'s definitions on the frames still in the
        ring. The results of :meth:`finish` are unchanged.
        """
    def take_finished(self) -> FinishedPixels:
        """The pixels finished since the last call; ``KernelParameterError`` before :meth:`watch`."""
    @property
    def watch_counts(self) -> tuple[int, int, int] | None:
        """Pixels of the live watch ``(lit, in a dip, finished)``; None before :meth:`watch`."""
    @property
    def frames_seen(self) -> int: ...
    @property
    def shape(self) -> tuple[int, int]: ...
    @property
    def dtype(self) -> Literal["uint8", "uint16"]: ...
    @property
    def normalised(self) -> bool: ...
    @property
    def window(self) -> int: ...
    @property
    def max_width(self) -> int: ...
    @property
    def ambiguity(self) -> float: ...
    @property
    def second_dips(self) -> bool: ...
    @property
    def simd_path(self) -> Literal["avx2", "sse2", "portable"]: ...

def triangulate_depth(
    rays: npt.NDArray[np.float64],
    times: npt.NDArray[np.float32],
    planes: npt.NDArray[np.float64],
    min_cos: float = 1e-3,
) -> npt.NDArray[np.float32]:
    """(H, W) camera Z of :func:`triangulate`'s points (the same intersections, value for value), NaN where
    it gives none; without the points' x, y and the mask. Chunks of pixels in parallel, GIL released."""

def triangulate(
    rays: npt.NDArray[np.float64],
    times: npt.NDArray[np.float32],
    planes: npt.NDArray[np.float64],
    min_cos: float = 1e-3,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_]]:
    """Intersect each pixel's camera ray with the shadow plane at its shadow time.

    ``rays`` (H, W, 3) unit camera-frame rays; ``times`` (H, W) frames, NaN = none;
    ``planes`` (N, 4) rows ``[nx, ny, nz, d]`` of ``n·X = d`` per frame (camera
    frame; a NaN row = no plane), linearly interpolated (sign-aligned) between
    frames. Returns camera-frame points (H, W, 3) float32 (NaN where invalid) and
    the validity mask (H, W) bool. Invalid: time NaN or outside [0, N−1], a
    missing plane, ``|n·r| < min_cos``, or a point not in front of the camera.
    """


def grid_faces(
    valid: npt.NDArray[np.uint8],
    depth: npt.NDArray[np.float32],
    sigma: npt.NDArray[np.float32],
    max_relative_jump: float,
    sigma_factor: float = 5.0,
) -> npt.NDArray[np.int32]:
    """Faces (F, 3) of the grid mesh of the valid pixels of (H, W) maps, vertices
    numbered by the valid pixels' row-major rank: :func:`gnomon.geometry.meshing.grid_mesh`'s
    faces, element for element (float32 arithmetic)."""

def clean_faces(
    n_vertices: int, faces: npt.NDArray[np.int32], min_vertices: int,
    pixels: npt.NDArray[np.int64] | None = None, width: int = 0,
) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.int64]]:
    """Drop edge-connected pieces of fewer than ``min_vertices`` vertices and give each
    fan meeting only at a vertex its own copy: the new faces (F', 3) and the input
    vertex each new vertex copies (V',), as :func:`gnomon.geometry.meshing.remove_small_components`.
    ``pixels``: each vertex's row-major pixel (strictly increasing) in a grid ``width`` wide, for a mesh
    on the pixel grid: the same result through the grid's edge slots (faster); any other mesh as without."""

@overload
def obj_text(
    vertices: npt.NDArray[np.float64],
    vertex_decimals: int,
    uv: npt.NDArray[np.float64] | None,
    normals: npt.NDArray[np.float64] | None,
    faces: npt.NDArray[np.int64],
    as_parts: Literal[False] = False,
) -> bytes:
    """The ``v``/``vt``/``vn``/``f`` lines of :func:`gnomon.outputs.obj.write_obj`, byte for byte."""

@overload
def obj_text(
    vertices: npt.NDArray[np.float64],
    vertex_decimals: int,
    uv: npt.NDArray[np.float64] | None,
    normals: npt.NDArray[np.float64] | None,
    faces: npt.NDArray[np.int64],
    as_parts: Literal[True],
) -> list[npt.NDArray[np.uint8]]:
    """The same text as a list of uint8 arrays (its blocks in order, not copied)."""

def grid_normals(
    points: npt.NDArray[np.float32],
    depth: npt.NDArray[np.float32],
    valid: npt.NDArray[np.uint8],
    camera_centre: tuple[float, float, float],
    max_relative_jump: float,
) -> npt.NDArray[np.float32]:
    """Unit normals (H, W, 3) of the surface on the pixel grid, towards the camera, NaN off it:
    :func:`gnomon.geometry.meshing.grid_normals` (its numpy definition), rows in parallel, f64 arithmetic."""

def ray_plane_angles(
    rays: npt.NDArray[np.float64],
    times: npt.NDArray[np.float64],
    planes: npt.NDArray[np.float64],
    selected: npt.NDArray[np.uint8],
) -> npt.NDArray[np.float64]:
    """Angles (degrees) between the rays (H, W, 3) of the ``selected`` pixels (H, W) and their shadow
    planes (rows of ``planes`` (N, 4) interpolated at ``times`` (H, W)), row-major, NaN where a plane
    is missing: :func:`gnomon.geometry.surface.ray_plane_angles`; chunks of pixels in parallel."""

def depth_sigma(
    rays: npt.NDArray[np.float64],
    times: npt.NDArray[np.float32],
    planes: npt.NDArray[np.float64],
    depth: npt.NDArray[np.float32],
    sigma_t_pixel: npt.NDArray[np.float32],
    line_sigma: npt.NDArray[np.float64],
    line_fill: float,
    step: float,
    min_cos: float = 1e-3,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32], npt.NDArray[np.float32]]:
    """σZ, ∂Z/∂t and the line's time σ (each (H, W) float32) of every pixel: the depths at
    ``times ± step`` (``rays`` (H, W, 3), ``planes`` (N, 4), ``min_cos`` as :func:`triangulate`)
    against ``depth`` (H, W; NaN = none, σZ NaN there), the pixel's ``sigma_t_pixel`` (H, W) and
    ``line_sigma`` (N,) interpolated at its time (``line_fill`` where that is not finite), in the
    arithmetic of :func:`gnomon.geometry.uncertainty.depth_sigma`'s numpy definition; chunks of pixels in
    parallel."""

def completion_sigma(
    rays: npt.NDArray[np.float64],
    times: npt.NDArray[np.float64],
    depth: npt.NDArray[np.float64],
    planes: npt.NDArray[np.float64],
    line_point: npt.NDArray[np.float64],
    line_direction: npt.NDArray[np.float64],
    sigma_rad: float,
    min_cos: float = 1e-3,
) -> npt.NDArray[np.float32]:
    """The σZ (H, W) float32 (world units, camera Z) a completed plane's error of ``sigma_rad`` (a turn
    about its completing line, ``line_point``/``line_direction`` (N, 3), NaN rows measured) adds at each
    pixel of ``rays`` (H, W, 3) with ``depth`` (H, W) at plane row ``times`` (H, W), ``planes`` (N, 4); 0
    where none: :func:`gnomon.geometry.uncertainty.completion_depth_sigma`'s numpy definition, value for value;
    chunks of pixels in parallel."""

def isochrone_crossings(
    times: npt.NDArray[np.float32],
    n_frames: int,
    unique: bool = True,
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Where the shadow-time map ``times`` (H, W) float32 (frames, NaN = none) crosses each integer frame
    ``0 … n_frames − 1``, sub-pixel: ``(frame, u, v)`` (K,) each, as
    :func:`gnomon.geometry.reference_lines.isochrone_crossings`'s numpy definition gives them (the same values, in
    its order); lines in parallel."""

def frame_lines(
    xy: npt.NDArray[np.float64],
    bounds: npt.NDArray[np.int64],
    k: float,
    iterations: int,
    min_points: int,
    min_extent_to_rms: float,
    min_extent_fraction: float,
) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64],
           npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    """Every frame's own shadow line on a reference plane (:func:`gnomon.geometry.reference_lines.lines_on_plane`'s
    fits): ``xy`` (K, 2) crossings in plane coordinates grouped by frame, frame t's being
    ``bounds[t]:bounds[t + 1]`` (``bounds`` (N + 1,)). Each frame with ``min_points`` crossings is fitted
    (:func:`gnomon.util.fitting.fit_line_robust` with ``k``, ``iterations``); a fit that keeps ``min_points``
    inliers and is a line (extent ≥ ``min_extent_to_rms`` × RMS) and reaches ``min_extent_fraction`` of
    the 90th percentile of those lines' extents is accepted, its direction turned within 90° of the
    previous accepted one. Returns ``(accepted (N,), centre (N, 2), direction (N, 2) unit, rms (N,),
    count (N,), extent (N,), inliers (K,))``, NaN / 0 / False off the accepted lines; frames in
    parallel."""

def line_times(
    xy: npt.NDArray[np.float64],
    lines: npt.NDArray[np.float64],
    frames: npt.NDArray[np.int64],
    steps: int,
) -> npt.NDArray[np.float64]:
    """When a plane's shadow lines pass each of its points ``xy`` (K, 2) (plane coordinates): ``lines`` (N, 3)
    ``(n_x, n_y, offset)`` in sweep order (signed distance ``x·n_x + y·n_y − offset`` > 0 ahead of a line),
    ``frames`` (N,) theirs, ``steps`` bisection steps; the time interpolated between the bracketing pair,
    NaN where none brackets the point. Element for element
    :func:`gnomon.geometry.plane_times._times_at_points_numpy`; points in parallel."""

def deblock_interpolate(
    times: npt.NDArray[np.float32],
    value: npt.NDArray[np.float64],
    size: int,
    u0: int,
    v0: int,
    span_max: float,
) -> npt.NDArray[np.float32]:
    """A compressed video's shadow times ``times`` (H, W) float32 (frames, NaN = none) interpolated bilinearly
    between the centres of its ``size``-pixel codec blocks (the first whole block at column ``u0``, row ``v0``),
    ``value`` (blocks down, blocks across) each block's time (NaN: it does not count): a pixel between four
    finite centres spanning at most ``span_max`` frames, with a time of its own, takes their interpolation,
    every other keeps its time. Element for element :func:`gnomon.capture.deblock._interpolate_numpy`; rows
    in parallel."""

def lut_lookup(
    lut: npt.NDArray[np.float32],
    table: npt.NDArray[np.float64],
    scale: float,
    values: npt.NDArray[np.float32],
) -> npt.NDArray[np.float32]:
    """``(scale * table[np.searchsorted(lut, values).clip(0, N - 1)]).astype(np.float32)`` of the flat ``values``
    (K,): ``lut`` (N,) sorted (increasing, NaN last; else ``KernelParameterError``), ``table`` (N,) one value
    per entry. Element for element the numpy expression; values in parallel."""

def fuse_supported(
    depths: npt.NDArray[np.float32],
    sigmas: npt.NDArray[np.float32],
    max_relative_jump: float,
    min_support: int = 2,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32], npt.NDArray[np.uint8]]:
    """K depth estimates (K, H, W) with their σ fused by inverse variance
    (:func:`gnomon.reconstruct.fusion.fuse_depths`, Gaussian weights), then the fused depths no
    ``min_support`` of 8 neighbours share dropped
    (:func:`gnomon.geometry.triangulation.supported_by_neighbours`): (depth, σ) (H, W) NaN where not
    kept, and per pixel 0 no estimate, 1 kept, 2 conflict, 3 unsupported; rows in parallel."""

def noise_samples(
    a: npt.NDArray[np.uint8] | npt.NDArray[np.uint16],
    b: npt.NDArray[np.uint8] | npt.NDArray[np.uint16],
    min_inside: int,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32], float, float] | None:
    """The pixels of two flat frames of one integer dtype that :func:`gnomon.capture.noise.image_noise_dn` fits
    (both inside the range, neither 0 nor the maximum), in order: ``(diff, level, median, mad)``, ``diff = a − b``
    and ``level = ½(a + b) − mean`` in float32 as numpy computes them, the differences' median and MAD from their
    histogram; None when fewer than ``min_inside`` pixels are inside."""

def clipped_fit_step(
    diff: npt.NDArray[np.float32],
    level: npt.NDArray[np.float32],
    offset: float,
    gain: float,
    limit: float,
    min_kept: int,
) -> tuple[int, float, float, float] | None:
    """One step of :func:`gnomon.capture.noise.image_noise_dn`'s clipped fit of ``diff`` against ``level`` (N,):
    ``(kept, offset, gain, rms)`` of the pixels within ``limit`` of ``offset + gain·level`` (float32 values, as
    floats), each float32 operation and mean numpy's, in its order; None when fewer than ``min_kept`` are kept."""

def lit_median(stack: npt.NDArray[np.uint8], lit: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
    """(H, W, C): per pixel and channel the median of the ``stack`` (K, H, W, C; C 3 for RGB, 1 for grey) samples
    it is ``lit`` (K, H, W) in (all K where it is lit in none), ``(s[(n−1)//2] + s[n//2] + 1) // 2`` of the n
    sorted samples, as :meth:`gnomon.capture.texture.LitColour.finish` defines it; chunks of pixels in parallel."""

def lit_median_between(
    stack: npt.NDArray[np.uint8], times: npt.NDArray[np.float64], start: npt.NDArray[np.float64],
    end: npt.NDArray[np.float64], margin: float,
) -> npt.NDArray[np.uint8]:
    """:func:`lit_median` with each pixel's lit frames found from its shadow interval: kept frame k (capture frame
    ``times[k]``) is shadowed where ``min(s, e) − margin ≤ times[k] ≤ max(s, e) + margin``, ``s``, ``e`` the
    pixel's ``start`` and ``end`` (H, W) with a NaN one taken as the other (both NaN: never), as
    :meth:`gnomon.capture.texture.LitColour.finish` defines it."""

def world_points(
    rays: npt.NDArray[np.float64],
    depth: npt.NDArray[np.float32],
    valid: npt.NDArray[np.uint8],
    rotation: tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]]
    | npt.NDArray[np.float64],
    translation: tuple[float, float, float] | npt.NDArray[np.float64],
) -> npt.NDArray[np.float32]:
    """World-frame points (H, W, 3) of a camera depth map (H, W), NaN off ``valid``: each pixel's ray
    ``r`` at ``p = r·Z/r_z`` (rounded to float32), then ``Rᵀ·(p − t)`` (pose world → camera), as
    :func:`gnomon.geometry.surface.build_surface` defines them; rows in parallel."""

def ray_map(
    width: int,
    height: int,
    intrinsics: tuple[float, float, float, float],
    dist: tuple[float, float, float, float, float],
    tol_px: float,
    max_steps: int,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    """Unit camera-frame rays (H, W, 3) of every pixel centre of OpenCV's pinhole camera with
    distortion ``(k1, k2, p1, p2, k3)`` (``intrinsics`` = ``(fx, fy, cx, cy)`` in pixels), and the
    (H, W) mask of the pixels solved: Newton's method from the pinhole point, a pixel solved once its
    ray reprojects within ``tol_px`` pixels of it on the unfolded branch (det J > 0), NaN rays where
    not within ``max_steps`` steps; rows in parallel, GIL released. As
    :meth:`gnomon.camera.models.OpenCVCamera.ray_map` uses it."""

def stl_records(vertices: npt.NDArray[np.float32], faces: npt.NDArray[np.int32]) -> npt.NDArray[np.uint8]:
    """The (F·50,) bytes of a binary STL file's records (normal, corners, attribute 0; little-endian),
    as :func:`gnomon.outputs.stl.write_stl` writes them."""

def retime_rows(
    times: npt.NDArray[np.float64],
    index: npt.NDArray[np.int64],
    wanted: npt.NDArray[np.uint8],
    n_frames: int,
    max_gap: float,
    min_gap: float,
    backstep: float,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_], npt.NDArray[np.int64], npt.NDArray[np.int64],
           npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64],
           npt.NDArray[np.float64]]:
    """The rows of a shadow-time map oriented along the sweep (times rising to the right) re-timed
    between its isochrones, as :func:`gnomon.reconstruct.retiming.retime_between_isochrones` defines it: the
    times, the re-timed mask, and per re-timed pixel (row-major) its ``index`` value, the crossings'
    pixels (left, right), phases and rises, their gap and the pixel's fraction of it."""

def average_across(
    times: npt.NDArray[np.float32],
    retimed: npt.NDArray[np.uint8],
    across_rows: bool,
    half: int,
    bend: float,
) -> npt.NDArray[np.float32]:
    """(H, W) re-timed times averaged across the sweep, as :func:`gnomon.reconstruct.retiming.average_across_sweep`
    defines it (f64 in numpy's order, rounded to f32): ``across_rows`` the pixels ``v ± d`` of a column,
    else ``u ± d`` of a row; rows in parallel, GIL released."""

def retime_rows_sigma(
    times: npt.NDArray[np.float64],
    index: npt.NDArray[np.int64],
    wanted: npt.NDArray[np.uint8],
    sigma: npt.NDArray[np.float64],
    n_frames: int,
    max_gap: float,
    min_gap: float,
    backstep: float,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_], npt.NDArray[np.float32]]:
    """:func:`retime_rows` and each pixel's time σ (``sigma``: every pixel's own σ in the caller's image,
    flat, indexed by ``index``'s values), as :meth:`gnomon.reconstruct.retiming.RetimedTimes.sigma` defines it:
    the times, the re-timed mask and the σ, each (H, W) and oriented as given."""
