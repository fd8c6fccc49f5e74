"""Pencil photos for lamp calibration (Bouguet & Perona §2), with exact ground truth.

``gnomon simulate desk_lamp --pencil-photos N`` (default 3) writes, beside the
sweep, N photos of the desk-lamp scene *without the stick* and with a
sharpened pencil standing upright on bare desk, one position per photo,
lit by the same lamp (same camera, lens, blur, gamma, noise and encoding as
the frames), plus ``pencil_log.toml`` — the field log ``gnomon calibrate lamp``
reads (:func:`gnomon.light.load_pencil_log`).

The pencil
----------
A vertical solid: a cylinder of radius ``PENCIL_RADIUS`` (3.5 mm) from the
desk up to ``PENCIL_HEIGHT − CONE_LENGTH``, then a sharpened cone up to the
apex at height ``PENCIL_HEIGHT`` (150 mm) above the base centre. Albedo
``PENCIL_ALBEDO``. It is shaded like every surface of the scene
(ambient + Lambert from the lamp's centre, hard shadows of the scene's
objects) and casts a **soft** shadow: the occluded fraction of the lamp
(a sphere of radius ``lamp_radius``, seen from a surface point as a disc)
is averaged over ``LAMP_SAMPLES`` points of that disc (a sunflower pattern).

Positions: a 10 mm grid of desk points is filtered to those where the whole
pencil stands clear of every object (≥ 6 mm), the pencil, its apex, its
base and its shadow's tip are inside the image (4 % margin), and the shadow
from base to tip falls on bare desk that is lit and visible from the camera
(not hidden by an object or the pencil); N positions are then picked by
farthest-point sampling, so the pencil's lines to the lamp are well spread.

What is written
---------------
* ``pencil/pencil_K.{jpg,png}``, K = 0 … N − 1;
* ``pencil_log.toml``: ``[camera]`` (+ ``[camera.pose]``), ``[[planes]]``
  ``desk``, and ``[pencil]`` with ``height``, ``sigma_px``, ``units``,
  ``plane`` and ``photos = [{ base = [u, v], tip = [u, v], image = "…" }, …]``:
  ``base`` is the true projection of the pencil's base centre (the point of
  the desk under the pencil's axis), ``tip`` the true projection of the shadow's
  tip — the point where the line from the lamp's centre through the apex meets
  the desk — each rounded to 0.1 px (so ``sigma_px = 0.05``: the rounding's
  σ ≈ 0.03 px, with margin);
* ground truth (in the capture's ``ground_truth.npz``): ``pencil_bases_world``,
  ``pencil_tops_world``, ``pencil_tips_world`` (N, 3), ``pencil_base_pixels``,
  ``pencil_tip_pixels`` (N, 2, unrounded), ``pencil_height``,
  ``pencil_radius`` (and ``lamp``); and a ``pencil`` entry in
  ``ground_truth.json``. With no photos the arrays have length 0.

Like the rest of the simulator, nothing here uses the pipeline's geometry.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gnomon.errors import GnomonError
from gnomon.simulate import geometry as geo
from gnomon.simulate.sensor import AMBIENT, encode_image
from gnomon.util import atomic, toml_io

PENCIL_HEIGHT = 150.0     # base to apex, mm
PENCIL_RADIUS = 3.5       # mm
CONE_LENGTH = 18.0        # the sharpened part, mm
PENCIL_ALBEDO = 0.55
LAMP_SAMPLES = 128        # points of the lamp's disc for the soft shadow
GRID_STEP = 10.0          # mm, candidate positions
CLEARANCE = 6.0           # mm between the pencil and any object
IMAGE_MARGIN = 0.04       # of the image size, for base, tip and apex
SIGMA_PX = 0.05           # what the log claims for its 0.1 px rounding


# --------------------------------------------------------------------------- the pencil

class Cone:
    """A solid cone: apex V, unit axis ``a`` pointing from the apex into
    the cone, half-angle with ``tan = k``, from the apex to ``length`` along the axis
    (the base disc is not a surface: the pencil's body covers it)."""

    def __init__(self, apex, axis, tan_half_angle: float, length: float) -> None:
        self.V = np.asarray(apex, dtype=np.float64)
        a = np.asarray(axis, dtype=np.float64)
        self.a = a / np.linalg.norm(a)
        self.k = float(tan_half_angle)
        self.L = float(length)

    def intersect(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        w = np.asarray(o, dtype=np.float64) - self.V
        d = np.asarray(d, dtype=np.float64)
        g = 1.0 + self.k * self.k
        wa = np.einsum("...i,i->...", w, self.a)
        da = np.einsum("...i,i->...", d, self.a)
        A = np.einsum("...i,...i->...", d, d) - g * da * da
        B = np.einsum("...i,...i->...", w, d) - g * wa * da
        C = np.einsum("...i,...i->...", w, w) - g * wa * wa
        disc = B * B - A * C
        ok = disc >= 0.0
        sq = np.sqrt(np.where(ok, disc, 0.0))
        best = np.full(np.broadcast(wa, da).shape, np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            for sgn in (-1.0, 1.0):
                t = (-B + sgn * sq) / A
                s = wa + t * da
                good = ok & np.isfinite(t) & (t > geo.EPS_T) & (s >= 0.0) & (s <= self.L)
                best = np.where(good & (t < best), t, best)
        return best

    def normal(self, X: np.ndarray) -> np.ndarray:
        q = np.asarray(X, dtype=np.float64) - self.V
        qa = np.einsum("...i,i->...", q, self.a)
        n = q - (1.0 + self.k * self.k) * qa[..., None] * self.a
        return n / np.linalg.norm(n, axis=-1, keepdims=True)


class Pencil:
    """A sharpened pencil standing on the desk (z = 0) with its base centre at ``base``."""

    def __init__(self, base_xy, height: float = PENCIL_HEIGHT, radius: float = PENCIL_RADIUS,
                 cone_length: float = CONE_LENGTH) -> None:
        x, y = (float(c) for c in base_xy)
        self.base = np.array([x, y, 0.0])
        self.top = np.array([x, y, float(height)])
        self.height, self.radius = float(height), float(radius)
        body = height - cone_length
        self.body = geo.Cylinder((x, y, body / 2.0), (0.0, 0.0, 1.0), radius, body)
        self.cone = Cone(self.top, (0.0, 0.0, -1.0), radius / cone_length, cone_length)

    def intersect(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        return np.minimum(self.body.intersect(o, d), self.cone.intersect(o, d))

    def normal(self, X: np.ndarray) -> np.ndarray:
        on_cone = X[..., 2] > self.body.c[2] + self.body.h + 1e-9
        return np.where(on_cone[..., None], self.cone.normal(X), self.body.normal(X))

    def shadow_tip(self, S: np.ndarray) -> np.ndarray:
        """Where the line from the lamp's centre S through the apex meets the desk."""
        k = S[2] / (S[2] - self.top[2])
        return S + k * (self.top - S)


def _inside_inflated(obj, X: np.ndarray, margin: float) -> np.ndarray:
    """Points X (M, 3) inside ``obj`` grown by ``margin`` (sphere, box or cylinder)."""
    if isinstance(obj, geo.Sphere):
        return np.linalg.norm(X - obj.c, axis=-1) < obj.r + margin
    if isinstance(obj, geo.Box):
        return (np.abs(obj._local(X)) <= obj.half + margin).all(axis=-1)
    if isinstance(obj, geo.Cylinder):
        q = X - obj.c
        z = q @ obj.a
        r = np.linalg.norm(q - z[:, None] * obj.a, axis=-1)
        return (np.abs(z) <= obj.h + margin) & (r <= obj.r + margin)
    raise TypeError(f"no containment test for {type(obj).__name__}")  # pragma: no cover


def _sunflower(n: int) -> np.ndarray:
    """n points evenly spread over the unit disc (Vogel's spiral), (n, 2)."""
    i = np.arange(n) + 0.5
    r = np.sqrt(i / n)
    th = i * math.pi * (3.0 - math.sqrt(5.0))
    return np.stack([r * np.cos(th), r * np.sin(th)], axis=1)


# --------------------------------------------------------------------------- positions

def pencil_positions(scene, n: int) -> np.ndarray:
    """n well-spread base positions (n, 2) on bare, lit, visible desk (see the module docstring)."""
    S, C = scene.S, scene.C
    W, H = scene.W, scene.H
    # The desk seen by the camera, roughly: from the image corners.
    corners = scene.desk_point(np.array([0.0, W - 1.0, 0.0, W - 1.0]), np.array([0.0, 0.0, H - 1.0, H - 1.0]))
    lo, hi = corners[:, :2].min(axis=0), corners[:, :2].max(axis=0)
    xs = np.arange(math.floor(lo[0] / GRID_STEP), math.ceil(hi[0] / GRID_STEP) + 1) * GRID_STEP
    ys = np.arange(math.floor(lo[1] / GRID_STEP), math.ceil(hi[1] / GRID_STEP) + 1) * GRID_STEP
    gx, gy = np.meshgrid(xs, ys)
    base = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    top = base + [0.0, 0.0, PENCIL_HEIGHT]
    tip = S + (S[2] / (S[2] - top[:, 2]))[:, None] * (top - S)
    mu, mv = IMAGE_MARGIN * W, IMAGE_MARGIN * H

    def in_image(X):
        uv = scene.project(X)
        return (uv[..., 0] >= mu) & (uv[..., 0] <= W - 1 - mu) & (uv[..., 1] >= mv) & (uv[..., 1] <= H - 1 - mv)

    ok = in_image(base) & in_image(tip) & in_image(top) & (S[2] > PENCIL_HEIGHT + 1.0)
    base, top, tip = base[ok], top[ok], tip[ok]
    # Clear of every object, the whole height.
    heights = np.linspace(0.0, PENCIL_HEIGHT, 16)
    axis_pts = base[:, None, :] + heights[None, :, None] * np.array([0.0, 0.0, 1.0])
    ok = np.ones(len(base), dtype=bool)
    for obj, _ in scene.objects.values():
        inside = _inside_inflated(obj, axis_pts.reshape(-1, 3), PENCIL_RADIUS + CLEARANCE)
        ok &= ~inside.reshape(axis_pts.shape[:2]).any(axis=1)
    # The apex is lit.
    for obj, _ in scene.objects.values():
        ok &= ~(obj.intersect(top, S - top) < 1.0)
    base, top, tip = base[ok], top[ok], tip[ok]
    # The shadow (base → tip, and a little to each side) on lit, visible, bare desk.
    f = np.linspace(0.0, 1.0, 25)
    seg = base[:, None, :] + f[None, :, None] * (tip - base)[:, None, :]
    side = np.cross(tip - base, [0.0, 0.0, 1.0])
    side /= np.maximum(np.linalg.norm(side, axis=-1, keepdims=True), 1e-12)
    pts = np.concatenate([seg + s * 1.5 * PENCIL_RADIUS * side[:, None, :] for s in (-1.0, 0.0, 1.0)], axis=1)
    flat = pts.reshape(-1, 3)
    good = in_image(flat)
    for obj, _ in scene.objects.values():
        good &= ~(obj.intersect(C, flat - C) < 1.0 - 1e-9)             # seen by the camera
        good &= ~(obj.intersect(flat + [0.0, 0.0, 1e-6], S - flat) < 1.0)   # lit
    ok = good.reshape(pts.shape[:2]).all(axis=1)
    base, tip = base[ok], tip[ok]
    # The pencil does not hide its own shadow's tip from the camera.
    keep = [i for i in range(len(base))
            if not (Pencil(base[i, :2]).intersect(C, tip[i] - C) < 1.0 - 1e-9)]
    cand = base[np.array(keep, dtype=np.int64)] if keep else np.zeros((0, 3))
    if len(cand) < n:
        raise GnomonError(f"simulate {scene.name}: only {len(cand)} places on the desk fit a pencil "
                          f"photo, {n} asked for")
    # Farthest-point sampling, starting from the candidate farthest from their centroid.
    chosen = [int(np.argmax(np.linalg.norm(cand - cand.mean(axis=0), axis=1)))]
    dmin = np.linalg.norm(cand - cand[chosen[0]], axis=1)
    while len(chosen) < n:
        j = int(np.argmax(dmin))
        chosen.append(j)
        dmin = np.minimum(dmin, np.linalg.norm(cand - cand[j], axis=1))
    return cand[chosen, :2]


# --------------------------------------------------------------------------- rendering

def pencil_linear_image(scene, pencil: Pencil) -> np.ndarray:
    """Linear radiance (H, W) of the stick-free scene with ``pencil`` in it, blurred and cropped."""
    C, S = scene.C, scene.S
    d = scene.rays_world_f
    t_p = pencil.intersect(C, d)
    t_scene = np.where(scene.hit_f, np.linalg.norm(np.where(scene.hit_f[..., None], scene.points_f, C) - C,
                                                    axis=-1), np.inf)
    on_pencil = t_p < t_scene
    L = scene.ambient_f + scene.direct_f * (1.0 - _pencil_occlusion(scene, pencil, ~on_pencil))
    # The pencil's own surface: ambient + Lambert, hard shadows of the objects.
    Pp = C + t_p[on_pencil][:, None] * d[on_pencil]
    n = pencil.normal(Pp)
    to_s = S - Pp
    dist2 = np.einsum("ij,ij->i", to_s, to_s)
    cos_i = np.einsum("ij,ij->i", n, to_s) / np.sqrt(dist2)
    blocked = np.zeros(len(Pp), dtype=bool)
    for obj, _ in scene.objects.values():
        blocked |= obj.intersect(Pp + 1e-6 * n, to_s) < 1.0
    direct = np.where(blocked, 0.0, scene.E * np.maximum(cos_i, 0.0) / dist2)
    albedo = getattr(scene.config, "pencil_albedo", None)
    L[on_pencil] = (PENCIL_ALBEDO if albedo is None else albedo) * (AMBIENT + direct)
    return scene._finish(L, True)


def _pencil_occlusion(scene, pencil: Pencil, mask: np.ndarray) -> np.ndarray:
    """Fraction of the lamp's disc the pencil hides, per (padded) pixel in ``mask``."""
    S, r_lamp = scene.S, scene.config.lamp_radius
    out = np.zeros(mask.shape)
    cand = mask & scene.receives_light_f
    P = scene.points_f[cand]
    # A loose test first: the segment P → S passes near the pencil's axis below its apex.
    v = S - P
    zmax = pencil.height + r_lamp + 1.0
    tau_top = np.clip((zmax - P[:, 2]) / v[:, 2], 0.0, 1.0)
    rel = pencil.base[:2] - P[:, :2]
    vh = v[:, :2]
    tau = np.clip(np.einsum("ij,ij->i", rel, vh) / np.maximum(np.einsum("ij,ij->i", vh, vh), 1e-12), 0.0, tau_top)
    gap = np.linalg.norm(P[:, :2] + tau[:, None] * vh - pencil.base[:2], axis=1)
    near = gap <= pencil.radius + r_lamp * tau + 1.0
    idx = np.flatnonzero(near)
    frac = np.zeros(len(P))
    if idx.size:
        Pn = P[idx]
        w = S - Pn
        wn = w / np.linalg.norm(w, axis=1, keepdims=True)
        helper = np.where(np.abs(wn[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        e1 = np.cross(wn, helper)
        e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
        e2 = np.cross(wn, e1)
        disc = _sunflower(LAMP_SAMPLES) * r_lamp
        hidden = np.zeros(len(Pn))
        for chunk in np.array_split(np.arange(LAMP_SAMPLES), 8):
            Sj = S + disc[chunk, 0][None, :, None] * e1[:, None, :] + disc[chunk, 1][None, :, None] * e2[:, None, :]
            dirs = Sj - Pn[:, None, :]
            hit = pencil.intersect(np.broadcast_to(Pn[:, None, :], dirs.shape), dirs) < 1.0
            hidden += hit.sum(axis=1)
        frac[idx] = hidden / LAMP_SAMPLES
    out[cand] = frac
    return out


# --------------------------------------------------------------------------- outputs

@dataclass
class PencilPhotos:
    """What :func:`write_pencil_photos` rendered and wrote."""

    bases_world: np.ndarray       # (N, 3), on the desk
    tops_world: np.ndarray        # (N, 3), the apexes
    tips_world: np.ndarray        # (N, 3), shadow tips on the desk
    base_pixels: np.ndarray       # (N, 2), exact
    tip_pixels: np.ndarray        # (N, 2), exact
    paths: list[Path] = field(default_factory=list)
    images: list[str] = field(default_factory=list)   # relative to the capture folder
    height: float = PENCIL_HEIGHT
    radius: float = PENCIL_RADIUS
    albedo: float = PENCIL_ALBEDO


def write_pencil_photos(scene, out: Path, n: int) -> PencilPhotos:
    """Render n pencil photos of ``scene`` into ``out/pencil/`` (atomically); return the truth."""
    c = scene.config
    xy = pencil_positions(scene, n)
    folder = out / "pencil"
    folder.mkdir(parents=True, exist_ok=True)
    side = 0 if getattr(c, "lamp_side", "left") == "left" else 1
    bases, tops, tips, paths, images = [], [], [], [], []
    for k, b in enumerate(xy):
        pencil = Pencil(b)
        rng = np.random.default_rng([c.seed, 4, side, k])
        img = scene.encode(pencil_linear_image(scene, pencil), rng)
        name = f"pencil_{k}.{c.extension}"
        atomic.write_bytes(folder / name, encode_image(img, c))
        bases.append(pencil.base)
        tops.append(pencil.top)
        tips.append(pencil.shadow_tip(scene.S))
        paths.append(folder / name)
        images.append(f"pencil/{name}")
    albedo = PENCIL_ALBEDO if getattr(c, "pencil_albedo", None) is None else float(c.pencil_albedo)
    return PencilPhotos(np.array(bases), np.array(tops), np.array(tips), scene.project(np.array(bases)),
                        scene.project(np.array(tips)), paths, images, albedo=albedo)


def ground_truth_arrays(ph: PencilPhotos | None) -> dict[str, np.ndarray]:
    if ph is None:
        z3, z2 = np.zeros((0, 3)), np.zeros((0, 2))
        ph = PencilPhotos(z3, z3, z3, z2, z2)
    return {
        "pencil_bases_world": ph.bases_world,
        "pencil_tops_world": ph.tops_world,
        "pencil_tips_world": ph.tips_world,
        "pencil_base_pixels": ph.base_pixels,
        "pencil_tip_pixels": ph.tip_pixels,
        "pencil_height": np.array(ph.height, dtype=np.float64),
        "pencil_radius": np.array(ph.radius, dtype=np.float64),
    }


def ground_truth_summary(ph: PencilPhotos | None) -> dict:
    if ph is None:
        return {"photos": 0}
    return {
        "photos": len(ph.images),
        "height_mm": ph.height,
        "radius_mm": ph.radius,
        "cone_length_mm": CONE_LENGTH,
        "albedo": ph.albedo,
        "images": ph.images,
        "bases_world": ph.bases_world.tolist(),
        "tops_world": ph.tops_world.tolist(),
        "tips_world": ph.tips_world.tolist(),
        "base_pixels": ph.base_pixels.tolist(),
        "tip_pixels": ph.tip_pixels.tolist(),
    }


def pencil_log(scene, ph: PencilPhotos) -> dict:
    """The ``gnomon calibrate lamp`` field log for these photos (see the module docstring)."""
    cam = scene.camera_table()
    return {
        "camera": cam,
        "planes": [{"name": "desk", "point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}],
        "pencil": {
            "height": float(ph.height),
            "sigma_px": SIGMA_PX,
            "units": "mm",
            "plane": "desk",
            "photos": [{"base": [round(float(x), 1) for x in b], "tip": [round(float(x), 1) for x in t],
                        "image": img}
                       for b, t, img in zip(ph.base_pixels, ph.tip_pixels, ph.images, strict=True)],
        },
    }


def write_pencil_log(scene, ph: PencilPhotos, path: Path) -> None:
    header = (f"Pencil photos for lamp calibration, written by `gnomon simulate {scene.name}` "
              f"(seed {scene.config.seed}).\n"
              "Run: gnomon calibrate lamp pencil_log.toml. Pixels are exact projections rounded to 0.1 px;\n"
              "the true lamp is `lamp` in ground_truth.npz.")
    toml_io.dump(pencil_log(scene, ph), path, header=header)
