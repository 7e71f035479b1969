"""Execute every notebook in notebooks/ so that the walkthroughs cannot rot."""

from __future__ import annotations

from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).resolve().parent.parent / "notebooks").glob("*.ipynb"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs(path, tmp_path):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(
        nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}}
    )
    client.execute()  # raises CellExecutionError on the first failing cell
    errors = [
        o
        for c in nb.cells
        if c.cell_type == "code"
        for o in c.get("outputs", [])
        if o.get("output_type") == "error"
    ]
    assert not errors


def test_notebooks_are_generated_from_their_source():
    """The committed .ipynb files match notebooks/make_notebooks.py (no hand edits)."""
    nbformat = pytest.importorskip("nbformat")
    import importlib.util

    src = NOTEBOOKS[0].parent / "make_notebooks.py"
    spec = importlib.util.spec_from_file_location("make_notebooks", src)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    for path in NOTEBOOKS:
        committed = nbformat.read(path, as_version=4)
        name = path.stem.upper()
        if hasattr(mod, name):
            assert [c.source for c in committed.cells] == [c.source for c in getattr(mod, name)]
