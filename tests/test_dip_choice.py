"""Choosing between two candidate dips by the surfaces they make (gnomon.light.dip_choice)."""

from __future__ import annotations

import numpy as np
import pytest

from gnomon.light.dip_choice import LINK_SHARE, STRICT_OFF_SHARE, choose_dips

H, W = 60, 80
JUMP = 0.02
ALL = np.ones((H, W), bool)


def scene():
    """A wall 20-22 m away (depth varying smoothly, 0.05 % per pixel at most: one surface), a
    reference region on its left 10 columns, an object 1 m in front of it (rows 40-49, columns
    50-59: off the reference plane, joined to nothing), and another shadow's wrong depths 7-10 m
    off."""
    y, x = np.mgrid[0:H, 0:W]
    wall = 20.0 + 2.0 * x / W + 0.5 * y / H
    true = wall.copy()
    obj = np.zeros((H, W), bool)
    obj[40:50, 50:60] = True
    true[obj] -= 1.0
    region = np.full((H, W), np.nan)
    region[:, :10] = wall[:, :10]
    wrong = true - 7.0 - 3.0 * x / W
    return wall, true, region, obj, wrong


def chosen_depth(dc, depth):
    return np.where(dc.choice == 1, depth[0], np.where(dc.choice == 2, depth[1], np.nan))


def test_the_candidate_on_the_supported_surface_wins_where_either_is_deeper():
    """The other shadow's dip is the deepest on the right half and the second on the left, and it
    crosses the region too: each pixel gets the candidate on the surface the region supports; the
    other shadow's surface (7-10 m off) is never chosen; the object, whose candidates join
    nothing the planes support, and a patch where only the other shadow's dip exists get no point."""
    wall, true, region, obj, wrong = scene()
    right = np.arange(W)[None, :].repeat(H, 0) >= W // 2
    depth = np.stack([np.where(right, wrong, true), np.where(right, true, wrong)])
    lone = np.zeros((H, W), bool)
    lone[5:15, 60:70] = True
    depth[0][lone], depth[1][lone] = wrong[lone], np.nan
    dc = choose_dips(depth, region, [wall], JUMP, fallback=ALL)
    assert dc.strict and dc.counts["off_region"] == int(np.isfinite(region).sum())
    got = chosen_depth(dc, depth)
    np.testing.assert_array_equal(got[~obj & ~lone], true[~obj & ~lone])
    assert np.isnan(got[obj | lone]).all()
    assert dc.counts["second_chosen"] == int((right & ~obj & ~lone).sum())
    assert dc.counts["refused"] == int((obj | lone).sum())


def test_without_another_shadow_on_the_regions_the_tracker_s_verdict_stands():
    """The regions see only the pole's dip: the best dip stays wherever the tracker kept it (even
    where the second would make a surface the plane supports), nothing is resolved or refused."""
    wall, true, region, obj, wrong = scene()
    depth = np.stack([true, np.where(np.arange(W)[None, :] >= 10, wrong, np.nan)])
    verdict = np.random.default_rng(3).random((H, W)) > 0.2
    dc = choose_dips(depth, region, [wall], JUMP, fallback=verdict)
    assert not dc.strict and dc.counts["off_region"] == 0
    np.testing.assert_array_equal(dc.choice == 1, verdict)
    assert not (dc.choice == 2).any() and not dc.ambiguous.any()


def test_two_supported_surfaces_leave_the_pixel_ambiguous():
    """Rows 0-29: both candidates lie on the plane (1.5 % apart: two surfaces, neither off the
    plane); rows 30-59: the second is the other shadow's, off the region's plane (so the regions
    show another shadow). The top rows are ambiguous, the bottom rows take the best dip."""
    wall, true, region, obj, wrong = scene()
    top = np.arange(H)[:, None].repeat(W, 1) < 30
    depth = np.stack([true, np.where(top, true * (1 + 1.5 * LINK_SHARE * JUMP), wrong)])
    dc = choose_dips(depth, region, [wall], JUMP, fallback=ALL)
    assert dc.counts["off_region"] > STRICT_OFF_SHARE * (dc.counts["on_region"] + dc.counts["off_region"])
    assert dc.ambiguous[top].all() and (dc.choice[top] == 0).all()
    assert (dc.choice[~top & ~obj] == 1).all()


def test_choose_dips_wants_two_candidates():
    with pytest.raises(ValueError, match="candidate depths"):
        choose_dips(np.zeros((H, W)), np.zeros((H, W)), [], JUMP, ALL)
