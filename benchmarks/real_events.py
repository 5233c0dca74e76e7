"""Disturbance events on REAL recordings: what the joint search finds, and what the loop says
per axis with and without their excision.

Reference data (not shipped, CC BY-NC-SA 4.0): /work/shared/reference (see its README): two
static ADIS16405 units recorded side by side, and the contaminated MTi-G gyro.  Per recording
this runs what ``imupipe analyze`` runs (:func:`imupipe.analysis.analyze.find_axis_events`'s
steps: spike-corrected fine means of every axis, :func:`imupipe.analysis.events.detect`; then
per axis the Allan deviation, the closed loop and the final model with the events excised, and
once more without) and prints the events and, per axis, the loop's accepted effects and the
final model's bootstrap p before → after the excision.

    python benchmarks/real_events.py [reference_dir] [--json OUT.json]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from real_final_model import recordings

from imupipe.analysis.analyze import axis_result
from imupipe.analysis.events import detect, event_mask, fill_excised, fine_means
from imupipe.model.effects import spike_candidate
from imupipe.stats.allan import allan_curves, tau_factors
from imupipe.vocab import sensor_of


def _effects(axis) -> list[str]:
    out = []
    for e in axis.loop.accepted:
        t = e.params.get("time_s")
        out.append(e.kind + ("" if t is None else f"@{t:.0f}s"))
    return out


def main() -> None:
    args = sys.argv[1:]
    out_json = None
    if "--json" in args:
        k = args.index("--json")
        out_json = Path(args[k + 1])
        del args[k : k + 2]
    ref = Path(args[0]) if args else Path("/work/shared/reference")
    summary: dict = {}
    for rec, (series, tau0) in recordings(ref).items():
        n = len(next(iter(series.values())))
        units = {a: "rad/s" if sensor_of(a) == "gyro" else "m/s^2" for a in series}
        means = {a: fine_means(y, tau0, spike_candidate(y, tau0)) for a, y in series.items()}
        found = detect(means, tau0, n, units, 0.0)
        tests = sum(found.detector.windows)
        print(f"## {rec}: {len(found.events)} event(s), {tests} windows tested")
        for e in found.events:
            sizes = ", ".join(f"{a} {v:+.3g} (z {e.z[a]:.1f})" for a, v in e.size.items())
            print(f"- {e.kind} at {e.start_s:.1f} s for {e.duration_s:.1f} s: {sizes}")
        mask = event_mask(list(found.events), n)
        m = tau_factors(n)
        rows = {}
        for name, y in series.items():
            runs = {}
            for label, excl in (("kept", None), ("excised", mask)):
                yy = y if excl is None else fill_excised(y, found)
                (curve,) = allan_curves([yy], tau0, m, excluded=excl)
                runs[label] = axis_result(name, yy, curve, tau0, None, None, True, excl)
            a, b = runs["kept"], runs["excised"]
            rows[name] = {
                "effects_kept": _effects(a),
                "effects_excised": _effects(b),
                "p_kept": a.loop.after.p_value,
                "p_excised": b.loop.after.p_value,
                "error_kept": a.loop.after.error,
                "error_excised": b.loop.after.error,
                "N_kept": a.terms.random_walk.value,
                "N_excised": b.terms.random_walk.value,
                "B_kept": a.terms.bias_instability.value,
                "B_excised": b.terms.bias_instability.value,
            }
            r = rows[name]
            print(
                f"  {name}: effects {r['effects_kept']} -> {r['effects_excised']}; final p "
                f"{r['p_kept']:.3f} -> {r['p_excised']:.3f}; error {r['error_kept']:.3g} -> "
                f"{r['error_excised']:.3g}"
            )
        summary[rec] = {
            "events": found.as_dict()["found"],
            "axes": rows,
            "excised_samples": int(0 if mask is None else np.sum(mask)),
        }
    if out_json is not None:
        out_json.write_text(json.dumps(summary, indent=1, default=float))


if __name__ == "__main__":
    main()
