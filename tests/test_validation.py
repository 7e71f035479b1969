"""Recovery is faithful: it ranks SLAM runs as their online trajectories do (issue 5, item 5)."""

from __future__ import annotations

import numpy as np
import pytest

from slamrel.validation import faithfulness_study


@pytest.mark.slow
def test_recovered_ranks_runs_like_online(capsys):
    study = faithfulness_study("complex1")
    n = len(study.configs)
    tau_g, tau_l = study.kendall_tau("global"), study.kendall_tau("consecutive")
    ratio = study.ratio("global")
    with capsys.disabled():
        print(
            f"\nfaithfulness over {n} runs: Kendall tau {tau_g:.3f} (global), "
            f"{tau_l:.3f} (consecutive); "
            f"recovered/online global error ratio min {ratio.min():.2f}, median "
            f"{np.median(ratio):.2f}, max {ratio.max():.2f}"
        )
    assert n >= 20
    assert tau_g >= 0.8 and tau_l >= 0.8
    # the final map is at least as good as the map the filter had online: recovered errors
    # are not larger than online ones beyond a small margin, and never an order smaller
    assert ratio.max() < 1.25 and ratio.min() > 0.25
