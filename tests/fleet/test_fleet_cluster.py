"""``imupipe fleet`` on real Dask clusters: a LocalCluster (2 worker processes) reading a local
file and an ``s3://`` prefix served by moto's server on 127.0.0.1; and a deployment-style
cluster (``dask scheduler`` + two ``dask worker`` processes) driven through ``--scheduler``,
with one worker killed mid-run.  Every server is bound to 127.0.0.1 and stopped here."""

from __future__ import annotations

import gc
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import polars as pl
import pytest
from matplotlib.image import imread

from imupipe.api import analyze, record
from imupipe.fleet.curves import UNIT_COLUMN
from imupipe.fleet.report import write_fleet_report
from imupipe.fleet.run import run_fleet
from imupipe.report.rerun_view import rerun_executable

BIN = Path(sys.executable).parent
SAMPLE = Path(__file__).resolve().parents[2] / "sample_logs" / "adis16364_default_5min.mcap"
FLEET_SCHEMA = json.loads(
    (Path(__file__).resolve().parents[2] / "schemas" / "fleet.schema.json").read_text()
)


def _record(path: Path, seed: int) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    record(path, duration="2m", rate_hz=100, seed=seed)
    return path


def _files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


@pytest.fixture
def s3_server(monkeypatch):
    """moto's S3 server on 127.0.0.1 (a free port); env set so that workers find it."""
    from moto.server import ThreadedMotoServer

    server = ThreadedMotoServer(ip_address="127.0.0.1", port=0, verbose=False)
    server.start()
    host, port = server.get_host_and_port()
    for key, value in {
        "AWS_ACCESS_KEY_ID": "testing",
        "AWS_SECRET_ACCESS_KEY": "testing",
        "AWS_DEFAULT_REGION": "us-east-1",
        "AWS_ENDPOINT_URL_S3": f"http://{host}:{port}",
    }.items():
        monkeypatch.setenv(key, value)
    try:
        yield f"http://{host}:{port}"
    finally:
        server.stop()


def test_local_cluster_local_and_s3_units(tmp_path, s3_server, schema_errors):
    import boto3

    local = _record(tmp_path / "unit_a.mcap", seed=1)
    remote = _record(tmp_path / "upload" / "unit_b.mcap", seed=2)
    s3 = boto3.client("s3", endpoint_url=s3_server)
    s3.create_bucket(Bucket="fleet")
    s3.upload_file(str(remote), "fleet", "site1/unit_b.mcap")
    s3.put_object(Bucket="fleet", Key="site1/notes.txt", Body=b"not a recording")

    out = tmp_path / "fleet"
    started = time.perf_counter()
    result = run_fleet([str(local), "s3://fleet/site1/"], out, workers=2)
    assert result.seconds == pytest.approx(time.perf_counter() - started, abs=0.5)

    assert [(u.name, u.status, u.source) for u in result.units] == [
        ("unit_a", "ok", str(local)),
        ("unit_b", "ok", "s3://fleet/site1/unit_b.mcap"),
    ]
    # each unit's folder holds exactly what `imupipe analyze` writes for that recording
    ref_a = analyze(local, tmp_path / "ref_a")
    assert _files(out / "unit_a") == _files(tmp_path / "ref_a")
    assert json.loads((out / "unit_a" / "report.json").read_text()) == ref_a.to_dict()
    # the s3 unit: the same bytes analysed locally, except that the report names the URL
    ref_b = analyze(remote, tmp_path / "ref_b").to_dict()
    got_b = json.loads((out / "unit_b" / "report.json").read_text())
    assert got_b["input"].pop("path") == "s3://fleet/site1/unit_b.mcap"
    ref_b["input"].pop("path")
    assert got_b == ref_b
    assert _files(out / "unit_b") == _files(tmp_path / "ref_b")
    assert "s3://fleet/site1/unit_b.mcap" in (out / "unit_b" / "report.md").read_text()
    rrd = subprocess.run(
        [rerun_executable(), "rrd", "print", "-vvv", str(out / "unit_b" / "recording.rrd")],
        capture_output=True, text=True, check=True,
    ).stdout  # fmt: skip
    assert "s3://fleet/site1/unit_b.mcap" in rrd and "imupipe-fleet-" not in rrd  # not the copy
    assert not (out / ".staging").exists()

    # fleet.parquet: every unit's curves, long form, equal to the unit's allan.parquet
    fleet = pl.read_parquet(out / "fleet.parquet")
    a = fleet.filter(pl.col(UNIT_COLUMN) == "unit_a").drop(UNIT_COLUMN)
    assert a.equals(pl.read_parquet(tmp_path / "ref_a" / "allan.parquet"))
    assert fleet[UNIT_COLUMN].unique().sort().to_list() == ["unit_a", "unit_b"]

    # fleet.json: the population median of N is the median of the units' final N
    doc = json.loads((out / "fleet.json").read_text())
    assert schema_errors(doc, FLEET_SCHEMA, FLEET_SCHEMA) == []
    assert (doc["recordings"], doc["analysed"], doc["failed"]) == (2, 2, 0)
    row = next(p for p in doc["population"] if p["axis"] == "gyro_x" and p["term"] == "random_walk")
    values = [
        u.report["axes"]["gyro_x"].get("ieee952_after", u.report["axes"]["gyro_x"]["ieee952"])[
            "random_walk"
        ]["value"]
        for u in result.units
    ]
    assert row["median"] == pytest.approx(float(np.median(values)), rel=1e-12)
    assert row["unit"] == "rad/s/sqrt(Hz)" and row["resolved"] == 2
    md = (out / "fleet.md").read_text()
    assert "2 recordings: 2 analysed, 0 failed." in md
    for name in ("fleet_adev_gyro.png", "fleet_terms_accel.png", "fleet.rrd"):
        assert (out / name).stat().st_size > 1000
    # the figures were drawn on the workers: the same PNGs as drawn here, each in its own file
    local = tmp_path / "local_report"
    local.mkdir()
    write_fleet_report(result.units, local, rrd=False)
    for sensor in ("gyro", "accel"):
        for kind in ("adev", "terms"):
            name = f"fleet_{kind}_{sensor}.png"
            assert (out / name).read_bytes() == (local / name).read_bytes(), name
    assert imread(out / "fleet_adev_gyro.png").shape == (420, 1260, 4)  # 3 panels of 4.2 in


def _wait_for(predicate, timeout_s: float, what: str):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def test_existing_scheduler_survives_a_killed_worker(tmp_path, schema_errors):
    from distributed import Client

    good = [_record(tmp_path / f"unit{k}.mcap", seed=10 + k) for k in range(4)]
    damaged = tmp_path / "damaged.mcap"  # MCAP magic, then garbage
    damaged.write_bytes(b"\x89MCAP0\r\n" + np.random.default_rng(0).bytes(20_000))
    not_mcap = tmp_path / "notes.mcap"
    not_mcap.write_text("this is not a recording\n")

    sched_file = tmp_path / "scheduler.json"
    local = ["--host", "127.0.0.1", "--dashboard-address", "127.0.0.1:0", "--no-dashboard"]
    procs: list[subprocess.Popen] = []
    client = None
    try:
        procs.append(
            subprocess.Popen(
                [BIN / "dask", "scheduler", "--port", "0", "--scheduler-file", sched_file, *local],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
        )
        _wait_for(sched_file.exists, 60, "the scheduler file")
        workers = [
            subprocess.Popen(
                [
                    BIN / "dask",
                    "worker",
                    "--scheduler-file",
                    sched_file,
                    "--nthreads",
                    "1",
                    "--no-nanny",
                    *local,
                ],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
            for _ in range(2)
        ]
        procs += workers
        client = Client(scheduler_file=str(sched_file), timeout="30s")
        client.wait_for_workers(2, timeout="60s")
        address = client.scheduler.address
        pids = client.run(os.getpid)  # {worker address: pid}

        fleet = subprocess.Popen(
            [BIN / "imupipe", "fleet", *map(str, [*good, damaged, not_mcap]),
             "--out", tmp_path / "out", "--scheduler", address, "--no-loop", "--no-rrd", "-q"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        procs.append(fleet)

        def busy_worker():
            processing = client.processing()
            return next((a for a, keys in processing.items() if keys), None)

        victim = _wait_for(busy_worker, 120, "a task on a worker")
        killed_at = time.time()
        os.kill(pids[victim], signal.SIGKILL)
        survivor = next(a for a in pids if a != victim)
        _, err = fleet.communicate(timeout=600)
        # the fleet froze no heap of a cluster that outlives it (only the embedded one's)
        assert client.run(gc.get_freeze_count, workers=[survivor]) == {survivor: 0}
    finally:
        if client is not None:
            client.close()
        # the fleet and the workers first, then the scheduler: a worker whose scheduler has
        # gone takes more than 30 s to obey SIGINT (distributed 2026.7, measured)
        for p in reversed(procs):
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()

    assert fleet.returncode == 2, err
    assert err.splitlines() == [
        f"warning: damaged: {damaged}: no IMU topic (topics in the file: none)",
        f"warning: notes: {not_mcap} is not an MCAP file (bad magic)",
        f"imupipe: error: 2 of 6 recordings failed (listed in {tmp_path / 'out'}/fleet.md)",
    ]
    doc = json.loads((tmp_path / "out" / "fleet.json").read_text())
    assert schema_errors(doc, FLEET_SCHEMA, FLEET_SCHEMA) == []  # failed units included
    units = {u["name"]: u for u in doc["units"]}
    assert [units[f"unit{k}"]["status"] for k in range(4)] == ["ok"] * 4
    # the killed worker's task ran again on the surviving worker: it did every good unit but
    # those the killed one had finished before the kill (a loaded machine may poll late)
    done_by = {k: units[f"unit{k}"]["worker"].rsplit(":", 1)[1] for k in range(4)}
    assert set(done_by.values()) <= {str(pids[survivor]), str(pids[victim])}
    for k, pid in done_by.items():
        if pid == str(pids[victim]):
            assert (tmp_path / "out" / f"unit{k}" / "report.json").stat().st_mtime <= killed_at
    assert str(pids[survivor]) in done_by.values()
    for k, path in enumerate(good):
        ref = analyze(path, tmp_path / f"ref{k}", loop=False, rrd=False)
        got = json.loads((tmp_path / "out" / f"unit{k}" / "report.json").read_text())
        assert got == ref.to_dict()
    assert not (tmp_path / "out" / "damaged").exists()
    assert "- notes: " in (tmp_path / "out" / "fleet.md").read_text()


def test_unreachable_scheduler_is_one_line_exit_2(tmp_path):
    rec = tmp_path / "x.mcap"
    rec.write_bytes(b"x")
    proc = subprocess.run(
        [BIN / "imupipe", "fleet", rec, "--out", tmp_path / "out", "--scheduler",
         "tcp://127.0.0.1:9", "-q"],
        capture_output=True,
        text=True,
        timeout=120,
    )  # fmt: skip
    assert proc.returncode == 2
    assert proc.stderr.startswith("imupipe: error: cannot reach the Dask scheduler at tcp://")
    assert len(proc.stderr.splitlines()) == 1


def test_embedded_workers_are_single_threaded():
    """One single-threaded worker per core: numba's prange kernels, polars' pool and BLAS each
    get one thread in an embedded worker, so two workers do not fight over two cores."""
    from imupipe.fleet.cluster import fleet_client

    def worker_threads() -> tuple[int, int, str | None]:  # local: pickled by value
        import numba
        import polars

        return (
            numba.config.NUMBA_NUM_THREADS,
            polars.thread_pool_size(),
            os.environ.get("OMP_NUM_THREADS"),
        )

    with fleet_client(workers=1) as client:
        (threads,) = client.run(worker_threads).values()
    assert threads == (1, 1, "1")


def test_the_embedded_cluster_has_the_workers_asked_for_on_127_0_0_1_and_stops(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Without a scheduler: ``workers`` worker processes (not threads of this process), one
    thread each, or one per core the process may use (``CPU_COUNT``, here pretended to be 1)
    without it; the scheduler, the workers and the dashboard (a free port, not 8787) on
    127.0.0.1 only (every socket listening in this process, which runs the scheduler and the
    nannies, and in each worker); the cluster closed when the block ends."""
    import imupipe.fleet.cluster as cluster

    def listening() -> set[str]:  # local: pickled by value
        import psutil

        conns = psutil.Process().net_connections("inet")
        return {c.laddr.ip for c in conns if c.status == psutil.CONN_LISTEN}

    monkeypatch.setattr(cluster, "CPU_COUNT", 1)
    for workers, expected in ((2, 2), (None, 1)):
        with cluster.fleet_client(workers=workers) as client:
            info = client.scheduler_info()
            pids = client.run(os.getpid)
            link = client.dashboard_link
            local = client.cluster
            here, there = listening(), client.run(listening)
        assert info["address"].startswith("tcp://127.0.0.1:")
        assert len(info["workers"]) == expected, workers
        assert all(a.startswith("tcp://127.0.0.1:") for a in info["workers"])
        assert [w["nthreads"] for w in info["workers"].values()] == [1] * expected
        assert len(set(pids.values())) == expected and os.getpid() not in pids.values()
        assert re.fullmatch(r"http://127\.0\.0\.1:(\d+)/status", link)
        assert not link.endswith(":8787/status")
        assert here == {"127.0.0.1"} and list(there.values()) == [{"127.0.0.1"}] * expected
        assert local.status.name == "closed" and client.status == "closed"


def test_the_embedded_workers_heaps_are_frozen_just_before_the_cluster_stops(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A worker that has run analyses takes ~0.6-0.9 s to exit (the interpreter's finalization
    collects its heap): the embedded cluster freezes its workers' heaps (``gc.freeze``) once the
    fleet's work is done, just before stopping them, and not earlier (a frozen heap is never
    collected again)."""
    import gc

    import imupipe.fleet.cluster as cluster

    seen = []
    real = cluster._freeze_worker_heaps

    def spy(client):
        before = client.run(gc.get_freeze_count)
        real(client)
        seen.append((list(before.values()), list(client.run(gc.get_freeze_count).values())))

    monkeypatch.setattr(cluster, "_freeze_worker_heaps", spy)
    with cluster.fleet_client(workers=2) as client:
        assert seen == []
        assert list(client.run(gc.get_freeze_count).values()) == [0, 0]
    ((before, after),) = seen
    assert before == [0, 0]
    assert len(after) == 2 and min(after) > 10_000  # every object a worker's imports made
    assert client.status == "closed"


def test_embedded_workers_keep_glibc_malloc_trimming_and_run_no_profiler():
    """Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536 and its workers sample every task's stack
    every 10 ms: 5.0 s instead of 3.6 s per 1 h unit.  The embedded cluster's workers have
    neither, and each is pinned to one thread; their event loop checks its health every second
    (not every 20 ms), and the host is read every 2 s; the scheduler still steals tasks (a long
    recording queued behind another moves to an idle worker)."""
    import os

    import dask.config

    from imupipe.fleet.cluster import fleet_client

    def probe():
        return (
            os.environ.get("MALLOC_TRIM_THRESHOLD_"),
            dask.config.get("distributed.worker.profile.enabled"),
            os.environ.get("NUMBA_NUM_THREADS"),
            dask.config.get("distributed.admin.tick.interval"),
            dask.config.get("distributed.admin.system-monitor.interval"),
        )

    with fleet_client(None, 1) as client:
        (seen,) = client.run(probe).values()
        stealing = client.run_on_scheduler(
            lambda dask_scheduler: "stealing" in dask_scheduler.extensions
        )
    assert seen == (None, False, "1", "1s", "2s")
    assert stealing
    assert dask.config.get("distributed.worker.profile.enabled")  # the client's is untouched
    assert dask.config.get("distributed.admin.tick.interval") == "20ms"


def test_a_script_without_a_main_guard_fails_in_seconds_instead_of_hanging(tmp_path):
    """Each embedded worker is a spawned process that imports the caller's script again: a
    script calling ``analyze_fleet`` at its top level started a cluster in every worker, and the
    fleet and its workers waited on each other for ever (measured: still waiting after 300 s).
    Now the worker refuses, saying why, and the fleet fails at once with one ``FleetError``."""
    script = tmp_path / "no_guard.py"
    script.write_text(
        "import imupipe\n"
        f"imupipe.analyze_fleet([{str(SAMPLE)!r}], {str(tmp_path / 'out')!r},"
        " workers=1)\n"
    )
    proc = subprocess.run(
        [sys.executable, script], capture_output=True, text=True, timeout=120, cwd=tmp_path
    )
    assert proc.returncode == 1
    last = proc.stderr.strip().splitlines()[-1]
    assert last.startswith("imupipe.errors.FleetError: the local Dask cluster of 1 worker(s)")
    assert last.endswith(
        "did not start: Nanny failed to start. (from a script: is imupipe.analyze_fleet "
        'called under `if __name__ == "__main__":`?)'
    )
    assert not (tmp_path / "out" / SAMPLE.stem).exists()
    assert (
        "FleetError: a fleet was started while a worker process was importing the calling "
        'script: call imupipe.analyze_fleet under `if __name__ == "__main__":`'
    ) in proc.stderr


def test_the_docs_give_deployments_the_embedded_clusters_settings():
    """docs/fleets.md's configuration file for a user's own cluster sets exactly the Dask
    options the embedded cluster changes (so the two cannot drift apart)."""
    from pathlib import Path

    import yaml

    from imupipe.fleet.cluster import WORKER_CONFIG

    page = (Path(__file__).resolve().parents[2] / "docs" / "fleets.md").read_text()
    (block,) = re.findall(r"```yaml\n(.*?)```", page, re.S)

    def flat(tree: dict, prefix: str = "") -> dict:
        out = {}
        for key, value in tree.items():
            name = f"{prefix}{key}"
            out |= flat(value, f"{name}.") if isinstance(value, dict) else {name: value}
        return out

    assert flat(yaml.safe_load(block)) == WORKER_CONFIG
