"""The notebooks: stored with their outputs (cheap checks), and still executing top
to bottom (slow: 20–90 s each on 2 cores with a cold compilation cache, ~5 min for
all five; the slow set of CI runs them)."""

from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = Path(__file__).resolve().parent.parent / "notebooks"
ALL = sorted(NOTEBOOKS.glob("*.ipynb"))
#: Every notebook is committed executed, figures inline. To refresh some after a
#: change: `python tests/test_notebooks.py notebooks/NAME.ipynb ...`.
STORED = ALL


def _code_cells(nb) -> list:
    return [c for c in nb.cells if c.cell_type == "code" and c.source.strip()]


@pytest.mark.parametrize("path", STORED, ids=lambda p: p.name)
def test_notebook_is_stored_with_outputs(path: Path):
    nb = nbformat.read(path, as_version=4)
    first = nb.cells[0]
    assert first.cell_type == "markdown" and first.source.startswith("# "), (
        "the title comes first"
    )
    cells = _code_cells(nb)
    # executed in one run, top to bottom: execution counts 1, 2, 3, ...
    assert [c.execution_count for c in cells] == list(range(1, len(cells) + 1)), (
        f"{path.name} is not stored executed in order: re-run it and save"
    )
    outputs = [o for c in cells for o in c.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    for c in cells:
        if "plt.show()" in c.source:
            kinds = {k for o in c.outputs for k in o.get("data", {})}
            assert "image/png" in kinds, f"a figure is missing: {c.source[:60]!r}"


@pytest.mark.slow
@pytest.mark.parametrize("path", ALL, ids=lambda p: p.name)
def test_notebook_runs(path: Path):
    _execute(path)  # raises CellExecutionError naming the failing cell


def _execute(path: Path):
    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(
        nb,
        timeout=900,
        kernel_name="python3",
        resources={"metadata": {"path": str(path.parent)}},
    )
    client.execute()
    return nb


if __name__ == "__main__":  # execute the notebooks named and store their outputs
    import sys

    for name in sys.argv[1:]:
        nbformat.write(_execute(Path(name).resolve()), name)
        print("executed and stored", name)
