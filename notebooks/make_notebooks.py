"""Write the walkthrough notebooks from the cell sources below.

Run ``python notebooks/make_notebooks.py --execute`` (needs the real data in
``../shared/data`` or ``SLAMREL_DATA``) to store the notebooks with their outputs, so that the
numbers and figures can be read without running anything; without ``--execute`` the
outputs are left empty. Notebooks are generated, not hand-edited, so that their source is
reviewable as plain Python; the test suite executes every ``notebooks/*.ipynb`` (and checks
that their cell sources are the ones below) so they cannot rot.
"""

from __future__ import annotations

from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

HERE = Path(__file__).resolve().parent

RELATION_METRIC = [
    new_markdown_cell(
        "# The relation metric, step by step\n\n"
        "Kümmerle et al. (2009) score a SLAM result by its *relative* motions: for reference "
        "relations $\\delta^*_{ij}$ between poses $i$ and $j$, the estimate's "
        "$\\delta_{ij} = x_i^{-1} \\circ x_j$ is compared in the frame of the relation, "
        "$\\varepsilon = \\frac1N \\sum \\| \\delta_{ij} \\ominus \\delta^*_{ij} \\|^2$. "
        "This notebook walks through it on slamrel's seeded example and, when the Freiburg "
        "data is present, on benchmark run 08."
    ),
    new_code_cell(
        "import os, tempfile, warnings\n"
        "from pathlib import Path\n"
        "import numpy as np\n"
        "from relation_metric.relations import generate_relations\n"
        "from relation_metric.evaluate import evaluate\n"
        "from relation_metric.alignment import absolute_trajectory_error\n"
        "from slamrel.simulation.example import example_trajectories\n"
        "reference, estimate = example_trajectories(seed=0)\n"
        "len(reference), reference.span()"
    ),
    new_markdown_cell(
        "Local (consecutive) relations see the odometry-like error; loop-closing and global "
        "relations see the accumulated drift. docs/design.md's measured pitfall: local relations "
        "alone cannot see global breakage."
    ),
    new_code_cell(
        "rows = []\n"
        "for strategy, kw in [('consecutive', {}), ('loops', {'radius': 2.0, 'min_separation_time': 60.0}),\n"
        "                     ('global', {'count': 2000, 'seed': 1})]:\n"
        "    rel = generate_relations(reference, strategy, **kw)\n"
        "    ev = evaluate(rel, estimate)\n"
        "    t, r = ev.translation['abs'], ev.rotation['abs']\n"
        "    rows.append((strategy, len(rel), t.mean, t.std, r.mean))\n"
        "    print(f'{strategy:12s} {len(rel):5d} relations: trans {t.mean:.4f} ± {t.std:.4f} m, rot {r.mean:.4f} rad')\n"
        "assert rows[2][2] > 5 * rows[0][2]  # global relations expose the drift"
    ),
    new_markdown_cell(
        "The naive absolute error depends on where an error happened; aligning first (Umeyama, "
        "SE(2) or Sim(2)) is its rescue, but still weighs early errors differently from late "
        "ones. Side by side:"
    ),
    new_code_cell(
        "for align in ('none', 'se2', 'sim2'):\n"
        "    ate = absolute_trajectory_error(estimate, reference, align=align)\n"
        "    print(f'ATE ({align:4s}): rmse {ate.translation_stats.rmse:.3f} m')"
    ),
    new_markdown_cell(
        "Where are the errors? The figure colours the estimate by the errors of the relations at each pose."
    ),
    new_code_cell(
        "from slamrel.plots.relation_errors import evaluation_figure\n"
        "rel = generate_relations(reference, 'global', count=2000, seed=1)\n"
        "fig = evaluation_figure(evaluate(rel, estimate), estimate)"
    ),
    new_markdown_cell(
        "## Freiburg benchmark run 08 (MIT CSAIL), as the C++ metricEvaluator scores it\n\n"
        "The printed reference is `0.030205 ± 0.029165 m` over 1172 relations (translation)."
    ),
    new_code_cell(
        "from slamrel.formats.trajectories import read_trajectory\n"
        "from slamrel.formats.relations import read_relations\n"
        "data = Path(os.environ.get('SLAMREL_DATA', Path.cwd().parent.parent / 'shared' / 'data')) / 'freiburg'\n"
        "if (data / 'mit-csail.relations').exists():\n"
        "    with warnings.catch_warnings():\n"
        "        warnings.simplefilter('ignore')\n"
        "        est = read_trajectory(data / 'benchmarks/08/test.log', skip_invalid=True).trajectory\n"
        "    odo = read_trajectory(data / 'mit-csail.clf', pose='odometry').trajectory\n"
        "    ev = evaluate(read_relations(data / 'mit-csail.relations'), est, odometry=odo,\n"
        "                  mode='metricevaluator', weights='1,1,0,0,0,0')\n"
        "    s = ev.combined['abs']\n"
        "    print(f'{s.mean:.6f} ± {s.std:.6f} m, min {s.min:.6f}, max {s.max:.6f}, n = {s.count}')\n"
        "    assert f'{s.mean:.6f}' == '0.030205'\n"
        "else:\n"
        "    print('Freiburg data not found at', data)"
    ),
]


RUN_WALKTHROUGH = [
    new_markdown_cell(
        "# `slamrel run`, step by step\n\n"
        "A filter-based SLAM run keeps no trajectory. slamrel rebuilds it offline by EKF "
        "localisation in the final map (same models, same data associations), smooths it, and "
        "scores it with the relation metric. This notebook runs the chain on a simulated world "
        "and shows why the recovery must not gate measurements away."
    ),
    new_code_cell(
        "import numpy as np\n"
        "from slamrel.simulation.worlds import make_world\n"
        "from slamrel.backends.ekf_slam import ekf_slam_bundle\n"
        "from slamrel.simulation.bundles import world_bundle\n"
        "from recovery.recover import recover\n"
        "from relation_metric.evaluate import evaluate\n"
        "from relation_metric.relations import generate_relations\n"
        "from relation_metric.trajectory import Trajectory\n"
        "world = make_world('complex1', noise='a', seed=0)\n"
        "log = world_bundle(world)            # odometry + measurements + true map\n"
        "bundle, slam = ekf_slam_bundle(log)      # what an EKF-SLAM run leaves: map, covariance, associations\n"
        "len(world.truth), bundle.map_ids.size, int(bundle.measurement_associated.sum())"
    ),
    new_code_cell(
        "rec = recover(bundle, method='smoother')\n"
        "truth = world.truth\n"
        "k = np.searchsorted(rec.trajectory.timestamps, truth.timestamps)\n"
        "recovered = Trajectory(truth.timestamps, rec.trajectory.poses[k])\n"
        "rel = generate_relations(truth, 'global', count=2000, seed=0)\n"
        "for name, est in [('recovered', recovered), ('dead reckoning', world.odometry)]:\n"
        "    print(f\"{name:15s} {evaluate(rel, est).translation['abs'].mean:.4f} m\")\n"
        "rec.report()['measurements']"
    ),
    new_markdown_cell(
        "## Gating can hide a broken map\n\n"
        "Corrupt 3% of the SLAM run's data associations: its map breaks. Localising in it with a "
        "99.9% χ² innovation gate throws most disagreeing measurements away and scores almost "
        "like a healthy run; without the gate the recovery is faithful to the broken map. The "
        "gated fraction is part of the result."
    ),
    new_code_cell(
        "broken, _ = ekf_slam_bundle(log, corrupt_fraction=0.03, seed=1)\n"
        "for gate in (None, 0.999):\n"
        "    r = recover(broken, method='smoother', gate=gate, max_outlier_run=None)\n"
        "    k = np.searchsorted(r.trajectory.timestamps, truth.timestamps)\n"
        "    e = evaluate(rel, Trajectory(truth.timestamps, r.trajectory.poses[k])).translation['abs'].mean\n"
        '    print(f"gate {gate}: global error {e:.3f} m, gated {100 * r.counts.gated_fraction:.1f}% of the measurements")'
    ),
    new_markdown_cell(
        "The whole chain, with its report, is one call (`slamrel run` on the command line):"
    ),
    new_code_cell(
        "import tempfile, json, pathlib\n"
        "from slamrel.pipeline import run_pipeline, write_report\n"
        "result = run_pipeline('simple1', noise='a', seed=0)\n"
        "html = write_report(result, pathlib.Path(tempfile.mkdtemp()) / 'report')\n"
        "m = json.loads((html.parent / 'metrics.json').read_text())\n"
        "{k: m[k]['translation']['abs']['mean'] for k in ('trajectory', 'dead_reckoning', 'online')}"
    ),
]

VALIDATION = [
    new_markdown_cell(
        "# Is the recovery faithful?\n\n"
        "Over 24 seeded EKF-SLAM runs on `complex1` (noise types a, b, c × 0–4% corrupted data "
        "associations × 2 seeds), compare the relation metric of the trajectory recovered from "
        "each run's final map with that of the trajectory the filter estimated online. If the "
        "recovery is faithful, both rank the runs alike (Kendall τ)."
    ),
    new_code_cell(
        "import numpy as np\n"
        "from slamrel.studies.faithfulness import faithfulness_study\n"
        "study = faithfulness_study('complex1')\n"
        "print('Kendall tau (global relations):', round(study.kendall_tau('global'), 3))\n"
        "print('Kendall tau (consecutive):     ', round(study.kendall_tau('consecutive'), 3))\n"
        "ratio = study.ratio('global')\n"
        "print('recovered / online, global: min %.2f, median %.2f, max %.2f' % (ratio.min(), np.median(ratio), ratio.max()))\n"
        "assert study.kendall_tau('global') >= 0.8"
    ),
    new_markdown_cell(
        "The mean errors agree within a factor of about 0.6–1.05: the recovered trajectory is "
        "never worse than the online one by more than a few percent, and up to ~1.6× better for "
        "healthy runs. The reason is that the recovery localises in the *final* map, which is "
        "better than the map the filter had early in the run; the recovered score measures the "
        "final map, not the filter's online estimate (docs/design.md)."
    ),
    new_code_cell(
        "import matplotlib.pyplot as plt\n"
        "fig, ax = plt.subplots(figsize=(5, 5))\n"
        "c = [cfg['corrupt_fraction'] for cfg in study.configs]\n"
        "sc = ax.scatter(study.online['global'], study.recovered['global'], c=c, cmap='viridis')\n"
        "lim = [0, max(study.online['global'].max(), study.recovered['global'].max()) * 1.05]\n"
        "ax.plot(lim, lim, 'k--', lw=0.8); ax.set_xlim(lim); ax.set_ylim(lim)\n"
        "ax.set_xlabel('online: global relation error [m]'); ax.set_ylabel('recovered [m]')\n"
        "fig.colorbar(sc, label='corrupted associations'); fig.tight_layout()"
    ),
    new_markdown_cell(
        "## Faithfulness over the filter's tuning as well\n\n"
        "The runs above differ in their noise and their wrong associations, but every filter "
        "was tuned right. Real filters are not. `tuning_study` runs EKF-SLAM on `complex1` "
        "(noise b) over a grid of **process-noise scale** {0.03, 0.1, 0.3, 1, 10} (the "
        "filter's assumed motion noise, relative to the true one) × **wrong associations** "
        "{0, 0.2, 0.5, 1, 2%}, and recovers each run with the CLI's default recovery (no "
        "gate; redescending robust weights `(c/d)²` beyond `c = 1.75` standardised by the "
        "scale of a plain pass; stretches where map and log disagree are re-entered and "
        "reported)."
    ),
    new_code_cell(
        "from slamrel.studies.faithfulness import tuning_study\n"
        "grid = tuning_study('complex1')\n"
        "print(f\"{'scale':>6s} {'wrong':>6s} {'online':>8s} {'recovered':>9s} {'ratio':>6s} "
        "{'disagree':>8s}\")\n"
        "for cfg, on, rec, dis in zip(grid.configs, grid.online['global'], "
        "grid.recovered['global'], grid.disagreement):\n"
        "    print(f\"{cfg['process_noise_scale']:6g} {100 * cfg['corrupt_fraction']:5.1f}% "
        '{on:8.3f} {rec:9.3f} {rec / on:6.2f} {100 * dis:7.1f}%")\n'
        "summary = grid.summary()\n"
        "summary"
    ),
    new_markdown_cell(
        "**How to read the two scores.** The *online* error is what the filter estimated "
        "while it ran; the *recovered* error is how well the run's **final map**, with the "
        "run's own models and associations, localises the log. They answer different "
        "questions, and a mis-tuned filter separates them:\n\n"
        "* An over-confident filter (process noise 0.03–0.1×) keeps a map whose covariance is "
        "too small; localising in it with the same over-confident motion model, the recovery "
        "sees innovations far outside their χ² bound and reports stretches of map/log "
        "disagreement (the `disagree` column) even without a wrong association. That is a "
        "true finding about the *tuning*: the map and the models do not agree with the "
        "log. The recovered error itself stays close to the online one (ratio ≤ 1.5).\n"
        "* An under-confident filter (10×) trusts its measurements more than its motion; its "
        "final map is good, and the recovered error is at or below the online one, as for "
        "well-tuned runs: the final map is better than the map the filter had early on.\n"
        "* A broken map (any wrong association) scores as broken, whatever the tuning: the "
        "recovered far-apart error stays of the order of the online one (ratio ≥ 0.5), so "
        "no broken map looks healthy.\n\n"
        "Read the recovered score as *the quality of the final map under the run's models* "
        "and the disagreement fraction as *how much of the log that map and those models "
        "cannot explain*; neither is the trajectory error the filter had online.\n\n"
        "**Rank statistics.** Kendall τ compares the two rankings of all 25 runs. Among the "
        "healthy runs the errors differ by less than the run-to-run spread, so their order is "
        "close to a coin toss and pulls τ down without saying anything about faithfulness; "
        "the question a user asks of the score — *is this run broken?* — is answered by the "
        "separation `P(recovered error of a broken run > that of a healthy run)` (the "
        "Mann–Whitney AUC), which should be 1."
    ),
    new_code_cell(
        "print('Kendall tau, far-apart: %.3f, consecutive: %.3f' % "
        "(summary['kendall_tau_global'], summary['kendall_tau_consecutive']))\n"
        "print('separation (broken vs healthy, far-apart): %.3f' % summary['separation_global'])\n"
        "print('recovered/online, broken runs min %.2f, healthy runs max %.2f' % "
        "(summary['ratio_broken_min'], summary['ratio_healthy_max']))\n"
        "assert summary['ratio_broken_min'] >= 0.5 and summary['ratio_healthy_max'] <= 1.5\n"
        "assert summary['kendall_tau_global'] >= 0.8 and summary['separation_global'] == 1.0\n"
        "fig, ax = plt.subplots(figsize=(5, 5))\n"
        "sc = ax.scatter(grid.online['global'], grid.recovered['global'], "
        "c=np.log10([c['process_noise_scale'] for c in grid.configs]), "
        "marker='o', cmap='coolwarm')\n"
        "ax.set_xscale('log'); ax.set_yscale('log')\n"
        "lim = [0.1, 30]; ax.plot(lim, lim, 'k--', lw=0.8)\n"
        "ax.set_xlabel('online: far-apart relation error [m]'); ax.set_ylabel('recovered [m]')\n"
        "fig.colorbar(sc, label='log10 process-noise scale'); fig.tight_layout()"
    ),
    new_markdown_cell(
        "## The default on real data: why it is the default\n\n"
        "MRCLAM dataset 7, robots 1–5, with the fitted noise and the surveyed map (whose frame "
        "is Vicon's). Error measures: position ATE after SE(2) alignment at the Vicon times "
        "(`filter`, `smoother`), the same without alignment (`_raw`), and the mean "
        "translational error of the 1 s relations (`_1s`) and of the loop relations (`_lp`: "
        "reference poses once a second, within 0.5 m of each other and at least 30 s apart); "
        "ratios are to min(plain EKF, "
        "99.9%-gated EKF). Variants: `plain` and `gated` without re-entry or weights, "
        "`reentry` (plain + re-entry, the default before), `default` (redescending weights, "
        "`c = 1.75`), `cauchy` (iterated, `c = 1.5`).\n\n"
        "Why the plain EKF loses: at the Vicon poses the measurements are heavy-tailed — the "
        "bearing residuals of robots 3 and 5 have a standard deviation of 0.08–0.09 rad "
        "against the fitted 0.008–0.009, and robot 5 sees landmark 9 with a bias of +0.078 rad "
        "and +0.18 m (a misread barcode, most likely). The iterated M-estimators do not "
        "remove that: at their fixed point a gross outlier still pulls by about `c √R_eff` "
        "(Cauchy) or more (Huber); the redescending weight, taken at the filter's own "
        "innovation covariance, pulls by `c²/d`, which vanishes as the outlier grows — the "
        "effect of a gate, without a gate's cliff (nothing is rejected, so a broken map "
        "stays visible)."
    ),
    new_code_cell(
        "import os\n"
        "from pathlib import Path\n"
        "from slamrel.importers.mrclam import mrclam_bundle\n"
        "from slamrel.studies.faithfulness import RECOVERY_VARIANTS, recovery_variants_table\n"
        "data = Path(os.environ.get('SLAMREL_DATA', Path.cwd().parent.parent / 'shared' / "
        "'data')) / 'mrclam' / 'MRCLAM_Dataset7'\n"
        "keep = {k: RECOVERY_VARIANTS[k] for k in ('plain', 'gated', 'reentry', 'default', "
        "'cauchy')}\n"
        "rows = recovery_variants_table({f'robot {r}': mrclam_bundle(data, r) for r in range(1, 6)}, "
        "keep)\n"
        "print(f\"{'':8s} {'variant':8s} {'filter':>7s} {'ratio':>6s} {'smooth':>7s} "
        "{'f_raw':>6s} {'s_raw':>6s} {'f_1s':>7s} {'s_1s':>7s} {'f_lp':>6s} {'s_lp':>6s} "
        "{'down%':>6s} {'loss%':>6s}\")\n"
        "for r in rows:\n"
        "    print(f\"{r['bundle']:8s} {r['variant']:8s} {r['filter']:7.4f} "
        "{r['filter_ratio']:6.3f} {r['smoother']:7.4f} {r['filter_raw']:6.3f} "
        "{r['smoother_raw']:6.3f} {r['filter_1s']:7.4f} {r['smoother_1s']:7.4f} "
        "{r['filter_loops']:6.3f} {r['smoother_loops']:6.3f} "
        "{100 * r['downweighted_fraction']:6.1f} {100 * r['downweight_loss']:6.1f}\")\n"
        "default = [r for r in rows if r['variant'] == 'default']\n"
        "assert all(r['filter_ratio'] <= 1.05 and r['gated_fraction'] == 0 for r in default)\n"
        "assert all(r['filter_1s_ratio'] <= 1.05 and r['filter_loops_ratio'] <= 1.05 "
        "for r in default)\n"
        "assert all(r['smoother_1s'] < r['filter_1s'] and r['smoother_loops'] < r['filter_loops'] "
        "for r in default)"
    ),
    new_markdown_cell(
        "The default's filter is within 0.87–1.03× of the better plain choice on every robot "
        "(aligned ATE), gates nothing and reports its down-weighted share (about a quarter of "
        "the measurements lose some weight; `loss%` is the share of information they lose). "
        "On the relation measures it is within 0.81–0.94× (1 s) and 0.91–1.04× (loops). "
        "Its smoother is below its filter on the 1 s and loop relations and the unaligned ATE "
        "of every robot, and on the aligned ATE of all but robot 4 — where every variant's "
        "smoother is "
        "1.03–1.04× its filter. Robot 4's measurements are biased at the Vicon poses (bearing "
        "−0.011 rad on average, negative for all 15 landmarks; range −0.16 to −0.29 m on "
        "landmarks 3–7, seen after a 25 s stretch without measurements around t = 265–290 s): "
        "the filter's error from that bias is largely a rigid offset, which the SE(2) "
        "alignment removes; the smoother spreads the biased corrections back over the "
        "stretch, which it does not.\n\n"
        "Smaller `c` fits MRCLAM slightly better (at `c = 1.25` the smoother also wins robot 4 "
        "aligned) but over-confident healthy runs of the grid above then look broken "
        "(recovered/online 1.71 at process noise 0.3×, separation 0.99); `c = 1.75` keeps the "
        "grid's bounds."
    ),
]


MRCLAM = [
    new_markdown_cell(
        "# MRCLAM dataset 7, robot 1\n\n"
        "Leung, Halpern, Barfoot, Liu, *The UTIAS Multi-Robot Cooperative Localization and "
        "Mapping Dataset*, IJRR 2011. The robot's odometry `(t, v, ω)` drives the velocity "
        "model; measurements of the 15 landmarks (barcodes mapped to subjects, sightings of the "
        "other robots left out and counted) are the known data association. Noise is fitted from "
        "the data against the Vicon ground truth. The data is read from `../shared/data` "
        "(`SLAMREL_DATA`); it is not part of this repository."
    ),
    new_code_cell(
        "import os, warnings\n"
        "from pathlib import Path\n"
        "import numpy as np\n"
        "from slamrel.importers.mrclam import mrclam_bundle, read_mrclam_robot, fit_noise\n"
        "data = Path(os.environ.get('SLAMREL_DATA', Path.cwd().parent.parent / 'shared' / 'data')) / 'mrclam' / 'MRCLAM_Dataset7'\n"
        "HAVE_DATA = data.exists()\n"
        "print('data:', data, 'found' if HAVE_DATA else 'NOT found: the cells below do nothing')"
    ),
    new_code_cell(
        "if HAVE_DATA:\n"
        "    robot = read_mrclam_robot(data, 1)\n"
        "    print(robot.controls.shape[0], 'controls;', robot.measurements.shape[0], 'landmark measurements;',\n"
        "          robot.robot_sightings, 'robot sightings left out;', robot.unknown_barcodes, 'unknown barcodes')\n"
        "    lm = np.loadtxt(data / 'Landmark_Groundtruth.dat')[:, :3]\n"
        "    for window in (0.5, 1.0, 2.0):\n"
        "        print(window, 's windows:', fit_noise(robot, lm, window=window))"
    ),
    new_markdown_cell(
        "The fitted control noise depends on the window: odometry errors are correlated in time "
        "(σ_v grows with the window) and short windows see the ground truth's own differentiation "
        "noise (σ_ω shrinks with the window). The bundle uses 1 s windows.\n\n"
        "MRCLAM's odometry rows are velocity *commands*. Against Vicon they lead the motion by "
        "about a quarter of a second and are ~10% too fast; the importer fits that delay and the "
        "two scales (`calibrate_odometry`), splits rows held over logging gaps (a 0.5 s gap "
        "would otherwise carry the noise of 2500 rows), and fits the noise on the result. Dead "
        "reckoning below uses the same corrected controls as the SLAM; the raw commands are "
        "shown too."
    ),
    new_code_cell(
        "if HAVE_DATA:\n"
        "    from slamrel.backends.ekf_slam import ekf_slam_bundle\n"
        "    from recovery.recover import recover\n"
        "    from recovery.steps import build_steps\n"
        "    from relation_metric import se2\n"
        "    from relation_metric.evaluate import evaluate\n"
        "    from relation_metric.relations import generate_relations\n"
        "    from relation_metric.trajectory import Trajectory\n"
        "    from slamrel.importers.mrclam import calibrate_odometry\n"
        "    print(calibrate_odometry(robot))\n"
        "    bundle = mrclam_bundle(data, 1)\n"
        "    raw = mrclam_bundle(data, 1, calibrate=False)\n"
        "    # EKF-SLAM with a 99.9% validation gate (10 rejections in a row: take the next one)\n"
        "    slam, online = ekf_slam_bundle(bundle, outlier_gate=0.999)\n"
        "    print((online.association < 0).sum(), 'of', online.association.size, 'measurements rejected by the gate')\n"
        "    # recovery uses the SLAM run's associations (rejected ones stay out), no gate of its own\n"
        "    rec = recover(slam, method='smoother', max_outlier_run=None)\n"
        "    gt = bundle.groundtruth\n"
        "    step = int(round(1 / np.median(np.diff(gt.timestamps))))\n"
        "    ref = Trajectory(gt.timestamps[::step], gt.poses[::step])\n"
        "    sets = {'consecutive 1 s': generate_relations(ref, 'consecutive'),\n"
        "            'loops': generate_relations(ref, 'loops', radius=0.5, min_separation_time=30)}\n"
        "    st = build_steps(bundle)\n"
        "    dead = Trajectory(st.times, se2.cumulative_compose(st.u, start=bundle.initial_pose))\n"
        "    st_raw = build_steps(raw)\n"
        "    dead_raw = Trajectory(st_raw.times, se2.cumulative_compose(st_raw.u, start=raw.initial_pose))\n"
        "    with warnings.catch_warnings():\n"
        "        warnings.simplefilter('ignore')\n"
        "        for name, est in (('recovered', rec.trajectory), ('dead reckoning', dead), ('raw odometry', dead_raw)):\n"
        "            for rs, rel in sets.items():\n"
        "                ev = evaluate(rel, est, max_time_diff=0.05, interpolate=True)\n"
        "                t = ev.translation['abs']\n"
        "                print(f'{name:15s} {rs:16s} {t.mean:.4f} ± {t.std:.4f} m over {t.count} relations')\n"
        "    print(rec.report()['measurements'])"
    ),
    new_markdown_cell(
        "EKF-SLAM has no absolute heading: landmarks are mapped from the pose the filter has when "
        "it first sees them, so the heading that dead reckoning lost before then stays in the "
        "whole map (robot 1: 20° within the first 40 s). Relations do not see such a rigid "
        "offset. For the picture each estimate is rigidly aligned to Vicon (Umeyama on the "
        "positions; the map moves with the recovered trajectory); the angles are printed."
    ),
    new_code_cell(
        "if HAVE_DATA:\n"
        "    import matplotlib.pyplot as plt\n"
        "    from relation_metric.alignment import umeyama\n"
        "    def to_vicon(tr):\n"
        "        at = np.column_stack([np.interp(tr.timestamps, gt.timestamps, gt.poses[:, k]) for k in range(2)])\n"
        "        return umeyama(tr.poses[:, :2], at)\n"
        "    al_rec, al_dr = to_vicon(rec.trajectory), to_vicon(dead)\n"
        "    print(f'alignment to Vicon: recovered + map {np.degrees(al_rec.angle):.1f} deg, dead reckoning {np.degrees(al_dr.angle):.1f} deg')\n"
        "    r_al, d_al = al_rec.apply(rec.trajectory.poses), al_dr.apply(dead.poses)\n"
        "    m_al = al_rec.apply(np.column_stack((slam.map_xy, np.zeros(len(slam.map_xy)))))\n"
        "    fig, ax = plt.subplots(figsize=(6, 6))\n"
        "    ax.plot(gt.poses[:, 0], gt.poses[:, 1], 'k-', lw=1, label='Vicon')\n"
        "    ax.plot(r_al[:, 0], r_al[:, 1], lw=0.8, label='recovered (aligned)')\n"
        "    ax.plot(d_al[:, 0], d_al[:, 1], lw=0.8, label='dead reckoning (aligned)')\n"
        "    ax.plot(bundle.map_xy[:, 0], bundle.map_xy[:, 1], 'k+', ms=8, label='surveyed landmarks')\n"
        "    ax.plot(m_al[:, 0], m_al[:, 1], 'ro', mfc='none', label='EKF-SLAM map (aligned)')\n"
        "    ax.set_aspect('equal'); ax.set_xlabel('x [m]'); ax.set_ylabel('y [m]'); ax.legend(fontsize=8)\n"
        "    plt.show()"
    ),
    new_markdown_cell(
        "Loop relations separate the SLAM result from dead reckoning by an order of magnitude. "
        "On 1 s consecutive relations the difference is small (over one second the corrected "
        "odometry is already good) but consistent in rotation: `slamrel compare`'s block-bootstrap "
        "test (below) finds the recovered trajectory better in rotation on all five robots "
        "(−19 to −37 %), in translation on robots 2 and 3 (−16 to −18 %; robots 1, 4 and 5, "
        "−5 to −12 %, are not significant after Holm over the table). Before the "
        "odometry calibration, the gap splitting and the gate, the recovered trajectory was "
        "*worse* than dead reckoning on 1 s relations: the smoother put its corrections into "
        "the logging gaps, and measurement outliers moved the pose.\n\n"
        "The map: the EKF-SLAM landmarks against the surveyed ones on the Delaunay mesh of the "
        "survey, one error per edge (length) and per corner (angle); the figure colours each "
        "edge by its error."
    ),
    new_code_cell(
        "if HAVE_DATA:\n"
        "    from IPython.display import display\n"
        "    from landmark_graph.map_compare import compare_maps\n"
        "    from landmark_graph.maps import LandmarkMap\n"
        "    from slamrel.plots.maps import map_figure\n"
        "    mc = compare_maps(LandmarkMap(slam.map_ids, slam.map_xy), LandmarkMap(*bundle.landmarks_groundtruth))\n"
        "    edges = mc.mesh.edges\n"
        "    ids = mc.reference.ids[mc.association.reference_rows]\n"
        "    print('edge (landmarks)   length error [m]')\n"
        "    for (a, b), e in zip(edges, mc.errors.edge_length):\n"
        "        print(f'{ids[a]:3d} - {ids[b]:3d}        {e:.3f}')\n"
        "    t = mc.as_dict()['translation']['abs']\n"
        "    print(f\"{t['count']} edges: mean {t['mean']:.3f} m, median {t['median']:.3f} m, max {t['max']:.3f} m\")\n"
        "    display(map_figure(mc))"
    ),
    new_markdown_cell(
        "## All five robots\n\n"
        "The same chain for every robot of the dataset, as `slamrel import mrclam DIR -o logs`, "
        "`slamrel slam logs/robotN --outlier-gate 0.999` and `slamrel run` do it. The table "
        "is `slamrel compare`'s: translational and rotational errors (abs and squared, mean ± "
        "std) per robot and relation set, and a paired test per pair: the mean difference with "
        "a block-bootstrap interval and p-value over the relations in time order, Holm-adjusted "
        "over the table — a statement about the difference the paper's table cannot make. Loop "
        "relations overlap one another nearly everywhere, so one run holds too few independent "
        "stretches to test them: the table gives their difference (−86 to −96 %) and says why "
        "there is no test."
    ),
    new_code_cell(
        "if HAVE_DATA:\n"
        "    from slamrel.report.tables import ResultErrors, compare_results\n"
        "    results, map_edges = [], {}\n"
        "    for r in range(1, 6):\n"
        "        b = mrclam_bundle(data, r)\n"
        "        s, _ = ekf_slam_bundle(b, outlier_gate=0.999)\n"
        "        est = recover(s, method='smoother', max_outlier_run=None).trajectory\n"
        "        st = build_steps(b)\n"
        "        dr = Trajectory(st.times, se2.cumulative_compose(st.u, start=b.initial_pose))\n"
        "        g = b.groundtruth\n"
        "        k = int(round(1 / np.median(np.diff(g.timestamps))))  # Vicon at ~1 Hz\n"
        "        ref = Trajectory(g.timestamps[::k], g.poses[::k])\n"
        "        rels = {'1 s': generate_relations(ref, 'consecutive'),\n"
        "                'loops': generate_relations(ref, 'loops', radius=0.5, min_separation_time=30)}\n"
        "        with warnings.catch_warnings():\n"
        "            warnings.simplefilter('ignore')\n"
        "            for rs, rel in rels.items():\n"
        "                for name, tr in (('EKF-SLAM + recovery', est), ('dead reckoning', dr)):\n"
        "                    ev = evaluate(rel, tr, max_time_diff=0.05, interpolate=True)\n"
        "                    v = ev.valid\n"
        "                    keys = np.array([f'{a} {c}' for a, c in zip(rel.first[v], rel.second[v])])\n"
        "                    results.append(ResultErrors(f'robot {r} {rs}', name, keys,\n"
        "                                                ev.errors.translation[v], ev.errors.rotation[v], 'rad'))\n"
        "        m = compare_maps(LandmarkMap(s.map_ids, s.map_xy), LandmarkMap(*b.landmarks_groundtruth))\n"
        "        map_edges[r] = m.errors.edge_length\n"
        "    comparison = compare_results(results)\n"
        "    from IPython.display import Markdown, display\n"
        "    display(Markdown(comparison.markdown()))"
    ),
    new_code_cell(
        "if HAVE_DATA:\n"
        "    fig, axes = plt.subplots(1, 3, figsize=(12, 3.5))\n"
        "    x = np.arange(1, 6)\n"
        "    for ax, rs in zip(axes[:2], ('1 s', 'loops')):\n"
        "        for k, name in enumerate(('EKF-SLAM + recovery', 'dead reckoning')):\n"
        "            st_ = [comparison.stats[f'robot {r} {rs}', name]['translation']['abs'] for r in x]\n"
        "            ax.bar(x + (k - 0.5) * 0.38, [q.mean for q in st_], 0.38, yerr=[q.std for q in st_], label=name)\n"
        "        ax.set_title(f'{rs} relations'); ax.set_xlabel('robot'); ax.set_ylabel('translation error [m]')\n"
        "    axes[1].set_yscale('log'); axes[0].legend(fontsize=8)\n"
        "    axes[2].boxplot([map_edges[r] for r in x], positions=x)\n"
        "    axes[2].set_title('EKF-SLAM map, mesh edges'); axes[2].set_xlabel('robot'); axes[2].set_ylabel('edge length error [m]')\n"
        "    fig.tight_layout(); plt.show()"
    ),
    new_markdown_cell(
        "Robot 4 stands still for about a third of the run. With a constant velocity-model "
        "noise its pose wandered under its biased measurements while it stood, and it was only "
        "at par with dead reckoning on 1 s relations; the importer's default noise grows with "
        "the commanded speeds (Probabilistic Robotics Table 5.3, α fitted from the data), which "
        "makes a robot at rest stay put (`--motion-noise constant` gives the old model)."
    ),
]

# The full-size study (10 runs), measured with `slamrel study pose-only --runs 10 -o DIR`;
# pasted as text because it takes about half an hour (see the cell that recomputes it).
POSE_ONLY_FULL_STUDY = (
    "Measured with `slamrel study pose-only --runs 10 --workers 2 -o DIR` at commit cc52a2b (480 cases; the pose-only pair least squares started at the truth, as in the paper; TORO-style: 100 iterations). Map NEES: NEES2 for full LS, NEES3 for the others.\n"
    "\n"
    "| world | noise | method | runs | NEES1 mean | NEES1 std | NEES1 gate | runs under gate | map NEES (2 / 3) mean | map gate | map runs under gate | RMS position error [m] | RMS heading error [rad] |\n"
    "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    "| hu-simple1 | a | full LS | 10 | 240.6 | 25.5 | 280.4 | 9 | 433.9 | 495.4 | 10 | 0.070 | 0.011 |\n"
    "| hu-simple1 | a | pose-only M1 | 10 | 135.8 | 13.5 | 280.4 | 10 | 399.1 | 495.4 | 10 | 0.139 | 0.020 |\n"
    "| hu-simple1 | a | pose-only M2 | 10 | 145.5 | 13.3 | 280.4 | 10 | 419.6 | 495.4 | 10 | 0.072 | 0.012 |\n"
    "| hu-simple1 | a | TORO-style (M2) | 10 | 295.6 | 47.3 | 280.4 | 5 | 449.8 | 495.4 | 10 | 0.133 | 0.020 |\n"
    "| hu-simple1 | b | full LS | 10 | 239.6 | 25.3 | 280.4 | 9 | 434.5 | 495.4 | 10 | 0.070 | 0.012 |\n"
    "| hu-simple1 | b | pose-only M1 | 10 | 122.0 | 13.9 | 280.4 | 10 | 394.4 | 495.4 | 10 | 0.129 | 0.020 |\n"
    "| hu-simple1 | b | pose-only M2 | 10 | 135.2 | 13.4 | 280.4 | 10 | 419.8 | 495.4 | 10 | 0.069 | 0.012 |\n"
    "| hu-simple1 | b | TORO-style (M2) | 10 | 287.2 | 54.8 | 280.4 | 6 | 449.4 | 495.4 | 10 | 0.129 | 0.020 |\n"
    "| hu-simple1 | c | full LS | 10 | 239.3 | 22.5 | 280.4 | 9 | 433.5 | 495.4 | 10 | 0.203 | 0.031 |\n"
    "| hu-simple1 | c | pose-only M1 | 10 | 185.0 | 13.8 | 280.4 | 10 | 419.6 | 495.4 | 10 | 0.455 | 0.059 |\n"
    "| hu-simple1 | c | pose-only M2 | 10 | 181.9 | 11.3 | 280.4 | 10 | 423.7 | 495.4 | 10 | 0.264 | 0.037 |\n"
    "| hu-simple1 | c | TORO-style (M2) | 10 | 370.1 | 40.4 | 280.4 | 0 | 455.9 | 495.4 | 9 | 0.395 | 0.055 |\n"
    "| hu-simple2 | a | full LS | 10 | 247.9 | 20.1 | 280.4 | 9 | 438.0 | 496.2 | 9 | 0.115 | 0.015 |\n"
    "| hu-simple2 | a | pose-only M1 | 10 | 140.1 | 9.7 | 280.4 | 10 | 403.2 | 496.2 | 10 | 0.182 | 0.024 |\n"
    "| hu-simple2 | a | pose-only M2 | 10 | 151.2 | 10.5 | 280.4 | 10 | 423.5 | 496.2 | 9 | 0.115 | 0.015 |\n"
    "| hu-simple2 | a | TORO-style (M2) | 10 | 242.8 | 15.1 | 280.4 | 10 | 435.8 | 496.2 | 9 | 0.115 | 0.016 |\n"
    "| hu-simple2 | b | full LS | 10 | 249.1 | 22.6 | 280.4 | 9 | 438.3 | 496.2 | 9 | 0.116 | 0.015 |\n"
    "| hu-simple2 | b | pose-only M1 | 10 | 127.5 | 12.5 | 280.4 | 10 | 398.4 | 496.2 | 10 | 0.187 | 0.024 |\n"
    "| hu-simple2 | b | pose-only M2 | 10 | 142.0 | 12.5 | 280.4 | 10 | 423.1 | 496.2 | 9 | 0.114 | 0.015 |\n"
    "| hu-simple2 | b | TORO-style (M2) | 10 | 235.9 | 18.6 | 280.4 | 9 | 435.2 | 496.2 | 9 | 0.106 | 0.016 |\n"
    "| hu-simple2 | c | full LS | 10 | 245.6 | 15.2 | 280.4 | 10 | 438.5 | 496.2 | 9 | 0.318 | 0.040 |\n"
    "| hu-simple2 | c | pose-only M1 | 10 | 185.7 | 9.2 | 280.4 | 10 | 421.8 | 496.2 | 9 | 0.490 | 0.062 |\n"
    "| hu-simple2 | c | pose-only M2 | 10 | 184.7 | 12.0 | 280.4 | 10 | 426.9 | 496.2 | 9 | 0.335 | 0.042 |\n"
    "| hu-simple2 | c | TORO-style (M2) | 10 | 297.6 | 25.1 | 280.4 | 2 | 438.5 | 496.2 | 9 | 0.357 | 0.047 |\n"
    "| hu-complex1 | a | full LS | 10 | 1251.4 | 48.1 | 1340.6 | 9 | 438.0 | 498.8 | 10 | 0.243 | 0.027 |\n"
    "| hu-complex1 | a | pose-only M1 | 10 | 903.8 | 111.7 | 1340.6 | 10 | 849.2 | 498.8 | 6 | 2.784 | 0.176 |\n"
    "| hu-complex1 | a | pose-only M2 | 10 | 854.6 | 40.6 | 1340.6 | 10 | 494.3 | 498.8 | 7 | 1.027 | 0.080 |\n"
    "| hu-complex1 | a | TORO-style (M2) | 10 | 1832.7 | 126.7 | 1340.6 | 0 | 605.3 | 498.8 | 3 | 1.306 | 0.099 |\n"
    "| hu-complex1 | b | full LS | 10 | 1259.4 | 51.3 | 1340.6 | 9 | 442.1 | 498.8 | 10 | 0.328 | 0.048 |\n"
    "| hu-complex1 | b | pose-only M1 | 10 | 845.5 | 164.6 | 1340.6 | 10 | 1005.6 | 498.8 | 4 | 3.451 | 0.226 |\n"
    "| hu-complex1 | b | pose-only M2 | 10 | 3042.7 | 3202.5 | 1340.6 | 7 | 12168.2 | 498.8 | 2 | 3.737 | 0.309 |\n"
    "| hu-complex1 | b | TORO-style (M2) | 10 | 3821.5 | 3160.6 | 1340.6 | 0 | 12179.4 | 498.8 | 1 | 3.885 | 0.317 |\n"
    "| hu-complex1 | c | full LS | 10 | 1254.3 | 53.5 | 1340.6 | 9 | 441.6 | 498.8 | 10 | 0.568 | 0.056 |\n"
    "| hu-complex1 | c | pose-only M1 | 10 | 1441.8 | 480.9 | 1340.6 | 6 | 1545.7 | 498.8 | 3 | 5.369 | 0.350 |\n"
    "| hu-complex1 | c | pose-only M2 | 10 | 1050.2 | 51.0 | 1340.6 | 10 | 441.7 | 498.8 | 9 | 1.377 | 0.104 |\n"
    "| hu-complex1 | c | TORO-style (M2) | 10 | 1897.7 | 124.4 | 1340.6 | 0 | 548.4 | 498.8 | 3 | 2.021 | 0.154 |\n"
    "| hu-complex2 | a | full LS | 10 | 1235.5 | 42.8 | 1340.6 | 10 | 444.8 | 497.5 | 10 | 0.082 | 0.014 |\n"
    "| hu-complex2 | a | pose-only M1 | 10 | 873.4 | 190.9 | 1340.6 | 9 | 754.3 | 497.5 | 6 | 2.167 | 0.160 |\n"
    "| hu-complex2 | a | pose-only M2 | 10 | 760.2 | 26.4 | 1340.6 | 10 | 413.4 | 497.5 | 10 | 0.112 | 0.018 |\n"
    "| hu-complex2 | a | TORO-style (M2) | 10 | 2458.5 | 112.4 | 1340.6 | 0 | 505.2 | 497.5 | 6 | 0.244 | 0.030 |\n"
    "| hu-complex2 | b | full LS | 10 | 53354.1 | 156329.4 | 1340.6 | 9 | 32019.3 | 497.5 | 9 | 0.412 | 0.091 |\n"
    "| hu-complex2 | b | pose-only M1 | 10 | 737.3 | 70.4 | 1340.6 | 10 | 659.8 | 497.5 | 5 | 2.254 | 0.178 |\n"
    "| hu-complex2 | b | pose-only M2 | 10 | 678.3 | 24.9 | 1340.6 | 10 | 408.4 | 497.5 | 10 | 0.125 | 0.026 |\n"
    "| hu-complex2 | b | TORO-style (M2) | 10 | 1783.6 | 119.0 | 1340.6 | 0 | 487.6 | 497.5 | 8 | 0.283 | 0.043 |\n"
    "| hu-complex2 | c | full LS | 10 | 1232.9 | 48.4 | 1340.6 | 10 | 445.8 | 497.5 | 10 | 0.220 | 0.035 |\n"
    "| hu-complex2 | c | pose-only M1 | 10 | 1460.4 | 855.9 | 1340.6 | 7 | 1164.4 | 497.5 | 5 | 4.686 | 0.317 |\n"
    "| hu-complex2 | c | pose-only M2 | 10 | 975.9 | 41.1 | 1340.6 | 10 | 426.1 | 497.5 | 10 | 0.311 | 0.044 |\n"
    "| hu-complex2 | c | TORO-style (M2) | 10 | 2068.6 | 94.3 | 1340.6 | 0 | 493.3 | 497.5 | 8 | 0.650 | 0.072 |\n"
    "\n"
    "### The paper's findings, checked\n"
    "\n"
    "- **holds** — full LS and pose-only M2 pass the NEES1 gate in most runs.\n"
    "  holds in all groups. hu-simple1/a: full 9/10, M2 10/10; hu-simple1/b: full 9/10, M2 10/10; hu-simple1/c: full 9/10, M2 10/10; hu-simple2/a: full 9/10, M2 10/10; hu-simple2/b: full 9/10, M2 10/10; hu-simple2/c: full 10/10, M2 10/10; hu-complex1/a: full 9/10, M2 10/10; hu-complex1/b: full 9/10, M2 7/10; hu-complex1/c: full 9/10, M2 10/10; hu-complex2/a: full 10/10, M2 10/10; hu-complex2/b: full 9/10, M2 10/10; hu-complex2/c: full 10/10, M2 10/10\n"
    "\n"
    "- **does not hold** — pose-only M2 is far more accurate than M1 (RMS position error at most half).\n"
    "  fails in 7/12 groups. hu-simple1/a: M1 0.139 m, M2 0.072 m; hu-simple1/b: M1 0.129 m, M2 0.069 m; hu-simple1/c: M1 0.455 m, M2 0.264 m; hu-simple2/a: M1 0.182 m, M2 0.115 m; hu-simple2/b: M1 0.187 m, M2 0.114 m; hu-simple2/c: M1 0.490 m, M2 0.335 m; hu-complex1/a: M1 2.784 m, M2 1.027 m; hu-complex1/b: M1 3.451 m, M2 3.737 m; hu-complex1/c: M1 5.369 m, M2 1.377 m; hu-complex2/a: M1 2.167 m, M2 0.112 m; hu-complex2/b: M1 2.254 m, M2 0.125 m; hu-complex2/c: M1 4.686 m, M2 0.311 m\n"
    "\n"
    "- **holds** — the TORO-style optimiser is less consistent than pose-only LS (higher mean NEES1).\n"
    "  holds in all groups. hu-simple1/a: M2 145, TORO 296; hu-simple1/b: M2 135, TORO 287; hu-simple1/c: M2 182, TORO 370; hu-simple2/a: M2 151, TORO 243; hu-simple2/b: M2 142, TORO 236; hu-simple2/c: M2 185, TORO 298; hu-complex1/a: M2 855, TORO 1833; hu-complex1/b: M2 3043, TORO 3822; hu-complex1/c: M2 1050, TORO 1898; hu-complex2/a: M2 760, TORO 2458; hu-complex2/b: M2 678, TORO 1784; hu-complex2/c: M2 976, TORO 2069\n"
    "\n"
    "- **does not hold** — the TORO-style optimiser is least consistent under noise c (NEES1 / gate).\n"
    "  fails for hu-complex1, hu-complex2. hu-complex1: a 1.37, b 2.85, c 1.42; hu-complex2: a 1.83, b 1.33, c 1.54; hu-simple1: a 1.05, b 1.02, c 1.32; hu-simple2: a 0.87, b 0.84, c 1.06\n"
    "\n"
    "- **does not hold** — the map fitted to the pose-only M2 trajectory (NEES3) is about as consistent as full LS's map (NEES2): within 25 %.\n"
    "  fails in 2/12 groups. hu-simple1/a: full 434, M2 420; hu-simple1/b: full 435, M2 420; hu-simple1/c: full 433, M2 424; hu-simple2/a: full 438, M2 423; hu-simple2/b: full 438, M2 423; hu-simple2/c: full 438, M2 427; hu-complex1/a: full 438, M2 494; hu-complex1/b: full 442, M2 12168; hu-complex1/c: full 442, M2 442; hu-complex2/a: full 445, M2 413; hu-complex2/b: full 32019, M2 408; hu-complex2/c: full 446, M2 426\n"
)

POSE_ONLY_STUDY = [
    new_markdown_cell(
        "# Evaluation of pose-only SLAM (Hu, Huang & Dissanayake 2010), reproduced\n\n"
        "Four methods on the paper's worlds (`hu-simple1/2`: 82 poses, `hu-complex1/2`: 420; "
        "0.5 m steps, 5 m / 180° sensor, 225 features, Cartesian observation noise a/b/c):\n\n"
        "* **full LS** — least squares over poses and landmarks;\n"
        "* **pose-only M1** — constraints between adjacent poses (and last–first), observation "
        "covariances × 2;\n"
        "* **pose-only M2** — constraints between every pair sharing ≥ 5 landmarks, each "
        "observation's covariance × the number of constraints using it;\n"
        "* **TORO-style** — tree-parameterised stochastic gradient descent on the M2 graph with "
        "spherical information.\n\n"
        "NEES1 is the whole trajectory's NEES with the joint covariance against the one-sided "
        "gate χ²₀.₉₅(3(N−1)) (280.36 for 82 poses, 1340.59 for 420); the map NEES is NEES2 "
        "for full LS and NEES3 (landmarks fitted with the poses held fixed) for the others."
    ),
    new_markdown_cell(
        "## A reduced study, run here\n\n"
        "One simple world, noise a and c, 2 runs, 30 TORO iterations: small enough for the "
        "test suite, which executes this notebook."
    ),
    new_code_cell(
        "import tempfile\n"
        "from pathlib import Path\n"
        "from slamrel.cli import main\n"
        "out = Path(tempfile.mkdtemp()) / 'study'\n"
        "rc = main(['study', 'pose-only', '--runs', '2', '--worlds', 'hu-simple1', '--noise', 'a,c',\n"
        "           '--toro-iterations', '30', '-q', '-o', str(out)])\n"
        "assert rc == 0\n"
        "print((out / 'table.md').read_text())"
    ),
    new_code_cell(
        "import csv\n"
        "from slamrel.studies.pose_only import findings\n"
        "def load(path):\n"
        "    rows = list(csv.DictReader(path.open()))\n"
        "    num = lambda v: int(v) if v.isdigit() else float(v)\n"
        "    return [{k: (v if k in ('world', 'noise', 'method') else num(v)) for k, v in r.items()}\n"
        "            for r in rows]\n"
        "for title, holds, evidence in findings(load(out / 'table.csv')):\n"
        "    print(f\"{'HOLDS' if holds else 'DOES NOT HOLD'}: {title}\\n    {evidence}\")"
    ),
    new_markdown_cell(
        "## The full-size study (10 runs, all worlds and noise types)\n\n" + POSE_ONLY_FULL_STUDY
    ),
    new_markdown_cell(
        "## Where the findings do not hold, and why\n\n"
        "* **M2 far more accurate than M1** holds on the complex worlds (M1 2.2–5.4 m, M2 "
        "0.11–1.4 m RMS), except hu-complex1/b where both fail (3.5 / 3.7 m). On the simple "
        "worlds Method 1's last–first constraint closes the single loop, so M1 is 1.4–1.9 × "
        "M2's error: worse, but not by the factor 2 the check asks for.\n"
        "* **TORO-style least consistent under noise c** holds on the simple worlds only. On the "
        "complex ones it is inconsistent under every noise type (NEES1 / gate 1.3–2.9, 0 of 10 "
        "runs under the gate) and worst under b on hu-complex1, where the Method 2 graph it "
        "optimises already fails in 3 of 10 runs (0.2 rad a step of heading noise leaves parts "
        "of the trajectory constrained by odometry alone), and under a on hu-complex2.\n"
        "* **NEES3 close to NEES2** fails on hu-complex1/b (the same 3 pose-only failures) and on "
        "hu-complex2/b, where it is full LS that fails once (seed 4: Levenberg–Marquardt from "
        "the odometry stops at 3.4 m RMS error, NEES1 ≈ 5 × 10⁵), not pose-only."
    ),
]


def main(argv: list[str] | None = None) -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--execute", action="store_true", help="run them and keep the outputs")
    args = ap.parse_args(argv)
    meta = {"kernelspec": {"name": "python3", "display_name": "Python 3", "language": "python"}}
    for name, cells in (
        ("relation_metric", RELATION_METRIC),
        ("run_walkthrough", RUN_WALKTHROUGH),
        ("validation", VALIDATION),
        ("mrclam", MRCLAM),
        ("pose_only_study", POSE_ONLY_STUDY),
    ):
        for i, cell in enumerate(cells):
            cell.id = f"{name}-{i:02d}"  # stable ids: regenerating gives no diff
        nb = new_notebook(cells=cells, metadata=meta)
        if args.execute:
            import nbclient

            nbclient.NotebookClient(
                nb, timeout=900, kernel_name="python3", resources={"metadata": {"path": str(HERE)}}
            ).execute()
        nbformat.write(nb, HERE / f"{name}.ipynb")


if __name__ == "__main__":
    main()
