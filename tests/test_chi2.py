"""gnomon.util.chi2: the χ² tail in closed form for whole degrees of freedom, against scipy.stats's
(an independent implementation: the regularised incomplete gamma function by series and continued
fractions)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from gnomon.util.chi2 import chi2_isf, chi2_sf

DOFS = [*range(1, 41), 59, 60, 199, 200, 2000]


@pytest.mark.parametrize("dof", DOFS)
def test_survival_function_is_scipys(dof: int) -> None:
    xs = np.concatenate([[1e-8, 1e-3, 0.1, 0.5, 1.0, 3.0, 10.0, 40.0, 150.0, 700.0], dof * np.linspace(0.2, 3.0, 15)])
    for x in xs:
        expected = float(chi2.sf(x, dof))
        if expected < 1e-280:  # beyond double precision's range either way
            assert chi2_sf(x, dof) < 1e-270
            continue
        assert chi2_sf(x, dof) == pytest.approx(expected, rel=1e-11, abs=0.0), x


@pytest.mark.parametrize("dof", DOFS)
def test_inverse_survival_function_is_scipys(dof: int) -> None:
    for p in (0.9, 0.5, 0.05, 0.01, 1e-3, 1e-6, 1e-12):
        x = chi2_isf(p, dof)
        assert x == pytest.approx(float(chi2.isf(p, dof)), rel=1e-10), p
        assert chi2_sf(x, dof) == pytest.approx(p, rel=1e-8)


def test_edges_and_refusals() -> None:
    assert chi2_sf(0.0, 3) == 1.0 and chi2_sf(-1.0, 2) == 1.0
    assert chi2_sf(1e6, 4) == 0.0
    for dof in (0, -2, 2.5):
        with pytest.raises(ValueError):
            chi2_sf(1.0, dof)  # type: ignore[arg-type]
    for p in (0.0, 1.0, -0.1, float("nan")):
        with pytest.raises(ValueError):
            chi2_isf(p, 2)
