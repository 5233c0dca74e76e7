"""Gap policies on recordings we did not write: ``--gaps longest`` against ``--gaps mask``.

Each recording is the independent generator's clean noise (``independent_generator.generate``:
the paper-like IEEE 952 terms of random size, no effect), ``--hours`` at 100 Hz, written as a
ROS 2 ``sensor_msgs/msg/Imu`` MCAP with frames dropped to make gaps:

- ``one_frame``: one frame missing near the middle;
- ``20_short``: 20 gaps of 1-500 frames (up to 5 s) at random places;
- ``10x30s``: ten gaps of 30 s; ``3x2min``: three gaps of 2 min; ``10min``: one of 10 min;
  ``1h``: one of 1 h (each at a random place).

Each is analysed with both policies (loop on, no figures or rrd).  Per scenario and policy the
table gives, over all axes of all seeds: the median and largest |N error| against the truth,
B within 15 % of the truth and B resolved, axes with an accepted effect (all false: the
recordings are clean), axes whose final model is rejected (p < 0.01), the longest τ reported.
The default policy ``auto`` is ``mask`` up to a gap of ``AUTO_MAX_GAP_S`` and ``longest`` beyond.

    python benchmarks/gap_policies.py [--hours 4] [--seeds 3 4 5 6 7 8 9 10]
        [--scenarios 20_short 10x30s 3x2min 10min 1h] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import independent_generator as gen

import imupipe
from imupipe.io.decode import IMU_SCHEMA
from imupipe.io.mcap_bulk import BulkWriter
from imupipe.testing.ros_cdr import imu_payloads

RATE_HZ = 100.0
T0_NS = 1_700_000_000_000_000_000
SCENARIOS = ("one_frame", "20_short", "10x30s", "3x2min", "10min", "1h")


def dropped(scenario: str, n: int, rng: np.random.Generator) -> np.ndarray:
    """bool (n,): the frames kept."""
    keep = np.ones(n, dtype=bool)
    if scenario == "one_frame":
        keep[n // 2 + int(rng.integers(-1000, 1000))] = False
    elif scenario == "20_short":
        for s in rng.integers(0, n - 600, 20):
            keep[s : s + int(rng.integers(1, 500))] = False
    elif scenario in ("10x30s", "3x2min"):
        count, length = {"10x30s": (10, 3_000), "3x2min": (3, 12_000)}[scenario]
        for s in rng.integers(0, n - length, count):
            keep[s : s + length] = False
    else:
        length = {"10min": 60_000, "1h": 360_000}[scenario]
        s = int(n * rng.uniform(0.2, 0.6))
        keep[s : s + length] = False
    return keep


def write(path: Path, y: np.ndarray, keep: np.ndarray) -> None:
    """The kept frames of ``y`` (n, 6) as Imu messages stamped on the 100 Hz grid."""
    stamps = (T0_NS + np.round(np.arange(len(y)) * 1e9 / RATE_HZ).astype(np.int64))[keep]
    values = y[keep]
    with open(path, "wb") as f:
        w = BulkWriter(f, profile="ros2")
        ch = w.register_channel("/imu/data", "cdr", w.register_schema(IMU_SCHEMA, "ros2msg", b""))
        for a in range(0, len(stamps), 100_000):
            s, v = stamps[a : a + 100_000], values[a : a + 100_000]
            w.write_chunk(ch, s, imu_payloads(s, v[:, :3], v[:, 3:]))
        w.finish()


def run(hours: float, seed: int, scenario: str) -> list[dict]:
    """Both policies on one gapped recording: one row each."""
    y, _, truth = gen.generate(hours, RATE_HZ, 1000 + seed)
    work = Path(tempfile.mkdtemp(prefix="gap_policies_"))
    rows = []
    try:
        write(work / "r.mcap", y, dropped(scenario, len(y), np.random.default_rng(seed)))
        for policy in ("longest", "mask"):
            r = imupipe.analyze(
                work / "r.mcap", work / policy, rrd=False, figures=False, gaps=policy
            ).to_dict()
            axes = {}
            for name, ax in r["axes"].items():
                terms = ax.get("ieee952_after") or ax["ieee952"]
                true = truth.noise[name]
                n_hat = terms["random_walk"]["value"]
                b_hat = terms["bias_instability"]["value"]
                axes[name] = {
                    "n_error": None if n_hat is None else n_hat / true.n - 1,
                    "b_error": None if b_hat is None else b_hat / true.b - 1,
                    "effects": [e["kind"] for e in ax.get("effects", [])],
                    "p_after": ax.get("model", {}).get("p_value_after"),
                    "tau_max_s": max(ax["allan"]["tau_s"]),
                }
            rows.append({"seed": seed, "scenario": scenario, "policy": policy, "axes": axes})
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return rows


def table(rows: list[dict]) -> str:
    out = [
        "| gaps | policy | median / max abs N error | B within 15 % | B resolved | axes with a "
        "(false) effect | rejected | longest tau (s) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for scenario in SCENARIOS:
        for policy in ("longest", "mask"):
            axes = [
                a for r in rows if (r["scenario"], r["policy"]) == (scenario, policy)
                for a in r["axes"].values()
            ]  # fmt: skip
            if not axes:
                continue
            n = [abs(a["n_error"]) for a in axes if a["n_error"] is not None]
            b = [a["b_error"] for a in axes]
            taus = [a["tau_max_s"] for a in axes]
            out.append(
                f"| {scenario} | {policy} | {np.median(n):.2%} / {max(n):.2%} | "
                f"{sum(e is not None and abs(e) < 0.15 for e in b)}/{len(b)} | "
                f"{sum(e is not None for e in b)}/{len(b)} | "
                f"{sum(bool(a['effects']) for a in axes)}/{len(axes)} | "
                f"{sum((a['p_after'] or 1.0) < 0.01 for a in axes)}/{len(axes)} | "
                f"{min(taus):.0f}-{max(taus):.0f} |"
            )
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--hours", type=float, default=4.0)
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(3, 11)))
    ap.add_argument("--scenarios", nargs="+", default=list(SCENARIOS[1:]), choices=SCENARIOS)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    rows = []
    for seed in args.seeds:
        for scenario in args.scenarios:
            rows += run(args.hours, seed, scenario)
            print(f"seed {seed} {scenario} done", file=sys.stderr, flush=True)
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1, default=float))
    print(table(rows))


if __name__ == "__main__":
    main()
