"""The ``room`` scene: the two-plane desk and wall lit as a room is, for the points only the lamp can give.

The scene of :mod:`gnomon.simulate.two_plane_scene` (desk, wall, printed markers,
an unknown lamp, the stick's sweep, here a 10 mm rod; the scan runs in two-plane mode; the desk and wall white,
albedo 0.72–0.88) with four
solids — the sphere and box of that scene, a cube and a standing can — and three
things the other scenes leave out:

* **Interreflection** (:mod:`gnomon.simulate.radiosity`): one bounce of the
  lamp's direct light between desk, wall and objects. The surfaces are cut into
  patches (``PATCH_MM`` on the planes, ``OBJECT_PATCH_MM`` on the solids); each
  frame, each patch's direct irradiance (its sub-samples' average, the stick's
  shadow and the solids' shadows included) is sent on to receiving points on a
  grid of every ``RECEIVER_STEP``-th pixel (form factors with visibility, computed
  once), and each pixel takes its bounced light from the grid points of its own
  surface around it (bilinear, only points on the same object with a normal
  within 14°), or from its own receiving point where none is. So a surface the
  lamp never reaches still dims when the stick's shadow crosses the desk or the
  wall it sees: late, slowly, and shallow.
* **A lamp of real size** for the solids' shadows too: the sphere of
  ``lamp_radius`` (3 mm) sampled at ``LAMP_SAMPLES`` points of its disc as each
  surface point sees it, so the solids' cast shadows have penumbrae (the stick's
  shadow is exact: :mod:`gnomon.simulate.shadow`).
* **Sensor noise as a sensor makes it**: shot noise (the linear signal as
  ``full_well`` electrons at full scale, a Gaussian of the Poisson variance) and
  read noise (``read_noise_e`` electrons), then gamma and quantisation
  (:func:`gnomon.simulate.sensor.encode_shot_noise`): about 3.5 DN at 220 DN with
  the defaults, more in the dark (the gamma stretches it).

The radiance of a pixel is ``ρ · (A + E_dir · (1 − f_stick) + E_ind(t))`` with a
small ambient ``A = AMBIENT_ROOM`` (the room beyond, the further bounces).

Ground truth (``ground_truth.npz``), beyond two_plane's: ``direct_light`` (H, W)
the share of the lamp's disc each surface point sees (0: never lit directly),
``lit_directly`` (that share > 0 and the surface facing the lamp), ``direct_share``
the direct light's share of the pixel's fully lit radiance, ``bounce_change`` the
relative change of the pixel's radiance through bounced light alone over the sweep
(max − min of the indirect term over the lit radiance), and ``bounce_only`` the
pixels never lit directly whose radiance bounced light changes by at least
``BOUNCE_ONLY_CHANGE`` (a scanner that times them times another surface's shadow).
``swept`` is two_plane's (lit directly, both edges crossed, not mixed).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from gnomon.simulate import geometry as geo
from gnomon.simulate import radiosity, sensor, shadow
from gnomon.simulate.desk_lamp import (
    BOX,
    CYLINDER,
    DESK,
    DESK_PEAK,
    SPHERE,
    SURFACE_PEAK,
    SimulationResult,
)
from gnomon.simulate.two_plane_scene import (
    BOX_SPEC,
    SPHERE_SPEC,
    WALL,
    WALL_Y,
    TwoPlaneConfig,
    TwoPlaneScene,
    render_two_plane,
    world_to_plane,
)

CUBE = 5
ROOM_OBJECT_NAMES = {DESK: "desk", SPHERE: "sphere", BOX: "box", CYLINDER: "can", WALL: "wall", CUBE: "cube"}
CUBE_SPEC: dict[str, Any] = {"centre": (-10.0, 95.0, 17.0), "size": (34.0, 34.0, 34.0), "yaw_deg": 35.0, "albedo": 0.75}
CAN_SPEC: dict[str, Any] = {"centre": (10.0, -60.0, 25.0), "radius": 16.0, "height": 50.0, "albedo": 0.65}

AMBIENT_ROOM = 0.02       # ambient irradiance (the room beyond, further bounces)
PATCH_MM = 25.0           # patch side on desk and wall
PLANE_SUBSAMPLES = 5      # per patch side on desk and wall
OBJECT_PATCH_MM = 9.0     # patch side on the solids
RECEIVER_STEP = 6         # px between the receiving points of the bounced light
LAMP_SAMPLES = 12         # points of the lamp's disc sampled for the solids' shadows
NORMAL_COS = 0.97         # a pixel takes bounced light from grid points whose normal is within ~14° of its own
BOUNCE_ONLY_CHANGE = 0.01  # relative change of the radiance through bounced light that counts (truth)
DESK_X = (-520.0, 520.0)   # the patched desk and wall (mm): beyond what the camera sees
DESK_Y = (-460.0, WALL_Y)
WALL_Z = (0.0, 480.0)


@dataclass(frozen=True)
class RoomConfig(TwoPlaneConfig):
    """``gnomon simulate room``: two_plane's options (640 × 480, 150 PNG frames by default) and the sensor's
    ``full_well`` (electrons at full scale; 0: no shot noise) and ``read_noise_e`` (electrons); ``noise`` (a
    Gaussian in DN after the gamma, as the other scenes') is 0 by default. ``bounce``: False renders the same
    room without interreflection (the direct light and the ambient only)."""

    width: int = 640
    height: int = 480
    frames: int = 150
    noise: float = 0.0
    jpeg_quality: int = 0
    stick_radius: float = 5.0
    full_well: float = 1150.0
    read_noise_e: float = 3.0
    bounce: bool = True

    @property
    def scene_name(self) -> str:
        return "room"

    def validate(self) -> None:
        super().validate()
        if not (math.isfinite(self.full_well) and (self.full_well == 0 or 50 <= self.full_well <= 1e7)):
            raise self.error(f"--full-well {self.full_well}: must be 0 (no shot noise) or 50 to 1e7 electrons")
        if not (math.isfinite(self.read_noise_e) and 0 <= self.read_noise_e <= 1000):
            raise self.error(f"--read-noise {self.read_noise_e}: must be 0 to 1000 electrons")
        if self.markers != "checker" or self.marks != "measured":
            raise self.error("--markers / --marks: the room has measured checker marks only (--markers checker "
                             "--marks measured)")


def _disc_samples(n: int) -> np.ndarray:
    """(n, 2) points of the unit disc, about equally spread (a sunflower)."""
    k = np.arange(n) + 0.5
    r = np.sqrt(k / n)
    a = k * math.pi * (3.0 - math.sqrt(5.0))
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


class RoomScene(TwoPlaneScene):
    """The room (see the module docstring)."""

    config: RoomConfig

    def _texture(self, ab: np.ndarray, key: int) -> np.ndarray:
        """A white desk and wall: two_plane's texture pulled to 0.72–0.88 (a room's bounce is strong)."""
        return 0.80 + 0.53 * (super()._texture(ab, key) - 0.60)

    def _objects(self) -> dict[int, tuple[geo.Surface, float]]:
        s, b, c, k = SPHERE_SPEC, BOX_SPEC, CUBE_SPEC, CAN_SPEC
        can_centre = np.asarray(k["centre"], dtype=np.float64)
        return {
            SPHERE: (geo.Sphere(s["centre"], s["radius"]), s["albedo"]),
            BOX: (geo.Box(b["centre"], b["size"], b["yaw_deg"]), b["albedo"]),
            CUBE: (geo.Box(c["centre"], c["size"], c["yaw_deg"]), c["albedo"]),
            CYLINDER: (geo.Cylinder(can_centre, (0.0, 0.0, 1.0), k["radius"], k["height"]), k["albedo"]),
        }

    # ------------------------------------------------------------- direct light from a lamp of real size
    def _lamp_visibility(self, P: np.ndarray, n: np.ndarray) -> np.ndarray:
        """(M,) share of the lamp's disc (radius ``lamp_radius``, as seen from each point P) no solid hides."""
        to_s = self.S - P
        dist = np.linalg.norm(to_s, axis=-1, keepdims=True)
        w = to_s / dist
        e1 = np.cross(w, [0.0, 0.0, 1.0])
        e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
        e2 = np.cross(w, e1)
        o = P + radiosity.SURFACE_OFFSET * n
        seen = np.zeros(len(P))
        solids = [obj for obj, _ in self.objects.values()]
        for dx, dy in _disc_samples(LAMP_SAMPLES) * self.config.lamp_radius:
            target = self.S + dx * e1 + dy * e2
            seen += ~radiosity.segment_blocked(o, target, solids)
        return seen / LAMP_SAMPLES

    def _light(self) -> None:
        n, hit = self.normals_f, self.hit_f
        Pz, _, dist2, cos_i, facing = self._lamp_geometry()
        vis = np.zeros(hit.shape)
        vis[facing] = self._lamp_visibility(Pz[facing], n[facing])
        raw = np.where(facing, self.albedo_f * np.maximum(cos_i, 0.0) * vis / dist2, 0.0)
        self._setup_bounce()
        ind = self.albedo_f * self._gather(self._patch_irradiance(None)) if self.config.bounce else np.zeros_like(raw)
        amb = self.albedo_f * AMBIENT_ROOM
        c = self.crop
        raw_c, ind_c, amb_c = raw[c], ind[c], amb[c]
        ref = (facing & (vis > 0.5) & np.isin(self.object_id_f, self.REFERENCE_IDS))[c]
        lit_sum = raw_c + ind_c
        i_ref = np.argmax(np.where(ref, lit_sum, -1.0))
        E = (DESK_PEAK - amb_c.flat[i_ref]) / lit_sum.flat[i_ref]
        total = amb + E * (raw + ind)
        if np.max(total) > SURFACE_PEAK:
            i_all = np.argmax(total)
            E = (SURFACE_PEAK - amb.flat[i_all]) / (raw + ind).flat[i_all]
        self.E = float(E)
        self.cos_incidence_f = np.where(hit, cos_i, np.nan)
        self.direct_f = E * raw
        self.ambient_f = amb
        self.indirect_lit_f = E * ind          # the bounced radiance with the stick away
        self.direct_light_f = vis              # the share of the lamp's disc each point sees
        self.lit_f = facing & (vis >= 0.5) & (cos_i > 0.05)
        self.receives_light_f = facing & (vis > 0.0)
        self.in_cast_shadow_f = facing & (vis < 1.0)
        self.dist_to_lamp_f = np.sqrt(dist2)

    # ------------------------------------------------------------- the bounce
    def _setup_bounce(self) -> None:
        """Patches, their direct irradiance without the stick, receiving points, form factors, the pixels'
        interpolation weights."""
        desk = radiosity.plane_patches(
            (DESK_X[0], DESK_Y[0], 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), DESK_X[1] - DESK_X[0],
            DESK_Y[1] - DESK_Y[0], PATCH_MM, PLANE_SUBSAMPLES,
            lambda X: self._texture(world_to_plane(DESK, X), 1))
        wall = radiosity.plane_patches(
            (DESK_X[0], WALL_Y, WALL_Z[1]), (1.0, 0.0, 0.0), (0.0, 0.0, -1.0), DESK_X[1] - DESK_X[0],
            WALL_Z[1] - WALL_Z[0], PATCH_MM, PLANE_SUBSAMPLES,
            lambda X: self._texture(world_to_plane(WALL, X), 5))
        parts = [desk, wall]
        for oid, (obj, albedo) in self.objects.items():
            if isinstance(obj, geo.Sphere):
                parts.append(radiosity.sphere_patches(obj, OBJECT_PATCH_MM, albedo))
            elif isinstance(obj, geo.Box):
                parts.append(radiosity.box_patches(obj, OBJECT_PATCH_MM, albedo))
            elif isinstance(obj, geo.Cylinder):
                parts.append(radiosity.cylinder_patches(obj, OBJECT_PATCH_MM, albedo))
            else:  # pragma: no cover - the room's solids are the three kinds above
                raise TypeError(f"no patches for object {oid}")
        patches = radiosity.concat_patches(parts)
        solids = [obj for obj, _ in self.objects.values()]
        # Each sub-sample's direct irradiance without the stick (E = 1): the solids' shadows from the lamp's
        # centre (the patches are far larger than the penumbrae), nothing under a solid.
        X = patches.sub_points
        nrm = patches.normal[patches.sub_patch]
        to_s = self.S - X
        d2 = np.einsum("ij,ij->i", to_s, to_s)
        cos_s = np.einsum("ij,ij->i", nrm, to_s) / np.sqrt(d2)
        ok = cos_s > 0
        ok[ok] &= ~radiosity.segment_blocked(X[ok] + radiosity.SURFACE_OFFSET * nrm[ok], self.S, solids)
        ok &= ~self._inside_solids(X + radiosity.SURFACE_OFFSET * nrm)
        self.patches = patches
        self.sub_direct = np.where(ok, np.maximum(cos_s, 0.0) / d2, 0.0)
        # Receiving points: every RECEIVER_STEP-th pixel of the padded grid, and the pixels that have none
        # of their own surface around them.
        grid = radiosity.receiver_grid(self.hit_f, self.object_id_f, self.normals_f, RECEIVER_STEP, NORMAL_COS)
        self.receivers = grid
        self.rx, self.pixel_index = grid.rx, grid.pixel_index
        self.pixel_nodes, self.pixel_weights = grid.nodes, grid.weights
        nf = self.normals_f
        self.form = radiosity.form_factors(self.points_f[self.rx], nf[self.rx], patches, solids)

    def _inside_solids(self, X: np.ndarray) -> np.ndarray:
        """(M,) bool: points strictly inside one of the solids (a ray from them meets its surface an odd
        number of times: for a convex solid, a ray up and a ray down both meet it)."""
        inside = np.zeros(len(X), dtype=bool)
        up = np.broadcast_to([0.0, 0.0, 1.0], X.shape)
        for obj, _ in self.objects.values():
            inside |= np.isfinite(obj.intersect(X, up)) & np.isfinite(obj.intersect(X, -up))
        return inside

    def _patch_irradiance(self, t: float | None) -> np.ndarray:
        """(J,) each patch's albedo times its direct irradiance (E = 1) at time t (None: the stick away)."""
        sub = self.sub_direct
        if t is not None:
            QA, QB = self.stick_pose(t)
            c = self.config
            _, _, w, h = shadow.stick_axes(self.S, QA, QB, self.motion)
            X = self.patches.sub_points
            near = (sub > 0) & (np.abs((X - self.S) @ w) <= 1.5 * (c.stick_radius + c.lamp_radius)
                                * np.linalg.norm(X - self.S, axis=1) / h + 1.0)
            if near.any():
                sub = sub.copy()
                sub[near] *= 1.0 - shadow.occluded_fraction(X[near], self.S, c.lamp_radius, QA, QB, c.stick_radius)
        return self.patches.albedo * self.patches.average(sub)

    def _gather(self, radiosity_j: np.ndarray) -> np.ndarray:
        """The bounced irradiance (E = 1) on the padded grid from the patches' radiosity (J,)."""
        return self.receivers.spread(self.form @ radiosity_j.astype(np.float32), self.hit_f.shape)

    def indirect_full(self, t: float) -> np.ndarray:
        """The bounced radiance on the padded grid at (fractional) time t."""
        if not self.config.bounce:
            return np.zeros(self.hit_f.shape, dtype=np.float32)
        return (self.E * self.albedo_f * self._gather(self._patch_irradiance(t))).astype(np.float32)

    # ------------------------------------------------------------- images
    def linear_image(self, t: float, *, blur: bool = True, shift: np.ndarray | None = None) -> np.ndarray:
        f = self._occlusion_full(t)
        return self._finish(self.ambient_f + self.direct_f * (1.0 - f) + self.indirect_full(t), blur, shift)

    def lit_image(self, *, blur: bool = True) -> np.ndarray:
        return self._finish(self.ambient_f + self.direct_f + self.indirect_lit_f, blur)

    def encode(self, L_blurred: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        c = self.config
        return sensor.encode_shot_noise(L_blurred, c.gamma, c.full_well, c.read_noise_e, c.noise, rng)

    # ------------------------------------------------------------- ground truth
    def _ground_truth(self) -> None:
        super()._ground_truth()
        lo = hi = self.indirect_full(0.0)
        for k in range(1, self.N):
            ind = self.indirect_full(float(k))
            lo, hi = np.minimum(lo, ind), np.maximum(hi, ind)
        lit = self.ambient_f + self.direct_f + self.indirect_lit_f
        with np.errstate(invalid="ignore", divide="ignore"):
            change = np.where(self.hit_f, (hi - lo) / np.maximum(lit, 1e-12), 0.0)
            share = np.where(self.hit_f, self.direct_f / np.maximum(lit, 1e-12), 0.0)
        c = self.crop
        self.bounce_change = change[c].astype(np.float32)
        self.direct_share = share[c].astype(np.float32)
        self.direct_light = self.direct_light_f[c].astype(np.float32)
        self.bounce_only = self.hit & ~self.receives_light & (self.bounce_change >= BOUNCE_ONLY_CHANGE)

    def ground_truth_arrays(self) -> dict[str, np.ndarray]:
        arrays = super().ground_truth_arrays()
        arrays.update({
            "direct_light": self.direct_light,
            "lit_directly": self.receives_light.copy(),
            "direct_share": self.direct_share,
            "bounce_change": self.bounce_change,
            "bounce_only": self.bounce_only,
        })
        return arrays

    def summary(self) -> dict:
        out = super().summary()
        out["objects"] = {ROOM_OBJECT_NAMES[k]: {"id": k} for k in self.objects}
        out["objects"]["sphere"].update(SPHERE_SPEC)
        out["objects"]["box"].update(BOX_SPEC)
        out["objects"]["cube"].update(CUBE_SPEC)
        out["objects"]["can"].update(CAN_SPEC)
        out["object_ids"] = {str(k): v for k, v in ROOM_OBJECT_NAMES.items()}
        out["room"] = {
            "ambient_irradiance": AMBIENT_ROOM, "bounce": self.config.bounce, "patches": len(self.patches),
            "receiving_points": int(len(self.rx[0])), "lamp_samples": LAMP_SAMPLES,
            "never_lit_directly": int((self.hit & ~self.receives_light).sum()),
            "bounce_only": int(self.bounce_only.sum()),
            "full_well_e": self.config.full_well, "read_noise_e": self.config.read_noise_e,
        }
        return out


def simulate_room(out_dir, config: RoomConfig | None = None, *,
                  progress: Callable[[int, int], None] | None = None) -> SimulationResult:
    """Render the room capture into ``out_dir`` (as :func:`gnomon.simulate.simulate_two_plane`)."""
    config = config or RoomConfig()
    header = (f"Synthetic capture written by `gnomon simulate room` (seed {config.seed}): the two-plane desk\n"
              "and wall with one bounce of interreflection, a lamp of real size, shot and read noise.\n"
              "Ground truth: ground_truth.npz and ground_truth.json beside this file.\n")
    return render_two_plane(out_dir, config, RoomScene, [config.seed, 3, 5], header, ROOM_OBJECT_NAMES, progress)
