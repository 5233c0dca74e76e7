"""imupipe.stats.robust (exact O(n) histogram selection, no copies) equals numpy bit for bit; each
test runs on both paths: numpy's for a short series, the selection for a long one (forced here by
``NUMPY_MAX``)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from scipy import ndimage

from imupipe import jit
from imupipe.stats import robust
from imupipe.stats.robust import (
    abs_quantile,
    mad,
    median,
    median_positive,
    row_medians,
    running_median,
)

RNG = np.random.default_rng(5)
CASES = {
    "odd": RNG.standard_normal(10001),
    "even": RNG.standard_normal(10000),
    "tiny": np.array([3.0, 1.0]),
    "quantised": np.round(RNG.standard_normal(200_000) * 10) * 0.05,
    "two_levels": np.repeat([0.0, 1.0], 50_000),
    "heavy_tail": RNG.standard_cauchy(100_001),
    "subnormal": np.tile([5e-324, 0.0, 1e-320], 3000),
    "strided": RNG.standard_normal((30_000, 3))[:, 1],
    "nan": np.array([1.0, np.nan, 2.0]),
    "inf": np.array([np.inf, 1.0, 2.0, 3.0]),
}
FINITE = [k for k in CASES if k not in ("nan", "inf")]
DEFAULT_NUMPY_MAX = robust.NUMPY_MAX  # before any test's monkeypatch


@pytest.fixture(autouse=True, params=["numpy", "selection"])
def path(request, monkeypatch) -> str:
    """Every test on numpy's path and on the histogram selection's."""
    if request.param == "selection":
        monkeypatch.setattr(robust, "NUMPY_MAX", -1)
    return request.param


@pytest.mark.parametrize("name", CASES)
def test_median_equals_numpy(name):
    x = CASES[name]
    assert median(x) == pytest.approx(np.median(x), rel=0, abs=0, nan_ok=True)


@pytest.mark.parametrize("name", FINITE)
def test_mad_equals_numpy(name):
    x = CASES[name]
    assert mad(x) == np.median(np.abs(x - np.median(x)))
    assert mad(x, 0.25) == np.median(np.abs(x - 0.25))


@pytest.mark.parametrize("name", FINITE)
def test_median_positive_equals_numpy(name):
    x = CASES[name]
    assert median_positive(x) == np.median(x[x > 0])


def test_float32_input_matches_float64_of_the_same_values():
    """The conditioning stage hands float32 stamp steps: the selection is exact on them too."""
    x = (RNG.standard_normal(50_001) * 1e-4 + 1e-3).astype(np.float32)
    assert median(x) == np.median(x.astype(np.float64))
    assert median_positive(x) == np.median(x[x > 0].astype(np.float64))
    assert mad(x) == np.median(np.abs(x.astype(np.float64) - np.median(x.astype(np.float64))))


def test_median_positive_without_positive_values_is_nan():
    assert np.isnan(median_positive(np.array([0.0, -1.0])))


@pytest.mark.parametrize("name", FINITE)
def test_statistics_of_differences_equal_numpy(name):
    x = CASES[name]
    d = np.diff(x)
    assert median(x, differences=True) == np.median(d)
    assert median_positive(x, differences=True) == pytest.approx(
        np.median(d[d > 0]) if (d > 0).any() else np.nan, rel=0, abs=0, nan_ok=True
    )
    assert mad(x, differences=True) == np.median(np.abs(d - np.median(d)))


@pytest.mark.parametrize("name", CASES)
@pytest.mark.parametrize("parts", [2, 3, 7])
def test_passes_over_several_parts_give_numpys_values(name, parts, monkeypatch):
    """A long record's passes read contiguous parts on several threads and add up their
    histograms: the same order statistics as numpy whatever the parts (ties, runs of equal
    values and a bin gathered from every part included)."""
    monkeypatch.setattr(jit, "PART_MIN", 1)
    monkeypatch.setattr(jit, "cores_here", lambda: parts)
    x = CASES[name]
    assert jit.parts(x.size) == min(parts, x.size)
    assert median(x) == pytest.approx(np.median(x), rel=0, abs=0, nan_ok=True)
    if name in FINITE:
        assert mad(x) == np.median(np.abs(x - np.median(x)))
        d = np.diff(x)
        assert mad(x, differences=True) == np.median(np.abs(d - np.median(d)))
        assert median_positive(x) == np.median(x[x > 0])
        assert abs_quantile(x, 0.999) == np.quantile(np.abs(x), 0.999, method="higher")


@pytest.mark.parametrize(
    ("rows", "cols", "half"),
    [(5000, 3, 16), (5000, 1, 0), (40, 2, 16), (1, 4, 3), (33, 2, 16), (34, 1, 16)],
)
@pytest.mark.parametrize("values", ["normal", "quantised"])
def test_running_median_equals_scipys_median_filter(rows, cols, half, values):
    x = RNG.standard_normal((rows, cols))
    if values == "quantised":  # many ties, and runs of equal values
        x = np.round(x * 2) / 2
    expected = ndimage.median_filter(x, size=(2 * half + 1, 1), mode="nearest")
    got = running_median(x, half)
    assert got.shape == x.shape and np.array_equal(got, expected)


@pytest.mark.parametrize("gap", [1, 2, 5, 16])
@pytest.mark.parametrize("values", ["normal", "quantised"])
def test_running_median_with_a_gap_is_the_median_of_the_rows_outside_it(gap, values):
    x = RNG.standard_normal((3000, 2))
    if values == "quantised":
        x = np.round(x * 2) / 2
    padded = np.pad(x, ((16, 16), (0, 0)), mode="edge")  # the edge rows repeated
    windows = np.lib.stride_tricks.sliding_window_view(padded, 33, axis=0)
    expected = np.median(windows[:, :, np.abs(np.arange(-16, 17)) >= gap], axis=2)
    assert np.array_equal(running_median(x, 16, gap), expected)


def test_running_median_with_a_gap_never_sees_the_centre_rows():
    x = np.zeros((41, 1))
    x[19:22] = 100.0  # row 20 and its two neighbours
    assert running_median(x, 5, 2)[20, 0] == 0.0  # rows 15-18 and 22-25 only
    assert running_median(x, 1, 1)[20, 0] == 100.0  # rows 19 and 21: only row 20 left out
    assert running_median(x, 1, 0)[20, 0] == 100.0
    x[17:19] = 40.0  # rows 17, 18, 22, 23: 40, 40, 0, 0, an even count: the middle two's mean
    assert running_median(x, 3, 2)[20, 0] == 20.0
    x[40] = 7.0  # the last row, repeated beyond the end: rows 37-38 and 42-43 -> 0, 0, 7, 7
    assert running_median(x, 3, 2)[40, 0] == 3.5


def test_running_median_refuses_a_gap_wider_than_its_window():
    with pytest.raises(ValueError, match="gap"):
        running_median(np.zeros((10, 1)), 3, 4)


def test_running_median_follows_a_level_step_and_ignores_a_spike():
    x = np.concatenate([np.zeros(50), np.full(50, 4.0)])[:, None]
    x[20] = 100.0
    level = running_median(x, 3)[:, 0]
    assert level[20] == 0.0 and level[46] == 0.0 and level[50] == 4.0 and level[53] == 4.0


def test_running_median_refuses_non_finite_values():
    with pytest.raises(ValueError, match="finite"):
        running_median(np.array([[1.0], [np.nan], [2.0]]), 1)


@pytest.mark.parametrize("width", [1, 2, 7, 25, 50])
def test_row_medians_equal_numpys_bit_for_bit(width):
    """Odd and even rows (the mean of the two middle values), quantised values with ties, a
    row with NaN (NaN, as numpy) and rows with ±inf."""
    rng = np.random.default_rng(width)
    rows = np.round(rng.standard_normal((400, width)) * 3) / 7
    rows[0, width // 2] = np.nan
    rows[1, 0] = np.inf
    rows[2, -1] = -np.inf
    got = row_medians(rows)
    assert np.array_equal(got, np.median(rows, axis=1), equal_nan=True)
    assert np.isnan(got[0]) and np.isnan(got).sum() == 1


def test_a_short_series_is_ranked_by_numpy_a_long_one_by_the_selection(monkeypatch):
    """Up to NUMPY_MAX values numpy ranks them (the selection's kernels never compile on a short
    record's first run); beyond, the histogram selection, which copies nothing."""
    monkeypatch.setattr(robust, "NUMPY_MAX", 100)
    passes: list[int] = []
    extent = robust._extent
    monkeypatch.setattr(robust, "_extent", lambda x, *a: passes.append(len(x)) or extent(x, *a))
    x = RNG.standard_normal(101)
    short, d = x[:100], np.diff(x[:100])
    assert median(short) == np.median(short)
    assert abs_quantile(short, 0.5) == np.quantile(np.abs(short), 0.5, method="higher")
    assert mad(short, differences=True) == np.median(np.abs(d - np.median(d)))
    assert passes == []  # 100 values: numpy's
    assert median(x) == np.median(x)
    assert abs_quantile(x, 0.5) == np.quantile(np.abs(x), 0.5, method="higher")
    assert passes == [101, 101]


@pytest.mark.parametrize(("half", "gap", "width"), [(16, 0, 33), (16, 2, 30), (3, 3, 2)])
def test_the_running_median_takes_numpys_path_up_to_numpy_max_window_values(
    half, gap, width, monkeypatch
):
    """Rows × columns × the window's width values at most NUMPY_MAX: numpy's sliding windows
    (2 half + 1 rows wide, or 2 (half − gap + 1) without the centre's); one more: the kernel."""
    taken: list[str] = []
    for name in ("_numpy_running_median", "_kernel_running_median"):
        real = getattr(robust, name)
        monkeypatch.setattr(
            robust, name, lambda x, h, g, real=real, name=name: taken.append(name) or real(x, h, g)
        )
    x = RNG.standard_normal((22, 1))
    expected = robust._kernel_running_median(kernel_input_2d(x[:21]), half, gap)
    taken.clear()
    monkeypatch.setattr(robust, "NUMPY_MAX", 21 * width)  # 21 rows exactly: numpy's
    assert np.array_equal(running_median(x[:21], half, gap), expected)
    running_median(x, half, gap)
    monkeypatch.setattr(robust, "NUMPY_MAX", 21 * width - 1)  # one value short: the kernel's
    running_median(x[:21], half, gap)
    running_median(x[:20], half, gap)
    numpy, kernel = "_numpy_running_median", "_kernel_running_median"
    assert taken == [numpy, kernel, kernel, numpy]


def kernel_input_2d(x: np.ndarray) -> np.ndarray:
    return jit.kernel_input(x, np.float64)


def test_the_order_statistics_take_numpys_path_up_to_numpy_max_values(monkeypatch):
    monkeypatch.setattr(robust, "NUMPY_MAX", 50)
    passes: list[int] = []
    extent = robust._extent
    monkeypatch.setattr(robust, "_extent", lambda x, *a: passes.append(len(x)) or extent(x, *a))
    x = RNG.standard_normal(51)
    median(x[:50]), median(x[:49]), abs_quantile(x[:50], 0.9), abs_quantile(x[:49], 0.9)
    assert passes == []
    median(x), abs_quantile(x, 0.9)
    assert passes == [51, 51]


def test_numpy_max_keeps_a_real_unit_on_numpy_and_12_h_on_the_selection():
    """A real 2.8 h ADIS16405 unit (10⁶ samples) and a 1 h / 100 Hz fleet unit take numpy's
    path; 12 h at 100 Hz (4.32 M samples: 35 MB a copy) the selection, which copies nothing."""
    assert 1_000_000 <= DEFAULT_NUMPY_MAX < 4_320_000


def test_a_negative_gap_is_refused():
    with pytest.raises(ValueError, match="0 <= gap <= half"):
        running_median(np.zeros((5, 1)), 3, -1)


@pytest.mark.filterwarnings("error")  # numpy's "Mean of empty slice" is not for the user
def test_one_value_and_none(path):
    assert abs_quantile(np.array([2.0]), 0.5) == 2.0
    assert abs_quantile(np.array([-2.0]), 0.999) == 2.0
    assert median(np.array([3.0])) == 3.0
    assert np.isnan(abs_quantile(np.array([]), 0.5))
    assert np.isnan(mad(np.array([])))


def test_a_single_row_running_median_is_the_row(path):
    """The edge rows repeated: a single row's window holds only it (the output is written,
    not left as whatever memory np.empty handed out)."""
    for _ in range(3):
        np.full((1, 4), np.nan)  # a freed block of NaN for np.empty to hand out again
        x = np.array([[1.0, -2.0, 3.5, 0.0]])
        assert np.array_equal(running_median(x, 3), x)
        assert np.array_equal(running_median(x, 3, 1), x)


def test_compile_long_record_kernels_compiles_every_type_a_long_record_passes():
    """In a fresh interpreter: after it, each selection kernel holds a float64 and a float32
    specialisation (read-only C arrays, what kernel_input hands over), the running median one."""
    probe = (
        "import json; from imupipe.stats import robust as r; r.compile_long_record_kernels(); "
        "print(json.dumps({k.__name__: sorted(str(s[0]) for s in k.signatures) for k in "
        "(r._extent_parts, r._histogram_parts, r._gather_parts, r._rank_bin, r._running_median)}))"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    sigs = json.loads(done.stdout.splitlines()[-1])
    ro = "readonly array({}, {}d, C)"
    assert (
        sigs["_extent_parts"]
        == sigs["_histogram_parts"]
        == sorted([ro.format("float32", 1), ro.format("float64", 1)])
    )
    assert sigs["_gather_parts"] == sigs["_extent_parts"]
    assert sigs["_rank_bin"] == ["array(int64, 1d, C)"]
    assert sigs["_running_median"] == [ro.format("float64", 2)]


@pytest.mark.parametrize("p", [0.1, 0.25, 0.5, 0.9])
@pytest.mark.parametrize("name", FINITE)
def test_abs_quantile_equals_numpys_at_any_level(name, p):
    """Of |x|, zeros included (two_levels: a quarter of the values)."""
    x = CASES[name]
    assert abs_quantile(x, p) == np.quantile(np.abs(x), p, method="higher")


def test_the_running_median_of_no_rows_and_of_a_1d_series():
    assert running_median(np.zeros((0, 3)), 4).shape == (0, 3)
    assert running_median(np.zeros((0, 3)), 4, 2).shape == (0, 3)
    with pytest.raises(ValueError, match="a finite 2-D array"):
        running_median(np.zeros(5), 2)
