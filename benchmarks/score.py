"""Scoring a scan of a real two-plane capture against its own reference planes.

Used by ``benchmarks/real_captures.py``; not part of the package (it needs
hand-drawn outlines of the object, which only a benchmark has).

Frames: the scan's world frame, i.e. the first plane's markers' frame (the
desk's). Each pixel sees the plane its ray meets first (desk and wall form a
concave corner). "Bare" pixels are those pixels inside the planes' marker
rectangles grown by ``margin`` (world units), away from the object's and its
cast shadow's outlines (grown by ``keep_out_px``) and from the markers.

False points are points off both reference planes (by more than ``false_mm``)
and outside the object. Other real surfaces in view (the frog capture's two
boxes) are outlined face by face: each face gets a robust plane fitted to the
scan's own points inside it (reported with its residual and its angle to the
first plane, so the reader can judge whether it is a real flat face), and a
point within ``false_mm`` of the plane of a face whose outline it lies in is a
point on that surface, not a false point. Both figures are printed: every point
off both planes, and those also off every outlined face.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from gnomon.camera.calibration import load_camera_file
from gnomon.camera.models import Pose
from gnomon.config.fieldlog import load_field_log
from gnomon.config.setup import ScanSetup, frame_source, resolve_scan
from gnomon.config.specs import FieldLog
from gnomon.runs.scan import ScanResult
from gnomon.runs.scan import scan as scan_in_memory


def frog_arguments(doc: str, argv: list[str] | None) -> argparse.Namespace:
    """A measuring script's arguments: ``FIELD_LOG [--frog]`` (the frog's regions of real_captures.py)."""
    ap = argparse.ArgumentParser(description=doc.split("\n")[0])
    ap.add_argument("field_log", type=Path)
    ap.add_argument("--frog", action="store_true", help="the frog's regions (real_captures.py's outlines)")
    return ap.parse_args(argv)


def scan_field_log(path: Path) -> tuple[FieldLog, ScanSetup, ScanResult]:
    """The field log at ``path`` loaded, resolved and scanned in memory (no files written)."""
    log = load_field_log(path)
    source = frame_source(log)
    setup = resolve_scan(log, source)
    return log, setup, scan_in_memory(setup, source)


@dataclass
class PlaneScore:
    name: str
    swept: int  # bare pixels with a shadow time
    points: int  # of those, with a point
    median_abs: float  # median |distance| to the markers' plane
    rms: float  # RMS distance to the markers' plane
    fit_median_abs: float  # median |distance| to the points' own best plane (flatness alone)
    fit_rms: float

    @property
    def coverage(self) -> float:
        return self.points / max(self.swept, 1)


@dataclass
class FaceScore:
    """A robust plane through the scan's points on one outlined face of another real surface (camera frame)."""

    name: str
    points: int  # scan points inside the face's outline (shrunk by a few pixels for the fit)
    inliers: int  # points the fit kept (within 3 × 1.4826·MAD of the plane)
    median_abs: float  # median |distance| of the inliers to the plane (world units)
    rms: float  # RMS of the inliers
    angle_to_first_deg: float  # angle between the face's normal and the first reference plane's normal
    normal: np.ndarray
    offset: float  # n·X = offset

    def line(self) -> str:
        return (f"    face '{self.name}': plane through {self.inliers} of its {self.points} points, residual median "
                f"{self.median_abs:.2f} mm, RMS {self.rms:.2f} mm, {self.angle_to_first_deg:.1f}"
                f" deg to the first plane")


@dataclass
class CaptureScore:
    name: str
    planes: list[PlaneScore]
    object_pixels: int = 0
    object_points: int = 0
    object_swept: int = 0
    object_swept_points: int = 0
    # the object's pixels by coverage class (coverage.npy: a point, or why there is none), name → count
    object_reasons: dict[str, int] = field(default_factory=dict)
    false_points: int = 0
    all_points: int = 0
    # points off both planes and outside the object but within false_mm of an outlined face's plane (real surfaces)
    on_faces: int = 0
    faces: list[FaceScore] = field(default_factory=list)
    # where the false points are: (place, count), places in the order tested (a point counts in the first)
    false_where: list[tuple[str, int, int | None]] = field(default_factory=list)
    # of false_points, those also farther than 5 of their own predicted σ from every surface (None: no sigma.npy)
    false_beyond_5_sigma: int | None = None
    notes: list[str] = field(default_factory=list)
    # (H, W) bool: the false points (for drawing where they are); None until scored
    false_mask: np.ndarray | None = None
    # with a volume (score_scan's ``volume``): its description, the points inside it and those of them off
    # both planes and outside the object (no face excused: what a scan cropped to it would output)
    volume: str | None = None
    volume_points: int = 0
    volume_off: int = 0

    def summary(self) -> str:
        """One line: each plane's planarity and coverage, the object's coverage, the false points (without an
        object outline, the points off both planes, the object's among them)."""
        planes = "; ".join(f"{p.name} {p.median_abs:.3f} / {p.rms:.3f} mm on {100 * p.coverage:.1f} %"
                           for p in self.planes)
        share = f"{100 * self.false_points / max(self.all_points, 1):.2f} % of {self.all_points}"
        if not self.object_pixels:  # no outline: the object's own points are off both planes too
            return f"{planes}; points off both planes by > 5 mm (object included: no outline) {share}"
        return f"{planes}; object {100 * self.object_points / self.object_pixels:.1f} %; false points {share}"

    def lines(self) -> list[str]:
        out = [f"{self.name}"]
        for p in self.planes:
            out.append(f"  {p.name:5s} planarity median {p.median_abs:.3f} mm, RMS {p.rms:.3f} mm "
                       f"(to its own best plane: median {p.fit_median_abs:.3f}, RMS {p.fit_rms:.3f}); "
                       f"coverage {100 * p.coverage:.1f} % of {p.swept} swept bare pixels")
        if self.object_pixels:
            out.append(f"  object coverage {100 * self.object_points / self.object_pixels:.1f} % of its "
                       f"{self.object_pixels} pixels "
                       f"({100 * self.object_swept_points / max(self.object_swept, 1):.1f} % "
                       f"of the {self.object_swept} with a shadow time)")
            if self.object_reasons:
                out.append("    its pixels: " + ", ".join(f"{name} {100 * n / self.object_pixels:.1f} %"
                                                       for name, n in self.object_reasons.items() if n))
        what = "outside the object" if self.object_pixels else "object included: no outline"
        off = self.false_points + self.on_faces
        out.append(f"  points off both planes by > 5 mm ({what}) "
                   f"{100 * off / max(self.all_points, 1):.2f} % of {self.all_points}")
        if self.faces:
            out.append(f"    of which within 5 mm of an outlined face of another real surface "
                       f"{100 * self.on_faces / max(self.all_points, 1):.2f} %:")
            out.extend(f.line() for f in self.faces)
            out.append(f"  false points (off both planes, outside the object and off every outlined face) "
                       f"{100 * self.false_points / max(self.all_points, 1):.2f} % of {self.all_points}")
        if self.false_beyond_5_sigma is not None:
            out.append(f"    of which farther than 5 sigma (their own predicted sigma) from every surface: "
                       f"{100 * self.false_beyond_5_sigma / max(self.all_points, 1):.2f} %")
        if self.false_where:
            out.append("    where: " + "; ".join(f"{place} {100 * n / max(self.all_points, 1):.2f} %"
                                                + (f" ({100 * b / max(self.all_points, 1):.2f} beyond 5 sigma)"
                                                   if b is not None else "")
                                                for place, n, b in self.false_where))
        if self.volume is not None:
            out.append(f"  within {self.volume}: {self.volume_points} points, off both planes by > 5 mm and outside "
                       f"the object {100 * self.volume_off / max(self.volume_points, 1):.2f} %")
        out.extend(f"  note: {n}" for n in self.notes)
        return out


def _polygon_mask(shape, polygons, grow_px: int = 0) -> np.ndarray:
    m = np.zeros(shape, dtype=np.uint8)
    for poly in polygons:
        cv2.fillPoly(m, [np.asarray(poly, dtype=np.int32).reshape(-1, 1, 2)], 1)
    if grow_px > 0:
        m = cv2.dilate(m, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * grow_px + 1, 2 * grow_px + 1)))
    elif grow_px < 0:
        m = cv2.erode(m, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (-2 * grow_px + 1, -2 * grow_px + 1)))
    return m.astype(bool)


def score_scan(name: str, scan_dir: Path, camera_file: Path,
               extents: dict[str, tuple[float, float, float, float]] | None,
               object_outline: list | None = None, shadow_outlines: list | None = None,
               keep_out_px: int = 12, marker_keep_out_px: int = 40, false_mm: float = 5.0,
               region_masks: dict[str, np.ndarray] | None = None,
               other_faces: dict[str, list] | None = None, border_px: int = 60,
               declared_planes: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
               volume: tuple[str, np.ndarray] | None = None) -> CaptureScore:
    """Score one scan.

    ``extents``: per plane, (x0, x1, y0, y1) in the plane's own 2-D frame
    (world units) where it is bare paper; ``object_outline``: the object's
    outline (pixels) in the first frame; ``shadow_outlines``: its cast
    shadows' outlines (pixels); ``other_faces``: flat faces of other real
    surfaces in view (boxes beside the planes), name → outline (pixels): not
    bare, and a point within ``false_mm`` of its face's fitted plane is not false.
    The false points are also counted by place (``false_where``): in the faces'
    outlines, near the markers, in the cast shadows, within ``border_px`` of
    the image's left and right sides (where the frog's desk board curls), elsewhere.
    ``declared_planes``: planes not measured from markers (absent from report.json's reference planes),
    name → (origin, 3×3 axes with the normal last), camera frame.
    ``volume``: (description, (2, 3) min and max corners of a box in the first plane's frame): the points
    inside it and those of them off both planes and outside the object, every face counted as off
    (what a scan with that ``[output] crop_box`` would output, world = the first marked plane's frame).
    """
    report = json.loads((scan_dir / "report.json").read_text())
    depth = np.load(scan_dir / "depth.npy")
    shadow_time = np.load(scan_dir / "shadow_time.npy")
    cam = load_camera_file(camera_file)
    rays = cam.ray_map().astype(np.float64)
    h, w = depth.shape
    planes = report["reference_planes"]
    # Each plane in the camera frame (from its own markers' pose): origin, axes, normal.
    frames = {}
    for p in planes:
        R = Pose.from_rvec_tvec(np.array(p["rvec"]), np.array(p["tvec"])).R
        frames[p["name"] if "name" in p else p["plane"]] = (np.array(p["tvec"]), R)
    frames.update(declared_planes or {})
    hits = {}
    for pname, (t, R) in frames.items():
        n = R[:, 2]
        with np.errstate(invalid="ignore", divide="ignore"):
            s = (n @ t) / (rays @ n)
        s[s <= 0] = np.inf
        hits[pname] = s
    names = list(frames)
    nearest = np.argmin(np.stack([hits[k] for k in names]), axis=0)
    pts_cam = rays * (depth / rays[..., 2])[..., None]
    markers = np.zeros((h, w), dtype=bool)
    for p in planes:
        for u, v in p["pixels"]:
            markers[max(int(v) - marker_keep_out_px, 0):int(v) + marker_keep_out_px,
                    max(int(u) - marker_keep_out_px, 0):int(u) + marker_keep_out_px] = True
    obj = _polygon_mask((h, w), [object_outline], keep_out_px) if object_outline else np.zeros((h, w), bool)
    shadow = _polygon_mask((h, w), shadow_outlines or [], keep_out_px)
    others = _polygon_mask((h, w), list((other_faces or {}).values()), keep_out_px)
    swept = np.isfinite(shadow_time)
    has = np.isfinite(depth)
    result = CaptureScore(name, [])
    dist_any = np.full((h, w), np.inf)
    for k, pname in enumerate(names):
        t, R = frames[pname]
        on = rays * hits[pname][..., None]
        local = np.einsum("hwi,ij->hwj", on - t, R)  # plane coordinates (x, y, ~0)
        if region_masks is not None:
            inside = region_masks[pname] & (nearest == k)
        else:
            assert extents is not None
            x0, x1, y0, y1 = extents[pname]
            inside = (nearest == k) & np.isfinite(hits[pname]) & (local[..., 0] >= x0) & (local[..., 0] <= x1) \
                & (local[..., 1] >= y0) & (local[..., 1] <= y1)
        bare = inside & ~obj & ~shadow & ~markers & ~others
        d = (pts_cam - t) @ R[:, 2]  # signed distance to the markers' plane
        dist_any = np.minimum(dist_any, np.where(np.isfinite(d), np.abs(d), np.inf))
        sel = bare & swept & has
        dd = d[sel]
        P = pts_cam[sel]
        c = P.mean(axis=0)
        normal = np.linalg.svd(P - c, full_matrices=False)[2][2]
        fit = (P - c) @ normal
        result.planes.append(PlaneScore(pname, int((bare & swept).sum()), int(sel.sum()),
                                        float(np.median(np.abs(dd))), float(np.sqrt(np.mean(dd ** 2))),
                                        float(np.median(np.abs(fit))), float(np.sqrt(np.mean(fit ** 2)))))
    if object_outline:
        tight = _polygon_mask((h, w), [object_outline], -3)
        result.object_pixels = int(tight.sum())
        result.object_points = int((tight & has).sum())
        result.object_swept = int((tight & swept).sum())
        result.object_swept_points = int((tight & swept & has).sum())
        if (scan_dir / "coverage.npy").exists():
            from gnomon.outputs.images import COVERAGE_CLASSES

            coverage = np.load(scan_dir / "coverage.npy")
            result.object_reasons = {name: int((tight & (coverage == k)).sum())
                                     for k, (name, _) in COVERAGE_CLASSES.items()}
    result.all_points = int(has.sum())
    off = has & ~obj & (dist_any > false_mm)
    on_face = np.zeros((h, w), dtype=bool)
    nearest_surface = dist_any.copy()  # distance to the planes, or to the plane of a face whose outline holds it
    first_normal = frames[names[0]][1][:, 2]
    for fname, outline in (other_faces or {}).items():
        face = fit_face(fname, pts_cam, has & _polygon_mask((h, w), [outline], -3), first_normal)
        if face is None:
            result.notes.append(f"face '{fname}': too few points to fit a plane")
            continue
        result.faces.append(face)
        to_face = np.abs(pts_cam @ face.normal - face.offset)
        inside = _polygon_mask((h, w), [outline], keep_out_px)
        on_face |= inside & (to_face <= false_mm)
        nearest_surface = np.where(inside, np.fmin(nearest_surface, to_face), nearest_surface)
    result.on_faces = int((off & on_face).sum())
    if volume is not None:
        t0, R0 = frames[names[0]]
        world = (pts_cam - t0) @ R0  # the first plane's frame: x, y along it, z along its normal
        lo, hi = np.asarray(volume[1], dtype=np.float64)
        with np.errstate(invalid="ignore"):
            within = has & np.all((world >= lo) & (world <= hi), axis=-1)
        result.volume, result.volume_points, result.volume_off = volume[0], int(within.sum()), int((off & within).sum())
    false = off & ~on_face
    result.false_points = int(false.sum())
    result.false_mask = false.copy()
    beyond = None
    if (scan_dir / "sigma.npy").exists():
        sigma = np.load(scan_dir / "sigma.npy")
        with np.errstate(invalid="ignore"):
            beyond = false & ~(nearest_surface <= 5.0 * sigma)
        result.false_beyond_5_sigma = int(beyond.sum())
    border = np.zeros((h, w), dtype=bool)
    border[:, :border_px] = border[:, w - border_px:] = True
    places = [("in the outlined faces, off their planes", others), ("near the markers", markers),
              ("in the object's cast shadow", shadow), (f"within {border_px} px of the image's sides", border),
              ("elsewhere", np.ones((h, w), dtype=bool))]
    for place, mask in places:
        if shadow_outlines or place != "in the object's cast shadow":
            result.false_where.append((place, int((false & mask).sum()),
                                       None if beyond is None else int((beyond & false & mask).sum())))
        false &= ~mask
    return result


def fit_face(name: str, pts_cam: np.ndarray, sel: np.ndarray, first_normal: np.ndarray,
             iterations: int = 10) -> FaceScore | None:
    """A robust total-least-squares plane through the points ``pts_cam[sel]``: refitted on the points
    within 3 × 1.4826·MAD of the last plane until the inliers no longer change; None below 100 points."""
    P = pts_cam[sel].astype(np.float64)
    if len(P) < 100:
        return None
    keep = np.ones(len(P), dtype=bool)
    normal, offset = np.array([0.0, 0.0, 1.0]), 0.0
    for _ in range(iterations):
        c = P[keep].mean(axis=0)
        normal = np.linalg.svd(P[keep] - c, full_matrices=False)[2][2]
        offset = float(normal @ c)
        r = np.abs(P @ normal - offset)
        mad = 1.4826 * float(np.median(r[keep]))
        new = r <= max(3.0 * mad, 1e-9)
        if np.array_equal(new, keep) or new.sum() < 3:
            break
        keep = new
    r = np.abs(P[keep] @ normal - offset)
    angle = float(np.degrees(np.arccos(min(abs(float(normal @ first_normal)), 1.0))))
    return FaceScore(name, len(P), int(keep.sum()), float(np.median(r)), float(np.sqrt(np.mean(r ** 2))), angle,
                     normal, offset)
