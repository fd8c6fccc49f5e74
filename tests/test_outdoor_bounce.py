"""Interreflection outdoors (gnomon.simulate.outdoor_bounce): a facade point's form factor to the street against
Lambert's closed form for a polygon, the axis-aligned solids against the general box, energy, and (slow) the
facade scene's bounced light against the street's first bounce in closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gnomon.simulate import geometry as geo
from gnomon.simulate import radiosity
from gnomon.simulate.outdoor_bounce import (
    FAR_PATCH_M,
    FAR_STREET,
    FAR_X,
    FAR_Y,
    GROUND_ALBEDO_MEAN,
    GROUND_X,
    GROUND_Y,
    AxisBox,
    _capped,
)


def polygon_factor(P: np.ndarray, n: np.ndarray, vertices: np.ndarray) -> float:
    """Form factor from a differential area at P (unit normal n) to a planar polygon wholly in front of it:
    Lambert's contour formula, F = (1/2π) |Σ_i γ_i · n·(R_i × R_{i+1}) / |R_i × R_{i+1}||, with R_i = V_i − P and
    γ_i the angle between R_i and R_{i+1} (Baum, Rushmeier & Winget, SIGGRAPH 1989, eq. 3)."""
    R = vertices - P
    total = 0.0
    for i in range(len(R)):
        a, b = R[i], R[(i + 1) % len(R)]
        c = np.cross(a, b)
        gamma = math.atan2(float(np.linalg.norm(c)), float(a @ b))
        total += gamma * float(n @ c) / float(np.linalg.norm(c))
    return abs(total) / (2 * math.pi)


def street(x0: float, x1: float, y0: float, y1: float) -> np.ndarray:
    return np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])


FACADE_NORMAL = np.array([0.0, 1.0, 0.0])


@pytest.mark.parametrize("point", [(3.0, 0.0, 2.0), (10.0, 0.0, 6.5), (-12.0, 0.0, 2.0)])
def test_a_facade_point_sees_the_street_as_the_closed_form_says(point):
    """The street (z = 0, y ≥ 0) in front of a facade point (normal +y), cut as the bounce cuts it (0.5 m patches
    near, ``FAR_PATCH_M`` beyond), gathers the closed form's factor for the whole rectangle to 1 % (the disc
    form's error: 0.5 m patches 2 m or more away, 5 m patches 8 m or more away)."""
    P = np.array(point)
    x0, x1 = GROUND_X
    parts = [radiosity.plane_patches((x0, GROUND_Y[0], 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), x1 - x0,
                                     GROUND_Y[1] - GROUND_Y[0], 0.5, 1, lambda X: np.ones(len(X)))]
    for (a0, a1), (b0, b1) in FAR_STREET:
        parts.append(radiosity.plane_patches((a0, b0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), a1 - a0, b1 - b0,
                                             FAR_PATCH_M, 1, lambda X: np.ones(len(X))))
    patches = radiosity.concat_patches(parts)
    F = float(radiosity.form_factors(P[None], FACADE_NORMAL[None], patches, []).sum())
    expected = polygon_factor(P, FACADE_NORMAL, street(*FAR_X, *FAR_Y))
    assert F == pytest.approx(expected, rel=1e-2)
    # The patched street is nearly all a vertical surface sees below the horizon (1/2 for an endless street)
    # for the points the pole's shadow sweeps (≤ 9 m up); the near street alone is not.
    assert 0.45 < expected < 0.5


def test_a_balcony_hides_the_street_below_it():
    """A box between the facade point and the street takes its share away: what is left is the closed form of the
    street minus the box's footprint as the point sees it through it (a box on the street: its own base)."""
    P = np.array([5.0, 0.0, 3.0])
    patches = radiosity.plane_patches((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), 10.0, 10.0, 0.25, 1,
                                      lambda X: np.ones(len(X)))
    box = AxisBox(np.array([4.0, 2.0, 0.0]), np.array([6.0, 3.0, 0.5]))  # a kerb block standing on the street
    F = radiosity.form_factors(P[None], FACADE_NORMAL[None], patches, [box])[0]
    # every patch whose centre lies under the block, or behind it as seen from P, is hidden
    c = patches.centre
    hidden = np.isinf(box.intersect(np.broadcast_to(P, c.shape), c - P)) == 0
    assert np.all(F[hidden] == 0.0)
    under = (c[:, 0] > 4.0) & (c[:, 0] < 6.0) & (c[:, 1] > 2.0) & (c[:, 1] < 3.0)
    assert hidden[under].all()
    full = polygon_factor(P, FACADE_NORMAL, street(0.0, 10.0, 0.0, 10.0))
    assert F.sum() < full - polygon_factor(P, FACADE_NORMAL, street(4.0, 6.0, 2.0, 3.0)) + 5e-3


def test_the_axis_aligned_box_meets_rays_where_the_general_box_does():
    rng = np.random.default_rng(0)
    o = rng.uniform(-1.5, 1.5, (20000, 3))
    d = rng.normal(size=(20000, 3))
    d[:500, 0] = 0.0       # rays parallel to a face
    d[500:1000, 2] = 0.0
    general = geo.Box((0.5, 0.2, 0.1), (1.0, 2.0, 0.5), 0.0)
    aligned = AxisBox(general.c - general.half, general.c + general.half)
    a, b = general.intersect(o, d), aligned.intersect(o, d)
    assert np.array_equal(np.isfinite(a), np.isfinite(b))
    assert 0.05 < np.isfinite(a).mean() < 0.95
    np.testing.assert_allclose(a[np.isfinite(a)], b[np.isfinite(b)], rtol=1e-12, atol=1e-12)


def test_form_factor_rows_are_capped_at_the_hemisphere():
    form = np.array([[0.2, 0.3], [0.7, 0.35], [0.0, 0.0]], dtype=np.float32)
    out = _capped(form.copy())
    np.testing.assert_allclose(out.sum(axis=1), [0.5, 1.0, 0.0], rtol=1e-6)
    np.testing.assert_allclose(out[1] / out[1].sum(), form[1] / form[1].sum(), rtol=1e-6)


@pytest.fixture(scope="module")
def bounce_scene():
    from gnomon.simulate.facade_sun import FacadeSunConfig, FacadeSunScene

    return FacadeSunScene(FacadeSunConfig(width=200, height=150, frames=16, seed=4, clouds=0, bounce=True))


@pytest.mark.slow
def test_the_facade_gathers_the_streets_first_bounce_as_the_closed_form_says(bounce_scene):
    """Receiving points on the bare wall below the ledge (0.3 m ≤ z < 2.8 m), away from the balconies (x < 16 m): what
    they gather from the sunlit street's patches in the first bounce (pole away) is the closed form,
    ρ̄_street · (sun · sin e + sky) · F(P → street), to 2 % (the disc form's error on the sub-sampled near
    patches and the 5 m far ones, and the street's few sub-samples in the ledge's shadow)."""
    from gnomon.simulate.facade_sun import WALL

    sc = bounce_scene
    b = sc.bounce
    k = sc.N // 2
    p = b.patches
    b1 = p.albedo * p.average(b.sub_irradiance(k, pole=False))
    on_street = (p.normal[:, 2] > 0.99) & (np.abs(p.centre[:, 2]) < 1e-9)
    P = sc.points_f[b.receivers.rx]
    oid = sc.object_id_f[b.receivers.rx]
    bare = ~sc.building.window_at(P[:, 0], P[:, 2], grow=0.5)[0]
    pick = np.nonzero((oid == WALL) & (P[:, 2] >= 0.3) & (P[:, 2] < 2.8) & (P[:, 0] < 16.0) & (P[:, 0] > -10.0)
                      & bare)[0]
    assert len(pick) >= 10
    d = sc.sun_world[k]
    e_street = sc.sun_strength[k] * sc.direct_factor[k] * max(d[2], 0.0) + sc.sky[k]
    gathered = b.form[pick][:, on_street] @ b1[on_street]
    closed = np.array([GROUND_ALBEDO_MEAN * e_street * polygon_factor(P[i], FACADE_NORMAL, street(*FAR_X, *FAR_Y))
                       for i in pick])
    np.testing.assert_allclose(gathered, closed, rtol=0.02)
    # the second bounce (street ← sunlit facade → street) is there, and bounded by energy: a patch sends on at
    # most its albedo times the brightest first radiosity it can see
    second = b.form[pick] @ (p.albedo * (b.form_pp @ b1.astype(np.float32)))
    assert np.all(second > 0.1 * closed)
    assert np.all(second <= b.form[pick].sum(axis=1) * p.albedo.max() * b1.max())


@pytest.mark.slow
def test_bounced_light_conserves_energy_and_the_poles_shadow_dims_it(bounce_scene):
    sc = bounce_scene
    b = sc.bounce
    assert b.form.sum(axis=1).max() <= 1.0 + 1e-5 and b.form_pp.sum(axis=1).max() <= 1.0 + 1e-5
    k = sc.N // 2
    rad = b.radiosity(k, pole=False)
    assert np.all(b.form @ rad <= rad.max() * b.form.sum(axis=1) + 1e-6)
    # the pole's shadow only takes light away, and never more than the street's whole sunlit first bounce
    with_pole, without = b.irradiance(k, pole=True), b.irradiance(k, pole=False)
    assert np.all(with_pole <= without + 1e-6)
    dip = sc.bounce_truth.dip
    assert dip.min() >= 0.0
    sw = sc.swept
    assert 0.0 < np.median(dip[sw]) < 0.01       # on the swept surface: well under a per cent
    assert sc.bounce_truth.share[sw].max() < 0.5  # the sun still lights what the pole's shadow sweeps


@pytest.mark.parametrize("scene", ["facade_sun", "facade_day"])
def test_the_command_line_asks_for_the_bounce_and_leaves_it_off_by_default(scene):
    from gnomon.cli import build_parser
    from gnomon.commands import simulate as simulate_command
    from gnomon.simulate.facade_sun import FacadeSunConfig

    argv = ["simulate", scene, "--out", "x"]
    off = simulate_command._options(build_parser(argv).parse_args(argv))
    on = simulate_command._options(build_parser(argv + ["--bounce"]).parse_args(argv + ["--bounce"]))
    assert "bounce" not in off and not FacadeSunConfig().bounce
    assert on["bounce"] is True
