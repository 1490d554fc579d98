"""The README's examples run, verbatim.

Every ```python block (in order, one namespace, one fresh Python process) and
every command line of every ```bash block (in a temporary directory, one shell
each, in order) is run as written; only the lines that install the package or run
the tests are skipped. Cheap tests check that they parse; running them is slow
(JIT compilation, three `jaxgeo validate` runs and `jaxgeo pattern`): 605 s on 2
cores in the CI rehearsal of 2026-12-07, in CI's slow set but for the
convergence study (`_by_hand_if_long`).
"""

from __future__ import annotations

import ast
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from jaxgeo.cli import build_parser

README = Path(__file__).resolve().parent.parent / "README.md"
_FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.M | re.S)


def _blocks(lang: str) -> list[str]:
    return [body for kind, body in _FENCE.findall(README.read_text()) if kind == lang]


def _skipped(line: str) -> bool:
    """Lines that install the package or run the tests."""
    words = line.split()
    return words[:2] == ["pip", "install"] or "pytest" in words


def _command_lines() -> list[str]:
    """The command lines in README order, without their comments; a command that
    appears twice (e.g. in the overview and in its own section) runs once."""
    lines = []
    for block in _blocks("bash"):
        for line in block.splitlines():
            line = line.strip()
            if not line or line.startswith("#") or _skipped(line):
                continue
            words = shlex.split(line, comments=True)
            command = shlex.join(words) if words[0] == "jaxgeo" else line
            if command not in lines:
                lines.append(command)
    return lines


def _is_setup(line: str) -> bool:
    """Lines that make the inputs of later lines without tracing any path (write a
    mesh, a CSV file): cheap, so run up front for every line's test."""
    return not line.startswith("jaxgeo ") or line.startswith("jaxgeo surface ")


COMMANDS = _command_lines()
PYTHON = "\n".join(_blocks("python"))


def _env() -> dict[str, str]:
    # the `jaxgeo` script of this interpreter's environment first on PATH; the
    # compilation cache of the test session (conftest) is inherited
    bindir = os.path.dirname(sys.executable)
    return {**os.environ, "PATH": bindir + os.pathsep + os.environ.get("PATH", "")}


def _run(line: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["bash", "-c", line],
        cwd=cwd,
        env=_env(),
        capture_output=True,
        text=True,
        timeout=1800,
    )


def test_readme_has_examples():
    assert PYTHON.strip() and any(c.startswith("jaxgeo path") for c in COMMANDS)
    assert any(c.startswith("jaxgeo surface") for c in COMMANDS), (
        "the README must say how to make the mesh files its commands use"
    )


def test_python_blocks_parse():
    ast.parse(PYTHON)


@pytest.mark.parametrize("line", [c for c in COMMANDS if c.startswith("jaxgeo ")])
def test_command_lines_parse(line):
    """Every option of every README command exists (cheap: argparse only)."""
    words = shlex.split(line)[1:]
    try:
        build_parser().parse_args(words)
    except SystemExit as e:  # argparse's usage error
        pytest.fail(f"README line does not parse: {line} (exit {e.code})")


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> Path:
    """A directory holding what the README's setup lines write."""
    d = tmp_path_factory.mktemp("readme")
    for line in COMMANDS:
        if _is_setup(line):
            r = _run(line, d)
            assert r.returncode == 0, f"{line}\n{r.stdout}\n{r.stderr}"
    return d


def test_setup_lines_run(workdir):
    """The setup lines (e.g. `jaxgeo surface ... -o tent.obj`) ran in `workdir`
    and wrote files."""
    assert any(workdir.iterdir())


#: The README's convergence study (`jaxgeo validate --resolution 3,4,5 --plot`)
#: compiles three mesh sizes for three methods: ~300 s on 2 cores, half of this
#: file's slow set. It is `long` (run by hand: `pytest -m long`) so that CI's
#: slow set keeps a margin in its 90 minutes (the rehearsal of 2026-12-07 passed
#: with 57 s to spare on a slow day); `jaxgeo validate` runs above in every
#: CI, and the study's summary and plot in `tests/test_validation.py`.
def _by_hand_if_long(line: str):
    return (
        pytest.param(line, marks=pytest.mark.long) if "--resolution" in line else line
    )


@pytest.mark.slow
@pytest.mark.parametrize(
    "line", [_by_hand_if_long(c) for c in COMMANDS if not _is_setup(c)]
)
def test_command_line_runs(line, workdir):
    r = _run(line, workdir)
    assert r.returncode == 0, f"{line}\nstdout:\n{r.stdout}\nstderr:\n{r.stderr}"


@pytest.mark.slow
def test_python_blocks_run(workdir):
    r = subprocess.run(
        [sys.executable, "-c", PYTHON],
        cwd=workdir,
        env=_env(),
        capture_output=True,
        text=True,
        timeout=1800,
    )
    assert r.returncode == 0, f"stdout:\n{r.stdout}\nstderr:\n{r.stderr}"
