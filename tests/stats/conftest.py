"""Data sets shared by the statistics tests."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="session")
def nist_1000() -> np.ndarray:
    """NIST SP 1065 1000-point set: n_{i+1} = 16807 n_i mod (2**31 - 1), y = n / (2**31 - 1)."""
    n = [1234567890]
    for _ in range(999):
        n.append((16807 * n[-1]) % 2147483647)
    assert n[1:4] == [395529916, 1209410747, 633705974]
    y = np.array(n, dtype=np.float64) / 2147483647
    y.flags.writeable = False  # shared by every test of the session
    return y
