"""The ``imupipe`` command line: record, info, analyze, fleet, view, demo.

Bad input never produces a traceback: every :class:`~imupipe.errors.ImupipeError` becomes one
line on stderr and exit code 2.  Set ``IMUPIPE_DEBUG=1`` to see tracebacks of internal errors.
"""

from __future__ import annotations

import os
import signal
import sys
from dataclasses import asdict, replace
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from imupipe.errors import ImupipeError

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


def topic_folder(topic: str) -> str:
    """Subfolder name for a topic's reports: ``/imu0/data_raw`` → ``imu0_data_raw``."""
    return topic.strip("/").replace("/", "_") or "root"


def _warn(message: str) -> None:
    typer.echo(f"warning: {message}", err=True)


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
        typer.echo(
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
        typer.echo(line)


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
    quiet: Quiet = False,
) -> None:
    """Analyse a recording: Allan deviation, IEEE 952 terms, effects; write reports."""
    from imupipe.analysis.analyze import AnalyzeOptions
    from imupipe.api import default_out_dir

    out_dir = out if out is not None else default_out_dir(path)
    options = AnalyzeOptions(
        topic=topic,
        taus_per_decade=taus_per_decade,
        gaps=gaps.value,
        loop=loop,
        rrd=rrd,
        memory_budget_bytes=round(memory_budget_gb * 1e9),
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
            typer.echo(f"== {name} -> {sub}/")
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
        typer.echo(format_table(result))
        typer.echo(f"reports written to {out_dir}/")


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
    taus_per_decade: Annotated[int, typer.Option(min=4, max=100)] = 10,
    gaps: Annotated[GapPolicy, typer.Option(help="As imupipe analyze.")] = GapPolicy.longest,
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


def main() -> None:
    """Console entry point: one-line errors, exit 2 for bad input."""
    try:
        code = app(standalone_mode=False)  # typer.Exit(n) comes back as n here
    except ImupipeError as exc:
        typer.echo(f"imupipe: error: {exc}", err=True)
        sys.exit(2)
    except KeyboardInterrupt:
        typer.echo("imupipe: interrupted", err=True)
        sys.exit(130)
    except typer.Abort:
        sys.exit(130)
    except Exception as exc:  # usage errors (typer's click) and anything unexpected: one line
        if hasattr(exc, "show") and hasattr(exc, "exit_code"):  # click.ClickException
            exc.show()
            sys.exit(exc.exit_code)
        if os.environ.get("IMUPIPE_DEBUG"):
            raise
        typer.echo(f"imupipe: internal error: {type(exc).__name__}: {exc}", err=True)
        sys.exit(1)
    sys.exit(code if isinstance(code, int) else 0)


if __name__ == "__main__":
    main()
