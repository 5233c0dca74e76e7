"""Every command shown in the docs is run by a test, so the docs cannot rot.

The ``imupipe …`` lines of the fenced code blocks (```` ``` ````, ```` ```bash ````,
```` ```sh ````, ```` ```console ````) of README.md and docs/*.md are run in document order, one
workspace per page, as ``python -m imupipe …``.  The workspace holds a copy of ``sample_logs/``,
the robot bag the docs analyse (``robot_bag/``, a rosbag2 directory with ``/imu/data``,
``/imu/temperature`` and ``/tf``) and ``units/`` (two recordings for ``imupipe fleet``).  Each
command must exit 0, or the code its line states with a ``# exits N`` comment, with no traceback
and no internal error on stderr.

Not run: the lines of :data:`NOT_RUN` (each with its reason), and the README's install line
``… && imupipe demo`` (it starts with ``python3``, not ``imupipe``: it is the 12 h main job the CI
runs).  A sub-command the CLI does not have fails.  Every relative link of the pages must
resolve.
"""

from __future__ import annotations

import glob
import os
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
import typer

from imupipe.cli import app
from imupipe.testing.busy_bag import write_robot_bag

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SHELL_FENCES = {"", "bash", "sh", "shell", "console"}

NOT_RUN: dict[str, str] = {
    "--source spi": "needs an ADIS16364 on an SPI bus",
    "--realtime": "records in real time (the night it documents) into a Rerun window or server",
    "/tmp/adis16405_bag": "a real ADIS16405 recording from /work/shared, not committed",
    "fleet_demo/": "a fleet of the real ADIS16405 recordings (not committed) and 4 x 2 h units",
}
"""A command containing the key is not run, for the reason given."""

VIEW_STUB = """\
import sys
import imupipe.report.rerun_view as rerun_view
stub = sys.argv.pop(1)
rerun_view.rerun_executable = lambda: stub
from imupipe.cli import main
main()
"""
"""``imupipe view`` with the viewer replaced by a program that checks the .rrd is not empty."""


@dataclass(frozen=True)
class DocCommand:
    page: str
    line: int
    text: str
    """The command as the page shows it, continuation lines joined, comment removed."""
    exit_code: int = 0


def doc_commands(markdown: str, page: str = "page.md") -> list[DocCommand]:
    """The ``imupipe`` command lines of the shell code blocks of ``markdown``, in order."""
    commands: list[DocCommand] = []
    fence: str | None = None
    pending, start = "", 0
    for number, raw in enumerate(markdown.splitlines(), 1):
        stripped = raw.strip()
        if stripped.startswith("```"):
            fence = stripped[3:].strip().lower() if fence is None else None
            pending = ""
            continue
        if fence not in SHELL_FENCES:
            continue
        if not pending:
            start = number
        line = pending + stripped.removeprefix("$ ")
        if line.endswith("\\"):
            pending = line[:-1] + " "
            continue
        pending = ""
        words = shlex.split(line, comments=True)
        if not words or words[0] != "imupipe":
            continue
        code = re.search(r"#.*\bexits (\d+)", line)
        commands.append(DocCommand(page, start, shlex.join(words), int(code[1]) if code else 0))
    return commands


def all_commands() -> list[DocCommand]:
    return [c for p in PAGES for c in doc_commands(p.read_text(), p.relative_to(ROOT).as_posix())]


def test_doc_commands_are_extracted_with_continuations_comments_and_codes() -> None:
    text = (
        "```bash\nimupipe record -o a.mcap \\\n  --duration 5m   # short\n```\n"
        "```python\nimupipe.analyze('x')\n```\n"
        "```console\n$ imupipe analyze missing.mcap   # exits 2\n```\n"
        "```\nimupipe analyze x --topic '#1'\nrerun x.rrd\n```\n"
        "imupipe analyze outside.mcap\n"
    )
    assert doc_commands(text) == [
        DocCommand("page.md", 2, "imupipe record -o a.mcap --duration 5m"),
        DocCommand("page.md", 9, "imupipe analyze missing.mcap", 2),
        DocCommand("page.md", 12, "imupipe analyze x --topic '#1'"),
    ]


def test_the_readme_shows_the_five_commands_and_every_skip_is_used() -> None:
    commands = all_commands()
    readme = {shlex.split(c.text)[1] for c in commands if c.page == "README.md"}
    assert {"record", "analyze", "view", "export", "fleet"} <= readme
    for key in NOT_RUN:
        assert any(key in c.text for c in commands), f"NOT_RUN entry {key!r} matches no command"


def test_every_relative_link_of_the_docs_resolves() -> None:
    broken = [
        f"{page.relative_to(ROOT)}: {target}"
        for page in PAGES
        for target in re.findall(r"\]\(([^)\s#]+)(?:#[^)]*)?\)", page.read_text())
        if "://" not in target and not (page.parent / target).exists()
    ]
    assert not broken


@pytest.fixture(scope="module")
def robot_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory = tmp_path_factory.mktemp("bag") / "robot_bag"
    write_robot_bag(directory)
    return directory


def _workspace(root: Path, robot_bag: Path) -> Path:
    shutil.copytree(ROOT / "sample_logs", root / "sample_logs")
    shutil.copytree(robot_bag, root / "robot_bag")
    (root / "units").mkdir()
    for unit in ("unit_a", "unit_b"):
        shutil.copy(root / "sample_logs/adis16364_default_5min.mcap", root / f"units/{unit}.mcap")
    viewer = root / ".viewer_stub"
    viewer.write_text('#!/bin/sh\ntest -s "$1"\n')
    viewer.chmod(0o755)
    return root


def _argv(command: DocCommand, workspace: Path) -> list[str]:
    words = shlex.split(command.text)[1:]
    args = [m for w in words for m in (sorted(glob.glob(w, root_dir=workspace)) or [w])]
    if args[0] == "view":
        return [sys.executable, "-c", VIEW_STUB, str(workspace / ".viewer_stub"), *args]
    return [sys.executable, "-m", "imupipe", *args]


@pytest.mark.parametrize("page", sorted({c.page for c in all_commands()}))
def test_every_command_of_the_page_runs(page: str, tmp_path: Path, robot_bag: Path) -> None:
    commands = [c for c in all_commands() if c.page == page]
    workspace = _workspace(tmp_path, robot_bag)
    group = typer.main.get_command(app)
    known = set(group.commands) | {o for p in group.params for o in p.opts}  # --version
    env = os.environ | {"NUMBA_NUM_THREADS": "1"}
    ran = 0
    for command in commands:
        if any(key in command.text for key in NOT_RUN):
            continue
        sub = shlex.split(command.text)[1]
        assert sub in known, f"{page}:{command.line}: no command {sub!r} in the CLI"
        done = subprocess.run(
            _argv(command, workspace), cwd=workspace, capture_output=True, text=True, env=env
        )
        where = f"{page}:{command.line}: {command.text}"
        assert "Traceback" not in done.stderr, f"{where}\n{done.stderr}"
        assert "internal error" not in done.stderr, f"{where}\n{done.stderr}"
        assert done.returncode == command.exit_code, f"{where}\n{done.stderr[-2000:]}"
        ran += 1
    assert ran or all(any(k in c.text for k in NOT_RUN) for c in commands)
