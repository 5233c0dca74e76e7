"""The ``imupipe`` command line: record, info, analyze, export, fleet, view, demo.

Bad input never produces a traceback: every :class:`~imupipe.errors.ImupipeError` becomes one
line on stderr and exit code 2.  Set ``IMUPIPE_DEBUG=1`` to see tracebacks of internal errors.
"""

from __future__ import annotations

import atexit
import contextlib
import gc
import hashlib
import math
import os
import signal
import string
import sys
import threading
from dataclasses import asdict, dataclass, replace
from enum import StrEnum
from pathlib import Path
from typing import Annotated, NoReturn

import typer

from imupipe import __version__, stopping
from imupipe.errors import ImupipeError
from imupipe.escape import printable
from imupipe.report.exports import (
    FORMATS,
    ExportOptions,
    Written,
    check_options,
    write_exports,
)

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Record ADIS16364 frames into MCAP and analyse their noise "
    "(overlapping Allan deviation, IEEE 952 terms, closed-loop effect search).",
)

Quiet = Annotated[bool, typer.Option("--quiet", "-q", help="No progress bars.")]


def _print_version(asked: bool) -> None:
    if asked:
        typer.echo(f"imupipe {__version__}")
        raise typer.Exit()


@app.callback()
def _options(
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_print_version, is_eager=True, help="Print the version and exit."
        ),
    ] = False,
) -> None:
    """Options before the command (``imupipe --version``: the version that writes
    ``report.json``'s ``generator``)."""


class Source(StrEnum):
    sim = "sim"
    spi = "spi"


class GapPolicy(StrEnum):
    auto = "auto"
    longest = "longest"
    fail = "fail"
    mask = "mask"


class Combine(StrEnum):
    worst = "worst"
    mean = "mean"


ExportFormat = StrEnum("ExportFormat", {n: n for n in (*FORMATS, "all")})
"""``--export`` / ``--format``: a format of :data:`imupipe.report.exports.FORMATS`, or all."""
CombineOption = Annotated[
    Combine,
    typer.Option(help="One value per sensor where a format takes one: worst axis or mean."),
]
InflateOption = Annotated[
    float,
    typer.Option(help="Factor on every exported noise strength (variances: its square)."),
]
StartOption = Annotated[
    float,
    typer.Option(
        "--start",
        help="Analyse from this time on, s from the recording's first frame (e.g. after "
        "the robot was set down).",
    ),
]
EndOption = Annotated[
    float | None,
    typer.Option(
        "--end",
        help="Analyse up to this time, s from the first frame; negative: that many seconds "
        "before the last frame (default: the last frame).",
    ),
]
RateOption = Annotated[
    float | None,
    typer.Option(
        "--rate", help="Filter/driver rate, Hz, for discrete formats (default: the recording's)."
    ),
]


ALL_TOPICS = "all"
"""``--topic all``: analyse every IMU topic, each into its own subfolder."""


_FOLDER_SAFE = frozenset(string.ascii_letters + string.digits + "_-")
_FOLDER_MAX = 200
"""Longest folder name :func:`topic_folder` makes (most file systems allow 255 bytes)."""


def _quote(part: str) -> str:
    """``part`` with every character outside [A-Za-z0-9_-] as %XX of its UTF-8 bytes."""
    return "".join(
        c if c in _FOLDER_SAFE else "".join(f"%{b:02X}" for b in c.encode("utf-8", "surrogatepass"))
        for c in part
    )


def topic_folder(topic: str) -> str:
    """Subfolder name of a topic's reports under ``--topic all``: ``/imu0/data_raw`` →
    ``imu0.data_raw``.

    The name is one path component that can never be ``.``, ``..`` or empty, so the reports
    stay inside ``--out``; and it is injective, so two topics never share a folder: the leading
    ``/`` is dropped and the others become ``.`` (when a level is empty, every ``/`` is ``%2F``),
    every other character outside [A-Za-z0-9_-] is ``%XX`` (``.``, ``%``, a NUL...), a topic
    without the leading ``/`` starts with ``%%``, and a name longer than :data:`_FOLDER_MAX`
    ends in ``~`` and 16 hex digits of the topic's SHA-256 (``~`` appears in no other name).
    """
    relative = not topic.startswith("/")
    parts = (topic if relative else topic[1:]).split("/")
    if "" in parts:  # "/", "//a", "/a/": a level is empty, so every "/" is quoted
        name = ("" if relative else "%2F") + "%2F".join(_quote(p) for p in parts)
    else:
        name = ".".join(_quote(p) for p in parts)
    name = ("%%" if relative else "") + name
    if len(name) > _FOLDER_MAX:
        digest = hashlib.sha256(topic.encode("utf-8", "surrogatepass")).hexdigest()[:16]
        name = f"{name[: _FOLDER_MAX - 17]}~{digest}"
    return name


def _warn(message: str) -> None:
    typer.echo(f"warning: {printable(message)}", err=True)


def _say(text: str) -> None:
    """Print ``text`` line by line, each with its control characters escaped (strings from the
    input never reach the terminal raw: :func:`imupipe.escape.printable`)."""
    for line in text.split("\n"):
        typer.echo(printable(line))


@app.command()
def record(
    output: Annotated[Path, typer.Option("--output", "-o", help="MCAP file to write.")] = Path(
        "run.mcap"
    ),
    duration: Annotated[str, typer.Option(help="Length: 12h, 30m, 90s or seconds.")] = "12h",
    rate: Annotated[float, typer.Option(help="Output rate, Hz.")] = 100.0,
    seed: Annotated[int, typer.Option(help="Simulator seed (same seed, same bytes).")] = 0,
    scenario: Annotated[
        Path | None, typer.Option(help="TOML scenario: noise terms and effects (simulator).")
    ] = None,
    truth: Annotated[
        Path | None, typer.Option(help="Write the simulator's ground truth to this JSON file.")
    ] = None,
    source: Annotated[Source, typer.Option(help="sim: virtual ADIS16364; spi: real one.")] = (
        Source.sim
    ),
    device: Annotated[str, typer.Option(help="spidev device for --source spi.")] = (
        "/dev/spidev0.0"
    ),
    data_ready: Annotated[
        str | None,
        typer.Option(
            help="GPIO CHIP:LINE wired to the sensor's DIO1 (--source spi), e.g. "
            "/dev/gpiochip0:17: rates the sensor makes are read on its data-ready edge."
        ),
    ] = None,
    serial: Annotated[int, typer.Option(help="Serial number stored in the metadata.")] = 0,
    realtime: Annotated[bool, typer.Option(help="Pace the simulator in real time.")] = False,
    view: Annotated[
        bool,
        typer.Option(
            help="Open a Rerun window showing the signals live and the Allan deviation so far "
            "(updated every minute)."
        ),
    ] = False,
    serve: Annotated[
        bool,
        typer.Option(
            help="As --view, but serve on 127.0.0.1:--view-port for "
            "'rerun --connect rerun+http://127.0.0.1:PORT/proxy'."
        ),
    ] = False,
    view_port: Annotated[
        int, typer.Option(min=1, max=65535, help="Port of --serve, on 127.0.0.1.")
    ] = 9876,
    quiet: Quiet = False,
) -> None:
    """Record ADIS16364 frames into an MCAP file (default: the paper's 12 h static test)."""
    from imupipe.api import record as run_record

    if serve and not quiet:
        typer.echo(
            f"live view: rerun --connect rerun+http://127.0.0.1:{view_port}/proxy",
            err=True,
        )
    summary = run_record(
        output,
        duration=duration,
        rate_hz=rate,
        seed=seed,
        scenario=scenario,
        truth=truth,
        source=source.value,
        device=device,
        data_ready=data_ready,
        serial=serial,
        realtime=realtime,
        progress=not quiet,
        view="serve" if serve else "view" if view else None,
        view_port=view_port,
    )
    if not quiet:
        _say(
            f"{summary.path}: {summary.frames} frames, {summary.duration_s:.1f} s at "
            f"{summary.rate_hz:g} Hz ({summary.rate_method}), "
            f"{summary.path.stat().st_size / 1e6:.1f} MB"
        )
    if summary.stop_signal is not None:
        name = signal.Signals(summary.stop_signal).name
        _warn(f"{name}: recorded {summary.frames} of {summary.requested} frames; file finished")
        raise typer.Exit(128 + summary.stop_signal)  # the shell convention for a signal


@app.command()
def info(path: Annotated[Path, typer.Argument(help="MCAP file or rosbag2 directory.")]) -> None:
    """Show the topics, message counts, device metadata and any damage of a recording."""
    from imupipe.io.info import describe

    for line in describe(path).lines():
        _say(printable(line))


@app.command()
def analyze(
    path: Annotated[
        Path,
        typer.Argument(
            help="MCAP file (ours or a ROS 2 bag's), or a rosbag2 directory (MCAP or SQLite "
            "storage)."
        ),
    ],
    out: Annotated[
        Path | None, typer.Option("--out", "-o", help="Output folder (default: FILE.imupipe/).")
    ] = None,
    topic: Annotated[
        str | None,
        typer.Option(help="IMU topic when there are several; 'all': one report per topic."),
    ] = None,
    taus_per_decade: Annotated[
        int, typer.Option(min=4, max=100, help="Points of the Allan curve per decade of tau.")
    ] = 10,
    gaps: Annotated[
        GapPolicy,
        typer.Option(
            help="auto: mask if no gap is longer than 1 h, else longest; longest: analyse "
            "the longest clean segment; fail: refuse; mask: analyse the whole recording, "
            "skipping the Allan terms that touch a gap or bad frame."
        ),
    ] = GapPolicy.auto,
    rrd: Annotated[bool, typer.Option(help="Write recording.rrd for the Rerun viewer.")] = True,
    rrd_full: Annotated[
        bool,
        typer.Option(
            help="Every raw frame in recording.rrd (default: a min/max envelope of 100 000 "
            "bins once a recording has more than 200 000 frames)."
        ),
    ] = False,
    loop: Annotated[bool, typer.Option(help="Run the closed-loop effect search.")] = True,
    memory_budget_gb: Annotated[
        float,
        typer.Option(
            min=0.0,
            help="Recordings whose whole-frame analysis would need more memory are decoded "
            "once into a temporary on-disk store and analysed one axis at a time (same results).",
        ),
    ] = 2.0,
    jobs: Annotated[
        int | None,
        typer.Option(
            min=1,
            help="Axes analysed at once, one per thread (default: the cores this process may "
            "use; fewer when --memory-budget-gb has no room for more). Same results.",
        ),
    ] = None,
    tmp_dir: Annotated[
        Path | None,
        typer.Option(
            help="Where a recording over the memory budget is spilled while it is analysed "
            "(~65 bytes a frame; default: the system's temporary directory; removed after).",
        ),
    ] = None,
    datasheet: Annotated[
        Path | None,
        typer.Option(
            help="TOML of the part's noise specs (N, B, K, rms per sensor with units) "
            "shown next to the measured terms; default: the ADIS16364's for its "
            "recordings."
        ),
    ] = None,
    export: Annotated[
        list[ExportFormat] | None,
        typer.Option(help="Also write this filter's noise file (repeatable; see imupipe export)."),
    ] = None,
    combine: CombineOption = Combine.worst,
    inflate: InflateOption = 1.0,
    export_rate: Annotated[
        float | None, typer.Option(help="Filter/driver rate, Hz, for the exports.")
    ] = None,
    temperature_topic: Annotated[
        str | None,
        typer.Option(
            help="sensor_msgs/msg/Temperature topic of the IMU (default: the one in the IMU "
            "topic's namespace or with its frame_id; none otherwise)."
        ),
    ] = None,
    start: StartOption = 0.0,
    end: EndOption = None,
    quiet: Quiet = False,
) -> None:
    """Analyse a recording: Allan deviation, IEEE 952 terms, effects; write reports."""
    from imupipe.analysis.analyze import AnalyzeOptions
    from imupipe.api import default_out_dir
    from imupipe.report.datasheet import load_datasheet

    if not math.isfinite(memory_budget_gb):
        raise ImupipeError(
            f"--memory-budget-gb must be a finite number of GB, got {memory_budget_gb}"
        )
    out_dir = out if out is not None else default_out_dir(path)
    if datasheet is not None:
        load_datasheet(datasheet)  # a bad file fails now, not after the analysis
    exporting = _ExportRequest(
        [f.value for f in export or []], ExportOptions(combine.value, inflate, export_rate)
    )
    exporting.check()
    # The imports' ~150,000 objects live as long as this process: out of the collector's full
    # passes (12 h at 100 Hz: 0.22 s in them per analysis in a fresh process, 0.03 s after).
    gc.freeze()
    options = AnalyzeOptions(
        topic=topic,
        taus_per_decade=taus_per_decade,
        gaps=gaps.value,
        loop=loop,
        rrd=rrd,
        rrd_full=rrd_full,
        memory_budget_bytes=round(memory_budget_gb * 1e9),
        tmp_dir=tmp_dir,
        datasheet=datasheet,
        temperature_topic=temperature_topic,
        workers=jobs,
        start_s=start,
        end_s=end,
    )
    if topic != ALL_TOPICS:
        _analyze_one(path, out_dir, options, quiet, exporting)
        return
    from imupipe.io.info import imu_topics

    topics = imu_topics(path)
    failed: list[str] = []
    for name in topics:
        sub = out_dir / topic_folder(name)
        if not quiet:
            _say(printable(f"== {name} -> {sub}/"))
        try:
            _analyze_one(path, sub, replace(options, topic=name), quiet, exporting)
        except ImupipeError as exc:
            _warn(f"topic {name}: {exc}")
            failed.append(name)
    if failed:
        raise ImupipeError(
            f"{len(failed)} of {len(topics)} IMU topics could not be analysed: " + ", ".join(failed)
        )


@dataclass(frozen=True)
class _ExportRequest:
    """The exports asked of ``analyze`` (``--export``) and their options."""

    formats: list[str]
    options: ExportOptions

    def check(self) -> None:
        """Reject bad options before the analysis runs."""
        check_options(self.options)

    def write(self, result, out_dir: Path) -> Written:
        if not self.formats:
            return Written([], [])
        return write_exports(result.to_dict(), self.formats, out_dir, self.options)


def _analyze_one(
    path: Path, out_dir: Path, options, quiet: bool, exporting: _ExportRequest
) -> None:
    """Analyse one IMU topic into ``out_dir``; write exports; print its table (stdout) and then
    its warnings, once (stderr: also with ``quiet``)."""
    from imupipe.api import analyze as run_analyze
    from imupipe.report.datasheet import load_datasheet
    from imupipe.report.report import format_table

    result = run_analyze(path, out_dir, progress=not quiet, **asdict(options))
    written = exporting.write(result, out_dir)
    if not quiet:
        sheet = load_datasheet(options.datasheet) if options.datasheet else None
        _say(format_table(result, sheet))
    for w in [*result.input.warnings, *written.skipped]:  # after the table, where it ends
        _warn(w)
    if not quiet:
        for p in written.paths:
            _say(printable(f"export: {p}"))
        _say(printable(f"reports written to {out_dir}/"))


@app.command("export")
def export_cmd(
    result_dir: Annotated[Path, typer.Argument(help="Output folder of imupipe analyze.")],
    format: Annotated[
        list[ExportFormat],
        typer.Option("--format", "-f", help="Filter format (repeatable; 'all': every one)."),
    ],
    out: Annotated[
        Path | None, typer.Option("--out", "-o", help="Folder to write into (default: RESULT_DIR).")
    ] = None,
    combine: CombineOption = Combine.worst,
    inflate: InflateOption = 1.0,
    rate: RateOption = None,
) -> None:
    """Write the final noise model as a filter's noise file (Kalibr, OpenVINS, VINS-Fusion,
    ORB-SLAM3, Basalt, GTSAM, sensor_msgs/Imu covariances)."""
    from imupipe.report.exports import export_result_dir

    options = ExportOptions(combine.value, inflate, rate)
    written = export_result_dir(result_dir, [f.value for f in format], out, options)
    for line in written.skipped:
        _warn(line)
    for path in written.paths:
        typer.echo(f"{path}")


@app.command()
def fleet(
    recordings: Annotated[
        list[str],
        typer.Argument(
            help="MCAP files, rosbag2 directories, folders or globs holding them, or fsspec "
            "URLs (s3://bucket/prefix/), read by the workers where they are."
        ),
    ],
    out: Annotated[Path, typer.Option("--out", "-o", help="Folder for the fleet report.")],
    scheduler: Annotated[
        str | None,
        typer.Option(
            envvar="DASK_SCHEDULER_ADDRESS",
            help="Existing Dask scheduler (tcp://host:8786); default: a local cluster started "
            "and stopped by this command.",
        ),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(
            min=1,
            help="Local cluster: worker processes (default: one per core). With --scheduler: "
            "wait until that many workers have joined.",
        ),
    ] = None,
    datasheet: Annotated[
        Path | None, typer.Option(help="Datasheet TOML to check every unit and the lot against.")
    ] = None,
    taus_per_decade: Annotated[int, typer.Option(min=4, max=100, help="As imupipe analyze.")] = 10,
    gaps: Annotated[GapPolicy, typer.Option(help="As imupipe analyze.")] = GapPolicy.auto,
    rrd: Annotated[bool, typer.Option(help="Write each unit's recording.rrd and fleet.rrd.")] = (
        True
    ),
    loop: Annotated[bool, typer.Option(help="Run the closed-loop effect search.")] = True,
    memory_budget_gb: Annotated[
        float,
        typer.Option(
            min=0.0,
            help="As imupipe analyze; capped at 60 % of each worker's memory limit.",
        ),
    ] = 2.0,
    start: StartOption = 0.0,
    end: EndOption = None,
    quiet: Quiet = False,
) -> None:
    """Analyse many recordings on a Dask cluster; write each unit's reports and the fleet's
    (fleet.json, fleet.parquet, fleet.md, fleet.rrd).  Exits 2 if any recording failed."""
    from imupipe.analysis.analyze import AnalyzeOptions
    from imupipe.errors import FleetError
    from imupipe.fleet.run import run_fleet

    options = AnalyzeOptions(
        taus_per_decade=taus_per_decade,
        gaps=gaps.value,
        loop=loop,
        rrd=rrd,
        memory_budget_bytes=round(memory_budget_gb * 1e9),
        start_s=start,
        end_s=end,
    )
    result = run_fleet(
        recordings,
        out,
        scheduler=scheduler,
        workers=workers,
        datasheet=datasheet,
        options=options,
        progress=not quiet,
    )
    for unit in result.failed:
        _warn(f"{unit.name}: {unit.error}")
    if not quiet:
        ok = len(result.units) - len(result.failed)
        typer.echo(
            f"{ok} of {len(result.units)} recordings analysed in {result.seconds:.1f} s; "
            f"fleet report in {result.out_dir}/fleet.md"
        )
    if result.failed:
        raise FleetError(
            f"{len(result.failed)} of {len(result.units)} recordings failed "
            f"(listed in {result.out_dir}/fleet.md)"
        )


@app.command()
def view(
    path: Annotated[Path, typer.Argument(help="Output folder of analyze, or an .rrd.")],
) -> None:
    """Open the Rerun viewer on an analysis' recording.rrd."""
    from imupipe.report.rerun_view import open_viewer

    rrd = path / "recording.rrd" if path.is_dir() else path
    if not rrd.is_file():
        raise ImupipeError(f"{rrd}: no Rerun recording (run imupipe analyze without --no-rrd)")
    open_viewer(rrd)


@app.command()
def demo(
    out: Annotated[Path, typer.Option("--out", "-o", help="Folder for the demo.")] = Path(
        "imupipe-demo"
    ),
    duration: Annotated[str, typer.Option(help="Length of the simulated recording.")] = "12h",
    seed: Annotated[int, typer.Option(help="Simulator seed (same seed, same bytes).")] = 0,
    quiet: Quiet = False,
) -> None:
    """The paper's experiment end to end: record 12 h of a virtual ADIS16364, then analyse it."""
    out.mkdir(parents=True, exist_ok=True)
    mcap_path = out / "adis16364.mcap"
    # the commands' own defaults (typer's Annotated options keep plain Python defaults)
    record(output=mcap_path, duration=duration, seed=seed, truth=out / "truth.json", quiet=quiet)
    analyze(path=mcap_path, out=out / "adis16364.imupipe", quiet=quiet)


def main() -> None:
    """Console entry point: one-line errors, exit 2 for bad input; SIGINT, SIGTERM and SIGHUP
    end a command with one line and 128 + the signal (``record`` finishes its file first)."""
    previous = stopping.install((signal.SIGINT, signal.SIGTERM, signal.SIGHUP))
    try:
        _run()
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def _run() -> None:
    try:
        code = app(standalone_mode=False)  # typer.Exit(n) comes back as n here
    except stopping.Stopped as stop:
        name = signal.Signals(stop.signum).name
        said = "interrupted" if stop.signum == signal.SIGINT else f"stopped by {name}"
        typer.echo(f"imupipe: {said}", err=True)
        sys.exit(128 + stop.signum)
    except ImupipeError as exc:
        typer.echo(f"imupipe: error: {printable(str(exc))}", err=True)
        sys.exit(2)
    except typer.Abort:
        typer.echo("imupipe: interrupted", err=True)
        sys.exit(130)
    except Exception as exc:  # usage errors (typer's click) and anything unexpected: one line
        if hasattr(exc, "show") and hasattr(exc, "exit_code"):  # click.ClickException
            exc.show()
            sys.exit(exc.exit_code)
        if os.environ.get("IMUPIPE_DEBUG"):
            raise
        message = printable(f"{type(exc).__name__}: {exc}")
        typer.echo(f"imupipe: internal error: {message}", err=True)
        sys.exit(1)
    sys.exit(code if isinstance(code, int) else 0)


def console() -> NoReturn:
    """The ``imupipe`` command (and ``python -m imupipe``): :func:`main`, then the process ends
    without the interpreter's finalization.

    Tearing down the modules of numba, polars, scipy, matplotlib and rerun costs ~0.6-0.9 s of
    CPU after an analysis (measured: 0.77-0.89 s from the last output written to the process
    gone), which every command would add to its wall time for nothing.  What finalization does
    that matters still happens: non-daemon threads are joined, the ``atexit`` handlers run
    (rerun's flush, temporary folders' finalizers, logging, multiprocessing's children), and
    stdout/stderr are flushed; then ``os._exit`` with :func:`main`'s exit status."""
    try:
        main()
        status: object = 0
    except SystemExit as stop:
        status = stop.code
    if isinstance(status, str):  # what sys.exit("message") means: the message, status 1
        print(status, file=sys.stderr)
        status = 1
    for thread in threading.enumerate():
        if thread is not threading.main_thread() and not thread.daemon:
            thread.join()
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):  # a closed pipe: nothing left to say
            stream.flush()
    os._exit(status if isinstance(status, int) else 0)


if __name__ == "__main__":
    console()
