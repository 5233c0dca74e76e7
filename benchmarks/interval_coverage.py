"""Benchmark: do the IEEE 952 fit's 95 % intervals hold the truth at their nominal rate, and how
precisely can any reading of the Allan curve know B?

``coverage``: records of known noise (white rate N, flicker B; Annex C PSD), fitted as the
analysis fits (``fit_noise_terms`` on a T/2 curve); each term's interval with the fitted τ
points counted as independent and with their correlation (:mod:`imupipe.stats.avar_covariance`,
the sandwich factor); prints the share of records whose truth lies below ``lo`` / above ``hi``
(an unresolved term: its bound) and how often B is resolved.

``precision``: for a 12 h / 100 Hz record of N, B, K, the spread of the fit's N, B and K
(its sandwich variance, linearised at the truth, on the points it reads) against the best
linear unbiased estimate from every τ of the curve with their full covariance (GLS) and the
Cramér–Rao bound of any unbiased estimator from the record itself (:func:`whittle_crb`).

``k_coverage``: records of N, B and a rate random walk K whose AVAR at T/2 is ``--k-share``
times the flicker plateau (K visible at long τ), fitted as the analysis fits: K's estimate
against the truth, how often it is resolved, and how often the truth lies above the upper end
of its two-sided profile interval at several levels (nominal (1 − level)/2): as the loop's slow
effects read it (R free, the τ points counted as the fit counts them, by their evidence weights;
they are whitened with K at the upper end of its 68 % interval, ``loop.SLOW_K_LEVEL``, designed
to be below the truth on 16 % of axes) and as the report gives it (R released only where the
data ask for it, ``ieee952.release_rate_ramp``, the points' correlation in the interval: the
sandwich factor); the median K is the report's.

``gm_coverage``: records of the independent generator (``independent_generator.py``, which
shares no code with imupipe) with a Gauss–Markov effect of ``--size`` on one axis, that axis
analysed as ``imupipe analyze`` does (``axis_result``, the closed loop): how often the effect
is found, and how often its Tc's and σ's 95 % intervals hold the truth, with the spread of the
standardised errors (the error over its interval's half-width on its side, × 1.96: 1 when the
intervals are calibrated).

``panel``: for every axis of a ``loop_validation.py --jsonl`` file, the chance that an
efficient unbiased estimate of B (spread at the Cramér–Rao bound, Gaussian) lies within 15 %
of the truth, summed over the panel, against the measured count.

    python benchmarks/interval_coverage.py coverage --records 200 --samples 262144
    python benchmarks/interval_coverage.py coverage --records 40 --samples 4320000 --b 0
    python benchmarks/interval_coverage.py k_coverage --records 60 --hours 12 --n 3e-4
    python benchmarks/interval_coverage.py precision
    python benchmarks/interval_coverage.py gm_coverage --records 80 --size 10 --jobs 2
    python benchmarks/interval_coverage.py panel long_clean.jsonl
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from scipy import stats

from imupipe.model import ieee952
from imupipe.stats.allan import FIT_MIN_TERMS, allan_curves, tau_factors
from imupipe.stats.avar_covariance import lag_sums

TAU0 = 0.01
PAPER_N, PAPER_B = 0.05 * np.pi / 180, 0.008 * np.pi / 180  # the paper's gyro, SI


def rate(n: int, rng: np.random.Generator, n_white: float, b_flicker: float) -> np.ndarray:
    """White rate noise N plus flicker B (two-sided PSD B²/(2πf), synthesised 8× longer)."""
    y = n_white / np.sqrt(TAU0) * rng.standard_normal(n)
    if b_flicker:
        f = np.fft.rfftfreq(8 * n, TAU0)
        shape = np.zeros_like(f)
        shape[1:] = np.sqrt(b_flicker**2 / (2 * np.pi * f[1:]) / TAU0)
        y += np.fft.irfft(np.fft.rfft(rng.standard_normal(8 * n)) * shape, 8 * n)[:n]
    return y


def coverage(records: int, samples: int, n_white: float, b_flicker: float) -> None:
    """Misses of N's and B's intervals over ``records`` draws, both ways."""
    misses = {False: np.zeros((2, 2)), True: np.zeros((2, 2))}
    resolved = {False: 0, True: 0}
    m = tau_factors(samples, min_terms=2)
    for seed in range(records):
        curve = allan_curves(rate(samples, np.random.default_rng(seed), n_white, b_flicker),
                             TAU0, m)[0]  # fmt: skip
        for correlated in (False, True):
            terms = ieee952.fit_noise_terms(curve, "gyro", TAU0, correlated)
            for k, (term, truth) in enumerate(
                ((terms.random_walk, n_white), (terms.bias_instability, b_flicker))
            ):
                misses[correlated][k] += [truth < (term.lo or 0.0), truth > term.hi]
            resolved[correlated] += terms.bias_instability.value is not None
    for correlated in (False, True):
        (n_lo, n_hi), (b_lo, b_hi) = 100 * misses[correlated] / records
        print(
            f"{'correlated' if correlated else 'independent'} points: N misses {n_lo:.1f} % "
            f"below / {n_hi:.1f} % above; B {b_lo:.1f} % / {b_hi:.1f} %, "
            f"resolved {100 * resolved[correlated] / records:.0f} %"
        )


K_LEVELS = (0.4, 0.68, 0.9, 0.95)
"""Two-sided profile levels whose upper end ``k_coverage`` checks (0.68: the slow effects')."""


def k_coverage(
    records: int, hours: float, n_white: float, b_flicker: float, k_share: float
) -> None:
    """K's estimate and the truth above its interval's upper end, over ``records`` draws of
    white N, flicker B (:func:`rate`) and a rate random walk K (a Wiener process of variance K² t,
    AVAR K² τ / 3) with K² (T/2) / 3 = ``k_share`` × the flicker plateau (2 ln 2 / π) B²."""
    samples = int(hours * 3600 / TAU0)
    k_rrw = np.sqrt(3 * k_share * 2 * np.log(2) / np.pi * b_flicker**2 / (samples * TAU0 / 2))
    m = tau_factors(samples, min_terms=FIT_MIN_TERMS)
    j = ieee952.TERM_NAMES.index("rate_random_walk")
    ratio, released, above = [], 0, np.zeros((2, len(K_LEVELS)))
    for seed in range(records):
        rng = np.random.default_rng(seed)
        y = rate(samples, rng, n_white, b_flicker)
        y += np.cumsum(k_rrw * np.sqrt(TAU0) * rng.standard_normal(samples))
        curve = allan_curves(y, TAU0, m)[0]
        done = ieee952.fit_curve(curve)  # what fit_noise_terms reports, profiled at other levels
        fit = done.fit
        rho = ieee952.fit_correlation(fit, TAU0, np.asarray(curve.n_terms))
        ratio.append(fit.coef[j] / k_rrw**2)
        released += fit.rate_ramp_fit is None
        reported = ieee952.interval_correlation(fit, j, rho)
        for c, (read, correlation) in enumerate(((fit.with_rate_ramp, None), (fit, reported))):
            for i, level in enumerate(K_LEVELS):
                hi = read.profile_interval(done.avar, done.edf, j, level, correlation)[1]
                above[c, i] += k_rrw**2 > hi
    ratio = np.sqrt(np.array(ratio))
    print(
        f"{records} records of {hours:g} h, N {n_white:.3g}, B {b_flicker:.3g}, "
        f"K {k_rrw:.3g} (AVAR at T/2 {k_share:g} x the flicker plateau): K fitted/true "
        f"median {np.median(ratio):.2f}, resolved on {100 * np.mean(ratio > 0):.0f} %; R "
        f"released on {100 * released / records:.0f} %"
    )
    for c, how in enumerate(("R free, evidence weights", "as reported")):
        print(f"  truth above the upper end ({how}): " + ", ".join(
            f"{level:g}: {100 * above[c, i] / records:.1f} % (nominal {50 * (1 - level):.1f})"
            for i, level in enumerate(K_LEVELS)
        ))  # fmt: skip


def whittle_crb(
    n_white: float, b_flicker: float, k_rrw: float, q_angle: float, seconds: float, tau0: float
) -> np.ndarray:
    """Relative spread (σ/value) of N, B, K, Q at the Cramér–Rao bound of a record of
    ``seconds`` sampled every ``tau0`` s, from the Whittle approximation of its likelihood.

    Each periodogram ordinate at f_k = k/T (k = 1 … n/2) is S(f_k) × χ²₂/2 with the two-sided
    rate PSD S = N² + B²/(2πf) + K²/(2πf)² + Q² τ0 (2 sin(πfτ0)/τ0)² (IEEE 952 Annex C; the
    last, white angle noise differenced), so the Fisher information of θ_i = ln c_i² is
    I_ij = Σ_k d_i d_j with d_i = c_i² g_i(f_k)/S(f_k) (Whittle 1953; Percival & Walden,
    Spectral Analysis for Physical Applications, §6.6); σ(c_i)/c_i = √(I⁻¹)_ii / 2 (NaN for a
    term that is zero, left out of the model).
    """
    f = np.arange(1, int(seconds / tau0) // 2 + 1) / seconds
    w = 2 * np.pi * f
    parts = np.stack([
        np.full_like(f, n_white**2), b_flicker**2 / w, (k_rrw / w) ** 2,
        q_angle**2 * tau0 * (2 * np.sin(np.pi * f * tau0) / tau0) ** 2,
    ])  # fmt: skip
    present = np.array([n_white, b_flicker, k_rrw, q_angle]) > 0
    share = parts[present] / parts.sum(axis=0)
    spread = np.full(4, np.nan)  # a term that is absent: not estimated
    spread[present] = np.sqrt(np.diag(np.linalg.inv(share @ share.T))) / 2
    return spread


def panel(path: Path, within: float = 0.15) -> None:
    """Expected share of a validation panel's axes with B within ``within`` of the truth for
    an unbiased Gaussian estimate with the spread of the Cramér–Rao bound and with the GLS's
    (:func:`allan_spreads`), against the measured share."""
    expected = np.zeros(2)
    measured = axes = 0
    for line in path.read_text().splitlines():
        rec = json.loads(line)
        truth = rec["truth"]
        seconds, tau0 = truth["hours"] * 3600, 1 / truth["rate_hz"]
        for axis, c in truth["noise"].items():
            bound = whittle_crb(c["n"], c["b"], c["k"], c["q"], seconds, tau0)[1]
            gls = allan_spreads((c["q"], c["n"], c["b"], c["k"]), seconds, tau0)[1][2]
            expected += 2 * stats.norm.cdf(within / np.array([bound, gls])) - 1
            error = rec["b_rel_error"].get(axis)
            measured += error is not None and abs(error) <= within
            axes += 1
    print(f"B within {within:.0%} of the truth: measured {measured}/{axes} "
          f"({measured / axes:.0%}); expected at the Cramér-Rao bound (Whittle) "
          f"{expected[0]:.1f} ({expected[0] / axes:.0%}), with the GLS of every tau "
          f"{expected[1]:.1f} ({expected[1] / axes:.0%})")  # fmt: skip


def allan_spreads(
    coef: tuple[float, float, float, float], seconds: float, tau0: float
) -> tuple[np.ndarray, np.ndarray]:
    """Relative spread of Q, N, B, K (``coef``, NaN where zero) from the Allan curve of a record
    of ``seconds``: the fit's (its sandwich variance on the points it reads, linearised at the
    truth) and the GLS's (every τ with the full covariance of :mod:`imupipe.stats.avar_covariance`:
    the best linear unbiased reading of the curve)."""
    n = int(seconds / tau0)
    m = tau_factors(n, min_terms=2)
    terms, tau = n + 1 - 2 * m, m * tau0
    coef2 = np.square(coef)
    present = coef2 > 0
    i, j = np.triu_indices(len(m))
    sums = np.empty((len(m), len(m)))
    sums[i, j] = sums[j, i] = lag_sums(m[i], m[j], terms[i], terms[j], tau0, tuple(coef2))
    scale = 2 * m**2 * tau0**2 * terms  # â(m) = Σ d² / scale
    cov = 2 * sums / np.outer(scale, scale)
    x = ieee952.design_columns(tau)[:, :4][:, present]
    mu = x @ coef2[present]
    dense = tau[-1] / 4
    idx = ieee952.fit_index(tau, 0, dense)
    nu = 2 * mu[idx] ** 2 / np.diag(cov)[idx] * ieee952.evidence_weights(tau, idx, dense)
    score = x[idx].T * (nu / (2 * mu[idx] ** 2))
    fisher_inv = np.linalg.inv(score @ x[idx])
    fit_var = fisher_inv @ score @ cov[np.ix_(idx, idx)] @ score.T @ fisher_inv
    gls_var = np.linalg.inv(x.T @ np.linalg.solve(cov, x))
    spreads = []
    for var in (fit_var, gls_var):
        spread = np.full(4, np.nan)
        spread[present] = np.sqrt(np.diag(var)) / (2 * coef2[present])
        spreads.append(spread)
    return spreads[0], spreads[1]


def precision(hours: float = 12.0) -> None:
    """Spread (%) of N, B, K: the fit's (sandwich, linearised at the truth) against GLS and
    the Cramér–Rao bound."""
    for truth in ((5e-4, 5e-5, 5e-7), (3e-4, 8e-5, 3e-7), (1e-3, 3e-5, 1e-6)):
        fit, gls = allan_spreads((0.0, *truth), hours * 3600, TAU0)
        bound = whittle_crb(*truth, 0.0, hours * 3600, TAU0)
        for k, name in enumerate(("N", "B", "K")):
            print(f"N, B, K = {truth}: {name} spread {100 * fit[k + 1]:.2f} % (the fit) "
                  f"{100 * gls[k + 1]:.2f} % (GLS, every tau) "
                  f"{100 * bound[k]:.2f} % (Cramér-Rao)")  # fmt: skip


def gm_one(seed: int, hours: float, size: float) -> tuple[dict, list[dict]]:
    """(the generator's effect, the (params, intervals) of every Gauss–Markov effect the loop
    accepted on its axis) of recording ``seed``."""
    import independent_generator as gen  # beside this file

    from imupipe.analysis.analyze import axis_result
    from imupipe.vocab import AXES

    y, _, truth = gen.generate(hours, 1 / TAU0, seed, "gauss_markov", size)
    axis = truth.effect["axis"]
    x = y[:, AXES.index(axis)] - (9.80665 if axis == "accel_z" else 0.0)
    (curve,) = allan_curves([x], TAU0, tau_factors(len(x)))
    result = axis_result(axis, x, curve, TAU0, None, None, True)
    found = [(e.params, e.intervals) for e in result.loop.accepted if e.kind == "gauss_markov"]
    return truth.effect, found


def gm_coverage(records: int, hours: float, size: float, jobs: int) -> None:
    """Tc's and σ's interval coverage over ``records`` recordings (seeds 440000…) of
    :func:`gm_one`."""
    seeds = range(440_000, 440_000 + records)
    with ProcessPoolExecutor(jobs) as pool:
        done = list(pool.map(gm_one, seeds, [hours] * records, [size] * records))
    z = {"tau_c_s": [], "sigma": []}
    for effect, found in done:
        for params, intervals in found[:1]:
            for name, zs in z.items():
                lo, hi = np.log(intervals[name])
                est, truth = np.log(params[name]), np.log(effect[name])
                with np.errstate(divide="ignore"):  # an interval censored at its estimate
                    zs.append(1.96 * (truth - est) / ((hi if truth > est else lo) - est))
    n = len(z["sigma"])
    print(f"{records} recordings of {hours:g} h, size {size:g}: Gauss-Markov found on {n}")
    for name, zs in z.items():
        zs = np.array(zs)
        spread = np.sqrt(np.mean(zs**2))
        print(f"  {name}: interval holds the truth on {np.sum(zs <= 1.96)} of {n}; "
              f"standardised error spread {spread:.2f} (calibrated: 1)")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)
    cov = sub.add_parser("coverage")
    cov.add_argument("--records", type=int, default=200)
    cov.add_argument("--samples", type=int, default=2**18)
    cov.add_argument("--n", type=float, default=PAPER_N, help="white rate N (rad/s/√Hz)")
    cov.add_argument("--b", type=float, default=PAPER_B, help="flicker B (rad/s); 0: none")
    kcov = sub.add_parser("k_coverage")
    kcov.add_argument("--records", type=int, default=60)
    kcov.add_argument("--hours", type=float, default=12.0)
    kcov.add_argument("--n", type=float, default=3e-4, help="white rate N (rad/s/√Hz)")
    kcov.add_argument("--b", type=float, default=2e-5, help="flicker B (rad/s)")
    kcov.add_argument("--k-share", type=float, default=10.0, help="K's AVAR at T/2 / plateau")
    sub.add_parser("precision")
    gm = sub.add_parser("gm_coverage")
    gm.add_argument("--records", type=int, default=80)
    gm.add_argument("--hours", type=float, default=2.0)
    gm.add_argument("--size", type=float, default=10.0)
    gm.add_argument("--jobs", type=int, default=2)
    pan = sub.add_parser("panel")
    pan.add_argument("jsonl", type=Path, help="a loop_validation.py --jsonl file")
    args = ap.parse_args()
    if args.command == "coverage":
        coverage(args.records, args.samples, args.n, args.b)
    elif args.command == "k_coverage":
        k_coverage(args.records, args.hours, args.n, args.b, args.k_share)
    elif args.command == "panel":
        panel(args.jsonl)
    elif args.command == "gm_coverage":
        gm_coverage(args.records, args.hours, args.size, args.jobs)
    else:
        precision()


if __name__ == "__main__":
    main()
