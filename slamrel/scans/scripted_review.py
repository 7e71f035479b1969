"""A scripted review of aligned relations: what a person at the review page would decide,
from the flags and the cycle check alone (for benchmarks, tests and notebooks).

Rules, in order:

1. accept every unflagged relation, reject every flagged one;
2. ``cycle_check``: reject the unflagged relations the cycle check contradicts
   (:func:`slamrel.scans.cycles.check_scan_relations` over the unflagged ones);
3. ``confirm``: accept a relation flagged *only* ``large correction`` or *only*
   ``ambiguous`` (:data:`CONFIRMABLE`) when its cycles with the unflagged relations confirm
   it (≥ 2 cycles, none failed) and none contradicts it — a person accepts a flagged
   relation its neighbours agree with. (Confirmation is evidence, not proof: relations
   wrong alike close their cycles with each other, :meth:`CycleCheck.confirmed`.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slamrel.scans.cycles import check_scan_relations
from slamrel.scans.relations import ScanRelations

__all__ = ["CONFIRMABLE", "ScriptedReview", "scripted_review"]

#: Flags a relation may carry alone and still be accepted when its cycles confirm it: a
#: correction from a drifting guess, a second hypothesis close in score.
CONFIRMABLE = ("large correction", "ambiguous")


@dataclass(frozen=True)
class ScriptedReview:
    """The decisions on ``P`` relations.

    Attributes
    ----------
    accepted : (P,) bool
    contradicted : int
        Unflagged relations rejected by the cycle check (rule 2).
    confirmed : int
        Flagged relations accepted on their cycles' word (rule 3).
    """

    accepted: NDArray[np.bool_]
    contradicted: int
    confirmed: int


def scripted_review(
    result: ScanRelations, *, cycle_check: bool = True, confirm: bool = True
) -> ScriptedReview:
    """Review ``result`` by the rules of the module docstring."""
    accept = ~result.flagged
    if not (cycle_check or confirm):
        return ScriptedReview(accept, 0, 0)
    soft = np.isin(result.flags, CONFIRMABLE)
    check = check_scan_relations(result, use=accept | soft if confirm else accept)
    contradicted = accept & check.contradicted if cycle_check else np.zeros_like(accept)
    extra = soft & check.confirmed() & ~check.contradicted if confirm else soft & False
    return ScriptedReview(
        (accept & ~contradicted) | extra, int(contradicted.sum()), int(extra.sum())
    )
