"""Mutation testing of imupipe's core with cosmic-ray (not CI: slow; minutes to hours per module).

Each chosen module is mutated one small change at a time (operator swapped, constant changed,
comparison flipped, ...) by cosmic-ray (PyPI ``cosmic-ray``), and the tests that cover that module
are run against each mutant.  A mutant the tests fail on is *killed*; one they pass on *survived*
and is either a missing test or an equivalent change (triaged in docs/mutation.md).

cosmic-ray edits the files IN PLACE and restores them after each mutant: run this only in a
checkout you own, with the module committed (the script refuses a module with uncommitted changes
and checks it is restored afterwards).

Usage (from the repository root, in the project's virtualenv with ``pip install cosmic-ray``)::

    python benchmarks/mutation_test.py pipeline/units.py pipeline/vocab.py
    python benchmarks/mutation_test.py pipeline/stats/edf.py --functions edf_overlapping --no-jit
    python benchmarks/mutation_test.py pipeline/stats/robust.py --sample 40
    python benchmarks/mutation_test.py pipeline/units.py --session /tmp/imupipe-mutation-XXXX
    python benchmarks/mutation_test.py --list

``--session`` resumes a session (printed at the start of a run) and re-tests only its survivors,
after tests were added to kill them.  ``--sample N`` runs a uniformly random N of the selected
mutants (seeded by ``--seed``) and skips the rest: the killed fraction of a random sample is an
unbiased estimate of the module's score (binomial standard error sqrt(p (1 - p) / N)).

Prints, per module: mutants, killed, survived, timeouts (counted as killed), skipped (outside
``--functions``/``--lines``, not in ``--sample``, inside an annotation (never evaluated under
``from __future__ import annotations``: always equivalent), or a float -> bit-operator swap
unless ``--all-operators``) and the diff of every survivor.
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import random
import re
import shlex
import sqlite3
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# module -> the test files that cover it (the subset run against each mutant; the fast, targeted
# files first: with ``-x`` most mutants are then killed within seconds)
TESTS: dict[str, tuple[str, ...]] = {
    "pipeline/units.py": ("tests/test_units.py",),
    "pipeline/vocab.py": ("tests/test_units.py", "tests/test_import_floors.py"),
    "pipeline/stats/allan.py": ("tests/stats/test_allan_mutants.py", "tests/stats/test_allan.py"),
    "pipeline/stats/edf.py": ("tests/stats/test_edf_mutants.py", "tests/stats/test_edf.py"),
    "pipeline/stats/avar_covariance.py": ("tests/stats/test_avar_covariance.py",),
    "pipeline/pages.py": ("tests/test_pages.py",),
    "pipeline/model/spectral_line.py": ("tests/model/test_spectral_line.py",),
    "pipeline/model/ahead.py": ("tests/analysis/test_first_run.py",),
    "pipeline/stats/robust.py": (
        "tests/stats/test_robust_mutants.py",
        "tests/stats/test_robust.py",
    ),
    "pipeline/model/ieee952.py": (
        "tests/model/test_ieee952_intervals.py",
        "tests/model/test_ieee952.py",
    ),
    "pipeline/analysis/condition.py": (
        "tests/analysis/test_condition.py",
        "tests/analysis/test_host_stamps.py",
        "tests/test_hostile.py::test_a_rate_switch_is_cut_not_averaged_into_jitter",
        "tests/io/test_ros_bags.py",
    ),
    "pipeline/analysis/events.py": ("tests/analysis/test_events.py",),
    "pipeline/analysis/common_mode.py": (
        "tests/analysis/test_common_mode.py",
        "tests/analysis/test_events.py",
        "tests/report/test_report_text.py",
    ),
    "pipeline/analysis/at_rest.py": ("tests/analysis/test_at_rest.py",),
    "pipeline/io/mcap_scan.py": (
        "tests/io/test_fuzz_decoder.py",
        "tests/io/test_busy_bags.py",
        "tests/io/test_mcap_io.py",
        "tests/io/test_cdr_rows.py",
        "tests/io/test_decode_contract.py",
        "tests/test_hostile.py",  # damaged and hostile files (~25 s)
        "tests/test_odd_inputs.py",
    ),
    "pipeline/io/db3_scan.py": ("tests/io/test_db3_bags.py",),
    "pipeline/io/rosbag2.py": (
        "tests/io/test_rosbag2_files.py",
        "tests/io/test_ros_bags.py",
        "tests/io/test_db3_bags.py",
        "tests/test_hostile.py::test_rosbag2_metadata_listing_files_outside_the_bag_is_refused",
        "tests/test_hostile.py::test_split_files_without_metadata_are_read_in_natural_order",
        "tests/test_hostile.py::test_a_listed_file_that_is_missing_is_warned_about",
        "tests/test_odd_inputs.py::test_rosbag2_directory_with_split_files",
    ),
    "pipeline/io/mcap_bulk.py": (
        "tests/io/test_mcap_io.py",
        "tests/recording/test_recorder_chunks.py",
        "tests/io/test_decode_contract.py",
        "tests/test_cli.py",
    ),
    "pipeline/io/mcap_walk.py": (
        "tests/io/test_cdr_rows.py",
        "tests/io/test_busy_bags.py",
        "tests/io/test_fuzz_decoder.py",
        "tests/io/test_mcap_io.py",
        "tests/test_odd_inputs.py",
    ),
    "pipeline/report/rerun_streams.py": ("tests/report/test_rerun_streams.py",),
    "pipeline/report/rerun_live.py": ("tests/report/test_rerun_live.py",),
    "pipeline/report/staging.py": (
        "tests/report/test_staging.py",
        "tests/test_hostile.py::test_interrupted_runs_leave_the_old_output_and_no_rrd_leaves_no_stale_recording",
        "tests/test_hostile.py::test_default_out_names_do_not_collide",
        "tests/test_hostile.py::test_an_out_that_cannot_take_the_reports_is_one_line",
        "tests/test_hostile.py::test_a_stop_whose_exception_python_swallowed_still_keeps_the_old_output",
    ),
    "pipeline/report/datasheet.py": (
        "tests/report/test_datasheet.py",
        "tests/fleet/test_fleet_population.py",
    ),
    "pipeline/report/rerun_view.py": (
        "tests/report/test_rerun_view.py",
        "tests/report/test_rerun_streams.py",
    ),
    "pipeline/io/decode.py": (
        "tests/io/test_decode_contract.py",
        "tests/io/test_scale_factors.py",
        "tests/io/test_ros_bags.py",
        "tests/io/test_column_store.py",  # the in-memory and spilled column stores
        "tests/io/test_column_sources.py",
        "tests/io/test_decode_memory.py",
        "tests/analysis/test_lowmem.py",
    ),
    # tests/recording/test_recorder_signals.py (real signals to a real-time subprocess, ~1 min)
    # is left out: too slow per mutant; tests/recording/ covers the same paths in process
    "pipeline/recording/recorder.py": (
        "tests/recording/test_recorder_chunks.py",
        "tests/io/test_mcap_io.py",
    ),
    "pipeline/report/report.py": (
        "tests/report/test_report_text.py",
        "tests/report/test_report.py",
    ),
    "pipeline/report/exports.py": (
        "tests/report/test_exports_values.py",
        "tests/report/test_exports.py",
    ),
    "pipeline/device/adis16364.py": (
        "tests/device/test_adis16364_scales.py",
        "tests/device/test_adis16364.py",
        "tests/io/test_scale_factors.py",
        "tests/io/test_decode_contract.py",
        "tests/report/test_accel_scale_end_to_end.py",
        "tests/recording/test_spi.py",  # the register map, SPI timing and start-up checks
        "tests/recording/test_simulator.py",
    ),
    # the rule tests first (fast; -x stops at the first failure); tests/model/test_loop_sim.py
    # (six 3 h axes per scenario, minutes) is left out of the per-mutant run for time
    "pipeline/model/loop.py": (
        "tests/model/test_loop_rules.py",
        "tests/model/test_time_error.py",
        "tests/model/test_loop_reuse.py",
        "tests/model/test_loop_short_line.py",
        "tests/model/test_loop.py",
    ),
    "pipeline/fleet/population.py": ("tests/fleet/test_fleet_population.py",),
    "pipeline/fleet/curves.py": ("tests/fleet/test_fleet_population.py",),
    "pipeline/fleet/discover.py": ("tests/fleet/test_fleet_population.py",),
    "pipeline/model/effects.py": (
        "tests/model/test_whitener.py",
        "tests/model/test_loop_vibration.py",
        "tests/model/test_loop_rules.py",
        "tests/model/test_effects_full_rate.py",
        "tests/model/test_loop.py",
    ),
    "pipeline/escape.py": (
        "tests/report/test_datasheet.py",
        "tests/report/test_report_text.py",
        "tests/test_hostile.py",
    ),
    "pipeline/report/paper.py": (
        "tests/report/test_paper_table.py",
        "tests/report/test_report.py",
        "tests/test_units.py",
    ),
    "pipeline/analysis/results.py": (
        "tests/report/test_results_contract.py",
        "tests/test_api.py",
        "tests/analysis/test_final_model.py",
        "tests/report/test_report.py",
        "tests/report/test_report_text.py",
    ),
    "pipeline/io/info.py": (
        "tests/io/test_info.py",
        "tests/io/test_mcap_io.py",
        "tests/io/test_db3_bags.py",
        "tests/test_odd_inputs.py",
    ),
    "pipeline/recording/noise.py": (
        "tests/recording/test_simulator.py",
        "tests/recording/test_scenario.py",
    ),
    "pipeline/report/figures.py": (
        "tests/report/test_allan_figure.py",
        "tests/report/test_figure_labels.py",
        "tests/report/test_figures_workers.py",
        "tests/report/test_loop_figure.py",
    ),
    "pipeline/device/frame_schema.py": (
        "tests/io/test_decode_contract.py",
        "tests/io/test_mcap_io.py",
        "tests/io/test_busy_bags.py",
    ),
    "pipeline/io/columns.py": (
        "tests/io/test_column_notes.py",
        "tests/io/test_column_sources.py",
        "tests/io/test_decode_memory.py",
        "tests/analysis/test_lowmem.py",
    ),
    "pipeline/recording/scenario.py": (
        "tests/recording/test_scenario.py",
        "tests/recording/test_simulator.py",
    ),
    "pipeline/jit.py": ("tests/test_jit.py", "tests/stats/test_allan_blocks.py"),
    "pipeline/report/outputs.py": (
        "tests/report/test_outputs.py",
        "tests/test_api.py",
        "tests/report/test_report.py",
    ),
    "pipeline/recording/simulator.py": (
        "tests/recording/test_simulator.py",
        "tests/recording/test_scenario.py",
        "tests/recording/test_recorder_signals.py",
    ),
    "pipeline/analysis/analyze.py": (
        "tests/test_api.py",
        "tests/analysis/test_final_model.py",
        "tests/test_cli.py",
        "tests/analysis/test_workers.py",
        "tests/test_odd_inputs.py",
        "tests/analysis/test_events.py",  # the first pass' events, excised beside the gaps
        "tests/analysis/test_outliers.py",  # the loop's second spike search after excision
        "tests/test_jit.py",  # the spilled path's compiling child
    ),
    "pipeline/cli.py": ("tests/test_cli.py", "tests/test_odd_inputs.py", "tests/test_hostile.py"),
    "pipeline/api.py": (
        "tests/test_api.py",
        "tests/test_cli.py",
        "tests/recording/test_recorder_chunks.py",
        "tests/report/test_outputs.py",
    ),
    "pipeline/fleet/report.py": (
        "tests/fleet/test_fleet_population.py",
        "tests/fleet/test_fleet_report_mutants.py",
        "tests/fleet/test_fleet_cluster.py",
    ),
    "pipeline/fleet/task.py": (
        "tests/fleet/test_fleet_task.py",
        "tests/fleet/test_fleet_task_mutants.py",
        "tests/fleet/test_fleet_population.py",
        "tests/analysis/test_workers.py",
        "tests/fleet/test_fleet_cluster.py",
    ),
    "pipeline/fleet/run.py": (
        "tests/fleet/test_fleet_run_mutants.py",
        "tests/fleet/test_fleet_population.py",
        "tests/test_cli.py",
        "tests/fleet/test_fleet_cluster.py",
    ),
    "pipeline/fleet/figure_plan.py": (
        "tests/fleet/test_fleet_population.py",
        "tests/fleet/test_fleet_cluster.py",  # the figures written
    ),
    "pipeline/analysis/workers.py": ("tests/analysis/test_workers.py", "tests/test_api.py"),
    "pipeline/recording/spi.py": ("tests/recording/test_spi.py",),
    "pipeline/progress.py": ("tests/test_progress.py", "tests/io/test_column_notes.py"),
    "pipeline/stopping.py": ("tests/test_hostile.py",),
    "pipeline/fleet/rerun_view.py": (
        "tests/report/test_rerun_view.py",
        "tests/report/test_rerun_streams.py",
    ),
    # the figures' tests in process first; then the LocalCluster run whose PNGs' size is pinned
    "pipeline/fleet/figures.py": (
        "tests/fleet/test_fleet_population.py",
        "tests/fleet/test_fleet_cluster.py::test_local_cluster_local_and_s3_units",
    ),
    # the in-process and one-worker tests first (seconds), then the real clusters (~2 min)
    "pipeline/fleet/cluster.py": (
        "tests/fleet/test_fleet_population.py::test_an_existing_scheduler_is_tried_for_10_s_and_its_workers_awaited_60_s",
        "tests/fleet/test_fleet_population.py::test_each_way_the_local_cluster_fails_to_start_is_one_fleet_error",
        "tests/fleet/test_fleet_cluster.py::test_the_embedded_cluster_has_the_workers_asked_for_on_127_0_0_1_and_stops",
        "tests/fleet/test_fleet_cluster.py::test_the_embedded_workers_heaps_are_frozen_just_before_the_cluster_stops",
        "tests/fleet/test_fleet_population.py::test_a_local_cluster_that_does_not_start_is_one_line",
        "tests/fleet/test_fleet_population.py::test_bad_arguments_fail_before_any_worker_starts",
        "tests/fleet/test_fleet_cluster.py::test_the_docs_give_deployments_the_embedded_clusters_settings",
        "tests/fleet/test_fleet_cluster.py::test_embedded_workers_are_single_threaded",
        "tests/fleet/test_fleet_cluster.py::test_embedded_workers_keep_glibc_malloc_trimming_and_run_no_profiler",
        "tests/fleet/test_fleet_cluster.py::test_a_script_without_a_main_guard_fails_in_seconds_instead_of_hanging",
        "tests/fleet/test_fleet_cluster.py::test_unreachable_scheduler_is_one_line_exit_2",
        "tests/fleet/test_fleet_cluster.py::test_local_cluster_local_and_s3_units",
        "tests/fleet/test_fleet_cluster.py::test_existing_scheduler_survives_a_killed_worker",
    ),
}


@dataclass(frozen=True)
class Score:
    """Outcome counts of one module's mutation run."""

    module: str
    mutants: int
    killed: int
    survived: int
    timeouts: int
    skipped: int
    survivors: tuple[str, ...]

    @property
    def score(self) -> float:
        """Killed fraction of the mutants that were run (timeouts count as killed)."""
        return self.killed / self.mutants if self.mutants else float("nan")


def _function_lines(module: Path, names: set[str]) -> set[int]:
    """Source lines (1-based) inside the named top-level or nested functions/classes."""
    lines: set[int] = set()
    for node in ast.walk(ast.parse(module.read_text())):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            if node.name in names:
                lines.update(range(node.lineno, (node.end_lineno or node.lineno) + 1))
    missing = names - {
        n.name
        for n in ast.walk(ast.parse(module.read_text()))
        if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef)
    }
    if missing:
        raise SystemExit(f"{module}: no function named {', '.join(sorted(missing))}")
    return lines


def _annotation_spans(module: Path) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """(start, end) positions of every annotation when the module has ``from __future__ import
    annotations``: they are never evaluated, so mutants inside them are always equivalent."""
    tree = ast.parse(module.read_text())
    future = any(
        isinstance(n, ast.ImportFrom)
        and n.module == "__future__"
        and any(a.name == "annotations" for a in n.names)
        for n in tree.body
    )
    if not future:
        return []
    notes: list[ast.expr] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.arg) and node.annotation is not None:
            notes.append(node.annotation)
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.returns:
            notes.append(node.returns)
        elif isinstance(node, ast.AnnAssign):
            notes.append(node.annotation)
    return [
        ((n.lineno, n.col_offset), (n.end_lineno or n.lineno, n.end_col_offset or 0)) for n in notes
    ]


def _test_command(tests: tuple[str, ...]) -> str:
    return shlex.join(
        [
            sys.executable,
            "-m",
            "pytest",
            "-x",
            "-q",
            "-p",
            "no:cacheprovider",
            "-p",
            "no:xdist",
            *tests,
        ]
    )


def _check_clean(module: str) -> None:
    diff = subprocess.run(["git", "diff", "--quiet", "HEAD", "--", module], cwd=ROOT, check=False)
    if diff.returncode != 0:
        raise SystemExit(f"{module} has uncommitted changes: commit it (mutation edits in place)")


# float arithmetic turned into bit operations raises TypeError on every call: always killed,
# and 5 of them per operator; skipped unless --all-operators
BIT_OPERATORS = re.compile(r"_(RShift|LShift|BitOr|BitAnd|BitXor)$")


def _retest_survivors(session: Path) -> None:
    """Forget the survivors of an earlier run so that ``exec`` tests them again (after tests were
    added), keeping every kill and skip."""
    with sqlite3.connect(session) as db:
        db.execute("DELETE FROM work_results WHERE test_outcome = 'SURVIVED'")


def _parse_lines(spec: str) -> set[int]:
    """``"225-240,300"`` -> the source lines (1-based) it names."""
    lines: set[int] = set()
    for part in filter(None, spec.split(",")):
        first, _, last = part.partition("-")
        lines.update(range(int(first), int(last or first) + 1))
    return lines


def run_module(
    module: str,
    functions: set[str],
    all_operators: bool,
    timeout: float,
    env: dict[str, str],
    resume: Path | None = None,
    lines: set[int] | None = None,
    sample: int | None = None,
    seed: int = 0,
    tests: tuple[str, ...] = (),
) -> Score:
    """Initialise, filter and execute one cosmic-ray session (or resume the one in ``resume``,
    re-testing its survivors); return the counts.

    Mutants outside ``functions`` and ``lines`` (when either is given) are skipped; ``sample``
    keeps a random ``sample`` of the rest (``seed``), skipping the others ("not sampled");
    ``tests`` replaces the module's test map."""
    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import WorkerOutcome, WorkResult

    _check_clean(module)
    command = _test_command(tests or TESTS[module])
    baseline = subprocess.run(shlex.split(command), cwd=ROOT, env=env, check=False)
    if baseline.returncode != 0:
        raise SystemExit(f"{module}: the unmutated tests fail ({command}); fix them first")

    work = resume or Path(tempfile.mkdtemp(prefix="imupipe-mutation-"))
    print(f"{module}: session in {work}", flush=True)
    config = work / "config.toml"
    session = work / "session.sqlite"
    if resume is not None:  # the survivors meet today's test map (e.g. a new test file)
        config.write_text(
            re.sub(
                r"(?m)^test-command = .*$",
                lambda _: f"test-command = {json.dumps(command)}",
                config.read_text(),
            )
        )
        _retest_survivors(session)
        return _execute(module, config, session, env)
    config.write_text(
        "[cosmic-ray]\n"
        f"module-path = {json.dumps(module)}\n"
        f"timeout = {timeout}\n"
        "excluded-modules = []\n"
        f"test-command = {json.dumps(command)}\n"
        "[cosmic-ray.distributor]\n"
        'name = "local"\n'
    )
    cr = [sys.executable, "-m", "cosmic_ray.cli"]
    subprocess.run([*cr, "init", str(config), str(session)], cwd=ROOT, env=env, check=True)

    keep = _function_lines(ROOT / module, functions) if functions else None
    annotations = _annotation_spans(ROOT / module)
    if lines:
        keep = (keep or set()) | lines
    with use_db(str(session), WorkDB.Mode.open) as db:
        pending = list(db.pending_work_items)
        drop = [
            item.job_id
            for item in pending
            if any(
                (keep is not None and m.start_pos[0] not in keep)
                or (not all_operators and BIT_OPERATORS.search(m.operator_name))
                for m in item.mutations
            )
        ]
        if drop:
            db.set_multiple_results(
                drop, WorkResult(worker_outcome=WorkerOutcome.SKIPPED, output="not selected")
            )
        dropped = set(drop)
        in_notes = [
            item.job_id
            for item in pending
            if item.job_id not in dropped
            and all(
                any(a <= tuple(m.start_pos) < b for a, b in annotations) for m in item.mutations
            )
        ]
        if in_notes:
            db.set_multiple_results(
                in_notes,
                WorkResult(worker_outcome=WorkerOutcome.SKIPPED, output="annotation (equivalent)"),
            )
        drop += in_notes
        chosen = sorted({item.job_id for item in pending} - set(drop))
        if sample is not None and sample < len(chosen):
            kept = set(random.Random(seed).sample(chosen, sample))
            db.set_multiple_results(
                [j for j in chosen if j not in kept],
                WorkResult(worker_outcome=WorkerOutcome.SKIPPED, output="not sampled"),
            )
        print(
            f"{module}: {min(len(chosen), sample or len(chosen))} of {len(chosen)} selected "
            f"mutants to run ({len(pending)} in the module)",
            flush=True,
        )
    return _execute(module, config, session, env)


def _execute(module: str, config: Path, session: Path, env: dict[str, str]) -> Score:
    """Run the pending mutants of a session and count the outcomes."""
    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import TestOutcome, WorkerOutcome

    cr = [sys.executable, "-m", "cosmic_ray.cli"]
    try:
        subprocess.run([*cr, "exec", str(config), str(session)], cwd=ROOT, env=env, check=True)
    finally:
        restored = subprocess.run(
            ["git", "diff", "--quiet", "HEAD", "--", module], cwd=ROOT, check=False
        )
        if restored.returncode != 0:
            raise SystemExit(f"{module} was NOT restored after mutation: `git checkout {module}`")

    killed = survived = timeouts = skips = 0
    survivors: list[str] = []
    with use_db(str(session), WorkDB.Mode.open) as db:
        for item, result in db.completed_work_items:
            if result.worker_outcome == WorkerOutcome.SKIPPED:
                skips += 1
                continue
            if result.test_outcome == TestOutcome.SURVIVED:
                survived += 1
                survivors.append(result.diff or item.job_id)
            else:
                killed += 1
                timeouts += result.output == "timeout"
    return Score(module, killed + survived, killed, survived, timeouts, skips, tuple(survivors))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("modules", nargs="*", help="module paths, e.g. pipeline/units.py")
    parser.add_argument("--functions", default="", help="comma-separated: mutate only these")
    parser.add_argument(
        "--lines", default="", help="also mutate these source lines, e.g. 225-240,300 (constants)"
    )
    parser.add_argument(
        "--sample", type=int, help="run a random sample of this many of the selected mutants"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of --sample")
    parser.add_argument("--timeout", type=float, default=300.0, help="s per mutant test run")
    parser.add_argument(
        "--no-jit", action="store_true", help="NUMBA_DISABLE_JIT=1 (no recompile per mutant)"
    )
    parser.add_argument(
        "--all-operators", action="store_true", help="also float -> bit-operator replacements"
    )
    parser.add_argument(
        "--session",
        type=Path,
        help="resume the session directory printed by an earlier run of ONE module, re-testing "
        "its survivors (after adding tests)",
    )
    parser.add_argument(
        "--tests",
        default="",
        help="comma-separated test files run against each mutant instead of the module's map "
        "(a targeted run of a few functions)",
    )
    parser.add_argument("--list", action="store_true", help="print the module -> tests map")
    args = parser.parse_args()
    if args.list or not args.modules:
        for module, tests in TESTS.items():
            print(f"{module}: {' '.join(tests)}")
        return
    unknown = [m for m in args.modules if m not in TESTS]
    if unknown:
        raise SystemExit(f"no test map for {', '.join(unknown)} (see --list)")
    env = dict(os.environ)
    if args.no_jit:
        env["NUMBA_DISABLE_JIT"] = "1"
    functions = {f for f in args.functions.split(",") if f}
    if args.session is not None and len(args.modules) != 1:
        raise SystemExit("--session resumes the run of one module")
    scores = [
        run_module(
            m,
            functions,
            args.all_operators,
            args.timeout,
            env,
            args.session,
            _parse_lines(args.lines),
            args.sample,
            args.seed,
            tuple(t for t in args.tests.split(",") if t),
        )
        for m in args.modules
    ]
    print("\nmodule                              mutants killed survived timeouts skipped score")
    for s in scores:
        print(
            f"{s.module:36s}{s.mutants:7d}{s.killed:7d}{s.survived:9d}{s.timeouts:9d}"
            f"{s.skipped:8d} {100 * s.score:5.1f} %"
        )
    for s in scores:
        for diff in s.survivors:
            print(f"\n--- survived in {s.module}:\n{diff}")


if __name__ == "__main__":
    main()
