"""The Python API: :func:`analyze`, :func:`analyze_fleet` and :func:`record`, what ``imupipe
analyze``, ``imupipe fleet`` and ``imupipe record`` run.  The command line (:mod:`imupipe.cli`)
only parses options and calls these.

    >>> import imupipe
    >>> result = imupipe.analyze("run.mcap", out="run.imupipe", rrd=False)
    >>> result.axes["gyro_x"].terms.random_walk.value      # N, rad/s/√Hz
    >>> result.to_polars()                                 # Allan curves, long form
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from imupipe.analysis.analyze import analyze as _run_analysis
from imupipe.analysis.analyze import analyze_options
from imupipe.analysis.results import AnalysisResult
from imupipe.errors import ImupipeError
from imupipe.progress import StageProgress
from imupipe.report.staging import staged_output

if TYPE_CHECKING:
    from imupipe.fleet.run import FleetResult
    from imupipe.recording.recorder import RecordSummary


def default_out_dir(path: str | Path) -> Path:
    """Where ``analyze`` writes when no ``out`` is given, beside the input: ``run.mcap`` →
    ``run.imupipe``; any other name gets ``.imupipe`` appended whole, so that two inputs never
    share an output (bag folders ``calib.day1`` → ``calib.day1.imupipe``); ``.`` is the
    current folder's name."""
    path = Path(path)
    if path.name in ("", ".."):  # "." or "..": the folder's own name
        path = path.resolve()
    if not path.name:
        raise ImupipeError(f"{path} has no name to derive an output folder from; give --out")
    stem = path.stem if path.suffix == ".mcap" else path.name
    return path.with_name(stem + ".imupipe")


def analyze(
    path: str | Path,
    out: str | Path | None = None,
    *,
    progress: bool = False,
    **options: Any,
) -> AnalysisResult:
    """Analyse a recording (an MCAP file or a rosbag2 directory) and write its reports.

    Args:
        path: the recording.
        out: output folder (default :func:`default_out_dir`), replaced as a whole when the
            analysis has written everything (:func:`imupipe.report.staging.staged_output`).
        progress: show progress bars on a terminal.
        **options: fields of :class:`imupipe.analysis.analyze.AnalyzeOptions` (``topic``,
            ``taus_per_decade``, ``gaps``, ``loop``, ``rrd``, ``figures``,
            ``memory_budget_bytes``, ``tmp_dir``: where a recording over the memory budget is
            spilled, default the system's temporary directory; ``workers``: axes analysed at
            once, default the usable cores, the same results; ``start_s``, ``end_s``: the time
            window analysed, s from the first frame, a negative end counting back from the
            last frame).

    Returns:
        The :class:`AnalysisResult`: SI values per axis; ``to_dict()`` is ``report.json``,
        ``to_polars()`` the Allan curves.

    Raises:
        ImupipeError: bad input or options, stated in one sentence.
    """
    from imupipe.report.datasheet import load_datasheet
    from imupipe.report.outputs import ReportOutputs

    out_dir = Path(out) if out is not None else default_out_dir(path)
    for name in ("tmp_dir", "datasheet"):
        if options.get(name) is not None:
            options[name] = Path(options[name])
    opts = analyze_options(**options)
    sheet = None if opts.datasheet is None else load_datasheet(opts.datasheet)
    with StageProgress(quiet=not progress) as bars, staged_output(out_dir) as staging:
        outputs = ReportOutputs(
            staging, opts.figures, opts.rrd_full, datasheet=sheet, processes=opts.workers
        )
        return _run_analysis(Path(path), opts, bars, outputs)


def analyze_fleet(
    recordings: Sequence[str | Path],
    out: str | Path,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    datasheet: str | Path | None = None,
    progress: bool = False,
    **options: Any,
) -> FleetResult:
    """Analyse many recordings on a Dask cluster and write the fleet report into ``out``.

    Args:
        recordings: MCAP files, rosbag2 directories, folders or globs holding them, fsspec
            URLs (``s3://bucket/prefix/``), read by the workers where they are.
        out: the fleet's folder: ``fleet.json``, ``fleet.parquet``, ``fleet.md``, ``fleet.rrd``
            and one folder per unit holding what :func:`analyze` writes.
        scheduler: an existing Dask scheduler (default ``DASK_SCHEDULER_ADDRESS``, else a
            LocalCluster of ``workers`` processes, one per core by default).
        datasheet: a datasheet TOML to check the units against.
        **options: as :func:`analyze`, applied to every unit.

    Returns:
        The :class:`imupipe.fleet.run.FleetResult`; failed recordings are in ``.failed``.

    Raises:
        ImupipeError: no recordings, a bad datasheet or option, an unreachable scheduler.
    """
    from imupipe.fleet.run import run_fleet

    return run_fleet(
        recordings,
        out,
        scheduler=scheduler,
        workers=workers,
        datasheet=datasheet,
        options=analyze_options(**options),
        progress=progress,
    )


def record(
    path: str | Path,
    *,
    duration: str | float = "12h",
    rate_hz: float = 100.0,
    seed: int = 0,
    scenario: str | Path | None = None,
    truth: str | Path | None = None,
    source: str = "sim",
    device: str = "/dev/spidev0.0",
    data_ready: str | None = None,
    serial: int = 0,
    realtime: bool = False,
    progress: bool = False,
    view: str | None = None,
    view_port: int = 9876,
) -> RecordSummary:
    """Record ADIS16364 frames into an MCAP file (default: the paper's 12 h static test).

    Args:
        duration: ``"12h"``, ``"30m"``, ``"90s"`` or seconds.
        rate_hz: output rate (Hz); a rate the sensor's SMPL_PRD divider makes is produced by
            the sensor, any other by host polling (the paper's 100 Hz).
        seed: simulator seed (same seed, same bytes).
        scenario: TOML scenario of noise terms and effects (simulator only).
        truth: write the simulator's ground truth to this JSON file.
        source: ``"sim"`` (virtual ADIS16364) or ``"spi"`` (a real one on ``device``).
        data_ready: ``CHIP:LINE`` of the GPIO wired to the sensor's DIO1 (e.g.
            ``/dev/gpiochip0:17``): a rate the sensor makes is then read on its data-ready edge.
        realtime: pace the simulator in real time (a real sensor always is).
        view: ``"view"`` (a Rerun window) or ``"serve"`` (a gRPC server for viewers to
            connect to) on 127.0.0.1:``view_port``: the signals live, and the Allan deviation
            so far every minute (:mod:`imupipe.report.rerun_live`).

    Raises:
        ImupipeError: bad options or a device that does not answer as an ADIS16364.
    """
    from imupipe.device.adis16364 import config_for_rate
    from imupipe.recording.recorder import parse_duration, write_truth
    from imupipe.recording.recorder import record as _run_recorder

    seconds = parse_duration(str(duration))
    if truth is not None and Path(truth).is_dir():
        raise ImupipeError(f"--truth {truth} is a folder; give the JSON file to write")
    config = config_for_rate(rate_hz, source=source, serial_number=serial)
    if source == "sim":
        from imupipe.recording.scenario import load_scenario
        from imupipe.recording.simulator import VirtualADIS16364

        frame_source = VirtualADIS16364(
            config, load_scenario(Path(scenario)) if scenario else None, seed=seed
        )
    elif source == "spi":
        if scenario or truth:
            raise ImupipeError("--scenario and --truth apply to the simulator only (--source sim)")
        from imupipe.recording.spi import open_spi_source

        frame_source = open_spi_source(device, config, data_ready=data_ready)
    else:
        raise ImupipeError(f"unknown source {source!r} (sim or spi)")
    live = None
    if view is not None:
        if view not in ("view", "serve"):
            raise ImupipeError(f"unknown view {view!r} (view or serve)")
        from imupipe.report.rerun_live import open_live_view

        frame_source = live = open_live_view(frame_source, view, view_port)
    n_frames = max(1, math.floor(seconds * frame_source.config.output_rate_hz + 0.5))
    try:
        with (
            StageProgress(quiet=not progress) as bars,
            bars.stage("record", n_frames, "frames") as adv,
        ):
            summary = _run_recorder(
                Path(path),
                frame_source,
                n_frames,
                realtime=realtime or source == "spi",
                progress=adv,
            )
    finally:
        if live is not None:
            live.finish()
    if truth is not None:
        write_truth(Path(truth), frame_source.truth())
    return summary
