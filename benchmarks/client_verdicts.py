"""The verdict on healthy runs of the independent textbook EKF-SLAM (issue 36's third class).

The client (``tests/clients/textbook_ekfslam.py``, shares no code with slamrel's EKF-SLAM) is
run with its pose noise ``Cx`` set to the true noise of its controls per step and proper
landmark initialisation (``--tuned``: σ_x = σ_y = σ_v·dt, σ_θ = σ_ω·dt; the sideways σ
overstates the true, zero, sideways noise: the world-frame diagonal cannot say it) or with its
PythonRobotics defaults (``Cx`` five to thirty times the true noise, improper initialisation), exported with its own model (``velocity-euler``,
``map_source: log``) and judged by ``slamrel run``'s pipeline (``slamrel.studies.calibration.
judged_case``, class ``textbook EKF-SLAM healthy``). The study code cannot import from
``tests/``, so this class runs here (and in ``tests/test_calibration.py``).

    nice python benchmarks/client_verdicts.py --seeds 10-19 --tuned
"""

from __future__ import annotations

import argparse
import collections
import math
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from clients.export import online  # noqa: E402
from clients.measure import export  # noqa: E402
from clients.textbook_ekfslam import Config, run  # noqa: E402

from slamrel.pipeline import RunInput, score_bundle  # noqa: E402
from slamrel.studies.calibration import TEXTBOOK, judged_case  # noqa: E402


def tuned_config() -> Config:
    """``Cx`` from the true control noise over one step (the client's ``dt``), landmarks
    initialised properly (from the pose and the measurement with their Jacobians; the default
    ``improper`` one enters at ``1 · I`` uncorrelated with the pose and then updates with the
    same measurement a second time: overconfident by construction)."""
    c = Config()
    sx = c.control_sigma[0] * c.dt
    return Config(cx=(sx, sx, c.control_sigma[1] * c.dt), init="proper")


def textbook_case(seed: int, tuned: bool = True) -> dict:  # type: ignore[type-arg]
    """One client run, exported with its own model and judged."""
    r = run(seed, tuned_config() if tuned else Config())
    with tempfile.TemporaryDirectory() as tmp:
        bundle, _ = export(r, Path(tmp), "velocity-euler")
        result = score_bundle(RunInput(bundle, name=f"textbook/{seed}", online=online(r)))
    return judged_case(result, TEXTBOOK)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", default="10-19")
    p.add_argument("--tuned", action="store_true")
    a = p.parse_args(argv)
    lo, _, hi = a.seeds.partition("-")
    counts: collections.Counter[str] = collections.Counter()
    for seed in range(int(lo), int(hi or lo) + 1):
        res = textbook_case(seed, a.tuned)
        counts[res["overall"]] += 1
        bad = {k: v for k, v in res["levels"].items() if v in ("amber", "red")}
        q = {
            k: round(float(res["values"][k]), 2)
            for k in ("consistency", "online_consistency", "map_consistency", "map_log")
            if isinstance(res["values"].get(k), float) and math.isfinite(res["values"][k])
        }
        print(f"seed {seed}: {res['overall']} {bad} q {q}", flush=True)
    print(f"class {TEXTBOOK} ({'tuned' if a.tuned else 'default'} Cx): {dict(counts)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
