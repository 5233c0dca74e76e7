"""The ``imupipe`` command line: record, info, analyze, view, demo.

Bad input never produces a traceback: every :class:`~imupipe.errors.ImupipeError` becomes one
line on stderr and exit code 2.  Set ``IMUPIPE_DEBUG=1`` to see tracebacks of internal errors.
"""

from __future__ import annotations

import hashlib
import math
import os
import signal
import string
import sys
from dataclasses import asdict, replace
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from imupipe.errors import ImupipeError
from imupipe.escape import printable

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Record ADIS16364 frames into MCAP and analyse their noise "
    "(overlapping Allan deviation, IEEE 952 terms, closed-loop effect search).",
)

Quiet = Annotated[bool, typer.Option("--quiet", "-q", help="No progress bars.")]


class Source(StrEnum):
    sim = "sim"
    spi = "spi"


class GapPolicy(StrEnum):
    longest = "longest"
    fail = "fail"


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
    serial: Annotated[int, typer.Option(help="Serial number stored in the metadata.")] = 0,
    realtime: Annotated[bool, typer.Option(help="Pace the simulator in real time.")] = False,
    quiet: Quiet = False,
) -> None:
    """Record ADIS16364 frames into an MCAP file (default: the paper's 12 h static test)."""
    from imupipe.api import record as run_record

    summary = run_record(
        output,
        duration=duration,
        rate_hz=rate,
        seed=seed,
        scenario=scenario,
        truth=truth,
        source=source.value,
        device=device,
        serial=serial,
        realtime=realtime,
        progress=not quiet,
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
    path: Annotated[Path, typer.Argument(help="MCAP file (ours or a ROS 2 bag's).")],
    out: Annotated[
        Path | None, typer.Option("--out", "-o", help="Output folder (default: FILE.imupipe/).")
    ] = None,
    topic: Annotated[
        str | None,
        typer.Option(help="IMU topic when there are several; 'all': one report per topic."),
    ] = None,
    taus_per_decade: Annotated[int, typer.Option(min=4, max=100)] = 10,
    gaps: Annotated[
        GapPolicy, typer.Option(help="longest: analyse the longest clean segment; fail: refuse.")
    ] = GapPolicy.longest,
    rrd: Annotated[bool, typer.Option(help="Write recording.rrd for the Rerun viewer.")] = True,
    loop: Annotated[bool, typer.Option(help="Run the closed-loop effect search.")] = True,
    memory_budget_gb: Annotated[
        float,
        typer.Option(
            min=0.0,
            help="Recordings whose whole-frame analysis would need more memory are decoded "
            "in passes (one axis at a time; same results).",
        ),
    ] = 2.0,
    temperature_topic: Annotated[
        str | None,
        typer.Option(
            help="sensor_msgs/msg/Temperature topic of the IMU (default: the one in the IMU "
            "topic's namespace or with its frame_id; none otherwise)."
        ),
    ] = None,
    quiet: Quiet = False,
) -> None:
    """Analyse a recording: Allan deviation, IEEE 952 terms, effects; write reports."""
    from imupipe.analysis.analyze import AnalyzeOptions
    from imupipe.api import default_out_dir

    if not math.isfinite(memory_budget_gb):
        raise ImupipeError(
            f"--memory-budget-gb must be a finite number of GB, got {memory_budget_gb}"
        )
    out_dir = out if out is not None else default_out_dir(path)
    options = AnalyzeOptions(
        topic=topic,
        taus_per_decade=taus_per_decade,
        gaps=gaps.value,
        loop=loop,
        rrd=rrd,
        memory_budget_bytes=round(memory_budget_gb * 1e9),
        temperature_topic=temperature_topic,
    )
    if topic != ALL_TOPICS:
        _analyze_one(path, out_dir, options, quiet)
        return
    from imupipe.io.info import imu_topics

    topics = imu_topics(path)
    failed: list[str] = []
    for name in topics:
        sub = out_dir / topic_folder(name)
        if not quiet:
            _say(printable(f"== {name} -> {sub}/"))
        try:
            _analyze_one(path, sub, replace(options, topic=name), quiet)
        except ImupipeError as exc:
            _warn(f"topic {name}: {exc}")
            failed.append(name)
    if failed:
        raise ImupipeError(
            f"{len(failed)} of {len(topics)} IMU topics could not be analysed: " + ", ".join(failed)
        )


def _analyze_one(path: Path, out_dir: Path, options, quiet: bool) -> None:
    """Analyse one IMU topic into ``out_dir``; print its warnings and table."""
    from imupipe.api import analyze as run_analyze
    from imupipe.report.report import format_table

    result = run_analyze(path, out_dir, progress=not quiet, **asdict(options))
    for w in result.input.warnings:
        _warn(w)
    if not quiet:
        _say(format_table(result))
        _say(printable(f"reports written to {out_dir}/"))


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
    seed: Annotated[int, typer.Option()] = 0,
    quiet: Quiet = False,
) -> None:
    """The paper's experiment end to end: record 12 h of a virtual ADIS16364, then analyse it."""
    out.mkdir(parents=True, exist_ok=True)
    mcap_path = out / "adis16364.mcap"
    record(
        output=mcap_path,
        duration=duration,
        seed=seed,
        truth=out / "truth.json",
        quiet=quiet,
        rate=100.0,
        scenario=None,
        source=Source.sim,
        device="",
        serial=0,
        realtime=False,
    )
    analyze(
        path=mcap_path,
        out=out / "adis16364.imupipe",
        topic=None,
        taus_per_decade=10,
        gaps=GapPolicy.longest,
        rrd=True,
        loop=True,
        quiet=quiet,
    )


class _Stopped(BaseException):
    """SIGINT, SIGTERM or SIGHUP arrived: unwinds like Ctrl-C (a staged output is removed), but
    past typer, which turns a KeyboardInterrupt into a silent exit 130."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def _stop(signum: int, frame: object) -> None:
    raise _Stopped(signum)


def main() -> None:
    """Console entry point: one-line errors, exit 2 for bad input; SIGINT, SIGTERM and SIGHUP
    end a command with one line and 128 + the signal (``record`` finishes its file first)."""
    previous = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    try:
        _run()
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def _run() -> None:
    try:
        code = app(standalone_mode=False)  # typer.Exit(n) comes back as n here
    except _Stopped as stop:
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


if __name__ == "__main__":
    main()
