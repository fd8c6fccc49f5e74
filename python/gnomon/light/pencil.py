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

The pencil log read by ``gnomon calibrate lamp`` is :mod:`gnomon.config.pencil_log`; the run,
:mod:`gnomon.runs.calibrate_lamp`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gnomon.camera.models import CameraModel, Pose
from gnomon.errors import GnomonError
from gnomon.geometry.reference_lines import PlaneInCamera
from gnomon.util.chi2 import chi2_sf

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
