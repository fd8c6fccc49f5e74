"""The room simulator's light: form factors against their closed forms, visibility, the sensor's shot noise,
and (slow) a small room's truth: bounced light conserves energy and dims the faces the lamp never reaches."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gnomon.simulate import geometry as geo
from gnomon.simulate import radiosity, sensor


def square_plate(half: float, height: float, size: float) -> radiosity.Patches:
    """A square of side 2·half at z = height, centred over the origin, facing down (normal −z)."""
    return radiosity.plane_patches((-half, half, height), (1.0, 0.0, 0.0), (0.0, -1.0, 0.0), 2 * half, 2 * half,
                                   size, 1, lambda X: np.ones(len(X)))


def plate_factor(half: float, height: float) -> float:
    """Form factor from a differential area at the origin (normal +z) to the parallel square above it: four
    times the closed form for a rectangle over one corner (Howell's catalogue, C-11)."""
    A = B = half / height
    a, b = math.sqrt(1 + A * A), math.sqrt(1 + B * B)
    corner = (A / a * math.atan(B / a) + B / b * math.atan(A / b)) / (2 * math.pi)
    return 4 * corner


RECEIVER = (np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]))


@pytest.mark.parametrize("half,height", [(50.0, 100.0), (100.0, 60.0), (30.0, 200.0)])
def test_form_factor_to_a_square_plate_matches_the_closed_form(half, height):
    patches = square_plate(half, height, size=half / 20)
    F = radiosity.form_factors(*RECEIVER, patches, []).sum()
    assert F == pytest.approx(plate_factor(half, height), rel=2e-3)


def test_form_factors_of_a_wide_plate_add_up_to_nearly_one():
    """Energy: under a plate 40 times as wide as it is far the receiver sees almost nothing else; the patches'
    factors approach the closed form's 0.9975 as the patches shrink (the disc form is exact only for patches
    small against their distance: here 20 mm away, 4 then 2 mm wide), and never exceed 1."""
    expected = plate_factor(400.0, 20.0)
    assert 0.997 < expected < 0.998
    errors = []
    for size in (4.0, 2.0):
        F = float(radiosity.form_factors(*RECEIVER, square_plate(400.0, 20.0, size=size), []).sum())
        assert F <= 1.0
        errors.append(abs(F - expected))
    assert errors[1] < 0.6 * errors[0]
    assert errors[1] < 2.5e-3


def test_a_solid_between_hides_the_patches_behind_it():
    patches = square_plate(50.0, 100.0, size=2.5)
    open_f = radiosity.form_factors(*RECEIVER, patches, [])[0]
    ball = geo.Sphere((0.0, 0.0, 50.0), 10.0)
    hidden = radiosity.form_factors(*RECEIVER, patches, [ball])[0]
    # the patches whose centre the ball hides: their rays from the origin pass within 10 mm of its centre
    d = patches.centre / np.linalg.norm(patches.centre, axis=1, keepdims=True)
    miss = np.linalg.norm(np.cross(d, [0.0, 0.0, 50.0]), axis=1)
    behind = miss < 10.0 - 1e-6
    assert behind.sum() > 20
    assert np.all(hidden[behind] == 0)
    np.testing.assert_array_equal(hidden[miss > 10.0 + 1e-6], open_f[miss > 10.0 + 1e-6])
    # what it hides is the disc it subtends: a cone of half-angle asin(10/50), F = sin² of it
    assert open_f.sum() - hidden.sum() == pytest.approx((10.0 / 50.0) ** 2, rel=0.03)


def test_shot_and_read_noise_at_220_dn():
    """The room's sensor: about 3.5 DN at 220 DN (full well 1150 e⁻, 3 e⁻ read noise, gamma 2.2), and the
    σ grows in the dark as √(signal) through the gamma's slope predicts."""
    rng = np.random.default_rng(1)
    for dn in (220.0, 60.0):
        L = (dn / 255.0) ** 2.2
        img = sensor.encode_shot_noise(np.full((400, 400), L, np.float32), 2.2, 1150.0, 3.0, 0.0, rng)
        e = L * 1150.0
        slope = 255.0 / 2.2 * L ** (1 / 2.2 - 1) / 1150.0          # DN per electron
        predicted = slope * math.sqrt(e + 9.0)
        measured = float(img.std())
        # quantisation adds 1/12 DN² (the rounding)
        assert measured == pytest.approx(math.hypot(predicted, math.sqrt(1 / 12)), rel=0.03)
        assert float(img.mean()) == pytest.approx(dn, abs=0.3)
        if dn == 220.0:
            assert 3.2 < measured < 3.8


@pytest.fixture(scope="module")
def room():
    from gnomon.simulate.room import RoomConfig, RoomScene

    return RoomScene(RoomConfig(width=240, height=180, frames=60, seed=2))


@pytest.mark.slow
def test_room_bounced_light_conserves_energy(room):
    """No receiving point gathers more than the whole hemisphere: Σ_j F ≤ 1; and what it gathers is at most
    the brightest patch's radiosity."""
    sums = room.form.sum(axis=1)
    assert sums.max() <= 1.0 + 1e-3
    assert np.median(sums) > 0.15  # the desk sees the wall, the wall the desk (an endless square corner: 0.5)
    radiosity_lit = room._patch_irradiance(None)
    gathered = room.form @ radiosity_lit
    assert np.all(gathered <= radiosity_lit.max() * sums + 1e-12)


@pytest.mark.slow
def test_room_truth_faces_the_lamp_never_reaches(room):
    never = room.hit & ~room.receives_light
    assert never.sum() > 200
    assert np.all(room.direct[never] == 0)
    # lit only by the bounce (and the ambient): it still dims as the stick's shadow crosses the desk
    assert room.bounce_only.sum() > 0.3 * never.sum()
    assert np.all(room.bounce_only <= never)
    assert np.all(room.bounce_change >= 0)
    # the swept pixels are lit directly: the lamp gives most of their light
    assert np.percentile(room.direct_share[room.swept], 5) > 0.5
    # the frames: the shadow only takes light away; on the faces the lamp never reaches only the bounced
    # light changes, and by no more than the truth's bounce_change says
    lit = room.lit_image(blur=False)
    lo = hi = room.linear_image(0.0, blur=False)
    for k in (0, 15, 30, 45):
        L = room.linear_image(float(k), blur=False)
        assert np.all(L <= lit + 1e-6)
        lo, hi = np.minimum(lo, L), np.maximum(hi, L)
    assert np.all((hi - lo)[never] <= room.bounce_change[never] * lit[never] + 1e-6)
    assert np.mean((hi - lo)[room.bounce_only] > 0) > 0.5
