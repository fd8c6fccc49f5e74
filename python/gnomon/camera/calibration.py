"""Camera calibration from chessboard photos, and the camera file.

* :func:`detect_chessboard` — automatic corner detection
  (``cv2.findChessboardCornersSB``, then ``cv2.cornerSubPix`` with a window
  sized to the board's squares in the image).
* :func:`calibrate_zhang` — Zhang's multi-view method through OpenCV
  (``cv2.calibrateCameraExtended``, 5 coefficients k1, k2, p1, p2, k3), with
  per-view reprojection errors, parameter standard deviations and rejection of
  outlier views.
* :func:`calibrate_images` — photos → :class:`CameraCalibration`, with either
  Zhang's method or our Tsai implementation (:mod:`gnomon.camera.tsai`); a video of
  the board stands for its sharp, distinct frames (:func:`views_from_video`).
* :func:`write_camera_file`, :func:`load_camera_file`, :func:`camera_from_table` —
  the camera file (TOML) that field logs reference.

Conventions: pixel centres at integer coordinates; the board's inner corners
are at ``(i·square, j·square, 0)`` in OpenCV's order (i < cols fastest);
``--board COLSxROWS`` counts *inner* corners, as OpenCV's ``patternSize``.
Reprojection errors are RMS lengths of the 2D residual vectors (pixels), as
OpenCV reports them (for isotropic noise σ per axis that is ≈ σ·√2).

Camera file format (TOML; lengths in the board's units where any)::

    model = "opencv"             # or "tsai"
    width = 1280                 # pixels
    height = 960
    # model = "opencv": pixels; dist = [k1, k2, p1, p2, k3] on normalised coordinates
    fx = 1050.2
    fy = 1048.1
    cx = 647.0
    cy = 474.2
    dist = [-0.12, 0.08, 0.0004, -0.0003, -0.02]
    # model = "tsai": f_mm (mm), kappa1 (1/mm², Xu = Xd·(1 + kappa1·r²)),
    # cx, cy (pixels), sx (-), dx_mm, dy_mm (frame-buffer pixel pitch, mm)

    [calibration]                # optional: how the numbers were obtained
    method = "zhang"             # "zhang" | "zhang-coplanar" | "tsai-coplanar" | "tsai-views" | ... (+ "+full")
    rms_px = 0.28                # over the views used
    n_views = 12
    images = ["a.png", ...]      # views used, and their RMS:
    per_view_rms_px = [0.27, ...]
    rejected = ["k.png"]         # outlier views, and their RMS before rejection
    rejected_rms_px = [2.4]
    skipped = ["blank.png"]      # no board found
    board = "9x6"                # inner corners
    square = 25.0                # board units

    [calibration.std]            # 1-σ standard deviations of the parameters
    fx = 0.9                     # (opencv: fx fy cx cy k1 k2 p1 p2 k3;
    ...                          #  tsai: f_mm kappa1 [cx cy sx])

The field log's inline ``[camera]`` uses the same keys.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from gnomon.camera.models import OpenCVCamera, Pose, TsaiCamera
from gnomon.capture.frames import FrameSource, apply_exif_orientation, decode_jpeg, exif_orientation, to_grey
from gnomon.errors import GnomonError
from gnomon.util import toml_io

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".pgm", ".ppm", ".webp")
OPENCV_STD_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
MIN_ZHANG_VIEWS = 3

_OPENCV_KEYS = {"model", "width", "height", "fx", "fy", "cx", "cy", "dist"}
_TSAI_KEYS = {"model", "width", "height", "f_mm", "kappa1", "cx", "cy", "sx", "dx_mm", "dy_mm"}
_SB_FLAGS = cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
_LM_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)


# --------------------------------------------------------------------------- boards and images


def parse_board(text: str) -> tuple[int, int]:
    """``"9x6"`` → (9, 6): inner corners per row (cols) and per column (rows)."""
    try:
        cols, rows = (int(x) for x in str(text).lower().replace("×", "x").split("x"))
    except ValueError:
        raise GnomonError(f"board '{text}': expected COLSxROWS inner corners, e.g. 9x6") from None
    if cols < 2 or rows < 2:
        raise GnomonError(f"board '{text}': needs at least 2x2 inner corners")
    return cols, rows


def board_points(cols: int, rows: int, square: float) -> np.ndarray:
    """Inner-corner coordinates (cols·rows, 3) on the board plane (board units), OpenCV's order."""
    i, j = np.meshgrid(np.arange(cols, dtype=np.float64), np.arange(rows, dtype=np.float64))
    return np.stack([i.ravel() * square, j.ravel() * square, np.zeros(i.size)], axis=1)


def read_grey(path: str | os.PathLike) -> np.ndarray:
    """Read an image file as a 2-D grey array (uint8 or uint16), upright by its EXIF orientation.

    Unreadable, or a JPEG whose data is corrupt inside (:func:`gnomon.capture.frames.decode_jpeg`) →
    GnomonError naming it.
    """
    p = Path(path)
    if not p.is_file():
        raise GnomonError(f"{p}: image not found")
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise GnomonError(f"{p}: cannot be read ({exc.strerror})") from None
    if raw.startswith(b"\xff\xd8"):  # a JPEG: decoded strictly (its luma)
        grey = decode_jpeg(p, raw, colour=False)
        if grey is not None:
            return grey
    flags = cv2.IMREAD_ANYDEPTH | cv2.IMREAD_GRAYSCALE | cv2.IMREAD_IGNORE_ORIENTATION
    img = cv2.imdecode(np.frombuffer(raw, np.uint8), flags)
    if img is None:
        from gnomon.capture.frames import unsupported_format

        raise GnomonError(f"{p}: {unsupported_format(raw) or 'not a readable image'}")
    return apply_exif_orientation(img, exif_orientation(raw))


CROPS = ("centre", "center")
"""``[camera] crop`` values: the frames are the sensor's largest centred crop of their aspect ratio."""


def other_aspect(calibrated: tuple[int, int], frames: tuple[int, int]) -> bool:
    """Whether frames of ``frames`` (width, height) pixels have another aspect ratio than a camera calibrated
    at ``calibrated`` (width, height): their scale factors differ by more than 1 % (a crop of the sensor,
    not a resampling; :func:`fit_camera_to_frames`)."""
    sw, sh = frames[0] / calibrated[0], frames[1] / calibrated[1]
    return abs(sw / sh - 1.0) > 0.01


def fit_camera_to_frames(
    camera: OpenCVCamera | TsaiCamera, width: int, height: int, where: str, frame_name: str = "frame 0",
    crop: str | None = None,
) -> tuple[OpenCVCamera | TsaiCamera, str | None]:
    """The camera for frames of ``width × height`` pixels: as it is, or rescaled from its own size.

    Intrinsics calibrated on stills at another resolution of the same sensor
    (same aspect ratio, within 1 %) are rescaled: focal lengths and pixel
    pitch by the size ratio, the centre with pixel centres at integer
    coordinates (``c' = (c + ½)·s − ½``); distortion is unchanged (it acts on
    normalised or sensor coordinates). Returns (camera, a note saying so, or
    None). Another aspect ratio means the video is a crop of the sensor, which
    no rescaling fixes: GnomonError, one line naming the frame and ``where``,
    unless ``crop`` is ``"centre"``: the frames are then taken as the largest
    centred crop of the calibrated image with their aspect ratio (a phone's
    16:9 video against its 3:2 or 4:3 photos), scaled to their size: the crop's
    origin ``o`` (pixel edges, calibrated pixels) moves the centre,
    ``c' = (c + ½ − o)·s − ½``. That is an assumption about the camera (some
    phones crop further to stabilise): the marks' fit checks it
    (``gnomon preview``, ``gnomon calibrate focal``).
    """
    w0, h0 = int(camera.width), int(camera.height)
    if (w0, h0) == (int(width), int(height)):
        return camera, None
    if crop is not None and crop not in CROPS:
        raise GnomonError(f"{where}: crop: expected \"centre\", got {crop!r}")
    sw, sh = width / w0, height / h0
    ox = oy = 0.0
    if other_aspect((w0, h0), (width, height)):
        if crop is None:
            raise GnomonError(
                f"{frame_name} is {width}x{height} but the camera's {w0}x{h0} ({where}) has another aspect ratio "
                f"({w0 / h0:.3f} vs {width / height:.3f}): the frames are a crop of the sensor, which rescaling "
                "cannot fix; calibrate the camera from frames of the capture itself (a video of the board in the "
                "same video mode: gnomon calibrate camera BOARD.mp4 ...), or, if they are its centred "
                "crop (a phone's video against its photos), add crop = \"centre\" to [camera] and check the "
                "marks' fit (gnomon preview)"
            )
        # the largest centred crop of the calibrated image with the frames' aspect ratio
        cw, ch = (w0, w0 * height / width) if width / height > w0 / h0 else (h0 * width / height, h0)
        ox, oy = (w0 - cw) / 2.0, (h0 - ch) / 2.0
        sw = sh = width / cw
    if isinstance(camera, OpenCVCamera):
        new: OpenCVCamera | TsaiCamera = OpenCVCamera(
            width=int(width), height=int(height), fx=camera.fx * sw, fy=camera.fy * sh,
            cx=(camera.cx + 0.5 - ox) * sw - 0.5, cy=(camera.cy + 0.5 - oy) * sh - 0.5, dist=camera.dist,
        )
    else:
        new = TsaiCamera(
            width=int(width), height=int(height), f_mm=camera.f_mm, kappa1=camera.kappa1,
            cx=(camera.cx + 0.5 - ox) * sw - 0.5, cy=(camera.cy + 0.5 - oy) * sh - 0.5,
            dx_mm=camera.dx_mm / sw, dy_mm=camera.dy_mm / sh, sx=camera.sx,
        )
    if ox or oy:
        return new, (f"{where}: camera calibrated at {w0}x{h0}, taken as its centred {w0 - 2 * ox:.0f}x"
                     f"{h0 - 2 * oy:.0f} crop scaled to the frames' {width}x{height}")
    return new, f"{where}: camera calibrated at {w0}x{h0}, rescaled to the frames' {width}x{height}"


def to_grey_u8(image: np.ndarray) -> np.ndarray:
    """Any grey or BGR image → 8-bit grey (16-bit and float data are stretched over their range, which
    helps the chessboard detector on dim 16-bit photos)."""
    img = to_grey(np.asarray(image))
    if img.dtype == np.uint8:
        return img
    f = img.astype(np.float64)
    lo, hi = float(np.nanmin(f)), float(np.nanmax(f))
    return np.clip(np.rint((f - lo) * (255.0 / max(hi - lo, 1e-12))), 0, 255).astype(np.uint8)


def expand_image_args(items: Sequence[str | os.PathLike]) -> list[Path]:
    """Command-line image arguments → files: a directory stands for its images, in natural order; a
    pattern (``"calib/*.jpg"``) for the files it matches (:func:`gnomon.capture.frames.expand_glob_argument`)."""
    from gnomon.capture.frames import expand_glob_argument, natural_key

    out: list[Path] = []
    for it in items:
        p = Path(it)
        matched = expand_glob_argument(it, "image")
        if matched is not None:
            out.extend(matched)
        elif p.is_dir():
            found = sorted((q for q in p.iterdir() if q.suffix.lower() in IMAGE_SUFFIXES), key=natural_key)
            if not found:
                heif = [q.name for q in p.iterdir() if q.suffix.lower() in (".heic", ".heif", ".avif")]
                why = (f"; {heif[0]} and the like are HEIF/AVIF, which is not read: export them as JPEG or PNG"
                       if heif else "")
                raise GnomonError(f"{p}: directory holds no images ({', '.join(IMAGE_SUFFIXES)}){why}")
            out.extend(found)
        else:
            out.append(p)
    return out


def _canonical_order(corners: np.ndarray, found: tuple[int, int], board: tuple[int, int]) -> np.ndarray:
    """Corners found with ``patternSize = found`` → OpenCV's order for ``board`` (cols, rows).

    A board found with its sides swapped, (rows, cols), is transposed, then one
    axis reversed so that the grid keeps the handedness OpenCV reports for a
    board found directly: the first row's direction turned by +90° (image
    x right, y down) points along the columns. That is a 90° turn of the board,
    never a mirror image.
    """
    cols, rows = board
    if found == board:
        return corners
    g = corners.reshape(found[1], found[0], 2).transpose(1, 0, 2)  # (rows, cols, 2)
    if _handedness(g) < 0:
        g = g[:, ::-1]
    return np.ascontiguousarray(g.reshape(-1, 2))


def _handedness(grid: np.ndarray) -> float:
    a = grid[0, -1] - grid[0, 0]
    b = grid[-1, 0] - grid[0, 0]
    return float(a[0] * b[1] - a[1] * b[0])


# Detector settings tried in turn: OpenCV's most accurate first; on some real
# photos (JPEG, uneven light) CALIB_CB_ACCURACY / NORMALIZE_IMAGE make the
# sector-based detector miss a board it finds without them, and the classic
# detector is the last resort.
_SB_FALLBACK_FLAGS = (_SB_FLAGS, cv2.CALIB_CB_EXHAUSTIVE)
_CLASSIC_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE


def _find_board(grey: np.ndarray, board: tuple[int, int], *, sb_flags: tuple[int, ...] = _SB_FALLBACK_FLAGS,
                classic: bool = True, classic_flags: int = _CLASSIC_FLAGS) -> np.ndarray | None:
    """The board's corners in ``board``'s order, found in either orientation: the sector detector with each
    of ``sb_flags`` in turn, then (``classic``) the classic detector with ``classic_flags``; None when none
    finds it."""
    cols, rows = board
    sizes = [(cols, rows)] if cols == rows else [(cols, rows), (rows, cols)]
    for flags in sb_flags:
        for size in sizes:
            ok, corners = cv2.findChessboardCornersSB(grey, size, flags=flags)
            if ok and corners is not None:
                return _canonical_order(corners.reshape(-1, 2).astype(np.float64), size, board)
    for size in sizes if classic else ():
        ok, corners = cv2.findChessboardCorners(grey, size, flags=classic_flags)
        if ok and corners is not None:
            pts = corners.reshape(-1, 2).astype(np.float64)
            g = pts.reshape(size[1], size[0], 2)
            if _handedness(g) < 0:  # the classic detector may report either handedness
                pts = np.ascontiguousarray(g[:, ::-1].reshape(-1, 2))
            return _canonical_order(pts, size, board)
    return None


DETECT_PX = 1000
"""A photo's long side for finding the board (then refined at full size): OpenCV's detectors' time grows
with the pixels, and a board that calibrates has squares of tens of pixels at that size."""


def detect_chessboard(image: np.ndarray, board: tuple[int, int], *, refine: bool = True) -> np.ndarray | None:
    """Find the chessboard's inner corners: (cols·rows, 2) pixels in OpenCV's order, or None.

    First fast (:func:`_find_board_quick`): on the photo scaled to ``DETECT_PX`` on its long side, OpenCV's
    classic detector, then its sector detector with plain settings; found there, the corners are scaled
    back and refined on the full-size photo. Where neither finds the board (as on some real JPEG photos),
    the full-size chain: ``cv2.findChessboardCornersSB`` with OpenCV's accurate settings first and plainer
    ones next, then the classic detector (seconds per photo at 1080p, tens of seconds at 12 Mpx). The board
    is found in either orientation (``board`` or its sides swapped, reordered to ``board``'s order, see
    :func:`_canonical_order`). ``cv2.cornerSubPix`` then refines each corner in a window of 0.4× the
    smallest corner spacing (larger windows average more gradient; on our rendered views this halves the
    SB detector's error, to ≈0.03–0.06 px RMS); from either start it converges to the same corner.
    """
    grey = to_grey_u8(image)
    pts = _find_board_quick(grey, board)
    if pts is not None:
        return refine_corners(grey, pts, board) if refine else pts
    pts = _find_board(grey, board)
    if pts is None:
        return None
    if not refine:
        return pts
    return refine_corners(grey, pts, board)


def _find_board_quick(grey: np.ndarray, board: tuple[int, int], classic: bool = True) -> np.ndarray | None:
    """The board's corners found on ``grey`` scaled to ``DETECT_PX`` (with ``classic`` the classic detector
    with its quick check first, then the sector detector's plain settings), in full-size pixels, not refined;
    None when not found."""
    h, w = grey.shape[:2]
    scale = min(1.0, DETECT_PX / max(w, h))
    small = grey if scale == 1.0 else cv2.resize(grey, (round(w * scale), round(h * scale)),
                                                  interpolation=cv2.INTER_AREA)
    pts = None
    if classic:
        pts = _find_board(small, board, sb_flags=(), classic_flags=_CLASSIC_FLAGS | cv2.CALIB_CB_FAST_CHECK)
    if pts is None:
        pts = _find_board(small, board, sb_flags=(cv2.CALIB_CB_NORMALIZE_IMAGE,), classic=False)
    if pts is None:
        return None
    return _origin_as_sector_detector(grey, (pts + 0.5) / scale - 0.5, board)  # pixel centres: (x + 0.5)/s − 0.5


def _origin_as_sector_detector(grey: np.ndarray, pts: np.ndarray, board: tuple[int, int]) -> np.ndarray:
    """Corners ``pts`` in OpenCV's order, turned by a half-turn (reversed) where needed so that the board's
    origin is where the sector detector puts it: on a board that a half-turn changes (cols and rows of
    different parity, e.g. 9x6), the corner whose square diagonally outside the board is the lighter (the
    classic detector reports the other end). A chessboard on a reference plane fixes the plane's frame
    by that origin. A board a half-turn leaves alike (e.g. 8x6) is returned as it is."""
    cols, rows = board
    if (cols - rows) % 2 == 0:
        return pts
    g = pts.reshape(rows, cols, 2)
    first = g[0, 0] - (g[0, 1] - g[0, 0]) / 2 - (g[1, 0] - g[0, 0]) / 2  # the square outside corner 0
    last = g[-1, -1] + (g[-1, -1] - g[-1, -2]) / 2 + (g[-1, -1] - g[-2, -1]) / 2

    def level(p: np.ndarray) -> float:
        return float(cv2.getRectSubPix(grey, (5, 5), (float(p[0]), float(p[1]))).mean())
    return pts if level(first) >= level(last) else np.ascontiguousarray(pts[::-1])


def refine_corners(grey: np.ndarray, pts: np.ndarray, board: tuple[int, int]) -> np.ndarray:
    """Corners ``pts`` (cols·rows, 2) of ``board`` in OpenCV's order, refined to sub-pixel on the 8-bit
    ``grey`` image by ``cv2.cornerSubPix`` (see :func:`detect_chessboard`)."""
    cols, rows = board
    grid = pts.reshape(rows, cols, 2)
    spacing = min(
        float(np.linalg.norm(np.diff(grid, axis=0), axis=2).min()),
        float(np.linalg.norm(np.diff(grid, axis=1), axis=2).min()),
    )
    win = int(np.clip(np.floor(0.4 * spacing), 2, 15))
    refined = cv2.cornerSubPix(grey, pts.astype(np.float32).reshape(-1, 1, 2), (win, win), (-1, -1), _SUBPIX_CRITERIA)
    refined = refined.reshape(-1, 2).astype(np.float64)
    # cornerSubPix can slide off a corner in a blurred or cluttered window: keep SB's there.
    moved = np.linalg.norm(refined - pts, axis=1) > 0.25 * spacing
    refined[moved] = pts[moved]
    return refined


# --------------------------------------------------------------------------- Zhang


@dataclass(frozen=True)
class ZhangResult:
    """Zhang's calibration of the views kept.

    ``names``/``per_view_rms_px``/``poses`` for the views used (board → camera
    poses); ``rejected`` = ((name, rms_px before rejection), ...); ``std`` the
    1-σ standard deviations of fx, fy, cx, cy, k1, k2, p1, p2, k3 (OpenCV's,
    from the Jacobian and the residual variance).
    """

    camera: OpenCVCamera
    rms_px: float
    names: tuple[str, ...]
    per_view_rms_px: tuple[float, ...]
    poses: tuple[Pose, ...]
    std: dict[str, float]
    rejected: tuple[tuple[str, float], ...] = ()
    warnings: tuple[str, ...] = ()


def _zhang_once(objs, pixs, size, flags, K0=None):
    K0 = np.eye(3) if K0 is None else np.asarray(K0, dtype=np.float64)
    d0 = np.zeros(5)
    o = [np.ascontiguousarray(x, dtype=np.float32).reshape(-1, 1, 3) for x in objs]
    p = [np.ascontiguousarray(x, dtype=np.float32).reshape(-1, 1, 2) for x in pixs]
    try:
        rms, K, dist, rvecs, tvecs, std_i, _std_e, _per_view = cv2.calibrateCameraExtended(
            o, p, size, K0, d0, flags=flags, criteria=_LM_CRITERIA
        )
    except cv2.error as exc:  # degenerate views (e.g. all alike) make OpenCV give up
        raise GnomonError(f"Zhang's calibration failed on these views: {exc.err}") from None
    dist = np.asarray(dist, dtype=np.float64).ravel()[:5]
    cam = OpenCVCamera(
        width=int(size[0]),
        height=int(size[1]),
        fx=float(K[0, 0]),
        fy=float(K[1, 1]),
        cx=float(K[0, 2]),
        cy=float(K[1, 2]),
        dist=_dist5(dist),
    )
    poses = [Pose.from_rvec_tvec(r, t) for r, t in zip(rvecs, tvecs, strict=True)]
    # Our own per-view RMS in float64 (length of the 2D residual, as OpenCV's).
    per_view = []
    for obj, pix, pose in zip(objs, pixs, poses, strict=True):
        projected = cam.project(pose.world_to_camera(np.asarray(obj, dtype=np.float64)))
        res = np.asarray(pix, dtype=np.float64).reshape(-1, 2) - projected
        per_view.append(float(np.sqrt(np.mean(np.sum(res * res, axis=1)))))
    std_i = np.asarray(std_i, dtype=np.float64).ravel()
    std = {k: float(std_i[i]) for i, k in enumerate(OPENCV_STD_NAMES)}
    if flags == PAPER_MODEL_FLAGS:  # OpenCV reports no σ for a focal length of fixed aspect
        std.update(_paper_model_std(cam, objs, pixs, rvecs, tvecs))
    fixed = {"cx": cv2.CALIB_FIX_PRINCIPAL_POINT, "cy": cv2.CALIB_FIX_PRINCIPAL_POINT, "k1": cv2.CALIB_FIX_K1,
             "k2": cv2.CALIB_FIX_K2, "k3": cv2.CALIB_FIX_K3, "p1": cv2.CALIB_ZERO_TANGENT_DIST,
             "p2": cv2.CALIB_ZERO_TANGENT_DIST}
    std = {k: v for k, v in std.items() if not flags & fixed.get(k, 0)}  # a parameter held has no σ
    all_sq = sum(r * r * len(o) for r, o in zip(per_view, objs, strict=True))
    total = float(np.sqrt(all_sq / sum(len(o) for o in objs)))
    return cam, total, per_view, poses, std


def calibrate_zhang(
    object_points: Sequence[np.ndarray],
    image_points: Sequence[np.ndarray],
    image_size: tuple[int, int],
    *,
    names: Sequence[str] | None = None,
    fix_k3: bool = False,
    reject_factor: float = 3.0,
    reject_floor_px: float = 0.5,
    min_views: int = MIN_ZHANG_VIEWS,
    paper_model: bool = False,
) -> ZhangResult:
    """Zhang's multi-view calibration through OpenCV, with outlier views rejected.

    ``object_points``: per view (N, 3) board coordinates (z = 0, board units);
    ``image_points``: per view (N, 2) pixels; ``image_size``: (width, height).
    A view whose RMS exceeds ``max(reject_factor × median RMS, reject_floor_px)``
    is dropped, worst first, recalibrating after each, while more than
    ``min_views`` remain; each drop is a warning. ``fix_k3`` holds k3 at 0
    (advisable for narrow fields of view). Fewer than ``min_views`` views → GnomonError.

    ``paper_model``: the model of Bouguet & Perona's set-up, where every view of the board lies in one
    plane (:data:`PAPER_MODEL_FLAGS`): the principal point held at the image centre, square pixels
    (fx = fy), k1 the only distortion; started from the focal length the views' homographies give
    (:func:`focal_from_homographies`). σ is then given for fx, fy and k1 only (the others are held).
    """
    n = len(object_points)
    names = list(names) if names is not None else [f"view {i}" for i in range(n)]
    if n < min_views:
        raise GnomonError(f"Zhang's calibration needs at least {min_views} views with a board, got {n}")
    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    K0 = None
    if paper_model:
        flags = PAPER_MODEL_FLAGS
        centre = ((image_size[0] - 1) / 2.0, (image_size[1] - 1) / 2.0)
        f0 = focal_from_homographies(object_points, image_points, centre) or float(max(image_size))
        K0 = np.array([[f0, 0.0, centre[0]], [0.0, f0, centre[1]], [0.0, 0.0, 1.0]])
    keep = list(range(n))
    rejected: list[tuple[str, float]] = []
    warns: list[str] = []
    while True:
        cam, rms, per_view, poses, std = _zhang_once([object_points[i] for i in keep],
                                                     [image_points[i] for i in keep], image_size, flags, K0)
        med = float(np.median(per_view))
        limit = max(reject_factor * med, reject_floor_px)
        worst = int(np.argmax(per_view))
        if per_view[worst] <= limit:
            break
        if len(keep) <= min_views:
            warns.append(
                f"{names[keep[worst]]}: reprojection RMS {per_view[worst]:.2f} px is an outlier (> {limit:.2f} px) "
                f"but only {len(keep)} views are left: kept"
            )
            break
        name = names[keep[worst]]
        rejected.append((name, per_view[worst]))
        warns.append(
            f"{name}: rejected as an outlier view (reprojection RMS {per_view[worst]:.2f} px > {limit:.2f} px = "
            f"max({reject_factor:g}× median {med:.2f}, {reject_floor_px:g}))"
        )
        keep.pop(worst)
    return ZhangResult(
        camera=cam,
        rms_px=rms,
        names=tuple(names[i] for i in keep),
        per_view_rms_px=tuple(per_view),
        poses=tuple(poses),
        std=std,
        rejected=tuple(rejected),
        warnings=tuple(warns),
    )


PAPER_MODEL_FLAGS = (cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_PRINCIPAL_POINT | cv2.CALIB_FIX_ASPECT_RATIO
                     | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3)
"""OpenCV's flags for the paper's camera: principal point at the image centre, square pixels, k1 only."""

COPLANAR_DEG = 5.0
"""Views whose board normals all lie within this angle (degrees) of each other are one plane's: the focal
length and the principal point cannot both be found from them (Zhang's method needs the board turned)."""


def _paper_model_std(cam: OpenCVCamera, objs, pixs, rvecs, tvecs) -> dict[str, float]:
    """1-σ of the paper model's fitted parameters (f as fx and fy, k1), as OpenCV's σ: from the Jacobian of
    the projections (``cv2.projectPoints``) in f, k1 and every view's pose, and the residuals' variance
    (their sum of squares over the 2N − P degrees of freedom)."""
    K, dist = cam.K, np.asarray(cam.dist, dtype=np.float64)
    blocks, residuals = [], []
    for obj, pix, r, t in zip(objs, pixs, rvecs, tvecs, strict=True):
        o = np.asarray(obj, dtype=np.float64).reshape(-1, 1, 3)
        proj, jac = cv2.projectPoints(o, np.asarray(r, np.float64), np.asarray(t, np.float64), K, dist)
        residuals.append(np.asarray(pix, dtype=np.float64).reshape(-1, 2) - proj.reshape(-1, 2))
        # columns: rvec (3), tvec (3), fx, fy, cx, cy, k1, k2, p1, p2, k3
        blocks.append((jac[:, 6] + jac[:, 7] * (cam.fy / cam.fx), jac[:, 10], jac[:, :6]))
    n_views = len(blocks)
    rows = sum(len(b[0]) for b in blocks)
    J = np.zeros((rows, 2 + 6 * n_views))
    at = 0
    for k, (df, dk1, dpose) in enumerate(blocks):
        J[at:at + len(df), 0], J[at:at + len(df), 1] = df, dk1
        J[at:at + len(df), 2 + 6 * k:8 + 6 * k] = dpose
        at += len(df)
    r = np.concatenate(residuals).ravel()
    dof = max(rows - J.shape[1], 1)
    cov = float(r @ r) / dof * np.linalg.pinv(J.T @ J)
    sf, sk1 = float(np.sqrt(cov[0, 0])), float(np.sqrt(cov[1, 1]))
    return {"fx": sf, "fy": sf * cam.fy / cam.fx, "k1": sk1}


def focal_from_homographies(object_points: Sequence[np.ndarray], image_points: Sequence[np.ndarray],
                            centre: tuple[float, float]) -> float | None:
    """The focal length (px) that makes every view's board-to-image homography a rotation, for square
    pixels and the principal point at ``centre`` (lens distortion ignored: a starting value); None when
    the views do not fix it (a board seen face-on).

    With pixels taken from ``centre``, a homography's columns h1, h2 are K·r1, K·r2 up to scale, and
    r1 ⟂ r2, |r1| = |r2| give, with u = 1/f², (h11·h12 + h21·h22)·u + h31·h32 = 0 and
    (h11² + h21² − h12² − h22²)·u + h31² − h32² = 0: u by least squares over the views (Zhang 2000, with
    the principal point known).
    """
    rows = []
    for obj, pix in zip(object_points, image_points, strict=True):
        found = cv2.findHomography(np.asarray(obj, np.float64)[:, :2], np.asarray(pix, np.float64) - centre)[0]
        H = np.asarray(found, dtype=np.float64) if found is not None else np.zeros((0, 0))  # None: degenerate
        if H.shape != (3, 3):
            continue
        H = H / np.linalg.norm(H)
        (a, b, _), (c, d, _), (e, g, _) = H
        rows += [(a * b + c * d, e * g), (a * a + c * c - b * b - d * d, e * e - g * g)]
    if not rows:
        return None
    m = np.asarray(rows)
    u = -float(m[:, 0] @ m[:, 1]) / float(m[:, 0] @ m[:, 0])
    return 1.0 / np.sqrt(u) if np.isfinite(u) and u > 0 else None


def normal_spread_deg(poses: Sequence[Pose]) -> float:
    """The largest angle (degrees) between two views' board normals (board → camera poses)."""
    n = np.array([p.R[:, 2] for p in poses])
    cos = np.clip(np.abs(n @ n.T), -1.0, 1.0)  # a board's normal up to its sign
    return float(np.degrees(np.arccos(cos.min()))) if len(n) > 1 else 0.0


def calibrate_views(
    object_points: Sequence[np.ndarray],
    image_points: Sequence[np.ndarray],
    image_size: tuple[int, int],
    *,
    names: Sequence[str] | None = None,
    fix_k3: bool = False,
    reject_factor: float = 3.0,
) -> tuple[ZhangResult, str, float]:
    """Zhang's calibration of the views, or, when they all lie in one plane, the paper's.

    The paper's model (:func:`calibrate_zhang` with ``paper_model``) is fitted first; when its board
    normals all lie within ``COPLANAR_DEG`` of each other (:func:`normal_spread_deg`), the views are one
    plane's (a board moved about on a desk, as in Bouguet & Perona's set-up): the focal length and the
    principal point are not observable together there (Zhang's full model fits absurd focal lengths and a
    distortion it cannot invert), so the paper's model is the result, with a warning that names the case
    and its numbers. Otherwise Zhang's full model. Returns (result, method, normal spread in degrees):
    method "zhang" or "zhang-coplanar".
    """
    paper = calibrate_zhang(object_points, image_points, image_size, names=names, reject_factor=reject_factor,
                            paper_model=True)
    spread = normal_spread_deg(paper.poses)
    if spread >= COPLANAR_DEG:
        full = calibrate_zhang(object_points, image_points, image_size, names=names, fix_k3=fix_k3,
                               reject_factor=reject_factor)
        return full, "zhang", spread
    cam, std = paper.camera, paper.std
    w = (f"all {len(paper.names)} views show the board in one plane (their board normals lie within {spread:.2g}° "
         f"of each other; Zhang's method needs the board turned by more than {COPLANAR_DEG:g}° between views): "
         "the focal length and the principal point cannot both be found from them, so the camera is the "
         "paper's: principal point at the image centre, square pixels, k1 the only distortion: "
         f"f = {cam.fx:.1f} ± {std['fx']:.2g} px, k1 = {cam.dist[0]:.4f} ± {std['k1']:.2g} (σ of the corners' "
         "noise only: a principal point off the centre biases f); for a full calibration add photos of the "
         "board tilted (held up, propped at 20–50°)")
    return replace(paper, warnings=paper.warnings + (w,)), "zhang-coplanar", spread


# --------------------------------------------------------------------------- photos → camera


@dataclass(frozen=True)
class CameraCalibration:
    """A calibrated camera and how it was obtained: what a camera file holds.

    ``method``: "zhang", "zhang-coplanar" (all views in one plane: :func:`calibrate_views`), or
    "tsai-coplanar" / "tsai-views" (+ "+full");
    ``names``/``per_view_rms_px``/``poses``: the views used (board → camera);
    ``rejected``: ((name, rms_px), ...) outlier views; ``skipped``: images
    without a board; ``std``: 1-σ parameter standard deviations.
    """

    camera: OpenCVCamera | TsaiCamera
    method: str
    rms_px: float
    names: tuple[str, ...]
    per_view_rms_px: tuple[float, ...]
    poses: tuple[Pose, ...]
    std: dict[str, float]
    board: tuple[int, int]
    square: float
    rejected: tuple[tuple[str, float], ...] = ()
    skipped: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()
    per_view_tsai: tuple[Any, ...] = ()
    # views taken from videos: name ("board.mp4#123") → its grey frame, and one line per video
    # saying how its views were picked
    video_frames: Mapping[str, np.ndarray] = field(default_factory=dict)
    # the photos' grey images by name, when asked for (calibrate_images(keep_photos=True): for a recording)
    photos: Mapping[str, np.ndarray] = field(default_factory=dict)
    video_notes: tuple[str, ...] = ()

    @property
    def n_views(self) -> int:
        return len(self.names)


VIDEO_VIEWS = 20
"""How many views ``gnomon calibrate camera`` picks from a board video by default."""
VIDEO_EXAMINED_PER_VIEW = 6  # frames examined per view wanted (evenly spaced through the video)
VIDEO_BLUR_FACTOR = 1.5  # a view whose edges are this much wider than the median view's is motion-blurred
VIDEO_MIN_SHIFT = 0.02  # views whose corners moved less than this share of the image diagonal are one view


@dataclass(frozen=True)
class VideoViews:
    """The views picked from a video of a board (see :func:`views_from_video`)."""

    names: list[str]  # "board.mp4#123" (the frame's index)
    corners: list[np.ndarray]  # (cols·rows, 2) each, full-size pixels, OpenCV's order
    frames: list[np.ndarray]  # their grey frames
    size: tuple[int, int]  # (w, h)
    note: str  # how many frames were examined, showed the board, were sharp, were picked


def _find_board_fast(grey: np.ndarray, board: tuple[int, int]) -> np.ndarray | None:
    """The board's corners on a video frame scaled to ``DETECT_PX`` (OpenCV's sector detector, plain
    settings: tens of ms where the accurate ones take a second on a frame without a board), scaled back
    to full size and refined there; None when not found."""
    pts = _find_board_quick(grey, board, classic=False)
    return None if pts is None else refine_corners(grey, pts, board)


def _view_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Median distance between two views' corners (px), the board's 180° turn (its corners in reverse
    order, the same pattern) counted as the same corners."""
    return float(min(np.median(np.linalg.norm(a - b, axis=1)), np.median(np.linalg.norm(a - b[::-1], axis=1))))


def pick_views(corners: Sequence[np.ndarray], blur_px: Sequence[float], max_views: int,
               min_shift_px: float) -> list[int]:
    """Indices of the views to calibrate from, in their original order: those not motion-blurred (edges
    at most ``VIDEO_BLUR_FACTOR`` times as wide as the median view's, ``blur_px`` from
    :func:`_edge_width`; NaN: not measured, left out), then, sharpest
    first, each next the one farthest from those picked (``_view_distance``), until ``max_views`` or
    until the farthest is within ``min_shift_px`` of one picked (the board held still: the same view
    again adds nothing but weight)."""
    sharp = _sharp(blur_px)
    if not sharp:
        return []
    picked = [min(sharp, key=lambda k: blur_px[k])]
    nearest = {k: _view_distance(corners[k], corners[picked[0]]) for k in sharp}
    while len(picked) < max_views:
        far = max((k for k in sharp if k not in picked), key=lambda k: nearest[k], default=None)
        if far is None or nearest[far] < min_shift_px:
            break
        picked.append(far)
        for k in sharp:
            nearest[k] = min(nearest[k], _view_distance(corners[k], corners[far]))
    return sorted(picked)


def views_from_video(path: str | os.PathLike, board: tuple[int, int], *, max_views: int = VIDEO_VIEWS,
                     progress: Callable[[int, int, str], None] | None = None,
                     source: FrameSource | None = None) -> VideoViews:
    """Views of a board filmed on video: up to ``VIDEO_EXAMINED_PER_VIEW × max_views`` frames, evenly
    spaced, are searched for the board (:func:`_find_board_fast`); of those showing it, the sharp and
    distinct ones are picked (:func:`pick_views`). Frames are decoded as a scan decodes them
    (:class:`gnomon.capture.frames.FrameSource`: the video's rotation applied; ``source``: the video already
    opened). ``progress(frames read, frames, name)`` as the video is read."""
    from gnomon.capture.frames import frame_pass

    p = Path(path)
    source = source if source is not None else FrameSource((), p, None)
    wanted = set(np.linspace(0, source.count - 1, min(source.count, VIDEO_EXAMINED_PER_VIEW * max_views))
                 .round().astype(int).tolist())
    found: list[tuple[int, np.ndarray, float]] = []  # (frame index, corners, edge width in px)
    size: tuple[int, int] | None = None
    examined = 0
    with frame_pass(source) as frames:
        for frame in frames:
            if progress:
                progress(frame.index + 1, source.count, p.name)
            if frame.index not in wanted:
                continue
            examined += 1
            grey = to_grey_u8(frame.grey)
            size = (grey.shape[1], grey.shape[0])
            corners = _find_board_fast(grey, board)
            if corners is not None:
                found.append((frame.index, corners, _edge_width(grey, corners, board)))
    if size is None:
        raise GnomonError(f"{p}: no frame decoded")
    blur = [b for _, _, b in found]
    picked = pick_views([c for _, c, _ in found], blur, max_views, VIDEO_MIN_SHIFT * float(np.hypot(*size)))
    sharp = len(_sharp(blur))
    # the picked frames again (a second decoding pass: holding every searched 4K frame would take a GB)
    index = {found[k][0]: k for k in picked}
    greys: dict[int, np.ndarray] = {}
    with frame_pass(source) as frames:
        for frame in frames:
            if frame.index in index:
                greys[frame.index] = to_grey_u8(frame.grey)
                if len(greys) == len(index):
                    break
    note = (f"{p}: {source.count} frames, {examined} examined, the board in {len(found)}, {sharp} sharp, "
            f"{len(picked)} distinct views picked")
    return VideoViews([f"{p}#{found[k][0]}" for k in picked], [found[k][1] for k in picked],
                      [greys[found[k][0]] for k in picked], size, note)


def _edge_width(grey: np.ndarray, corners: np.ndarray, board: tuple[int, int]) -> float:
    """The board's edge width (px) by ``cv2.estimateChessboardSharpness``, the wider of the board's two
    directions (it measures one at a time; a motion smears the edges across it only); NaN if unmeasured."""
    pts = corners.astype(np.float32).reshape(-1, 1, 2)
    widths = [float(np.asarray(cv2.estimateChessboardSharpness(grey, board, pts, vertical=v)[0]).ravel()[0])
              for v in (False, True)]  # each a Scalar: (sharpness, min and max brightness, 0)
    return max(widths) if all(np.isfinite(widths)) else float("nan")


def _sharp(blur_px: Sequence[float]) -> list[int]:
    """Indices of the views not motion-blurred: edge width measured and at most ``VIDEO_BLUR_FACTOR`` times
    the median measured one."""
    blur = np.asarray(blur_px, dtype=np.float64)
    finite = blur[np.isfinite(blur)]
    if finite.size == 0:
        return []
    limit = VIDEO_BLUR_FACTOR * float(np.median(finite))
    return [k for k in range(len(blur)) if np.isfinite(blur[k]) and blur[k] <= limit]


def detect_in_images(
    paths: Sequence[str | os.PathLike],
    board: tuple[int, int],
    *,
    progress: Callable[[int, int, str], None] | None = None,
    max_video_views: int = VIDEO_VIEWS,
    keep: dict[str, np.ndarray] | None = None,
) -> tuple[list[str], list[np.ndarray], tuple[int, int], list[str], list[str], dict[str, np.ndarray], list[str]]:
    """Read the images (and videos: :func:`views_from_video`) and find the board in each.

    Returns (names with a board, their corners, image size (w, h), names
    skipped, warnings, the video views' frames by name, one note per video).
    Images of different sizes, or unreadable ones, are a GnomonError naming
    the image; an image without a board is skipped with a warning.
    ``progress(done, total, name)`` counts an image as one and a video as its
    frames. ``keep``: filled with each photo showing the board, its grey image by name.
    """
    from gnomon.capture.frames import VIDEO_SUFFIXES

    if len(paths) == 0:
        raise GnomonError("no images given")
    videos = {k: FrameSource((), Path(p), None) for k, p in enumerate(paths)
              if Path(p).suffix.lower() in VIDEO_SUFFIXES}
    weight = [videos[k].count if k in videos else 1 for k in range(len(paths))]
    total = sum(weight)

    def progress_from(start: int, frames_read: int, frames: int, name: str) -> None:
        assert progress is not None
        progress(start + frames_read, total, name)
    names, corners, skipped, warns = [], [], [], []
    video_frames: dict[str, np.ndarray] = {}
    notes: list[str] = []
    size: tuple[int, int] | None = None
    first = ""

    def same_size(name: str, w: int, h: int) -> None:
        nonlocal size, first
        if size is None:
            size, first = (w, h), name
        elif (w, h) != size:
            raise GnomonError(f"{name}: image size {w}x{h} differs from {size[0]}x{size[1]} of {first}; all views "
                              "must come from one camera setting")

    for k, path in enumerate(paths):
        p = Path(path)
        done = sum(weight[:k])
        if k in videos:
            views = views_from_video(p, board, max_views=max_video_views, source=videos[k],
                                     progress=None if progress is None else partial(progress_from, done))
            same_size(str(p), *views.size)
            names += views.names
            corners += views.corners
            video_frames.update(zip(views.names, views.frames, strict=True))
            notes.append(views.note)
            if not views.names:
                skipped.append(str(p))
                warns.append(f"{p}: no {board[0]}x{board[1]} chessboard found (inner corners) in any frame examined")
            continue
        if progress:
            progress(done, total, p.name)
        img = read_grey(p)
        h, w = img.shape[:2]
        same_size(str(p), w, h)
        c = detect_chessboard(img, board)
        if c is None:
            skipped.append(str(p))
            warns.append(f"{p}: no {board[0]}x{board[1]} chessboard found (inner corners); skipped")
            continue
        names.append(str(p))
        corners.append(c)
        if keep is not None:
            keep[str(p)] = img
    if progress:
        progress(total, total, "")
    assert size is not None
    return names, corners, size, skipped, warns, video_frames, notes


def calibrate_images(
    paths: Sequence[str | os.PathLike],
    board: tuple[int, int],
    square: float,
    *,
    model: str = "zhang",
    pixel_pitch_mm: tuple[float, float] | None = None,
    sx: float = 1.0,
    full: bool = False,
    fix_k3: bool = False,
    reject_factor: float = 3.0,
    progress: Callable[[int, int, str], None] | None = None,
    max_video_views: int = VIDEO_VIEWS,
    keep_photos: bool = False,
) -> CameraCalibration:
    """Chessboard photos → a calibrated camera.

    ``board``: inner corners (cols, rows); ``square``: the square's side
    (board units, e.g. mm). ``model="zhang"``: OpenCV's 5-coefficient model
    by Zhang's method, ≥ 3 views. ``model="tsai"``: Tsai's model; each view by
    Tsai's coplanar two-stage method, then, with several views, a joint
    refinement (see :func:`gnomon.camera.tsai.calibrate_views`); needs
    ``pixel_pitch_mm = (dx, dy)`` and takes ``sx`` a priori; ``full``
    optimises Cx, Cy (and sx with several views) too. ``keep_photos``: the result holds the photos' grey
    images (``photos``), e.g. for a recording of the views, which then need not be read again.
    """
    if model not in ("zhang", "tsai"):
        raise GnomonError(f"model '{model}': expected 'zhang' or 'tsai'")
    if not square > 0:
        raise GnomonError(f"square {square}: the square's side must be positive")
    if model == "tsai" and pixel_pitch_mm is None:
        raise GnomonError("--model tsai needs the sensor's pixel pitch (--pixel-pitch DX[,DY] in mm, e.g. 0.0028): "
                          "Tsai's method takes dx, dy a priori")
    photos: dict[str, np.ndarray] | None = {} if keep_photos else None
    names, corners, size, skipped, warns, video_frames, notes = detect_in_images(
        paths, board, progress=progress, max_video_views=max_video_views, keep=photos)
    obj = board_points(board[0], board[1], square)
    if model == "zhang":
        if len(names) < MIN_ZHANG_VIEWS:
            missing = f" (none in {', '.join(Path(s).name for s in skipped)})" if skipped else ""
            if notes:
                views = "1 distinct view shows" if len(names) == 1 else f"{len(names)} distinct views show"
                raise GnomonError(f"only {views} the {board[0]}x{board[1]} chessboard{missing} "
                                  f"({'; '.join(notes)}); Zhang's method needs at least {MIN_ZHANG_VIEWS}: "
                                  "film the board turned and tilted in several ways")
            raise GnomonError(
                f"only {len(names)} of {len(paths)} images show the {board[0]}x{board[1]} chessboard{missing}; "
                f"Zhang's method needs at least {MIN_ZHANG_VIEWS}"
            )
        z, method, _ = calibrate_views([obj] * len(names), corners, size, names=names, fix_k3=fix_k3,
                                       reject_factor=reject_factor)
        return CameraCalibration(
            camera=z.camera,
            method=method,
            rms_px=z.rms_px,
            names=z.names,
            per_view_rms_px=z.per_view_rms_px,
            poses=z.poses,
            std=z.std,
            board=board,
            square=float(square),
            rejected=z.rejected,
            skipped=tuple(skipped),
            warnings=tuple(warns) + z.warnings,
            video_frames=video_frames,
            photos=photos or {},
            video_notes=tuple(notes),
        )
    from gnomon.camera import tsai

    if len(names) < 1:
        raise GnomonError(f"none of the {len(paths)} images shows the {board[0]}x{board[1]} chessboard")
    assert pixel_pitch_mm is not None  # checked on entry, before the images are read
    dx, dy = pixel_pitch_mm
    r = tsai.calibrate_views([(obj, c) for c in corners], size[0], size[1], dx, dy, sx=sx, full=full, names=names)
    method = "tsai-coplanar" if len(r.names) == 1 else "tsai-views"
    if full:
        method += "+full"
    return CameraCalibration(
        camera=r.camera,
        method=method,
        rms_px=r.rms_px,
        names=r.names,
        per_view_rms_px=r.per_view_rms_px,
        poses=r.poses,
        std=r.std,
        board=board,
        square=float(square),
        rejected=tuple((n, float("nan")) for n in names if n not in r.names),  # Tsai failed on these
        skipped=tuple(skipped),
        warnings=tuple(warns) + r.warnings,
        per_view_tsai=r.per_view,
        video_frames=video_frames,
        video_notes=tuple(notes),
        photos=photos or {},
    )


# --------------------------------------------------------------------------- camera file


def camera_to_table(camera: OpenCVCamera | TsaiCamera) -> dict[str, Any]:
    """The camera's keys, as in a camera file or a field log's inline [camera]."""
    if isinstance(camera, OpenCVCamera):
        return {
            "model": "opencv",
            "width": int(camera.width),
            "height": int(camera.height),
            "fx": float(camera.fx),
            "fy": float(camera.fy),
            "cx": float(camera.cx),
            "cy": float(camera.cy),
            "dist": [float(x) for x in camera.dist],
        }
    if isinstance(camera, TsaiCamera):
        return {
            "model": "tsai",
            "width": int(camera.width),
            "height": int(camera.height),
            "f_mm": float(camera.f_mm),
            "kappa1": float(camera.kappa1),
            "cx": float(camera.cx),
            "cy": float(camera.cy),
            "sx": float(camera.sx),
            "dx_mm": float(camera.dx_mm),
            "dy_mm": float(camera.dy_mm),
        }
    raise TypeError(f"not a camera model: {type(camera).__name__}")


def calibration_to_table(cal: CameraCalibration) -> dict[str, Any]:
    """The whole camera file as nested dicts: camera keys plus a [calibration] table."""
    t = camera_to_table(cal.camera)
    t["calibration"] = {
        "method": cal.method,
        "rms_px": float(cal.rms_px),
        "n_views": cal.n_views,
        "images": [Path(n).name for n in cal.names],
        "per_view_rms_px": [float(x) for x in cal.per_view_rms_px],
        "rejected": [Path(n).name for n, _ in cal.rejected],
        "rejected_rms_px": [float(r) for _, r in cal.rejected],
        "skipped": [Path(n).name for n in cal.skipped],
        "board": f"{cal.board[0]}x{cal.board[1]}",
        "square": float(cal.square),
        "std": {k: float(v) for k, v in cal.std.items()},
    }
    return t


_HEADER = """Gnomon camera file, written by `gnomon calibrate camera`.
Pixels: centre of the top-left pixel at (0, 0). Camera frame: x right, y down, z forward.
model "opencv": fx fy cx cy in pixels; dist = [k1, k2, p1, p2, k3] (OpenCV's model).
model "tsai": f_mm (mm), kappa1 (1/mm^2, Xu = Xd*(1 + kappa1*r^2)), cx cy (px), sx, dx_mm dy_mm (pixel pitch, mm).
[calibration]: reprojection RMS in pixels (length of the 2D error); std = 1-sigma standard deviations."""


def write_camera_file(path: str | os.PathLike, cal: CameraCalibration | OpenCVCamera | TsaiCamera) -> None:
    """Write a camera file (TOML) atomically; a bare camera has no [calibration] table."""
    table = calibration_to_table(cal) if isinstance(cal, CameraCalibration) else camera_to_table(cal)
    toml_io.dump(table, path, header=_HEADER)


def _dist5(values: Any) -> tuple[float, float, float, float, float]:
    """OpenCV's five distortion coefficients (k1, k2, p1, p2, k3) as floats."""
    k1, k2, p1, p2, k3 = (float(x) for x in values)
    return k1, k2, p1, p2, k3


def _number(table: Mapping[str, Any], key: str, where: str, *, positive: bool = False, integer: bool = False) -> float:
    if key not in table:
        raise GnomonError(f"{where}: missing key '{key}'")
    v = table[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise GnomonError(f"{where}: key '{key}' must be a number, got {v!r}")
    if integer and (not isinstance(v, int) or v <= 0):
        raise GnomonError(f"{where}: key '{key}' must be a positive integer, got {v!r}")
    if not np.isfinite(v):
        raise GnomonError(f"{where}: key '{key}' must be finite, got {v!r}")
    if positive and not v > 0:
        raise GnomonError(f"{where}: key '{key}' must be positive, got {v!r}")
    return v


def camera_from_table(table: Mapping[str, Any], where: str, *,
                      extra_keys: Sequence[str] = ()) -> OpenCVCamera | TsaiCamera:
    """Build the camera from a camera file's keys or a field log's inline [camera].

    ``where`` names the file/table in messages (e.g. ``"scan.toml: [camera]"``).
    Keys other than the model's, ``calibration`` and ``extra_keys`` (e.g.
    ``("file", "pose")`` for a field log) are an error naming the key.
    """
    model = table.get("model", "opencv")
    if model not in ("opencv", "tsai"):
        raise GnomonError(f"{where}: key 'model' must be \"opencv\" or \"tsai\", got {model!r}")
    allowed = (_OPENCV_KEYS if model == "opencv" else _TSAI_KEYS) | {"calibration"} | set(extra_keys)
    for k in table:
        if k not in allowed:
            raise GnomonError(f"{where}: unknown key '{k}' for model \"{model}\"")
    width = int(_number(table, "width", where, integer=True))
    height = int(_number(table, "height", where, integer=True))
    if model == "opencv":
        dist = table.get("dist", [0.0] * 5)
        if (
            not isinstance(dist, list)
            or len(dist) != 5
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x) for x in dist)
        ):
            raise GnomonError(f"{where}: key 'dist' must be 5 numbers [k1, k2, p1, p2, k3], got {dist!r}")
        return OpenCVCamera(
            width=width,
            height=height,
            fx=float(_number(table, "fx", where, positive=True)),
            fy=float(_number(table, "fy", where, positive=True)),
            cx=float(_number(table, "cx", where)),
            cy=float(_number(table, "cy", where)),
            dist=_dist5(dist),
        )
    return TsaiCamera(
        width=width,
        height=height,
        f_mm=float(_number(table, "f_mm", where, positive=True)),
        kappa1=float(_number(table, "kappa1", where)),
        cx=float(_number(table, "cx", where)),
        cy=float(_number(table, "cy", where)),
        dx_mm=float(_number(table, "dx_mm", where, positive=True)),
        dy_mm=float(_number(table, "dy_mm", where, positive=True)),
        sx=float(_number(table, "sx", where, positive=True)) if "sx" in table else 1.0,
    )


def load_camera_file(path: str | os.PathLike) -> OpenCVCamera | TsaiCamera:
    """Read a camera file written by :func:`write_camera_file` (or by hand)."""
    return camera_from_table(toml_io.load(path), str(path))


def load_calibration_info(path: str | os.PathLike) -> dict[str, Any]:
    """The camera file's [calibration] table (empty if absent), e.g. for report.json."""
    t = toml_io.load(path).get("calibration", {})
    if not isinstance(t, dict):
        raise GnomonError(f"{path}: [calibration] must be a table")
    return t
