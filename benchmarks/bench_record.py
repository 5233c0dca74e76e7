"""Benchmark: simulated recording vs a bare loop of the mcap library's ``Writer.add_message``.

Both run in this process on the same frame count; the baseline writes the same pre-built CDR
payloads one ``add_message`` call at a time (zstd chunks, the library's defaults), so it costs
only the library's per-message path.  The figure that matters is the ratio: ≥ 1 means that
simulating the sensor and writing its frames costs no more than the library's bare loop.

Usage: ``python benchmarks/bench_record.py [--hours 12] [--rate 100]``
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from mcap.writer import CompressionType, Writer

from imupipe.device.adis16364 import config_for_rate
from imupipe.device.frame_schema import (
    DEFAULT_TOPIC,
    MESSAGE_ENCODING,
    PROFILE,
    SCHEMA_ENCODING,
    SCHEMA_NAME,
    encode_frames,
    message_definition,
)
from imupipe.recording.recorder import record
from imupipe.recording.simulator import VirtualADIS16364


def bare_loop(path: Path, payloads: list[bytes], stamps: list[int]) -> float:
    start = time.perf_counter()
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile=PROFILE)
        sid = w.register_schema(SCHEMA_NAME, SCHEMA_ENCODING, message_definition().encode())
        cid = w.register_channel(DEFAULT_TOPIC, MESSAGE_ENCODING, sid)
        for stamp, data in zip(stamps, payloads, strict=True):
            w.add_message(cid, log_time=stamp, data=data, publish_time=stamp)
        w.finish()
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=12.0)
    parser.add_argument("--rate", type=float, default=100.0)
    args = parser.parse_args()
    n = round(args.hours * 3600 * args.rate)
    config = config_for_rate(args.rate)
    with tempfile.TemporaryDirectory() as tmp:
        ours_path = Path(tmp) / "ours.mcap"
        start = time.perf_counter()
        record(ours_path, VirtualADIS16364(config, seed=1), n)
        ours = time.perf_counter() - start
        size = ours_path.stat().st_size
        ours_path.unlink()

        block = VirtualADIS16364(config, seed=1).frames(n)  # pre-built, not timed
        raw = encode_frames(block, config.frame_id)
        payloads = [row.tobytes() for row in raw]
        stamps = block.stamp_ns.tolist()
        del raw, block
        base = bare_loop(Path(tmp) / "bare.mcap", payloads, stamps)

    print(f"frames: {n} ({args.hours:g} h at {args.rate:g} Hz), file {size / 1e6:.1f} MB")
    print(f"imupipe record (simulate+encode+write): {ours:.2f} s, {n / ours / 1e3:.0f} k frames/s")
    print(f"bare mcap Writer.add_message loop:      {base:.2f} s, {n / base / 1e3:.0f} k frames/s")
    print(f"ratio (bare loop time / imupipe time): {base / ours:.2f}x")


if __name__ == "__main__":
    main()
