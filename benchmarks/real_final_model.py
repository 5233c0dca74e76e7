"""The final model on REAL recordings: two static ADIS16405 units and the contaminated MTi-G gyro.

Reference data (not shipped, CC BY-NC-SA 4.0): /work/shared/reference (see its README).  For
every axis this runs what ``imupipe analyze`` runs per axis (overlapping Allan deviation, the
closed loop, the final model) and prints, per axis: the final B and its plateau 0.664 B next to
the lowest upper confidence bound of the measured deviation (a possible B lies below it), the
largest ratio of an unresolved term's asymptote to the measured upper bound (≤ 1: consistent
with the curve), the loop's error before → after and where the fit starts and why.

    python benchmarks/real_final_model.py [reference_dir] [--write-test-data tests/data/F.json]

``--write-test-data`` stores the few numbers tests/analysis/test_final_model.py needs: per axis the
Allan curve (tau, adev, edf; adev after the loop's corrections) to 7 digits and the final
model's terms, as report.json states them.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from imupipe.analysis.analyze import axis_result
from imupipe.analysis.results import jsonable
from imupipe.model.ieee952 import avar_upper, design_columns, monotone_edf
from imupipe.stats.allan import allan_curves, tau_factors
from imupipe.units import RAD_PER_DEG, STANDARD_GRAVITY
from imupipe.vocab import TERM_NAMES

DEFAULT_DIR = Path("/work/shared/reference")
AXES = ("gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z")


def recordings(ref: Path) -> dict[str, tuple[dict[str, np.ndarray], float]]:
    """{recording: ({axis: SI series}, tau0 s)}."""
    out = {}
    for unit in ("imu1", "imu2"):
        data = np.load(ref / "adis16405" / f"adis16405_{unit}_lsb.npz")
        values = data["counts"].astype(np.float64) * data["lsb"]
        si = np.concatenate([values[:, :3] * RAD_PER_DEG, values[:, 3:] * STANDARD_GRAVITY], 1)
        out[f"adis16405_{unit}"] = (
            {a: np.ascontiguousarray(si[:, i]) for i, a in enumerate(AXES)},
            0.01,  # both units: 100 Hz (reference README)
        )
    mtig = np.load(ref / "mtig_cont_gyro_x.npz")
    out["mtig_gyro"] = ({"gyro_x": np.asarray(mtig["gyro_x"], float)}, 1.0 / float(mtig["rate_hz"]))
    return out


def _digits(x: np.ndarray) -> list[float]:
    """7 significant digits (the stored curves stay small)."""
    return [float(f"{v:.7g}") for v in np.asarray(x, dtype=float)]


def main() -> None:
    args = sys.argv[1:]
    target = None
    if "--write-test-data" in args:
        k = args.index("--write-test-data")
        target = Path(args[k + 1])
        del args[k : k + 2]
    ref = Path(args[0]) if args else DEFAULT_DIR
    stored: dict = {}
    for rec, (series, tau0) in recordings(ref).items():
        for name, y in series.items():
            m = tau_factors(len(y))
            (curve,) = allan_curves([y], tau0, m)
            axis = axis_result(name, y, curve, tau0, None, None, loop=True)
            tau = np.asarray(curve.tau_s)
            hi = np.sqrt(avar_upper(np.asarray(curve.adev) ** 2, monotone_edf(curve.edf)))
            final = axis.terms
            b = final.bias_instability
            lowest = float(np.nanmin(hi))
            plateau = None if b.value is None else 0.664 * b.value
            cols = design_columns(tau)
            keep = tau >= final.fit_tau_min_s * (1 - 1e-9)
            worst = 0.0
            for j, term in enumerate(TERM_NAMES):
                t = getattr(final, term)
                if t.value is None and t.hi is not None:
                    ratio = t.hi * np.sqrt(cols[keep, j]) / hi[keep]
                    worst = max(worst, float(np.nanmax(ratio)))
            loop = axis.loop
            print(
                f"{rec:16s} {name:8s} B {b.value if b.value is not None else b.hi:.3g} "
                f"({'fitted' if b.value is not None else 'bound'}) plateau "
                f"{plateau if plateau is not None else float('nan'):.3g} <= lowest 95 % bound "
                f"{lowest:.3g}: {plateau is None or plateau <= lowest}; unresolved asymptote / "
                f"bound max {worst:.3f}; error {loop.before.error:.3g} -> {loop.after.error:.3g}"
                f" (bootstrap p {loop.before.p_value:.3g} -> {loop.after.p_value:.3g})"
                f"; effects {[e.kind for e in loop.accepted]}"
            )
            print(f"    fit: {final.fit_note}")
            stored[f"{rec}/{name}"] = jsonable(
                {
                    "sensor": axis.sensor,
                    "tau_s": _digits(curve.tau_s),
                    "adev": _digits(curve.adev),
                    "edf": _digits(curve.edf),
                    "adev_after": _digits(loop.adev_after),
                    "final": {"ieee952": final.as_dict(), "fit": final.fit_summary()},
                    "effects": [e.kind for e in loop.accepted],
                    "error_before": loop.before.error,
                    "error_after": loop.after.error,
                }
            )
    if target is not None:
        target.write_text(json.dumps(stored, separators=(",", ":")) + "\n")
        print(f"wrote {target}")


if __name__ == "__main__":
    main()
