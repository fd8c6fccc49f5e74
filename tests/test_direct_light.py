"""No point without a direct shadow event (issue 36): the dips bounced light makes, the edge of the lamp's light
and faces lit mostly by bounced light, on hand-made maps and on the simulated room scanned end to end."""

from __future__ import annotations

import numpy as np
import pytest

from gnomon.geometry.validity import (
    BOUNCE_SHARE,
    EDGE_OF_LIGHT_PX,
    EDGES_AGREE_SIGMAS,
    MOSTLY_BOUNCE_SHARE,
    direct_light,
)


def test_direct_light_sorts_the_dips_by_what_made_them():
    """A lit desk (dips taking 0.8 of the lit level) with, inside it, a face the lamp never reaches whose
    dip is bounced light (0.1), a face with no dip at all, and a dim face (0.4: lit mostly by bounce) whose
    left half has edges agreeing within their σ and right half not."""
    H, W = 60, 90
    relative = np.full((H, W), 0.8)
    dip = np.ones((H, W), dtype=bool)
    bounce = (slice(10, 20), slice(10, 20))
    dark = (slice(10, 20), slice(40, 50))
    dim = (slice(35, 50), slice(10, 70))
    relative[bounce] = 0.1
    dip[dark] = False
    relative[dim] = 0.4
    typical = 0.8  # the median over the candidates: most of them are the lit desk
    assert 0.1 < BOUNCE_SHARE * typical < 0.4 < MOSTLY_BOUNCE_SHARE * typical < 0.8
    sigma = np.full((H, W), 0.5)
    d0 = np.full((H, W), 600.0)
    d1 = d0.copy()
    d1[35:50, 40:70] += 2.0 * EDGES_AGREE_SIGMAS * np.hypot(0.5, 0.5)   # the right half disagrees
    d1[35:50, 10:40] += 0.5 * EDGES_AGREE_SIGMAS * np.hypot(0.5, 0.5)   # the left half agrees
    candidates = dip.copy()
    out = direct_light(candidates, dip, relative, [d0, d1], [sigma, sigma])

    expected_bounce = np.zeros((H, W), dtype=bool)
    expected_bounce[bounce] = True
    np.testing.assert_array_equal(out.bounce_only, expected_bounce)
    # within EDGE_OF_LIGHT_PX (a disc) of the bounce-only and the dark faces, not on them
    vv, uu = np.mgrid[:H, :W]
    near = np.zeros((H, W), dtype=bool)
    for sl in (bounce, dark):
        dv = np.maximum(np.maximum(sl[0].start - vv, vv - (sl[0].stop - 1)), 0)
        du = np.maximum(np.maximum(sl[1].start - uu, uu - (sl[1].stop - 1)), 0)
        near |= dv * dv + du * du <= EDGE_OF_LIGHT_PX ** 2
    np.testing.assert_array_equal(out.edge_of_light, near & candidates & ~expected_bounce)
    expected_disagree = np.zeros((H, W), dtype=bool)
    expected_disagree[35:50, 40:70] = True
    np.testing.assert_array_equal(out.edges_disagree, expected_disagree)
    assert not out.refused[25:30, :].any()  # the lit desk between them keeps every point
    # one edge only: a dim face cannot be checked, and is refused whole
    single = direct_light(candidates, dip, relative, [d0], [sigma])
    assert single.edges_disagree[dim].all()


def test_the_shares_are_the_captures_own():
    """Room lights on: the lamp adds only a tenth of every pixel's light. The dips are still the lamp's
    own shadow (the same share everywhere), and none is refused."""
    relative = np.full((30, 40), 0.1)
    dip = np.ones((30, 40), dtype=bool)
    d = np.full((30, 40), 500.0)
    s = np.ones((30, 40))
    assert not direct_light(dip, dip, relative, [d, d], [s, s]).refused.any()


@pytest.mark.slow
def test_no_point_where_the_lamp_never_shines(tmp_path):
    """The room (one bounce of interreflection, a 3 mm lamp, shot noise), scanned as shipped in two-plane
    mode: no point on the pixels the lamp never lights directly, at most 1 % false points, and the directly
    lit swept pixels covered (95 % and more: 96 % before the screen on this scene)."""
    from gnomon import api
    from gnomon.outputs.images import NO_DIRECT_LIGHT
    from gnomon.runs.accuracy import depth_accuracy
    from gnomon.simulate.room import RoomConfig, simulate_room

    result = simulate_room(tmp_path / "room", RoomConfig(width=400, height=300, frames=100))
    gt = dict(np.load(result.ground_truth))
    scan = api.scan(result.field_log)
    truth = gt["depth"].astype(np.float64)
    never = np.isfinite(truth) & ~gt["lit_directly"]
    assert never.sum() > 1000 and gt["bounce_only"].sum() > 1000
    assert not (np.isfinite(scan.depth) & never).any()
    acc = depth_accuracy(scan.depth.astype(np.float64), truth, gt["swept"], float(gt["camera_distance_mm"]),
                         sigma=scan.sigma, swept_surface=gt["swept_surface"])
    assert acc.false_point_rate <= 0.01
    assert acc.coverage >= 0.95
    # the refused pixels are counted by their reason, in coverage.npy and report.json
    assert scan.coverage is not None
    refused = scan.report["coverage"]["no_direct_light"]
    assert (scan.coverage == NO_DIRECT_LIGHT).sum() == sum(refused.values())
    assert (scan.coverage[never] == NO_DIRECT_LIGHT).sum() > 100
    assert any("the light's own shadow did not make their dip" in n for n in scan.notes)
