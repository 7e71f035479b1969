"""``slamrel relations align`` on the MIT CSAIL log: relations that evaluate reads back."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import require_data

from relation_metric.se2 import between
from slamrel.cli import main


@pytest.mark.slow
def test_align_at_given_times_reproduces_the_authors_relations(tmp_path, capsys):
    log = require_data("freiburg", "mit-csail.clf")
    authors = np.loadtxt(require_data("freiburg", "mit-csail.relations"))
    subset = tmp_path / "first.relations"
    np.savetxt(subset, authors[:40], fmt="%.5f")
    out, report = tmp_path / "out.relations", tmp_path / "out.csv"
    args = ["relations", "align", str(log), "--at", str(subset), "-o", str(out)]
    code = main([*args, "--report", str(report)])
    assert code == 0
    assert "40 relations from 1988 FLASER scans" in capsys.readouterr().out
    ours = np.loadtxt(out)
    np.testing.assert_array_equal(ours[:, :2], np.loadtxt(subset)[:, :2])  # the given times
    e = between(authors[:40, [2, 3, 7]], ours[:, [2, 3, 7]])
    # the authors' relations are independent: consecutive pairs agree to a few centimetres
    assert np.median(np.hypot(e[:, 0], e[:, 1])) < 0.04
    assert np.degrees(np.median(np.abs(e[:, 2]))) < 0.5
    rows = report.read_text().splitlines()
    assert len(rows) == 41 and rows[0].startswith("t1,t2,x,y,theta,")
    # slamrel evaluate reads the file back
    made = tmp_path / "c.relations"
    assert main(["relations", "align", str(log), "-o", str(made), "--distance", "3", "-q"]) == 0
    assert main(["evaluate", str(made), str(log), "-q"]) == 0


def test_align_option_mistakes_exit_2(tmp_path, capsys):
    log = require_data("freiburg", "mit-csail.clf")
    code = main(["relations", "align", str(log), "-o", str(tmp_path / "x"), "--distance", "0"])
    assert code == 2
    assert "--distance must be positive" in capsys.readouterr().err
