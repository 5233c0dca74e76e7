"""Benchmark: stage 1 (decode) on bags as robots record them, against the mcap library's
``iter_messages`` and rosbags' ``AnyReader`` over the same file, in the same process.

Bags (rosbag2 directories written message by message in arrival order by the mcap library's
Writer, zstd chunks of 1 MiB, :mod:`imupipe.testing.busy_bag`):

* ``busy``: ``sensor_msgs/msg/Imu`` at ``--imu-rate`` Hz (frame_id changing length per message)
  + ``/tf`` 100 Hz + ``/odom`` 50 Hz + a 10 Hz temperature topic;
* ``busy+camera``: the same plus a 10 Hz ``sensor_msgs/msg/CompressedImage`` of 20 kB;
* ``busy, no compression``: the busy bag's topics in uncompressed chunks (the decoding itself,
  without the decompression that bounds the zstd bags);
* ``busy, SQLite (.db3)``: the busy bag's topics in rosbag2's SQLite storage (ROS 2 Humble's
  default), written by rosbags' rosbag2 writer; against ``AnyReader`` only (no MCAP to iterate);
* ``adis+tf``: our ADIS16364 frames at ``--imu-rate`` Hz interleaved with ``/tf``;
* with ``--imu-temp-hours H``: ``sensor_msgs/msg/Imu`` at 100 Hz and a 10 Hz Temperature topic,
  H hours (issue 10 measured 41 s to decode 12 h of it);
* with ``--recorder-hours H``: our recorder's own file (ADIS frames alone, simulated);
* with ``--bag DIR`` (repeatable): a rosbag2 directory you already have, its IMU on
  ``--topic`` (``sensor_msgs/msg/Imu``, for rosbags to deserialise; the generated bags above
  are then not made: ``--minutes 0``).

Each compressed bag also gets the time to decompress its chunks alone (zstandard, the same
library ours uses, one thread): the floor of any decoder that reads every chunk.

Ours is :func:`imupipe.io.decode.decode` (whole decode contract: stamps, six axes in SI units,
temperature, time base); the baselines only get the IMU messages (``iter_messages`` without any
CDR decoding: the ratio understates our advantage) or decode them (``AnyReader.deserialize``,
the six axes then read from the message objects).  Ours is timed best of ``--repeat`` (the first
call loads the compiled kernels); each baseline once.

``--analyze`` also times the whole ``imupipe analyze`` (all stages, rrd included) of the busy
bag, run as a user runs it (a child process).

Usage: ``python benchmarks/bench_decode.py [--minutes 60] [--imu-rate 200] [--analyze]
[--imu-temp-hours 12] [--recorder-hours 12] [--bag DIR --topic /imu/data]``
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import Chunk
from rosbags.highlevel import AnyReader

from imupipe.device.adis16364 import DeviceConfig, config_for_rate
from imupipe.device.frame_schema import DEFAULT_TOPIC, METADATA_NAME
from imupipe.io.decode import TEMPERATURE_SCHEMA, decode
from imupipe.recording.recorder import record
from imupipe.recording.simulator import VirtualADIS16364
from imupipe.testing.busy_bag import (
    Stream,
    adis_stream,
    imu_stream,
    other_streams,
    write_rosbag2,
    write_rosbag2_db3,
)
from imupipe.testing.ros_cdr import temperature_payloads

IMU_TOPIC = "/imu/data"


def iter_messages(path: Path, topic: str = IMU_TOPIC) -> int:
    """IMU messages through the mcap library's reader (framing only, no CDR decoding)."""
    count = 0
    with open(path, "rb") as f:
        for _ in make_reader(f).iter_messages(topics=[topic]):
            count += 1
    return count


def inflate_only(path: Path) -> int:
    """Decompress every zstd chunk of the file (found through its chunk index) and nothing
    else; returns the chunks."""
    count = 0
    inflater = zstandard.ZstdDecompressor()
    with open(path, "rb") as f:
        for index in make_reader(f).get_summary().chunk_indexes:
            if index.compression != "zstd":
                continue
            f.seek(index.chunk_start_offset + 1 + 8)  # past the record's opcode and length
            chunk = Chunk.read(ReadDataStream(f))
            inflater.decompress(chunk.data, max_output_size=chunk.uncompressed_size)
            count += 1
    return count


def any_reader(bag: Path, topic: str = IMU_TOPIC) -> int:
    """IMU messages through rosbags' AnyReader, deserialised, the six axes read out."""
    count = 0
    with AnyReader([bag]) as reader:
        connections = [c for c in reader.connections if c.topic == topic]
        for connection, _, raw in reader.messages(connections=connections):
            msg = reader.deserialize(raw, connection.msgtype)
            w, a = msg.angular_velocity, msg.linear_acceleration
            (w.x, w.y, w.z, a.x, a.y, a.z)  # noqa: B018 (what an analysis reads)
            count += 1
    return count


@dataclass(frozen=True)
class Timing:
    wall: float
    cpu: float
    """CPU seconds of this process, all threads (``time.process_time``): on a shared machine
    the steadier measure; ours counts its unpack threads too."""


def timed(f: Callable[[], int], repeat: int = 1) -> tuple[Timing, int]:
    """Best wall and best CPU time of ``repeat`` calls, and the call's result."""
    wall = cpu = float("inf")
    result = 0
    for _ in range(repeat):
        start, start_cpu = time.perf_counter(), time.process_time()
        result = f()
        wall = min(wall, time.perf_counter() - start)
        cpu = min(cpu, time.process_time() - start_cpu)
    return Timing(wall, cpu), result


def line(name: str, t: Timing, n: int) -> str:
    return (
        f"  {name:<22} wall {t.wall:7.2f} s {n / t.wall / 1e6:6.2f} M IMU msg/s"
        f" | CPU {t.cpu:7.2f} s {n / t.cpu / 1e6:6.2f} M IMU msg/s"
    )


def ratio(name: str, base: Timing, ours: Timing) -> str:
    wall, cpu = base.wall / ours.wall, base.cpu / ours.cpu
    return f"  ratio {name} / imupipe decode: wall {wall:.1f}x, CPU {cpu:.1f}x"


def bench(
    name: str, bag: Path, mcap_file: Path, repeat: int, rosbags: bool, topic: str = IMU_TOPIC
) -> None:
    ours, n = timed(lambda: decode(bag, topic=topic).frames.height, repeat)
    base, count = timed(lambda: iter_messages(mcap_file, topic))
    assert count == n, (count, n)
    size_mb = mcap_file.stat().st_size / 1e6
    print(f"\n{name}: {n} IMU messages, file {size_mb:.0f} MB")
    print(line("imupipe decode", ours, n))
    inflate, chunks = timed(lambda: inflate_only(mcap_file))
    if chunks:
        print(
            line("zstd decompression", inflate, n) + f" ({inflate.cpu / ours.cpu:.0%} of ours, CPU)"
        )
    print(line("mcap iter_messages", base, n))
    print(ratio("iter_messages", base, ours))
    if rosbags:
        anyr, count = timed(lambda: any_reader(bag, topic))
        assert count == n, (count, n)
        print(line("rosbags AnyReader", anyr, n))
        print(ratio("AnyReader", anyr, ours))


def bench_db3(name: str, bag: Path, repeat: int, topic: str = IMU_TOPIC) -> None:
    """Ours against rosbags' AnyReader over a rosbag2 SQLite bag."""
    ours, n = timed(lambda: decode(bag, topic=topic).frames.height, repeat)
    anyr, count = timed(lambda: any_reader(bag, topic))
    assert count == n, (count, n)
    size_mb = sum(f.stat().st_size for f in bag.glob("*.db3")) / 1e6
    print(f"\n{name}: {n} IMU messages, file {size_mb:.0f} MB")
    print(line("imupipe decode", ours, n))
    print(line("rosbags AnyReader", anyr, n))
    print(ratio("AnyReader", anyr, ours))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--imu-rate", type=float, default=200.0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--analyze", action="store_true", help="also time imupipe analyze")
    parser.add_argument(
        "--imu-temp-hours",
        type=float,
        default=0.0,
        help="also a bag of Imu at 100 Hz and Temperature at 10 Hz of this length",
    )
    parser.add_argument(
        "--recorder-hours",
        type=float,
        default=0.0,
        help="also our recorder's own file (ADIS frames alone) of this length at --imu-rate",
    )
    parser.add_argument("--bag", type=Path, action="append", default=[], help="a rosbag2 dir")
    parser.add_argument("--topic", default=IMU_TOPIC, help="the IMU topic of --bag")
    args = parser.parse_args()
    for bag in args.bag:
        mcap_file = next(iter(sorted(bag.glob("*.mcap"))))
        bench(str(bag), bag, mcap_file, args.repeat, rosbags=True, topic=args.topic)
    if args.minutes <= 0:
        return
    seconds = args.minutes * 60
    with tempfile.TemporaryDirectory() as tmp:
        imu = imu_stream(IMU_TOPIC, seconds, args.imu_rate, seed=1, awkward=False)
        busy = [imu, *other_streams(seconds, camera=False, seed=2)]
        cases = {
            "busy": (busy, "zstd"),
            "busy+camera": ([imu, *other_streams(seconds, camera=True, seed=2)], "zstd"),
            "busy, no compression": (busy, ""),
        }
        print(f"{args.minutes:g} min, IMU at {args.imu_rate:g} Hz, chunks of 1 MiB")
        for name, (streams, compression) in cases.items():
            bag = Path(tmp) / name
            start = time.perf_counter()
            mcap_file = write_rosbag2(bag, streams, compression=compression)
            print(f"\n({name} written by the mcap library in {time.perf_counter() - start:.0f} s)")
            bench(name, bag, mcap_file, args.repeat, rosbags=True)
            if name == "busy" and args.analyze:
                cmd = [sys.executable, "-m", "imupipe", "analyze", str(bag), "-q", "--out"]
                start = time.perf_counter()
                subprocess.run([*cmd, str(Path(tmp) / "out")], check=True)
                whole = time.perf_counter() - start
                print(f"  whole imupipe analyze (decode..rrd): {whole:.2f} s")
        bag = Path(tmp) / "busy.db3"
        start = time.perf_counter()
        write_rosbag2_db3(bag, busy)
        print(f"\n(busy, SQLite written by rosbags in {time.perf_counter() - start:.0f} s)")
        bench_db3("busy, SQLite (.db3)", bag, args.repeat)
        del cases, busy, imu
        adis = [
            adis_stream(IMU_TOPIC, seconds, args.imu_rate, seed=3),
            other_streams(seconds, False, 2)[0],
        ]
        bag = Path(tmp) / "adis+tf"
        meta = {METADATA_NAME: DeviceConfig().to_metadata()}
        mcap_file = write_rosbag2(bag, adis, metadata=meta)
        bench("adis+tf", bag, mcap_file, args.repeat, rosbags=False)
        if args.imu_temp_hours:
            hours = args.imu_temp_hours
            bag = Path(tmp) / "imu+temperature"
            imu = imu_stream(IMU_TOPIC, hours * 3600, 100, seed=4, awkward=False)
            t = imu.log_time[::10]  # 10 Hz, as the IMU's clock
            celsius = 25 + np.random.default_rng(5).normal(0, 0.1, len(t))
            payloads = list(temperature_payloads(t, celsius, frame_id="imu_link"))
            temperature = Stream("/imu/temperature", TEMPERATURE_SCHEMA, payloads, t)
            mcap_file = write_rosbag2(bag, [imu, temperature])
            del imu, temperature
            bench(f"Imu 100 Hz + Temperature 10 Hz, {hours:g} h", bag, mcap_file, 1, False)
        if args.recorder_hours:
            path = Path(tmp) / "recorder.mcap"
            n = round(args.recorder_hours * 3600 * args.imu_rate)
            record(path, VirtualADIS16364(config_for_rate(args.imu_rate), seed=2), n)
            name = f"recorder {args.recorder_hours:g} h (ADIS frames alone)"
            bench(name, path, path, args.repeat, rosbags=False, topic=DEFAULT_TOPIC)


if __name__ == "__main__":
    main()
