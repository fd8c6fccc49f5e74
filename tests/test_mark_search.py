"""Marks found without hints (issue 34, item 2) and the field log `gnomon regions` completes.

The images are drawn here: 2×2 checkers as two dark quadrilaterals meeting at a known centre (anti-aliased
by supersampling), on a textured background with distractors (a box's corner, a line's end, a blob); the
references are the centres they were drawn at.
"""

from __future__ import annotations

import cv2
import numpy as np

from gnomon.camera.plane_pose import search_markers, split_marks
from gnomon.commands.regions import switch_on_masks

SS = 4  # supersampling of the drawing


def checker(img: np.ndarray, centre: tuple[float, float], a: np.ndarray, b: np.ndarray) -> None:
    """Draw (at SS×) a 2×2 checker centred at ``centre`` (px) with sides along ``a`` and ``b`` (px vectors:
    each square spans them), dark squares in the a+b and −a−b quadrants, on a white margin."""
    # output pixel i averages drawing pixels i·SS … i·SS + SS − 1, whose centre is i·SS + (SS − 1)/2
    c = np.array(centre) * SS + (SS - 1) / 2.0
    a, b = a * SS, b * SS

    def fill(poly: np.ndarray, value: int) -> None:  # polygon vertices to 1/16 px (shift 4)
        cv2.fillConvexPoly(img, np.round(poly * 16).astype(np.int32), value, cv2.LINE_8, 4)

    fill(np.array([c - 1.4 * (a + b), c + 1.4 * (a - b), c + 1.4 * (a + b), c - 1.4 * (a - b)]), 235)
    for s in (1, -1):
        fill(np.array([c, c + s * a, c + s * (a + b), c + s * b]), 25)


def scene(centres: list[tuple[float, float]], size=(600, 800), seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    h, w = size
    big = np.full((h * SS, w * SS), 150, np.uint8)
    # distractors: a box (its corners are L-junctions), a thick line ending, a dark blob
    cv2.rectangle(big, (40 * SS, 250 * SS), (160 * SS, 330 * SS), 60, -1)
    cv2.line(big, (300 * SS, 280 * SS), (420 * SS, 300 * SS), 30, 6 * SS)
    cv2.circle(big, (520 * SS, 300 * SS), 25 * SS, 40, -1)
    for k, c in enumerate(centres):
        turn = np.radians(10 * k - 20)
        a = 9.0 * np.array([np.cos(turn), np.sin(turn)])
        b = 7.0 * np.array([-np.sin(turn + 0.15), np.cos(turn + 0.15)])  # a little shear: perspective
        checker(big, c, a, b)
    img = cv2.resize(big, (w, h), interpolation=cv2.INTER_AREA).astype(np.float64)
    img += rng.normal(0.0, 2.0, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


DESK = [(90.3, 520.6), (720.2, 495.4), (668.7, 380.1), (128.9, 398.2)]
WALL = [(130.4, 110.7), (655.1, 95.2), (148.8, 210.3), (645.6, 200.9)]


def test_every_checker_found_where_it_was_drawn_and_nothing_else() -> None:
    img = scene(DESK + WALL)
    found = search_markers(img)
    assert len(found) == 8, [d.pixel for d in found]
    drawn = np.array(DESK + WALL)
    for d in found:
        miss = np.min(np.linalg.norm(drawn - np.array(d.pixel), axis=1))
        assert miss < 0.1, (d.name, d.pixel)
    groups = split_marks(found)
    assert sorted(np.round([d.pixel for d in groups.lower]).tolist()) == sorted(np.round(DESK).tolist())
    assert sorted(np.round([d.pixel for d in groups.upper]).tolist()) == sorted(np.round(WALL).tolist())


def test_a_missing_mark_is_asked_for_and_fewer_are_listed() -> None:
    """Seven marks with a clear gap between the planes (the wall's lowest mark and the desk's far row, 170 px,
    against 18 px between the desk's two far marks): 4 on the desk, 3 on the wall, the wall named as short. Six: nothing
    assigned (no split is sure), all six listed."""
    groups = split_marks(search_markers(scene(DESK + WALL[:3])))
    assert len(groups.lower) == 4 and len(groups.upper) == 3 and not groups.complete
    assert "the upper plane has 3" in groups.why
    six = split_marks(search_markers(scene(DESK[:3] + WALL[:3])))
    assert not six.lower and not six.upper and len(six.found) == 6
    assert "6 printed 2x2 checkers found" in six.why


TEMPLATE = """[capture]
frames = "frames/*.jpg"

[[planes]]
name = "desk"
markers = []
# mask = "regions/desk_mask.png"

[[planes]]
name = "wall"
mask = "hand/wall.png"

[[planes]]
name = "shelf"
# mask = "elsewhere/shelf_mask.png"

[light]
kind = "two-plane"
"""


def test_regions_switches_on_only_the_template_lines_for_the_masks_it_wrote() -> None:
    import tomllib

    masks = {"desk": "regions/desk_mask.png", "wall": "regions/wall_mask.png", "shelf": "regions/shelf_mask.png"}
    switched, text = switch_on_masks(TEMPLATE, masks)
    assert switched == ["desk"]
    log = tomllib.loads(text)
    assert [p.get("mask") for p in log["planes"]] == ["regions/desk_mask.png", "hand/wall.png", None]
    assert log["light"]["kind"] == "two-plane"
    assert switch_on_masks(text, masks) == ([], text)  # a second run changes nothing


def cross_scene(centres: list[tuple[float, float]], size=(600, 800), seed: int = 0) -> np.ndarray:
    """Hand-drawn crosses (two pen strokes, 18 px long, 3 px wide, turned and not quite square) on bright
    paper with its shading, beside a pen line (the stick's trace), a blot, a darker box and a dark stroke's
    end: the references are the strokes' crossing points."""
    rng = np.random.default_rng(seed)
    h, w = size
    yy, xx = np.mgrid[0:h * SS, 0:w * SS]
    big = (200 - 30 * xx / (w * SS) - 15 * yy / (h * SS)).astype(np.uint8)  # paper under a lamp
    cv2.rectangle(big, (40 * SS, 250 * SS), (160 * SS, 330 * SS), 90, -1)
    cv2.line(big, (300 * SS, 280 * SS), (460 * SS, 300 * SS), 70, 3 * SS)
    cv2.circle(big, (560 * SS, 300 * SS), 6 * SS, 60, -1)
    for k, (u, v) in enumerate(centres):
        c = np.array([u, v]) * SS + (SS - 1) / 2.0
        for turn in (np.radians(25 + 7 * k), np.radians(25 + 7 * k + 80)):
            d = 9.0 * SS * np.array([np.cos(turn), np.sin(turn)])
            p0, p1 = np.round((c - d) * 16).astype(int), np.round((c + d) * 16).astype(int)
            cv2.line(big, tuple(p0), tuple(p1), 45, 3 * SS, cv2.LINE_AA, 4)
    img = cv2.resize(big, (w, h), interpolation=cv2.INTER_AREA).astype(np.float64)
    img += rng.normal(0.0, 2.0, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


def test_every_cross_found_where_it_was_drawn_and_nothing_else() -> None:
    """Hand-drawn crosses, no hints: each found within 0.3 px of where its strokes cross (a fifth of a
    stroke's width), none among the line, the blot and the box; 4 + 4 split into the two planes, kind
    "cross" (init writes them as exact pixels)."""
    from gnomon.camera.plane_pose import search_crosses

    found = search_crosses(cross_scene(DESK + WALL))
    assert len(found) == 8, [d.pixel for d in found]
    drawn = np.array(DESK + WALL)
    got = np.array([d.pixel for d in found])
    miss = np.linalg.norm(got[:, None, :] - drawn[None], axis=2).min(axis=1)
    assert miss.max() <= 0.3, miss
    assert {d.kind for d in found} == {"cross"}
    groups = split_marks(found)
    assert groups.complete
    assert sorted(np.round([d.pixel for d in groups.lower]).tolist()) == sorted(np.round(DESK).tolist())


def test_init_writes_the_crosses_it_found(tmp_path) -> None:
    """A capture with crosses and no printed checkers: `gnomon init` writes 4 + 4 exact pixels."""
    import re

    from gnomon.cli import main

    frames = tmp_path / "frames"
    frames.mkdir()
    img = cross_scene(DESK + WALL, seed=3)
    for i in range(3):
        cv2.imwrite(str(frames / f"f{i:02d}.png"), img)
    assert main(["init", str(frames), "--out", str(tmp_path / "field_log.toml")]) == 0
    text = (tmp_path / "field_log.toml").read_text()
    pixels = np.array([[float(u), float(v)] for u, v in re.findall(r"pixel = \[([\d.]+), ([\d.]+)\]", text)])
    assert len(pixels) == 8 and "pixel_hint" not in text.split("[[planes]]", 1)[1].split("[light]")[0]
    assert np.linalg.norm(pixels[:4] - np.array(sorted(DESK, key=lambda p: p[1])), axis=1).max() <= 0.3
