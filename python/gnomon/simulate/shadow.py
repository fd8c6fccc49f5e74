"""The stick's shadow from an extended (spherical) lamp, analytically.

The stick is a straight circular cylinder of radius ``r_stick`` whose axis
passes through two points QA, QB (it is long enough that its ends never
shadow the view). The lamp is a sphere of radius ``r_lamp`` centred at S with
uniform radiance, so from a surface point P it looks like a uniform disc of
angular radius ``ρ = asin(r_lamp / |S − P|)``.

**Seen from P**, the stick is a band of directions bounded by the two planes
through P that contain the axis direction D and are tangent to the cylinder;
they make the angle ``α = asin(r_stick / h_P)`` with the plane through P and
the axis (``h_P`` the distance from P to the axis). The occluded fraction of
the lamp is the fraction of its disc inside the band: with ``δ₁, δ₂`` the
signed angular distances of the disc's centre (the direction to S) inside
each bounding plane, and ``F(x) = ½ + (x·√(1−x²) + asin x)/π`` the fraction of
a unit disc on the inner side of a chord at signed distance x from its centre
(the circular-segment area formula),

    occluded = clip(F(δ₁/ρ) + F(δ₂/ρ) − 1, 0, 1).

(The disc is tiny — a few milliradians — so treating it as flat in the
tangent plane is exact to ~ρ², far below anything measurable.)

**Seen from S**, the same condition reads: a bounding plane through P passes
through S exactly when P lies on one of the two planes through S that contain
D and are tangent to the stick. So the half-occlusion point of each penumbra
— the *penumbra centre* — is exactly the plane through S tangent to the stick
on that side. Those are the ground-truth shadow planes
(:func:`tangent_planes`).

Orientation: ``motion`` is a world vector in the direction the shadow moves.
Both planes' normals point *ahead* (towards not-yet-shadowed points), so for a
point X beyond the stick, ``n·X − d`` is positive before the edge reaches it
and negative after: the entering (leading) edge has ``n_enter``, the leaving
(trailing) edge ``n_leave``, and X is in the shadow when
``n_enter·X < d_enter`` and ``n_leave·X > d_leave``.
"""

from __future__ import annotations

import numpy as np


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def stick_axes(S: np.ndarray, QA: np.ndarray, QB: np.ndarray, motion: np.ndarray):
    """The stick's frame as seen from S, vectorised over poses.

    Returns (D, u, w, h): D the unit axis direction, u the unit vector from S
    to the closest point of the axis, h that distance, w = ±D × u oriented
    along ``motion`` (the central shadow plane's normal).
    """
    D = _unit(QB - QA)
    foot = QA + _dot(S - QA, D)[..., None] * D
    su = foot - S
    h = np.linalg.norm(su, axis=-1)
    u = su / h[..., None]
    w = np.cross(D, u)
    sign = np.where(_dot(w, motion) >= 0.0, 1.0, -1.0)
    return D, u, w * sign[..., None], h


def tangent_planes(S, QA, QB, r_stick: float, motion):
    """The entering and leaving penumbra-centre planes through S tangent to the stick.

    Vectorised over leading dimensions of QA, QB. Returns ``(enter, leave)``,
    each (..., 4) as ``[nx, ny, nz, d]`` with unit n and ``n·X = d``; normals
    point ahead of the moving shadow (see the module docstring).
    """
    S = np.asarray(S, dtype=np.float64)
    _, u, w, h = stick_axes(S, np.asarray(QA, float), np.asarray(QB, float), np.asarray(motion, float))
    sin_a = r_stick / h
    cos_a = np.sqrt(1.0 - sin_a * sin_a)
    n_enter = cos_a[..., None] * w - sin_a[..., None] * u
    n_leave = cos_a[..., None] * w + sin_a[..., None] * u
    enter = np.concatenate([n_enter, _dot(n_enter, S)[..., None]], axis=-1)
    leave = np.concatenate([n_leave, _dot(n_leave, S)[..., None]], axis=-1)
    return enter, leave


def _disc_fraction(x: np.ndarray) -> np.ndarray:
    """Fraction of a unit disc on the inner side of a chord at signed distance x."""
    x = np.clip(x, -1.0, 1.0)
    return 0.5 + (x * np.sqrt(1.0 - x * x) + np.arcsin(x)) / np.pi


def occluded_fraction(P: np.ndarray, S, r_lamp: float, QA, QB, r_stick: float) -> np.ndarray:
    """Fraction of the lamp's disc hidden by the stick, seen from each point P (M, 3).

    One stick pose (QA, QB). Exact for the cylinder/sphere model up to the
    flat-disc approximation (error ~ρ², ρ ≈ 0.005 rad).
    """
    S = np.asarray(S, dtype=np.float64)
    QA = np.asarray(QA, dtype=np.float64)
    D = _unit(np.asarray(QB, dtype=np.float64) - QA)
    q = QA - P                                     # P → a point of the axis
    a = q - _dot(q, D)[..., None] * D              # P → axis, perpendicular to D
    h = np.linalg.norm(a, axis=-1)
    u = a / h[..., None]
    w = np.cross(D, u)
    v = S - P
    dist = np.linalg.norm(v, axis=-1)
    vu = _dot(v, u)
    vw = _dot(v, w)
    sin_a = np.minimum(r_stick / h, 1.0)
    cos_a = np.sqrt(1.0 - sin_a * sin_a)
    rho = np.arcsin(np.minimum(r_lamp / dist, 1.0))
    d1 = np.arcsin(np.clip((vu * sin_a - vw * cos_a) / dist, -1.0, 1.0))
    d2 = np.arcsin(np.clip((vu * sin_a + vw * cos_a) / dist, -1.0, 1.0))
    frac = _disc_fraction(d1 / rho) + _disc_fraction(d2 / rho) - 1.0
    return np.clip(frac, 0.0, 1.0)
