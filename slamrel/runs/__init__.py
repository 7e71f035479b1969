"""What one run of ``slamrel run`` computed, as types: below the pipeline and the report.

The pipeline (:mod:`slamrel.pipeline`) builds a :class:`~slamrel.runs.result.RunResult`; the
report (:mod:`slamrel.report`) and the verdict read it; ``metrics.json`` is written from it.
Both sit above this package, so neither imports the other for its types:

* :mod:`slamrel.runs.time_base` — the report's one time axis (:class:`TimeBase`);
* :mod:`slamrel.runs.nees` — the NEES of an estimate against the ground truth, the one
  computation behind every NEES slamrel reports (``slamrel run`` and ``slamrel recover``);
* :mod:`slamrel.runs.result` — :class:`RunResult` and its parts (:class:`MapSummary`,
  :class:`DisplayFrame`, :class:`RelationSetRule`).

It imports the libraries only (and :mod:`slamrel.constants`).
"""
