"""A plane's distance from the line where it meets another: the shadow's kinks at their corner.

Marks nobody measured fix a plane's orientation, not its distance from the
camera (:func:`gnomon.camera.plane_pose.fit_rectangle_pose`). Two planes that
meet (a desk and a wall) share a line, and every shadow that crosses both
bends on it: in the image, a frame's shadow line on the one plane and its line
on the other meet at a pixel of their corner. That pixel's ray meets the
corner at the one depth both planes give it, so the plane of known distance
(``anchor``) sets the other's (``other``) frame by frame:

* the other plane's line and the camera's centre span a plane through the
  camera (its back-projection, the same at any distance of the other plane);
* it cuts the anchor's line at the corner point P (camera frame);
* the other plane passes through P: its distance is ``n·P``.

The frames' distances are combined by their median (robust to a frame whose
line on either plane is an object's), its σ from their spread. The corner
points all lie on one line, the planes' intersection: its direction against
``n_anchor × n_other`` checks the two planes' orientations
(``corner_angle_deg``).

Camera frame, the anchor's units.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gnomon.geometry.reference_lines import ReferenceLines

__all__ = ["CornerTie", "MIN_TIE_FRAMES", "tie_by_corner"]

#: Frames whose two lines meet needed for a distance (fewer: no tie).
MIN_TIE_FRAMES = 5
#: A frame's two lines must cross at more than this angle in the image (their back-projections, degrees):
#: nearly parallel lines put their crossing anywhere along them.
MIN_CROSSING_DEG = 5.0
# The median of n Gaussian samples has a σ of about 1.2533 σ/√n; 1.4826·MAD is σ.
MEDIAN_EFFICIENCY = 1.2533
MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True)
class CornerTie:
    """The distance of ``other`` from where its shadow lines meet ``anchor``'s.

    ``offset`` the other plane's ``d`` in ``n·X = d`` (its distance from the
    camera's centre, signed as its normal is: negative for a normal towards
    the camera; the anchor's units), ``sigma`` its 1 σ; ``frames`` how many frames' lines met;
    ``spread`` one frame's robust σ relative to ``offset``; ``corner`` (3,),
    ``direction`` (3,) the line the crossings trace (camera frame);
    ``corner_angle_deg`` its angle to the line where the two planes meet.
    """

    offset: float
    sigma: float
    frames: int
    spread: float
    corner: np.ndarray
    direction: np.ndarray
    corner_angle_deg: float


def tie_by_corner(anchor: ReferenceLines, other: ReferenceLines) -> CornerTie | None:
    """``other``'s distance from the frames whose shadow lines cross both planes (None: fewer than
    :data:`MIN_TIE_FRAMES`). Each plane's lines in the camera frame (``other``'s at any distance: only
    their back-projections count); only lines long enough to set their own direction are used."""
    n_b = other.plane.normal
    both = anchor.found & other.found & ~anchor.extrapolated & ~other.extrapolated
    frames = np.flatnonzero(both)
    if len(frames) < MIN_TIE_FRAMES:
        return None
    pa, da = anchor.point[frames], anchor.direction[frames]
    m = np.cross(other.point[frames], other.direction[frames])  # the back-projection's normal
    m /= np.linalg.norm(m, axis=1, keepdims=True)
    along = np.einsum("ij,ij->i", m, da)
    crossing = np.abs(along) > np.sin(np.radians(MIN_CROSSING_DEG))
    if crossing.sum() < MIN_TIE_FRAMES:
        return None
    s = -np.einsum("ij,ij->i", m[crossing], pa[crossing]) / along[crossing]
    corner = pa[crossing] + s[:, None] * da[crossing]
    d = corner @ n_b  # the other plane's n·X = d, in its own sense of the normal (either way round)
    ok = d * np.sign(other.plane.offset) > 0
    if ok.sum() < MIN_TIE_FRAMES:
        return None
    d, corner = d[ok], corner[ok]
    offset = float(np.median(d))
    spread = MAD_TO_SIGMA * float(np.median(np.abs(d - offset)))
    sigma = MEDIAN_EFFICIENCY * spread / np.sqrt(len(d))
    near = np.abs(d - offset) <= max(3.0 * spread, 1e-12 * offset)
    centre = corner[near].mean(axis=0)
    direction = np.linalg.svd(corner[near] - centre)[2][0]
    meet = np.cross(anchor.plane.normal, n_b)
    angle = float(np.degrees(np.arccos(min(1.0, abs(float(direction @ meet)) / float(np.linalg.norm(meet))))))
    return CornerTie(offset, float(sigma), int(len(d)), spread / abs(offset), centre, direction, angle)
