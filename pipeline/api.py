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
from imupipe.record.recorder import RecordSummary, parse_duration, write_truth
from imupipe.record.recorder import record as _run_recorder

if TYPE_CHECKING:
    from imupipe.fleet.run import FleetResult


def default_out_dir(path: str | Path) -> Path:
    """Where ``analyze`` writes when no ``out`` is given: ``FILE.imupipe`` beside the input."""
    return Path(path).with_suffix(".imupipe")


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
        out: output folder (default :func:`default_out_dir`).
        progress: show progress bars on a terminal.
        **options: fields of :class:`imupipe.analysis.analyze.AnalyzeOptions` (``topic``,
            ``taus_per_decade``, ``gaps``, ``loop``, ``rrd``, ``figures``,
            ``memory_budget_bytes``).

    Returns:
        The :class:`AnalysisResult`: SI values per axis; ``to_dict()`` is ``report.json``,
        ``to_polars()`` the Allan curves.

    Raises:
        ImupipeError: bad input or options, stated in one sentence.
    """
    opts = analyze_options(**options)
    out_dir = Path(out) if out is not None else default_out_dir(path)
    with StageProgress(quiet=not progress) as bars:
        return _run_analysis(Path(path), out_dir, opts, bars)


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
    serial: int = 0,
    realtime: bool = False,
    progress: bool = False,
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
        realtime: pace the simulator in real time (a real sensor always is).

    Raises:
        ImupipeError: bad options or a device that does not answer as an ADIS16364.
    """
    from imupipe.device.adis16364 import config_for_rate

    seconds = parse_duration(str(duration))
    config = config_for_rate(rate_hz, source=source, serial_number=serial)
    if source == "sim":
        from imupipe.record.scenario import load_scenario
        from imupipe.record.simulator import VirtualADIS16364

        frame_source = VirtualADIS16364(
            config, load_scenario(Path(scenario)) if scenario else None, seed=seed
        )
    elif source == "spi":
        if scenario or truth:
            raise ImupipeError("--scenario and --truth apply to the simulator only (--source sim)")
        from imupipe.record.spi import open_spi_source

        frame_source = open_spi_source(device, config)
    else:
        raise ImupipeError(f"unknown source {source!r} (sim or spi)")
    n_frames = max(1, math.floor(seconds * frame_source.config.output_rate_hz + 0.5))
    with StageProgress(quiet=not progress) as bars, bars.stage("record", n_frames, "frames") as adv:
        summary = _run_recorder(
            Path(path), frame_source, n_frames, realtime=realtime or source == "spi", progress=adv
        )
    if truth is not None:
        write_truth(Path(truth), frame_source.truth())
    return summary
