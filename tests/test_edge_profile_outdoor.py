"""The disc-past-a-band profile that benchmarks/edge_profile_outdoor.py measured (and that is not kept in the scan):
its model is the simulator's own occluded fraction of the sun's disc by the pole, and its fit finds the tangent
planes' times on noiseless samples, so the measurement in docs/method.md compares the physics, not a slip."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from gnomon.simulate import shadow

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("edge_profile_outdoor",
                                                  ROOT / "benchmarks" / "edge_profile_outdoor.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    saved = list(sys.path)
    try:
        spec.loader.exec_module(module)
    finally:  # the script puts the source tree first on sys.path: not for the tests after (their subprocesses)
        sys.path[:] = saved
    return module


RHO = math.radians(0.533 / 2)


def pole_dip(h: float, elevation_deg: float, omega: float, t: np.ndarray, r: float = 0.05) -> np.ndarray:
    """The simulator's occluded fraction of the sun's disc by a vertical pole (radius r, at the origin) seen from
    a point h m away on the ground, the sun turning in azimuth by ``omega`` rad per frame, behind the pole at t = 0."""
    e = math.radians(elevation_deg)
    P = np.array([h, 0.0, 0.0])
    phi = math.pi + omega * t                       # the sun's azimuth, seen from the pole: behind it from P
    d = np.stack([np.cos(e) * np.cos(phi), np.cos(e) * np.sin(phi), np.full_like(t, math.sin(e))], axis=-1)
    Ps = np.broadcast_to(P, d.shape)
    return shadow.occluded_fraction(Ps, Ps + d, math.sin(RHO), (0.0, 0.0, 0.0), (0.0, 0.0, 30.0), r)


@pytest.mark.parametrize("h", [6.0, 16.0])   # an umbra (α > ρ) and the facade's antumbra (α ≈ 0.67 ρ)
def test_the_band_profile_is_the_simulators_disc_past_the_pole(bench, h):
    omega, e = math.radians(0.25), 20.0
    t = np.linspace(-6, 6, 481)
    w = RHO / (math.cos(math.radians(e)) * omega)            # as sun_disc_frames: ρ / (cos e · dφ/dt)
    a = math.asin(math.cos(math.radians(e)) * 0.05 / h) / (math.cos(math.radians(e)) * omega)
    f = bench.band_share(t, 0.0, a, w)
    expected = pole_dip(h, e, omega, t)
    assert expected.max() > 0.5
    np.testing.assert_allclose(f, expected, atol=2e-3)


def test_the_fit_finds_the_tangent_planes_times(bench):
    """Noiseless samples of the simulator's dip at whole frames (the facade's antumbra, 16 m from the pole), the
    levels 0.8 and 0.25 of the lit one unknown: the fit's enter and leave, started 0.3 and 0.2 frame off, are the
    tangent planes' times to 0.01 frame; the mid-level crossings, linearly interpolated, are a third of a frame out."""
    omega, e, h = math.radians(0.25), 20.0, 16.0
    ce = math.cos(math.radians(e))
    w = RHO / (ce * omega)
    a_true = math.asin(ce * 0.05 / h) / (ce * omega)
    tcs = np.array([20.0, 20.25, 20.5, 20.75])
    t = np.arange(40.0)[:, None] * np.ones((1, len(tcs)))
    f = np.stack([pole_dip(h, e, omega, np.arange(40.0) - tc) for tc in tcs], axis=1)
    y = 0.8 - (0.8 - 0.25) * f
    k0 = np.floor(tcs - a_true).astype(int) - 3
    K = 14
    rows = k0[None] + np.arange(K)[:, None]
    ys, ts = np.take_along_axis(y, rows, 0), np.take_along_axis(t, rows, 0)
    tc, a, _, _ = bench.fit_band(ys, ts, np.ones_like(ys), tcs + 0.3, np.full(len(tcs), a_true + 0.2),
                                 np.full(len(tcs), w))
    np.testing.assert_allclose(tc - a, tcs - a_true, atol=0.01)
    np.testing.assert_allclose(tc + a, tcs + a_true, atol=0.01)
    # the mid-level crossing of the same samples on the entering side
    mid = (y.max(axis=0) + y.min(axis=0)) / 2
    enter_mid = []
    for j in range(len(tcs)):
        k = int(np.nonzero(y[:, j] < mid[j])[0][0]) - 1
        enter_mid.append(k + (y[k, j] - mid[j]) / (y[k, j] - y[k + 1, j]))
    assert np.all(np.array(enter_mid) < tcs - a_true - 0.2)
