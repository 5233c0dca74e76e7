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
    python benchmarks/mutation_test.py pipeline/units.py --session /tmp/imupipe-mutation-XXXX
    python benchmarks/mutation_test.py --list

``--session`` resumes a session (printed at the start of a run) and re-tests only its survivors,
after tests were added to kill them.

Prints, per module: mutants, killed, survived, timeouts (counted as killed), skipped (outside
``--functions``, or a float -> bit-operator swap unless ``--all-operators``) and the diff of
every survivor.
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import re
import shlex
import sqlite3
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# module -> the test files that cover it (the subset run against each mutant)
TESTS: dict[str, tuple[str, ...]] = {
    "pipeline/units.py": ("tests/test_units.py",),
    "pipeline/vocab.py": ("tests/test_units.py", "tests/test_import_floors.py"),
    "pipeline/stats/allan.py": ("tests/test_allan.py",),
    "pipeline/stats/edf.py": ("tests/test_edf.py",),
    "pipeline/stats/robust.py": ("tests/test_robust.py",),
    "pipeline/analysis/condition.py": ("tests/test_condition.py",),
    # the rule tests first (fast; -x stops at the first failure); tests/test_loop_sim.py (six
    # 3 h axes per scenario, minutes) is left out of the per-mutant run for time
    "pipeline/model/loop.py": ("tests/model/test_loop_rules.py", "tests/test_loop.py"),
    "pipeline/model/effects.py": (
        "tests/model/test_loop_rules.py",
        "tests/test_effects_full_rate.py",
        "tests/test_loop.py",
    ),
    "pipeline/io/decode.py": ("tests/test_scale_factors.py", "tests/test_ros_bags.py"),
    "pipeline/recording/recorder.py": ("tests/test_mcap_io.py", "tests/test_recorder_signals.py"),
    "pipeline/report/report.py": ("tests/test_report.py",),
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


def run_module(
    module: str,
    functions: set[str],
    all_operators: bool,
    timeout: float,
    env: dict[str, str],
    resume: Path | None = None,
) -> Score:
    """Initialise, filter and execute one cosmic-ray session (or resume the one in ``resume``,
    re-testing its survivors); return the counts."""
    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import WorkerOutcome, WorkResult

    _check_clean(module)
    command = _test_command(TESTS[module])
    baseline = subprocess.run(shlex.split(command), cwd=ROOT, env=env, check=False)
    if baseline.returncode != 0:
        raise SystemExit(f"{module}: the unmutated tests fail ({command}); fix them first")

    work = resume or Path(tempfile.mkdtemp(prefix="imupipe-mutation-"))
    print(f"{module}: session in {work}", flush=True)
    config = work / "config.toml"
    session = work / "session.sqlite"
    if resume is not None:
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
    with use_db(str(session), WorkDB.Mode.open) as db:
        drop = [
            item.job_id
            for item in db.pending_work_items
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
        run_module(m, functions, args.all_operators, args.timeout, env, args.session)
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
