"""Are report.json, allan.parquet and imu.yaml of the committed sample_logs byte-identical to
reference outputs (e.g. captured before a refactoring)?

Analyses every ``sample_logs/*.mcap`` (by its relative path, as report.json records it; run
from the repository root) with the in-memory column source, and again with the spilled one
(``memory_budget_bytes=0``: decoded once into a temporary on-disk store), and compares the
three files byte for byte with ``REFERENCE/<sample>/``.  The spilled run's report.json differs
only in the warning that names the low-memory path; that warning is removed before comparing.
Exit code 1 if anything differs.  Capture references with ``--write``:

    python benchmarks/check_outputs_identical.py --write /tmp/before     # before the change
    python benchmarks/check_outputs_identical.py --reference /tmp/before # after it
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import sys
import tempfile
from pathlib import Path

import imupipe

FILES = ("report.json", "allan.parquet", "imu.yaml")
SAMPLES = Path("sample_logs")


def without_low_memory_note(report: bytes) -> bytes:
    """report.json as the in-memory source writes it: the low-memory warnings removed."""
    doc = json.loads(report)
    doc["input"]["warnings"] = [
        w for w in doc["input"]["warnings"] if not w.startswith("low-memory path")
    ]
    return (json.dumps(doc, indent=2, allow_nan=False) + "\n").encode()


def digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:16]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    group = ap.add_mutually_exclusive_group(required=True)
    group.add_argument("--reference", type=Path, help="folder of <sample>/ reference outputs")
    group.add_argument("--write", type=Path, help="write the outputs here as references")
    args = ap.parse_args()
    samples = sorted(SAMPLES.glob("*.mcap"))
    if not samples:
        sys.exit("no sample_logs/*.mcap here: run from the repository root")
    if args.write:
        for sample in samples:
            imupipe.analyze(sample, out=args.write / sample.stem)
        print(f"references of {len(samples)} samples written to {args.write}/")
        return 0
    differ = 0
    with tempfile.TemporaryDirectory(prefix="imupipe-check-") as tmp:
        for sample in samples:
            for source, budget in (("in-memory", 2_000_000_000), ("spilled", 0)):
                out = Path(tmp) / source / sample.stem
                imupipe.analyze(
                    sample, out=out, rrd=False, figures=False, memory_budget_bytes=budget
                )
                for name in FILES:
                    got = (out / name).read_bytes()
                    if name == "report.json" and source == "spilled":
                        got = without_low_memory_note(got)
                    want = (args.reference / sample.stem / name).read_bytes()
                    same = got == want
                    differ += not same
                    print(
                        f"{'identical' if same else 'DIFFERS  '} {sample.name:32s} {source:9s} "
                        f"{name:14s} sha256 {digest(got)}" + ("" if same else f" != {digest(want)}")
                    )
            shutil.rmtree(Path(tmp) / "spilled" / sample.stem)
    print(f"{differ} of {2 * len(samples) * len(FILES)} files differ")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
