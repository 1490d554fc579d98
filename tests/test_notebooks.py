"""The notebooks: stored with their outputs (cheap checks), and still executing top
to bottom (slow: several minutes of JIT compilation and validation)."""

from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = Path(__file__).resolve().parent.parent / "notebooks"
ALL = sorted(NOTEBOOKS.glob("*.ipynb"))
#: Notebooks committed executed, figures inline. To refresh one after a change:
#: `jupyter nbconvert --to notebook --execute --inplace notebooks/NAME.ipynb`.
STORED = [
    NOTEBOOKS / "01_validation.ipynb",
    NOTEBOOKS / "02_gradients.ipynb",
    NOTEBOOKS / "05_four_point_sail.ipynb",
]


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


@pytest.mark.long  # over ~10 min on 2 cores: by hand, `pytest -m long`
@pytest.mark.slow
@pytest.mark.parametrize("path", ALL, ids=lambda p: p.name)
def test_notebook_runs(path: Path):
    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(
        nb,
        timeout=900,
        kernel_name="python3",
        resources={"metadata": {"path": str(path.parent)}},
    )
    client.execute()  # raises CellExecutionError naming the failing cell
