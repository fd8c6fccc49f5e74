"""Light models: the desk lamp located from the shadows of a standing pencil.

Bouguet & Perona (ICCV 1998); docs/method.md §7. A pencil of known height h stands
vertically on a calibrated plane (the desk). In each photo the user marks the
pencil's base b̄ and the tip t̄ₛ of its shadow (pixels). Both back-project
onto the plane, to B and Tₛ; the pencil's top is ``T = B + h·n`` (n the unit
plane normal on the camera's side, where the pencil stands and the lamp
shines). The lamp S lies on the line through Tₛ and T; with N ≥ 2 photos, S
is the point closest to all lines in the least-squares sense:
``Σᵢ (I − dᵢdᵢᵀ)·S = Σᵢ (I − dᵢdᵢᵀ)·Tᵢ``, dᵢ the unit direction of line i.

Uncertainty: σ_px (pixels, isotropic, independent) on every base and tip
coordinate — and optionally σ_h on the height, common to all photos — is
propagated to first order through the whole chain (camera rays, plane
intersection, pencil top, least squares) with a central-difference Jacobian,
giving the 3×3 covariance of S in the world frame (world units²). The same
Jacobian predicts the spread of the residuals, so a χ² test with 2N − 3
degrees of freedom tells whether the clicks are as good as σ_px claims (a
misplaced click or a leaning pencil shows up there). A wrong height does not:
by similar triangles it scales the lamp's height above the plane and leaves
its foot unchanged, with the lines still meeting — hence ``sigma_height``,
which only ever widens the covariance along the normal. The camera
calibration and pose are taken as exact.

Field log for ``gnomon calibrate lamp FIELD_LOG``
-------------------------------------------------
The same ``[camera]`` (with ``[camera.pose]``) and ``[[planes]]`` tables as a
scan's field log (see ``field_logs/README.md``; a plane's ``regions`` are
optional here and ignored), or, without ``[camera.pose]``, a scan's
``[capture]`` and planes with markers or a chessboard (optionally in their own
``image``): the pose is then measured from them as a scan measures it, the
first such plane's frame being the world's (the paper's set-up: a board on
the desk photographed from the scan's place), plus::

    [pencil]
    height = 80.0          # pencil height, world units (required, > 0)
    sigma_px = 0.3         # 1σ of each clicked pixel coordinate (default 0.3)
    sigma_height = 0.0     # 1σ of the height, world units (default 0)
    plane = "desk"         # the [[planes]] name it stands on (default: the first plane)
    units = "mm"           # world units, "mm" or "m" (default: [capture] units, else "mm")
    empty = "empty.jpg"    # optional: the desk without the pencil (same camera and lamp)
    gamma = 2.2            # the photos' encoding (default: [capture] gamma, else "srgb")
    photos = [             # ≥ 2 photos; pixels, centre of the top-left pixel = (0, 0)
        { base = [412.3, 310.8], tip = [301.0, 355.2], image = "pencil1.jpg" },
        { base = [220.5, 280.1], image = "pencil2.jpg" },   # tip found against `empty`
    ]

``image`` is informational when both pixels are given. A photo without
``tip`` needs its ``image`` and ``[pencil] empty`` (or, without it, at least
3 photos with their ``image``: their per-pixel median is the empty desk): the
shadow's tip is then found by comparing the two photos' irradiance, and the
base (a hint, a few pixels off at most) is moved onto the shadow's axis
(:mod:`gnomon.pencil_detection`). ``[capture]``, ``[light]``,
``[scan]`` and ``[site]`` tables are ignored, so a scan's own field log may
carry the ``[pencil]`` table; any other table is an error. The result is
written to ``lamp.toml`` beside the field log: a ``[light]`` table
(``kind = "lamp"``, ``position``) ready to paste into a scan's field log, and a
``[lamp_calibration]`` table with the covariance, 1σ per axis, residuals, χ²
and warnings.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gnomon import toml_io
from gnomon.camera import CameraModel, Pose
from gnomon.chi2 import chi2_sf
from gnomon.errors import FieldLogError, GnomonError
from gnomon.fieldlog import UNITS, _parse_camera, _Table
from gnomon.reference_lines import PlaneInCamera

# The lines are "close to parallel" below this spread (see LampCalibration).
MIN_LINE_SPREAD_DEG = 5.0
# Warn when the largest 1σ axis exceeds this fraction of the lamp's distance to the pencils.
MAX_RELATIVE_SIGMA = 0.01
# Warn when the χ² of the residuals has a p-value below this.
MIN_CHI2_P = 1e-3
# Central-difference steps for the Jacobian: small against σ, large against the
# undistortion's convergence (1e-12 in normalised coordinates).
_STEP_PX = 1e-2
_STEP_HEIGHT_REL = 1e-5


@dataclass
class LampCalibration:
    """The lamp position from pencil photos, world frame.

    ``position_world`` (3,) and ``covariance`` (3, 3) in world units / world
    units². Per photo i: ``bases_world[i]`` B, ``shadow_tips_world[i]`` Tₛ,
    ``tops_world[i]`` T (all on or above the plane), ``directions_world[i]``
    the unit direction of the line from Tₛ through T (towards the lamp), and
    ``residuals[i]`` the distance from S to that line (world units).
    ``plane_normal_world``: the plane's unit normal, turned to the camera's side.
    ``line_spread_deg``: the lines' angular spread, 2·asin(√(λmin/N)) with
    λmin the smallest eigenvalue of Σ(I − ddᵀ) — for two lines exactly the
    angle between them; small values mean nearly parallel lines and a lamp
    poorly located along them. ``chi2`` (with ``dof`` = 2N − 3) compares the
    residuals with those σ_px predicts; NaN when σ is zero.
    """

    position_world: np.ndarray
    covariance: np.ndarray
    residuals: np.ndarray
    bases_world: np.ndarray
    shadow_tips_world: np.ndarray
    tops_world: np.ndarray
    directions_world: np.ndarray
    plane_normal_world: np.ndarray
    height: float
    sigma_px: float
    sigma_height: float
    line_spread_deg: float
    chi2: float
    dof: int
    warnings: list[str] = field(default_factory=list)

    @property
    def sigma_world(self) -> np.ndarray:
        """1σ per world axis (world units)."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def n_photos(self) -> int:
        return len(self.residuals)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _solve_lines(
    camera: CameraModel,
    pose: Pose,
    plane,
    normal_world: np.ndarray,
    bases_px: np.ndarray,
    tips_px: np.ndarray,
    heights: np.ndarray,
) -> dict[str, np.ndarray]:
    """The whole chain for M variants at once: pixels (M, N, 2), heights (M,) → S (M, 3) etc."""
    m, n = bases_px.shape[:2]
    pix = np.concatenate([bases_px.reshape(-1, 2), tips_px.reshape(-1, 2)])
    on_plane = pose.camera_to_world(plane.intersect(camera.rays(pix)))
    B = on_plane[: m * n].reshape(m, n, 3)
    Ts = on_plane[m * n :].reshape(m, n, 3)
    T = B + heights[:, None, None] * normal_world
    d = _unit(T - Ts)
    P = np.eye(3) - d[..., :, None] * d[..., None, :]  # (M, N, 3, 3) projectors ⟂ each line
    A = P.sum(axis=1)
    b = np.einsum("mnij,mnj->mi", P, T)
    with np.errstate(invalid="ignore"):
        S = np.linalg.solve(A, b[..., None])[..., 0]
    r = np.einsum("mnij,mnj->mni", P, S[:, None, :] - T)  # perpendicular offset of S from each line
    return {"S": S, "B": B, "Ts": Ts, "T": T, "d": d, "A": A, "r": r}


def calibrate_lamp_from_pencil(
    camera: CameraModel,
    pose: Pose,
    plane_point_world: np.ndarray,
    plane_normal_world: np.ndarray,
    bases_px: np.ndarray,
    tips_px: np.ndarray,
    height: float,
    sigma_px: float = 0.3,
    *,
    sigma_height: float = 0.0,
) -> LampCalibration:
    """Locate a point lamp from N ≥ 2 photos of a pencil standing on a known plane.

    ``camera``: any model with ``rays(pixels)``; ``pose``: world → camera
    (``X_cam = R·X_world + t``); ``plane_point_world``, ``plane_normal_world``:
    the plane the pencil stands on (world frame; the normal's sign does not
    matter, it is turned towards the camera); ``bases_px``, ``tips_px``: (N, 2)
    pixels of the pencil's base and of its shadow's tip; ``height``: the
    pencil's height (world units); ``sigma_px``: 1σ of each pixel coordinate;
    ``sigma_height``: 1σ of the height (world units).

    Raises :class:`GnomonError` for fewer than 2 photos, a height ≤ 0, a pixel
    whose ray misses the plane, or exactly parallel lines.
    """
    bases = np.asarray(bases_px, dtype=np.float64)
    tips = np.asarray(tips_px, dtype=np.float64)
    if bases.ndim != 2 or bases.shape[1:] != (2,) or tips.shape != bases.shape:
        raise GnomonError(
            f"pencil bases and tips must both be (N, 2) pixel arrays, got {bases.shape} and {tips.shape}"
        )
    n = len(bases)
    if n < 2:
        raise GnomonError(f"the lamp needs at least 2 pencil photos, got {n}")
    if not (np.all(np.isfinite(bases)) and np.all(np.isfinite(tips))):
        raise GnomonError("pencil base and tip pixels must be finite numbers")
    if not (math.isfinite(height) and height > 0):
        raise GnomonError(f"pencil height must be > 0, got {height!r}")
    if not (math.isfinite(sigma_px) and sigma_px >= 0):
        raise GnomonError(f"sigma_px must be ≥ 0, got {sigma_px!r}")
    if not (math.isfinite(sigma_height) and sigma_height >= 0):
        raise GnomonError(f"sigma_height must be ≥ 0, got {sigma_height!r}")

    p0 = np.asarray(plane_point_world, dtype=np.float64).reshape(3)
    nrm = np.asarray(plane_normal_world, dtype=np.float64).reshape(3)
    if not np.linalg.norm(nrm) > 0:
        raise GnomonError("the plane normal must not be the zero vector")
    nrm = nrm / np.linalg.norm(nrm)
    cam_side = float(nrm @ (pose.camera_centre_world - p0))
    if abs(cam_side) < 1e-12 * (1.0 + np.linalg.norm(p0)):
        raise GnomonError("the camera lies in the pencil's plane: it cannot see the pencil")
    if cam_side < 0:
        nrm = -nrm  # the pencil stands on the side the camera sees
    plane = PlaneInCamera.from_world(p0, nrm, pose)

    # Nominal solution first, to report a missed plane clearly.
    nominal = _solve_lines(camera, pose, plane, nrm, bases[None], tips[None], np.array([height]))
    for name, arr, pix in (("base", nominal["B"][0], bases), ("shadow tip", nominal["Ts"][0], tips)):
        bad = np.flatnonzero(~np.all(np.isfinite(arr), axis=1))
        if bad.size:
            i = int(bad[0])
            raise GnomonError(
                f"photo {i + 1}: the {name} pixel ({pix[i, 0]:g}, {pix[i, 1]:g}) does not see the plane "
                "(its ray misses it or meets it behind the camera)"
            )
    A = nominal["A"][0]
    eig = np.linalg.eigvalsh(A)
    if not np.all(np.isfinite(nominal["S"])) or eig[0] <= 1e-14 * n:
        raise GnomonError("the pencil's lines are parallel: move the pencil so that its shadows point different ways")
    S = nominal["S"][0]

    # Jacobian by central differences: variant 2k perturbs parameter k by +step, 2k+1 by −step.
    # Parameters: bases (u, v) per photo, then tips (u, v) per photo, then the height.
    n_par = 4 * n + 1
    vb = np.repeat(bases[None], 2 * n_par, axis=0)
    vt = np.repeat(tips[None], 2 * n_par, axis=0)
    vh = np.full(2 * n_par, height)
    step_h = _STEP_HEIGHT_REL * height
    for k in range(n_par):
        for sign, row in ((1.0, 2 * k), (-1.0, 2 * k + 1)):
            if k < 2 * n:
                vb[row, k // 2, k % 2] += sign * _STEP_PX
            elif k < 4 * n:
                j = k - 2 * n
                vt[row, j // 2, j % 2] += sign * _STEP_PX
            else:
                vh[row] += sign * step_h
    var = _solve_lines(camera, pose, plane, nrm, vb, vt, vh)
    steps = np.r_[np.full(4 * n, _STEP_PX), step_h]
    J_S = ((var["S"][0::2] - var["S"][1::2]) / (2 * steps[:, None])).T  # (3, n_par)
    r_flat = var["r"].reshape(2 * n_par, -1)
    J_r = ((r_flat[0::2] - r_flat[1::2]) / (2 * steps[:, None])).T  # (3N, n_par)
    weights = np.r_[np.full(4 * n, sigma_px**2), sigma_height**2]
    cov = (J_S * weights) @ J_S.T
    cov = 0.5 * (cov + cov.T)

    # χ² of the residual vectors against their predicted covariance (rank 2N − 3).
    r0 = nominal["r"][0].reshape(-1)
    dof = 2 * n - 3
    chi2 = float("nan")
    if sigma_px > 0 or sigma_height > 0:
        cov_r = (J_r * weights) @ J_r.T
        lam, vec = np.linalg.eigh(0.5 * (cov_r + cov_r.T))
        lam, vec = lam[-dof:], vec[:, -dof:]
        if np.all(lam > 0):
            chi2 = float(np.sum((vec.T @ r0) ** 2 / lam))

    residuals = np.linalg.norm(nominal["r"][0], axis=1)
    spread_deg = float(np.degrees(2.0 * np.arcsin(np.sqrt(np.clip(eig[0] / n, 0.0, 1.0)))))
    T, d, B = nominal["T"][0], nominal["d"][0], nominal["B"][0]

    warnings: list[str] = []
    if spread_deg < MIN_LINE_SPREAD_DEG:
        warnings.append(
            f"the pencil's lines are close to parallel (spread {spread_deg:.2f}° < {MIN_LINE_SPREAD_DEG:g}°): "
            "the lamp is poorly located along them; spread the pencil positions around the scene"
        )
    behind = [i + 1 for i in range(n) if float((S - T[i]) @ d[i]) <= 0.0]
    if behind:
        warnings.append(
            f"photo(s) {', '.join(map(str, behind))}: the lamp comes out on the shadow's side of the pencil top "
            "(base and tip swapped?)"
        )
    distance = float(np.linalg.norm(S - B.mean(axis=0)))
    sigma_max = float(np.sqrt(max(np.linalg.eigvalsh(cov)[-1], 0.0)))
    if sigma_max > MAX_RELATIVE_SIGMA * distance:
        warnings.append(
            f"the lamp is uncertain: largest 1σ {sigma_max:.3g} is {100 * sigma_max / distance:.2g} % of its "
            f"distance to the pencils ({distance:.4g}); add photos with the pencil spread further apart"
        )
    if math.isfinite(chi2):
        p_value = chi2_sf(chi2, dof)
        if p_value < MIN_CHI2_P:
            warnings.append(
                f"the lines miss each other by more than σ_px = {sigma_px:g} px explains (χ² = {chi2:.3g} for "
                f"{dof} dof, p = {p_value:.1g}): check the clicked pixels and that the pencil stood upright"
            )

    return LampCalibration(
        position_world=S,
        covariance=cov,
        residuals=residuals,
        bases_world=B,
        shadow_tips_world=nominal["Ts"][0],
        tops_world=T,
        directions_world=d,
        plane_normal_world=nrm,
        height=float(height),
        sigma_px=float(sigma_px),
        sigma_height=float(sigma_height),
        line_spread_deg=spread_deg,
        chi2=chi2,
        dof=dof,
        warnings=warnings,
    )


# --------------------------------------------------------------------------- field log


@dataclass(frozen=True)
class PencilLog:
    """A parsed lamp-calibration field log (see the module docstring)."""

    path: Path
    camera: CameraModel
    pose: Pose
    plane_name: str
    plane_point: np.ndarray
    plane_normal: np.ndarray
    height: float
    sigma_px: float
    sigma_height: float
    units: str
    bases_px: np.ndarray
    tips_px: np.ndarray  # NaN rows: to be found against the empty-desk photo
    images: tuple[str | None, ...]
    empty: Path | None = None  # photo of the desk without the pencil
    gamma: float | str = "srgb"  # the photos' encoding, to compare irradiance


# Tables of a scan's field log that a lamp calibration does not read.
_IGNORED_SECTIONS = ("capture", "light", "scan", "site")


# What measures a plane in a scan's field log (gnomon.scan_setup.resolve_reference_planes).
_MARK_KEYS = ("markers", "chessboard", "square", "image", "x_axis", "aruco", "charuco")


def _pose_from_marked_planes(path: Path, data: dict[str, Any]
                             ) -> tuple[Any, Pose, dict[str, tuple[np.ndarray, np.ndarray]]]:
    """Without ``[camera.pose]``: the field log at ``path`` (``data``: its tables, as read) read as a scan's
    and its planes measured from their own markers or board (the first one's frame is the world's). Returns
    the camera (fitted to the frames), the pose and each plane's point and unit normal in that world."""
    from gnomon.fieldlog import load_field_log
    from gnomon.scan_setup import frame_source, resolve_reference_planes

    marked = [pl for pl in data.get("planes", []) if isinstance(pl, dict) and any(k in pl for k in _MARK_KEYS)]
    if "capture" not in data or not marked:
        raise FieldLogError(f"{path}: missing required table [camera.pose] (the world → camera transform), or a "
                            "[capture] and a plane with markers or a chessboard to measure it from")
    log = load_field_log(path, without_light=True)
    log, _ = resolve_reference_planes(log, frame_source(log))
    assert log.pose is not None  # a marked plane was measured
    planes = {pl.name: (np.asarray(pl.point, float), np.asarray(pl.normal, float) / np.linalg.norm(pl.normal))
              for pl in log.planes}
    return log.camera, log.pose, planes


def load_pencil_log(path: str | Path) -> PencilLog:
    """Read ``[camera]``, ``[camera.pose]``, ``[[planes]]`` and ``[pencil]``; errors name file and key.

    Without ``[camera.pose]`` the pose comes from the planes' own markers or chessboard, measured as a scan
    of the same field log measures them (it then needs its ``[capture]``): the paper's set-up, a board on
    the desk photographed from the scan's place."""
    p = Path(path)
    if not p.is_file():
        raise FieldLogError(f"{p}: field log not found")
    root = _Table(p, "field log", toml_io.load(p))
    base = p.resolve().parent

    if "camera" not in root.data:
        raise FieldLogError(f"{p}: missing required table [camera]")
    camera, pose, _, _, _ = _parse_camera(_Table(p, "camera", root.data.pop("camera")), base)
    measured: dict[str, tuple[np.ndarray, np.ndarray]] | None = None
    if pose is None:
        # no pose typed: the planes' own markers or board place the camera, as in a scan of this field log
        camera, pose, measured = _pose_from_marked_planes(p, root.data)

    raw_planes = root.data.pop("planes", None)
    if not isinstance(raw_planes, list) or not raw_planes:
        raise FieldLogError(f"{p}: missing required [[planes]] (the plane the pencil stands on)")
    planes: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for i, raw in enumerate(raw_planes):
        t = _Table(p, f"planes.{i}", raw)
        name = t.string("name", f"plane{i}")
        point = t.vector("point", 3, [0.0, 0.0, 0.0])
        normal = t.vector("normal", 3, [0.0, 0.0, 1.0])
        if np.linalg.norm(normal) < 1e-12:
            raise t.error("normal", "must not be the zero vector")
        for key in ("regions", "mask") + (_MARK_KEYS if measured is not None else ()):
            t.take(key, None)  # the scan's bare regions, and what measured the plane: not needed here
        t.done()
        planes.setdefault(name, measured[name] if measured is not None and name in measured
                          else (point, normal / np.linalg.norm(normal)))

    capture_units = None
    capture = root.data.get("capture")
    if isinstance(capture, dict) and capture.get("units") in UNITS:
        capture_units = capture["units"]
    for name in _IGNORED_SECTIONS:
        root.data.pop(name, None)

    if "pencil" not in root.data:
        raise FieldLogError(f"{p}: missing required table [pencil] (the pencil photos)")
    t = _Table(p, "pencil", root.data.pop("pencil"))
    height = t.number("height", positive=True)
    sigma_px = t.number("sigma_px", 0.3)
    if sigma_px < 0:
        raise t.error("sigma_px", f"must be ≥ 0, got {sigma_px:g}")
    sigma_height = t.number("sigma_height", 0.0)
    if sigma_height < 0:
        raise t.error("sigma_height", f"must be ≥ 0, got {sigma_height:g}")
    plane_name = t.string("plane", next(iter(planes)))
    if plane_name not in planes:
        raise t.error("plane", f"no [[planes]] entry is named {plane_name!r} (have: {', '.join(map(repr, planes))})")
    units = t.string("units", capture_units or "mm", UNITS)
    empty = base / t.string("empty") if "empty" in t.data else None
    if empty is not None and not empty.is_file():
        raise t.error("empty", f"{empty} not found")
    gamma: float | str = "srgb"
    if isinstance(capture, dict) and isinstance(capture.get("gamma"), (int, float, str)):
        gamma = capture["gamma"]
    if "gamma" in t.data:
        gamma = t.take("gamma")
    if not (gamma == "srgb" or (isinstance(gamma, (int, float)) and not isinstance(gamma, bool) and gamma > 0)):
        raise t.error("gamma", f"expected a positive number or 'srgb', got {gamma!r}")
    photos = t.take("photos")
    if not isinstance(photos, list) or not all(isinstance(x, dict) for x in photos):
        raise t.error("photos", "expected a list of { base = [u, v], tip = [u, v] } tables")
    if len(photos) < 2:
        raise t.error("photos", f"the lamp needs at least 2 pencil photos, got {len(photos)}")
    t.done()
    bases: list[np.ndarray] = []
    tips: list[np.ndarray] = []
    images: list[str | None] = []
    w, h = camera.width, camera.height
    for i, raw in enumerate(photos):
        pt = _Table(p, f"pencil.photos.{i}", raw)
        image = pt.string("image") if "image" in pt.data else None
        for key, out in (("base", bases), ("tip", tips)):
            if key == "tip" and "tip" not in pt.data:
                # found automatically: needs this photo and the empty desk (or the photos' median)
                median = len(photos) >= MEDIAN_PHOTOS and all(isinstance(x.get("image"), str) for x in photos)
                if image is None or (empty is None and not median):
                    raise pt.error("tip", "missing: give the tip's pixel, or the photo's 'image' and "
                                          "[pencil] 'empty' (a photo of the desk without the pencil; or at "
                                          f"least {MEDIAN_PHOTOS} photos, each with its 'image')")
                out.append(np.array([np.nan, np.nan]))
                continue
            uv = pt.vector(key, 2)
            if not (-0.5 <= uv[0] <= w - 0.5 and -0.5 <= uv[1] <= h - 0.5):
                raise pt.error(key, f"pixel {uv.tolist()} is outside the {w}x{h} image")
            out.append(uv)
        images.append(image)
        pt.done()
    root.done()
    point, normal = planes[plane_name]
    return PencilLog(
        p, camera, pose, plane_name, point, normal, height, sigma_px, sigma_height, units,
        np.array(bases), np.array(tips), tuple(images), empty, gamma,
    )


MEDIAN_PHOTOS = 3
"""Without ``[pencil] empty``, this many photos (or more) stand for the empty desk: their median."""


def _median_photo(folder: Path, log: PencilLog) -> np.ndarray:
    """The per-pixel median of the pencil photos (as encoded: the median commutes with the decoding).
    Each photo's pencil and shadow cover pixels the others leave bare, so with 3 or more photos spread
    around the scene it is the desk without the pencil."""
    from gnomon.calibration import read_grey

    photos: list[np.ndarray] = []
    for name in log.images:
        assert name is not None
        photo = read_grey(folder / name)
        if photos and photo.shape != photos[0].shape:
            raise GnomonError(f"{log.path}: [pencil] photo {name} is {photo.shape[1]}x{photo.shape[0]}, "
                              f"{log.images[0]} {photos[0].shape[1]}x{photos[0].shape[0]}")
        photos.append(photo)
    return np.median(np.stack(photos), axis=0).round().astype(photos[0].dtype)


def detect_missing_tips(log: PencilLog) -> tuple[PencilLog, list[str]]:
    """Find the shadow tips the log leaves out (and refine those photos' bases) against ``empty``.

    Returns the completed log and one line per detected photo. See
    :mod:`gnomon.pencil_detection`.
    """
    from dataclasses import replace

    from gnomon.calibration import read_grey
    from gnomon.pencil_detection import detect_pencil
    from gnomon.reference_lines import PlaneInCamera
    from gnomon.tracking import decoding_lut

    missing = np.flatnonzero(~np.isfinite(log.tips_px[:, 0]))
    if len(missing) == 0:
        return log, []
    folder = log.path.resolve().parent
    if log.empty is not None:
        empty_raw, empty_name = read_grey(log.empty), log.empty.name
    else:  # the desk as most photos see it: the pencil stands elsewhere in each (checked when the log was read)
        assert len(log.images) >= MEDIAN_PHOTOS and all(name is not None for name in log.images)
        empty_raw, empty_name = _median_photo(folder, log), f"the median of the {len(log.images)} photos"
    lut = decoding_lut(log.gamma, empty_raw.dtype)
    empty = lut[empty_raw]
    plane = PlaneInCamera.from_world(log.plane_point, log.plane_normal, log.pose)
    # the pencil stands on the camera's side of the plane (a board's normal may point into the desk)
    up = np.asarray(log.plane_normal, dtype=np.float64)
    if (log.pose.camera_centre_world - log.plane_point) @ up < 0:
        up = -up
    bases, tips, lines = log.bases_px.copy(), log.tips_px.copy(), []
    for i in missing:
        name = log.images[i]
        assert name is not None  # a tip to find needs its photo (checked when the log was read)
        photo_raw = read_grey(folder / name)
        if photo_raw.shape != empty_raw.shape:
            raise GnomonError(f"{log.path}: [pencil] photo {name} is {photo_raw.shape[1]}x{photo_raw.shape[0]}, "
                              f"the empty desk {empty_raw.shape[1]}x{empty_raw.shape[0]}")
        foot = plane.intersect(log.camera.rays(bases[i][None]))[0]
        if not np.all(np.isfinite(foot)):
            raise GnomonError(f"{log.path}: [pencil] photo {name}: the base pixel does not see the plane")
        foot_world = log.pose.camera_to_world(foot)
        top_world = foot_world + log.height * up
        top_px = log.camera.project(log.pose.world_to_camera(top_world)[None])[0]
        found = detect_pencil(lut[photo_raw], empty, bases[i], top_px, source=f"{log.path}: {name}")
        bases[i], tips[i] = found.base_px, found.tip_px
        lines.append(f"photo {i + 1} ({name}): base {found.base_px.round(2).tolist()}, "
                     f"tip {found.tip_px.round(2).tolist()} (found against {empty_name})")
    return replace(log, bases_px=bases, tips_px=tips), lines


def _decimals(sigma: float) -> int:
    """Decimals showing a value to about a tenth of its 1σ."""
    if not (sigma > 0 and math.isfinite(sigma)):
        return 3
    return int(min(6, max(0, 1 - math.floor(math.log10(sigma)))))


def _degenerate_lamp(cal, distance: float) -> str | None:
    """Why a lamp estimate must not be written without --force (its σ is a large part of its distance,
    or the photos' lines are nearly parallel), or None."""
    sig = np.asarray(cal.sigma_world, dtype=float)
    if not (np.all(np.isfinite(cal.position_world)) and np.all(np.isfinite(sig))):
        return "not finite"
    if sig.max() > 0.25 * distance:
        return f"σ {sig.max():.3g} against a distance of {distance:.3g} to the pencils"
    if math.isfinite(cal.line_spread_deg) and cal.line_spread_deg < 2.0:
        return f"the photos' lines spread over {cal.line_spread_deg:.2g}° only"
    return None


def calibrate_lamp_cli(args: argparse.Namespace) -> int:
    """``gnomon calibrate lamp FIELD_LOG``: reads ``args.field_log`` (a Path), prints the
    lamp ± 1σ, residuals and warnings, writes ``lamp.toml`` beside the field log (atomic)."""
    log, detected = detect_missing_tips(load_pencil_log(args.field_log))
    for line in detected:
        print(line)
    try:
        cal = calibrate_lamp_from_pencil(
            log.camera, log.pose, log.plane_point, log.plane_normal, log.bases_px, log.tips_px,
            log.height, log.sigma_px, sigma_height=log.sigma_height,
        )
    except GnomonError as exc:
        raise GnomonError(f"{log.path}: [pencil] {exc}") from None

    u = log.units
    sig = cal.sigma_world
    dec = _decimals(float(sig.min()))
    print(
        f"lamp from {cal.n_photos} pencil photos (plane {log.plane_name!r}, height {log.height:g} {u}, "
        f"σ = {log.sigma_px:g} px)"
    )
    print(
        f"position (world, {u}): "
        + "   ".join(f"{a} = {x:.{dec}f} ± {s:.2g}" for a, x, s in zip("xyz", cal.position_world, sig, strict=True))
    )
    distance = float(np.linalg.norm(cal.position_world - cal.bases_world.mean(axis=0)))
    height_above = float(np.dot(cal.position_world - log.plane_point, cal.plane_normal_world))
    print(f"  {height_above:.{dec}f} {u} above the plane, {distance:.{dec}f} {u} from the pencils")
    print(f"residuals (distance from the lamp to each photo's line, {u}):")
    for i, r in enumerate(cal.residuals):
        name = f"  ({log.images[i]})" if log.images[i] else ""
        print(f"  photo {i + 1}: {r:.{dec + 1}f}{name}")
    if math.isfinite(cal.chi2):
        print(f"consistency: χ² = {cal.chi2:.3g} for {cal.dof} dof; line spread {cal.line_spread_deg:.1f}°")
    for w in cal.warnings:
        print(f"warning: {w}")

    out = log.path.parent / "lamp.toml"
    problem = _degenerate_lamp(cal, distance)
    if problem is not None and not getattr(args, "force", False):
        raise GnomonError(f"{out}: not written: the lamp estimate is degenerate ({problem}); take photos with "
                          "the pencil in places spread around the scene, or write it anyway with --force")
    data = {
        "light": {"kind": "lamp", "position": cal.position_world},
        "lamp_calibration": {
            "field_log": log.path.name,
            "units": u,
            "frame": "world",
            "sigma": sig,
            "covariance": cal.covariance,
            "photos": cal.n_photos,
            "height": cal.height,
            "sigma_px": cal.sigma_px,
            "sigma_height": cal.sigma_height,
            "residuals": cal.residuals,
            "chi2": cal.chi2,
            "dof": cal.dof,
            "line_spread_deg": cal.line_spread_deg,
            "warnings": list(cal.warnings),
        },
    }
    header = (
        f"Lamp position from {cal.n_photos} pencil photos: gnomon calibrate lamp {log.path.name}\n"
        f"World frame, {u}; covariance in {u}². Paste [light] into a scan's field log."
    )
    toml_io.dump(data, out, header)
    print(f"wrote {out}")
    return 0
