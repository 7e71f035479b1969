"""Execute every notebook in notebooks/ so that the walkthroughs cannot rot (the full tier:
executing them takes minutes and a kernel each)."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import require_data

NOTEBOOKS = sorted((Path(__file__).resolve().parent.parent / "notebooks").glob("*.ipynb"))
#: The real data each notebook reads (under ``SLAMREL_DATA``): without it the notebook skips
#: (fails under ``CI=true``) instead of failing in a cell or printing that it did nothing.
NEEDS = {
    "mrclam": ("mrclam", "MRCLAM_Dataset7"),
    "relation_metric": ("freiburg", "mit-csail.relations"),
    "validation": ("mrclam", "MRCLAM_Dataset7"),
}


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs(path, tmp_path):
    if path.stem in NEEDS:
        require_data(*NEEDS[path.stem])
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


def test_every_notebook_that_reads_real_data_says_which():
    """:data:`NEEDS` names exactly the notebooks whose source reads ``SLAMREL_DATA``."""
    reads = {p.stem for p in NOTEBOOKS if "SLAMREL_DATA" in p.read_text()}
    assert reads == set(NEEDS)


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
