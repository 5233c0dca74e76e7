"""Check our overlapping Allan variance against the avar R package on a real ADIS16405 recording.

Reference (not shipped, CC BY-NC-SA 4.0): /work/shared/reference/adis16405/ — 1e6 samples at
100 Hz of a static ADIS16405 (counts x LSB, deg/s and g) and ``adis_av.json``, the avar
package's maximum-overlap Allan variance at m = 2**1 .. 2**18.  Its estimator
(``avar_mo_cpp``) sums the T - 2m squared differences of adjacent m-averages, k = 0..T-2m-1,
and divides by 2 (T - 2m + 1); ours (NIST SP 1065 eq. 11) sums all N - 2m = T - 2m + 1 terms.
So avar_R = avar_ours - d_last**2 / (2 m**2 (T - 2m + 1)), with d_last the last second
difference; to first order avar_R = avar_ours (T - 2m)/(T - 2m + 1).  Prints the largest
relative difference under both the exact and the first-order conversion, per axis.

    /work/venv/bin/python benchmarks/validate_adis16405.py [reference_dir]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from imupipe.stats.allan import oadev, phase

DEFAULT_DIR = Path("/work/shared/reference/adis16405")


def main() -> None:
    ref_dir = Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT_DIR
    data = np.load(ref_dir / "adis16405_imu1_lsb.npz")
    reference = json.loads((ref_dir / "adis_av.json").read_text())
    y = data["counts"].astype(np.float64) * data["lsb"]
    tau0 = 1.0 / float(data["rate_hz"])
    t = y.shape[0]
    worst_exact = worst_first_order = 0.0
    for col, name in enumerate(data["columns"]):
        entry = reference["avar"][str(name)]
        m = np.rint(np.asarray(entry["levels"]) / tau0).astype(np.int64)
        adev, _ = oadev(y[:, col], tau0, m)
        x = phase(y[:, col], tau0)
        d_last = x[-1] - 2.0 * x[-1 - m] + x[-1 - 2 * m]
        avar_exact = adev**2 - d_last**2 / (2.0 * (m * tau0) ** 2 * (t - 2 * m + 1))
        avar_first = adev**2 * (t - 2 * m) / (t - 2 * m + 1)
        r_avar = np.asarray(entry["allan"])
        exact = np.max(np.abs(avar_exact / r_avar - 1.0))
        first = np.max(np.abs(avar_first / r_avar - 1.0))
        worst_exact, worst_first_order = max(worst_exact, exact), max(worst_first_order, first)
        print(f"{name:9s} m=2..{m[-1]}: max rel diff exact {exact:.2e}, first-order {first:.2e}")
    print(f"max relative difference (exact conversion)       {worst_exact:.2e}")
    print(f"max relative difference (factor (T-2m)/(T-2m+1)) {worst_first_order:.2e}")


if __name__ == "__main__":
    main()
