"""The public Python API: ``import imupipe`` (never ``pipeline``), analyze/record, the result's
``to_dict()`` (report.json) and ``to_polars()`` (allan.parquet's contract)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import polars as pl
import pytest

import imupipe
from imupipe.analysis.results import ALLAN_SCHEMA
from imupipe.errors import ImupipeError

SAMPLE = Path(__file__).resolve().parents[1] / "sample_logs" / "adis16364_default_5min.mcap"


def test_import_name_is_imupipe_not_pipeline(tmp_path: Path) -> None:
    code = (
        "import importlib.util, imupipe;"
        "print(importlib.util.find_spec('pipeline') is None, sorted(imupipe.__all__))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, check=True
    ).stdout.split(maxsplit=1)
    assert out[0] == "True"
    assert out[1].strip() == str(
        [
            "AnalysisResult",
            "ImupipeError",
            "RecordSummary",
            "__version__",
            "analyze",
            "analyze_fleet",
            "record",
        ]
    )


def test_readme_example_records_and_analyses(tmp_path: Path) -> None:
    # the README's five lines, on a short recording
    summary = imupipe.record(tmp_path / "run.mcap", duration="90s", rate_hz=100, seed=3)
    result = imupipe.analyze(tmp_path / "run.mcap", rrd=False, figures=False, loop=False)
    n = result.axes["gyro_x"].terms.random_walk
    curves = result.to_polars()
    assert (summary.frames, summary.requested, summary.rate_hz) == (9000, 9000, 100.0)
    assert summary.rate_method == "host_poll"
    # the default output folder is FILE.imupipe beside the input, holding the same document
    written = json.loads((tmp_path / "run.imupipe" / "report.json").read_text())
    assert written == result.to_dict()
    assert written["axes"]["gyro_x"]["ieee952"]["random_walk"]["value"] == n.value
    # by default the whole recording, from its first frame
    assert written["input"]["window_s"] == [0.0, None] and written["input"]["frames"] == 9000
    # the curve is published up to T/4 (22.5 s; the fit reads it to T/2)
    assert result.axes["gyro_x"].curve.tau_s[-1] == pytest.approx(19.95, abs=0.01)
    assert n.unit == "rad/s/sqrt(Hz)"
    # the paper's N of 0.05 °/√s is 8.73e-4 rad/s/√Hz; 90 s gives it within ~10 %
    assert n.value == pytest.approx(0.05 * 3.141592653589793 / 180, rel=0.1)
    assert curves.schema == ALLAN_SCHEMA
    assert curves.equals(pl.read_parquet(tmp_path / "run.imupipe" / "allan.parquet"))
    assert sorted(curves["axis"].unique()) == sorted(result.axes)


def test_unknown_analyze_option_is_an_imupipe_error(tmp_path: Path) -> None:
    with pytest.raises(ImupipeError, match=r"unknown analyze option\(s\) \['rdd'\]"):
        imupipe.analyze(SAMPLE, tmp_path, rdd=False)


def test_record_refuses_truth_for_a_real_sensor(tmp_path: Path) -> None:
    with pytest.raises(ImupipeError, match="simulator only"):
        imupipe.record(tmp_path / "x.mcap", source="spi", truth=tmp_path / "t.json")


SUBPACKAGES = ("device", "io", "recording", "stats", "model", "analysis", "report", "testing")


@pytest.mark.parametrize("name", SUBPACKAGES)
def test_subpackage_exports_resolve_and_shadow_no_module(name: str) -> None:
    import importlib
    import pkgutil

    package = importlib.import_module(f"imupipe.{name}")
    modules = {m.name for m in pkgutil.iter_modules(package.__path__)}
    assert package.__all__, f"imupipe.{name} names no public API"
    for public in package.__all__:
        assert public not in modules, f"imupipe.{name}.{public} hides the module of that name"
        assert getattr(package, public) is not None
    for module in modules:  # a submodule stays reachable as an attribute after the imports
        assert importlib.import_module(f"imupipe.{name}.{module}").__name__.endswith(module)
        assert type(getattr(package, module)).__name__ == "module"


def test_the_readme_calls_by_keyword_work(tmp_path: Path) -> None:
    """As the README calls them: ``out=`` and the options by keyword (``path=`` too)."""
    summary = imupipe.record(path=tmp_path / "k.mcap", duration="20s", seed=1)
    assert summary.frames == 2000
    result = imupipe.analyze(
        path=tmp_path / "k.mcap", out=tmp_path / "k_out", rrd=False, figures=False, loop=False
    )
    assert (tmp_path / "k_out" / "report.json").is_file() and result.input.frames == 2000


def test_the_default_output_folder_of_every_kind_of_name(tmp_path: Path, monkeypatch) -> None:
    """``run.mcap`` → ``run.imupipe`` (relative stays relative); any other name keeps its
    suffix (``bag.v2`` → ``bag.v2.imupipe``); ``.`` and ``..`` are their folders' names."""
    from imupipe.api import default_out_dir

    here = tmp_path / "a" / "b"
    here.mkdir(parents=True)
    monkeypatch.chdir(here)
    assert default_out_dir("run.mcap") == Path("run.imupipe")
    assert default_out_dir("bag.v2") == Path("bag.v2.imupipe")
    assert default_out_dir(".") == tmp_path.resolve() / "a" / "b.imupipe"
    assert default_out_dir("..") == tmp_path.resolve() / "a.imupipe"
