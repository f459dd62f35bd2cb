"""PDOP of a standalone fix: a known geometry, frame invariance, degenerate sets."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coopnav_env.nav import pdop


def test_pdop_of_a_known_geometry_its_frame_and_degenerate_cases():
    # the zenith and three satellites at 0 deg elevation, 120 deg apart, one clock:
    # G^T G = diag(1.5, 1.5, 1, 4) with the z-clock coupling -1, so the z variance is
    # 4 / (4 - 1) = 4/3 and PDOP = sqrt(2/3 + 2/3 + 4/3)
    az = np.radians([0.0, 120.0, 240.0])
    u = np.vstack([[0.0, 0.0, 1.0], np.column_stack([np.sin(az), np.cos(az), np.zeros(3)])])
    sys1 = np.zeros(4, dtype=int)
    assert pdop(u, sys1) == pytest.approx(math.sqrt(8.0 / 3.0))
    rot = np.array([[0.0, -1.0, 0.0], [0.6, 0.0, 0.8], [-0.8, 0.0, 0.6]])  # orthonormal
    assert pdop(u @ rot.T, sys1) == pytest.approx(pdop(u, sys1))
    # a second constellation adds an unknown: four satellites of two systems cannot fix
    assert pdop(u, np.array([0, 0, 0, 1])) == math.inf
    assert pdop(u[:3], sys1[:3]) == math.inf  # fewer satellites than unknowns
    assert pdop(np.tile(u[:1], (5, 1)), np.zeros(5, dtype=int)) == math.inf  # one direction
