"""Benchmark: do the IEEE 952 fit's 95 % intervals hold the truth at their nominal rate, and how
precisely can any reading of the Allan curve know B?

``coverage``: records of known noise (white rate N, flicker B; Annex C PSD), fitted as the
analysis fits (``fit_noise_terms`` on a T/2 curve); each term's interval with the fitted τ
points counted as independent and with their correlation (:mod:`imupipe.stats.avar_covariance`,
the sandwich factor); prints the share of records whose truth lies below ``lo`` / above ``hi``
(an unresolved term: its bound) and how often B is resolved.

``precision``: for a 12 h / 100 Hz record of N, B, K, the spread of the fit's N, B and K
(its sandwich variance, linearised at the truth, on the points it reads) against the best
linear unbiased estimate from every τ of the curve with their full covariance (GLS).

    python benchmarks/interval_coverage.py coverage --records 200 --samples 262144
    python benchmarks/interval_coverage.py coverage --records 40 --samples 4320000 --b 0
    python benchmarks/interval_coverage.py precision
"""

from __future__ import annotations

import argparse

import numpy as np

from imupipe.model import ieee952
from imupipe.stats.allan import allan_curves, tau_factors
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


def precision(hours: float = 12.0) -> None:
    """Spread (%) of N, B, K: the fit's (sandwich, linearised at the truth) against GLS."""
    n = int(hours * 3600 / TAU0)
    m = tau_factors(n, min_terms=2)
    terms, tau = n + 1 - 2 * m, m * TAU0
    i, j = np.triu_indices(len(m))
    for truth in ((5e-4, 5e-5, 5e-7), (3e-4, 8e-5, 3e-7), (1e-3, 3e-5, 1e-6)):
        coef2 = np.square(truth)
        sums = np.empty((len(m), len(m)))
        sums[i, j] = sums[j, i] = lag_sums(m[i], m[j], terms[i], terms[j], TAU0, (0, *coef2))
        scale = 2 * m**2 * TAU0**2 * terms  # â(m) = Σ d² / scale
        cov = 2 * sums / np.outer(scale, scale)
        x = ieee952.design_columns(tau)[:, 1:4]
        mu = x @ coef2
        dense = tau[-1] / 4
        idx = ieee952.fit_index(tau, 0, dense)
        nu = 2 * mu[idx] ** 2 / np.diag(cov)[idx] * ieee952.evidence_weights(tau, idx, dense)
        score = x[idx].T * (nu / (2 * mu[idx] ** 2))
        fisher_inv = np.linalg.inv(score @ x[idx])
        fit_var = fisher_inv @ score @ cov[np.ix_(idx, idx)] @ score.T @ fisher_inv
        gls_var = np.linalg.inv(x.T @ np.linalg.solve(cov, x))
        for k, name in enumerate(("N", "B", "K")):
            spread = [100 * np.sqrt(v[k, k]) / (2 * coef2[k]) for v in (fit_var, gls_var)]
            print(f"N, B, K = {truth}: {name} spread {spread[0]:.2f} % (the fit) "
                  f"{spread[1]:.2f} % (GLS, {len(m)} tau)")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)
    cov = sub.add_parser("coverage")
    cov.add_argument("--records", type=int, default=200)
    cov.add_argument("--samples", type=int, default=2**18)
    cov.add_argument("--n", type=float, default=PAPER_N, help="white rate N (rad/s/√Hz)")
    cov.add_argument("--b", type=float, default=PAPER_B, help="flicker B (rad/s); 0: none")
    sub.add_parser("precision")
    args = ap.parse_args()
    if args.command == "coverage":
        coverage(args.records, args.samples, args.n, args.b)
    else:
        precision()


if __name__ == "__main__":
    main()
