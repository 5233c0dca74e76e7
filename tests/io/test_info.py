"""``imupipe info``: the lines a user reads about a recording, value by value."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mcap.writer import Writer

from imupipe.io.info import RecordingInfo, TopicInfo, describe, imu_topics
from imupipe.testing.busy_bag import T0_NS, imu_stream, write_rosbag2_db3
from imupipe.testing.ros_cdr import imu_payloads

IMU = "sensor_msgs/msg/Imu"


def write_topics(path: Path, topics: dict[str, tuple[str, np.ndarray]]) -> Path:
    """An MCAP file (the mcap library's writer, one chunk) with an Imu channel per topic:
    {topic: (message encoding, log times in ns)}; a topic with no times has no messages."""
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test")
        schema = w.register_schema(IMU, "ros2msg", b"")
        for topic, (encoding, times) in topics.items():
            channel = w.register_channel(topic, encoding, schema)
            rows = imu_payloads(times, np.zeros((len(times), 3)), np.zeros((len(times), 3)))
            for t, row in zip(times.tolist(), rows, strict=True):
                w.add_message(channel, log_time=t, data=row.tobytes(), publish_time=t)
        w.finish()
    return path


def test_each_topic_line_gives_messages_duration_and_rate(tmp_path: Path) -> None:
    times = T0_NS + np.arange(1000) * 10_000_000  # 1000 messages over 9.99 s
    path = write_topics(
        tmp_path / "f.mcap",
        {
            "/imu": ("cdr", times),
            "/one": ("cdr", times[:1]),  # a single message: no duration, no rate
            "/none": ("cdr", times[:0]),  # a channel that never published
            "/cbor": ("cbor", times[:10]),  # an encoding imupipe does not read
        },
    )
    lines = describe(path).lines()
    assert lines[0] == f"{path}: {path.stat().st_size / 1e6:.1f} MB, 1 chunks"
    assert lines[1:] == [
        f"  /cbor  [{IMU}, 'cbor' encoding: not read]  10 messages, 0.1 s, 100.00 Hz",
        f"  /imu  [{IMU}]  1000 messages, 10.0 s, 100.00 Hz",
        f"  /none  [{IMU}]  0 messages, 0.0 s, 0.00 Hz",
        f"  /one  [{IMU}]  1 messages, 0.0 s, 0.00 Hz",
    ]
    assert imu_topics(path) == ["/imu", "/one"]  # CDR and holding messages


def test_a_topics_duration_is_its_log_time_span() -> None:
    topic = TopicInfo("/imu", IMU, messages=3, start_ns=2_000_000_000, end_ns=5_500_000_000)
    assert topic.duration_s == 3.5
    assert TopicInfo("/imu", IMU, messages=1, start_ns=None, end_ns=7).duration_s == 0.0
    assert TopicInfo("/imu", IMU, messages=1, start_ns=7, end_ns=None).duration_s == 0.0
    head, rate_line = RecordingInfo(Path("f"), 0, 0, [topic], {}).lines()
    assert head == "f: 0.0 MB, 0 chunks"  # MCAP unless said otherwise
    assert rate_line.endswith("3 messages, 3.5 s, 0.57 Hz")  # (3 − 1) / 3.5 s
    unset = TopicInfo("/imu", IMU, messages=3, start_ns=0, end_ns=0)  # a writer's log times
    assert RecordingInfo(Path("f"), 0, 0, [unset], {}).lines()[1] == (
        f"  /imu  [{IMU}]  3 messages, every log time 0 ns (not set by the file's writer?)"
    )


def test_a_sqlite_bag_names_its_storage(tmp_path: Path) -> None:
    imu = imu_stream("/imu/data", 2.0, 100.0, seed=1, awkward=False)
    db3 = write_rosbag2_db3(tmp_path / "bag", [imu])
    info = describe(tmp_path / "bag")
    assert info.sqlite and info.chunks == 0
    assert info.lines()[0] == f"{tmp_path / 'bag'}: {db3.stat().st_size / 1e6:.1f} MB, " + (
        "rosbag2 SQLite storage (.db3)"
    )
    assert info.lines()[1].startswith(f"  /imu/data  [{IMU}]  {len(imu.payloads)} messages")


def test_metadata_values_are_shown_whole_up_to_80_characters() -> None:
    lines = RecordingInfo(
        Path("f"), 0, 0, [], {"unit": {"exact": "b" * 80, "long": "a" * 81}}
    ).lines()
    assert lines[1] == f"  metadata unit: exact={'b' * 80}, long={'a' * 80} … (81 characters)"


def test_an_mcap_file_is_not_sqlite(tmp_path: Path) -> None:
    path = write_topics(tmp_path / "f.mcap", {"/imu": ("cdr", T0_NS + np.arange(5))})
    assert describe(path).sqlite is False
