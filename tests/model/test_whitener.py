"""The loop's exact GLS (:class:`effects.Whitener`) on a series with masked blocks (gaps).

The time-domain tests (steps, warm-up, couplings, ramp, the time-domain error) read the
whitened first differences of coarse block means.  Under the gap policy "mask" the blocks
holding a gap's fill are left out and the differences are taken between consecutive observed
blocks; their covariance must then be exact, or a long gap's noise-free fill reads as a bias
step (measured before: false steps and warm-ups on 4 of 8 clean 4 h recordings with a 1 h gap).

The covariance is checked against an independent closed form: white rate noise N² gives
independent block means of variance N²/D; a rate random walk W (variance K² t) gives block
means of covariance K²·(min(i, j) + 1/2)·D between blocks i ≠ j and K²·(i + 1/3)·D within one
(E[min(s, t)] for s, t uniform over the blocks).
"""

from __future__ import annotations

import numpy as np
import pytest

from imupipe.model import effects, loop
from imupipe.model.loop import AxisSignals
from imupipe.stats.allan import allan_curves

N2, K2 = 1e-6, 1e-9  # white (rad/s)²/Hz, rate random walk (rad/s)²/s
N_D, DT = 3000, 0.5  # block means of 0.5 s: 1000 coarse blocks of 1.5 s


def _gapped() -> np.ndarray:
    excluded = np.zeros(N_D, bool)
    excluded[700:1300] = True  # a 300 s gap
    excluded[2001] = True  # one block
    return excluded


def _block_mean_covariance(n: int, span: float) -> np.ndarray:
    """Covariance of the block means of white noise N² plus a random walk K² t (closed form)."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    walk = np.where(i == j, i * span + span / 3, (np.minimum(i, j) + 0.5) * span)
    return np.where(i == j, N2 / span, 0.0) + K2 * walk


def test_differences_across_a_gap_are_whitened_exactly():
    whiten = effects.Whitener(effects.NoisePsd(N2, 0.0, np.inf, K2), N_D, DT, _gapped())
    blocks = whiten.blocks
    assert whiten.factor == 3 and len(blocks) == 1000 - 200 - 1 - 1  # 200 + 1 blocks left out
    assert blocks[232] == 232 and blocks[233] == 434  # the gap: coarse blocks 233-433
    rows = np.arange(len(blocks) - 1)
    between = np.zeros((len(blocks) - 1, N_D // whiten.factor))
    between[rows, blocks[:-1]], between[rows, blocks[1:]] = -1.0, 1.0
    cov = between @ _block_mean_covariance(N_D // whiten.factor, whiten.span) @ between.T
    white = whiten.inv_chol @ cov @ whiten.inv_chol.T
    assert np.abs(white - np.eye(len(white))).max() < 1e-5
    # the ramp's whitened differences: each difference spans its blocks' distance
    assert whiten.drift == pytest.approx(whiten.inv_chol @ np.diff(blocks), rel=1e-12)
    assert np.diff(blocks).max() == 202
    # the time-domain fit's ln det Σ: that of the exact covariance (to its 1e-5 whitening)
    assert whiten.log_det == pytest.approx(np.linalg.slogdet(cov)[1], abs=1e-3)  # of ~-11292
    plain = effects.Whitener(effects.NoisePsd(N2, 0.0, np.inf, K2), N_D, DT)  # Levinson's
    every = np.diff(np.eye(N_D // whiten.factor), axis=0)
    cov = every @ _block_mean_covariance(N_D // whiten.factor, whiten.span) @ every.T
    assert plain.log_det == pytest.approx(np.linalg.slogdet(cov)[1], abs=1e-3)


def test_a_masked_whitener_inverts_its_cholesky_factor_only_when_read(monkeypatch):
    """Whitening solves with L; L⁻¹ (an m³/3 triangular inverse, ~11 ms at 1023 blocks) is
    formed once, when the bias-step scan reads its columns: 11 of the 136 whiteners a real
    ADIS16405 unit's loop builds.  The solve and the inverse agree to rounding."""
    inversions = []
    trtri = effects._DTRTRI
    monkeypatch.setattr(effects, "_DTRTRI", lambda *a: inversions.append(1) or trtri(*a))
    whiten = effects.Whitener(effects.NoisePsd(N2, 0.0, np.inf, K2), N_D, DT, _gapped())
    y = 1e-3 * np.random.default_rng(5).standard_normal((N_D, 2))
    whitened, log_det = whiten(y), whiten.log_det
    assert inversions == []
    d = np.diff(whiten.coarse(y)[whiten.blocks], axis=0)
    assert whitened == pytest.approx(
        whiten.inv_chol @ d, rel=1e-9, abs=1e-12 * np.abs(whitened).max()
    )
    assert whiten.inv_chol is whiten.inv_chol and inversions == [1]
    assert not whiten.inv_chol.flags.writeable
    assert log_det == pytest.approx(-2 * np.sum(np.log(np.diag(whiten.inv_chol))), rel=1e-12)


def test_the_fill_of_a_gap_is_never_read():
    whiten = effects.Whitener(effects.NoisePsd(N2, 0.0, np.inf, K2), N_D, DT, _gapped())
    y = 1e-3 * np.random.default_rng(2).standard_normal(N_D)
    filled = y.copy()
    filled[_gapped()] = 5.0  # any fill, however far from the level
    assert np.array_equal(whiten(y), whiten(filled))


def test_without_a_masked_block_the_levinson_whitener_is_unchanged(monkeypatch):
    """Gap-free series keep the O(m²) Levinson recursion: no m × m Cholesky (O(m³), ~10x
    slower at 1024 blocks) is ever factorised for them."""
    psd = effects.NoisePsd(N2, 2e-7, 0.5, K2)

    def no_cholesky(*args, **kwargs):
        raise AssertionError("the gap-free whitener factorised the full covariance")

    monkeypatch.setattr(effects, "_cholesky", no_cholesky)
    plain = effects.Whitener(psd, N_D, DT)
    unmasked = effects.Whitener(psd, N_D, DT, np.zeros(N_D, bool))
    assert np.array_equal(plain.inv_chol, unmasked.inv_chol)
    assert np.array_equal(plain.blocks, np.arange(1000))


def test_the_masked_covariance_is_factorised_as_scipy_does_without_holding_the_gil():
    """``effects._cholesky`` calls scipy's LAPACK dpotrf through ctypes (which releases the GIL;
    ``scipy.linalg.cholesky`` holds it): the same factor, bit for bit, on a gapped record's
    covariance (symmetric to the bit); a matrix that is not positive definite is refused."""
    gamma = 1e-6 * np.exp(-np.arange(1000) / 40.0)
    gamma[0] *= 3.0
    blocks = effects.observed_blocks(_gapped(), 1000, 3)
    cov = effects._summed_covariance(gamma, blocks)
    assert np.array_equal(cov, cov.T)
    chol = effects._cholesky(cov.copy())
    assert np.array_equal(chol, effects.linalg.cholesky(cov, lower=True))
    assert chol[0, 1] == 0.0 and chol[1, 0] != 0.0
    with pytest.raises(effects.linalg.LinAlgError, match="not positive definite"):
        effects._cholesky(-cov)


def test_the_masked_solve_and_inverse_are_scipys_without_holding_the_gil():
    """Whitening with L and forming L⁻¹ call LAPACK dtrtrs and dtrtri through ctypes too
    (scipy's ``solve_triangular`` and ``lapack.dtrtri`` hold the GIL: 1.5 s of an analysis of
    a real unit, session 48): the same bits as scipy's for one column and several, the caller's
    array left as it was; a zero pivot is refused."""
    whiten = effects.Whitener(effects.NoisePsd(N2, 0.0, np.inf, K2), N_D, DT, _gapped())
    m = len(whiten.blocks) - 1
    chol = whiten._chol
    d = np.random.default_rng(3).standard_normal((m, 3))
    kept = d.copy()
    for columns in (d[:, 0], d, d[:, :0]):
        expected = effects.linalg.solve_triangular(chol, columns, lower=True, check_finite=False)
        assert np.array_equal(whiten.whitened(columns), expected)
    assert np.array_equal(d, kept)
    for wrong in (d[:-1], np.vstack([d, d[:1]])):  # scipy refuses these too; LAPACK would not
        with pytest.raises(ValueError, match=f"{len(wrong)} differences for a whitener of {m}"):
            whiten.whitened(wrong)
    assert np.array_equal(whiten.inv_chol, effects.linalg.lapack.dtrtri(chol, lower=1)[0])
    singular = effects.Whitener.__new__(effects.Whitener)
    singular._chol = np.asfortranarray(np.diag([1.0, 0.0, 2.0]))
    with pytest.raises(effects.linalg.LinAlgError, match="dtrtrs 2"):
        singular.whitened(np.ones(3))
    with pytest.raises(effects.linalg.LinAlgError, match="dtrtri 2"):
        singular.inv_chol  # noqa: B018 (a cached property: reading it inverts)


def test_a_mask_leaving_too_few_blocks_is_not_applied():
    excluded = np.ones(N_D, bool)
    excluded[: 3 * (effects.MIN_OBSERVED_BLOCKS - 1)] = False  # 15 whole coarse blocks
    whiten = effects.Whitener(effects.NoisePsd(N2, 0.0, np.inf, 0.0), N_D, DT, excluded)
    assert len(whiten.blocks) == 1000


def _white_with_gap(fill: float, step: float, seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """White block means (σ 1) with a 300-block gap at 1200-1500 filled with ``fill`` and a
    level ``step`` from the gap on."""
    y = np.random.default_rng(seed).standard_normal(N_D)
    excluded = np.zeros(N_D, bool)
    excluded[1200:1500] = True
    y[1200:] += step
    y[excluded] = fill
    return y, excluded


def test_a_gap_filled_off_the_level_makes_no_step():
    """The fill 3 σ off the level is a plain step to a GLS that reads it (p ~ 1e-60); left
    out, no change point is significant."""
    y, excluded = _white_with_gap(fill=3.0, step=0.0)
    psd = effects.NoisePsd(DT, 0.0, np.inf, 0.0)  # unit-variance block means
    read = effects.step_candidate(y, DT, effects.Whitener(psd, N_D, DT))
    left_out = effects.step_candidate(y, DT, effects.Whitener(psd, N_D, DT, excluded))
    assert read.p_value < 1e-20
    assert left_out.p_value > 0.01


def test_a_step_across_a_gap_is_found_where_the_data_resume():
    """A level change across the gap is still seen (the difference spanning it counts); where
    in the gap it happened cannot be told, so the step is placed at the first observed coarse
    block after the gap (1500 blocks of 0.5 s = 750 s; here the noise puts the best change
    point there, not a block or two before the gap) and its interval covers the whole gap,
    600-750 s, give or take the grid's block either side."""
    y, excluded = _white_with_gap(fill=0.0, step=1.0, seed=0)
    psd = effects.NoisePsd(DT, 0.0, np.inf, 0.0)
    step = effects.step_candidate(y, DT, effects.Whitener(psd, N_D, DT, excluded))
    assert step.p_value < 1e-20
    assert step.params["time_s"] == 750.0
    assert step.intervals["time_s"] == [597.0, 754.5]
    assert step.params["size"] == pytest.approx(1.0, abs=0.05)


def test_a_trace_of_fill_keeps_the_block_and_the_levinson_whitener():
    """A lost message fills a trace of a coarse block: up to 1 % of it, the block is read
    (and the whitener is the gap-free one, bit for bit); beyond, it is left out."""
    psd = effects.NoisePsd(N2, 0.0, np.inf, K2)
    trace = np.zeros(N_D)
    trace[1500] = 0.03  # 3 % of one 0.5 s block: 1 % of its 1.5 s coarse block
    kept = effects.Whitener(psd, N_D, DT, trace)
    assert np.array_equal(kept.inv_chol, effects.Whitener(psd, N_D, DT).inv_chol)
    trace[1501] = 0.001  # a little more: the coarse block (500) is left out
    assert 500 not in effects.Whitener(psd, N_D, DT, trace).blocks


def test_an_axis_builds_the_whitener_of_a_model_once():
    """The loop asks for the whitener of a round's model again a round later
    (:meth:`loop._Axis.whitener`): an equal PSD gives the one already built (with blocks left
    out, an O(m³) Cholesky), read-only and equal to a fresh one; another PSD its own; the
    oldest is dropped beyond :data:`loop.WHITENERS_KEPT`.  The axis' time-domain fit is
    :func:`loop.time_domain_fit`'s."""
    y = 1e-3 * np.random.default_rng(3).standard_normal(60_000)
    excluded = np.zeros(y.size, bool)
    excluded[20_000:26_000] = True
    signals = AxisSignals("gyro_x", "gyro", y, 0.01, None, None, excluded=excluded)
    ax = loop._Axis(signals, allan_curves(y, 0.01)[0])
    psd = effects.NoisePsd(N2, 0.0, np.inf, K2)
    first = ax.whitener(psd)
    assert ax.whitener(effects.NoisePsd(N2, 0.0, np.inf, K2)) is first
    fresh = effects.Whitener(psd, len(ax.y_d), ax.dt, ax.masked_d)
    assert np.array_equal(first.inv_chol, fresh.inv_chol) and len(first.blocks) < len(ax.y_d)
    assert np.array_equal(first.blocks, fresh.blocks)
    assert not (first.inv_chol.flags.writeable or first.drift.flags.writeable)
    louder = [ax.whitener(effects.NoisePsd(k * N2, 0.0, np.inf, K2)) for k in range(2, 6)]
    assert louder[0] is not first and len({id(w) for w in louder}) == loop.WHITENERS_KEPT
    assert ax.whitener(psd) is not first  # dropped: the oldest of five
    assert ax.whitener(effects.NoisePsd(5 * N2, 0.0, np.inf, K2)) is louder[-1]
    state = loop._State(ax.avar, ax.y_d.copy(), None)
    fit = state.fit(ax)
    assert ax.time_fit(fit, {}, ax.y_d) == loop.time_domain_fit(fit, {}, ax.y_d, ax.dt, ax.masked_d)


def test_an_axis_keeps_a_spectrum_while_its_series_is_the_same_object():
    """:meth:`loop._Axis.spectral` computes once per key while the series (and its correction)
    are the very same objects: an equal copy, or another correction, computes again; the oldest
    of more than :data:`loop.SPECTRA_KEPT` keys is dropped."""
    y = np.random.default_rng(4).standard_normal(60_000)
    ax = loop._Axis(AxisSignals("gyro_x", "gyro", y, 0.01, None, None), allan_curves(y, 0.01)[0])
    calls: list[str] = []

    def compute(tag: str):
        return lambda: calls.append(tag) or {"tag": tag}

    first = ax.spectral(("line", 0.5), (y, None), compute("a"))
    assert ax.spectral(("line", 0.5), (y, None), compute("b")) is first and calls == ["a"]
    assert ax.spectral(("line", 0.5), (y.copy(), None), compute("c"))["tag"] == "c"
    fix = object()
    assert ax.spectral(("line", 0.5), (y, fix), compute("d"))["tag"] == "d"
    assert ax.spectral(("line", 0.5), (y, fix), compute("e"))["tag"] == "d"
    for k in range(loop.SPECTRA_KEPT):
        ax.spectral(("other", k), (y, None), compute(f"o{k}"))
    assert ax.spectral(("line", 0.5), (y, fix), compute("f"))["tag"] == "f"  # dropped
    assert ax.spectral(("other", 1), (y, None), compute("g"))["tag"] == "o1"
    assert calls == ["a", "c", "d", *(f"o{k}" for k in range(loop.SPECTRA_KEPT)), "f"]


Q2 = 4e-6  # quantisation Q² (rad)²: AVAR 3 Q² / τ²


@pytest.mark.parametrize("masked", [False, True], ids=["levinson", "masked"])
def test_quantisation_is_whitened_exactly_and_alone(masked: bool):
    """White phase noise e (variance Q²) makes a block mean (e_end − e_start)/D: block means of
    variance 2Q²/D² and lag-one covariance −Q²/D² (closed form, independent of the code's
    (6, −4, 1) for their differences).  With white rate noise, and alone: a model whose
    short-τ curve is all 3Q²/τ² (a quiet sensor under a vibration line above the fitted range)
    had a zero covariance and a ZeroDivisionError."""
    for white, tolerance in ((N2, 1e-5), (0.0, 1e-2)):  # alone: the unit roots' MA(2)
        psd = effects.NoisePsd(white, 0.0, np.inf, 0.0, quantization=Q2)
        whiten = effects.Whitener(psd, N_D, DT, _gapped() if masked else None)
        n, span = N_D // whiten.factor, whiten.span
        i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        means = np.where(i == j, white / span + 2 * Q2 / span**2, 0.0)
        means -= np.where(np.abs(i - j) == 1, Q2 / span**2, 0.0)
        blocks = whiten.blocks
        between = np.zeros((len(blocks) - 1, n))
        rows = np.arange(len(blocks) - 1)
        between[rows, blocks[:-1]], between[rows, blocks[1:]] = -1.0, 1.0
        cov = between @ means @ between.T
        whitened = whiten.inv_chol @ cov @ whiten.inv_chol.T
        assert np.abs(whitened - np.eye(len(whitened))).max() < tolerance


def test_a_perfect_fit_makes_a_worse_one_infinitely_worse_and_an_equal_one_no_worse():
    """The profile deviance (RSS − RSS_best)/s² when the best fit leaves no residual (s² = 0,
    a whitened series of zeros): inf above it, 0 at it, never the 0/0 NaN that made a warm-up's
    intervals NaN (with a RuntimeWarning) on a constant record with one spike."""
    perfect = effects.SpectralFit(np.zeros(1), np.zeros((1, 1)), 0.0, 0.0, 0.0)
    with np.errstate(all="raise"):
        dev = effects.profile_deviance(np.array([0.0, 2.0, 0.0]), perfect)
    assert dev.tolist() == [0.0, np.inf, 0.0]
    noisy = effects.SpectralFit(np.zeros(1), np.zeros((1, 1)), 0.0, 2.0, 10.0)
    assert effects.profile_deviance(np.array([10.0, 16.0]), noisy).tolist() == [0.0, 3.0]
