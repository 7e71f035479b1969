"""UTIAS Multi-Robot Cooperative Localization and Mapping (MRCLAM) datasets.

Leung, Halpern, Barfoot, Liu, "The UTIAS Multi-Robot Cooperative Localization and Mapping
Dataset", IJRR 2011. A dataset directory holds, per robot N, ``RobotN_Odometry.dat``
(``time v ω``), ``RobotN_Measurement.dat`` (``time barcode range bearing``),
``RobotN_Groundtruth.dat`` (``time x y θ``, Vicon), and ``Barcodes.dat`` (``subject
barcode``), ``Landmark_Groundtruth.dat`` (``subject x y σx σy``). Subjects 1–5 are the
robots, the others landmarks. ``#`` lines are headers; tabs and spaces separate fields.

Measurements are mapped from barcodes to subjects; sightings of robots are counted and left
out of landmark SLAM; barcodes that are in no table are counted and left out. Nothing is
dropped without being counted in :class:`MrclamRobot`.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import nnls

from recovery.bundle import Bundle
from recovery.models import (
    MotionModel,
    MotionPersisting,
    PersistingError,
    SensorModel,
)
from relation_metric import se2
from relation_metric.consistency import outlier_share_of_tail
from relation_metric.errors import InputError
from relation_metric.ids import integer_ids, rows_of
from relation_metric.timeorder import FILTER_TIME_TOLERANCE, TimeOrderWarning, sort_by_time
from relation_metric.trajectory import Trajectory, readonly
from slamrel.formats.bundle import InvalidMeasurementWarning
from slamrel.formats.text import PathLike, RowLines, read_numeric_table

__all__ = [
    "MrclamRobot",
    "NoiseFit",
    "FitCheck",
    "check_fit",
    "thin_sightings",
    "OdometryCalibration",
    "calibrate_odometry",
    "resample_controls",
    "fit_noise",
    "ControlWindows",
    "control_windows",
    "MotionPersistingFit",
    "fit_motion_persisting",
    "white_alpha",
    "read_mrclam_robot",
    "read_barcodes",
    "N_ROBOTS",
]

N_ROBOTS = 5


@dataclass(frozen=True)
class MrclamRobot:
    """One robot's logs, ready for landmark SLAM.

    Attributes
    ----------
    robot : int
    controls : ndarray, shape (K, 3)
        ``[t, v, ω]``, each held until the next row (velocity-model input).
    measurements : ndarray, shape (M, 4)
        ``[t, range, bearing, subject]`` of landmark sightings only.
    groundtruth : Trajectory
    robot_sightings : int
        Measurements of other robots (subjects 1–5), left out.
    unknown_barcodes : dict of int → int
        Barcodes in no table, with their counts, left out.
    reordered : dict of str → int
        Rows of each ``.dat`` file that went back in time by at most
        :data:`~relation_metric.timeorder.FILTER_TIME_TOLERANCE` and were put in time order.
    nonpositive_ranges : int
        Measurements with a range of 0 or below (the dataset holds some: −0.035 m), left out
        and warned about, naming the first one's line: a range-bearing model needs a positive
        range, and refusing the whole run for them would lose it.
    """

    robot: int
    controls: NDArray[np.float64]
    measurements: NDArray[np.float64]
    groundtruth: Trajectory
    robot_sightings: int
    unknown_barcodes: dict[int, int]
    reordered: dict[str, int] = field(default_factory=dict)
    nonpositive_ranges: int = 0


def _time_ordered(
    path: Path, rows: NDArray[np.float64], lines: Callable[[int], int], what: str
) -> tuple[NDArray[np.float64], int]:
    """``rows`` (time in column 0) under the filter-log rule of ``relation_metric.timeorder``.

    Steps back of at most ``FILTER_TIME_TOLERANCE`` (0.05 s) are stable-sorted, counted
    (returned) and warned about; a larger one raises :class:`InputError` with file:line and
    both times.
    """
    order, report = sort_by_time(
        rows[:, 0], tolerance=FILTER_TIME_TOLERANCE, lines=lines, path=path, what=what
    )
    if not report.out_of_order:
        return rows, 0
    warnings.warn(
        f"{path}: {report.describe(what)}; put in time order", TimeOrderWarning, stacklevel=3
    )
    return rows[order], report.out_of_order


@contextmanager
def _about(path: Path, also: str) -> Iterator[None]:
    """Name ``path`` (and ``also``: the other files involved) in an :class:`InputError`
    raised in the block that names no file."""
    try:
        yield
    except InputError as exc:
        if exc.path is not None:
            raise
        raise InputError(f"{exc.message} ({also})", path=path, line=exc.line) from None


def _unique_subjects(path: Path, subjects: NDArray[np.float64], lines: RowLines) -> None:
    """Landmark subjects: integers, each surveyed once (a repeat is refused at its line:
    which of two positions is the landmark's is unknown)."""
    ids = integer_ids(subjects, lines, path, "subject")
    uniq, first, counts = np.unique(ids, return_index=True, return_counts=True)
    if (counts > 1).any():
        dup = int(uniq[counts > 1][0])
        k = int(np.flatnonzero(ids == dup)[1])
        raise InputError(
            f"landmark subject {dup} is given twice (first at line "
            f"{lines(int(first[counts > 1][0]))}); expected each landmark once",
            path=path,
            line=lines(k),
        )


def read_barcodes(directory: PathLike) -> dict[int, int]:
    """``barcode → subject`` from ``Barcodes.dat``."""
    path = Path(directory) / "Barcodes.dat"
    values, lines = read_numeric_table(
        path, columns=("subject", "barcode"), describe="Barcodes.dat"
    )
    codes = integer_ids(values[:, 1], lines, path, "barcode")
    subjects = integer_ids(values[:, 0], lines, path, "subject")
    uniq, counts = np.unique(codes, return_counts=True)
    if (counts > 1).any():
        dup = int(uniq[counts > 1][0])
        k = int(np.flatnonzero(codes == dup)[1])
        raise InputError(f"barcode {dup} is given twice", path=path, line=lines(k))
    return dict(zip(codes.tolist(), subjects.tolist()))


def read_mrclam_robot(directory: PathLike, robot: int) -> MrclamRobot:
    """Read robot ``robot`` (1–5) of an MRCLAM dataset directory."""
    d = Path(directory)
    if not d.is_dir():
        raise InputError("not a directory; expected an MRCLAM dataset folder", path=d)
    if not 1 <= robot <= N_ROBOTS:
        raise InputError(f"robot must be 1..{N_ROBOTS}, got {robot}", path=d)
    barcodes = read_barcodes(d)
    odo_path = d / f"Robot{robot}_Odometry.dat"
    odo, odo_lines = read_numeric_table(
        odo_path, columns=("time", "v", "omega"), describe="MRCLAM odometry"
    )
    reordered: dict[str, int] = {}
    odo, reordered[odo_path.name] = _time_ordered(odo_path, odo, odo_lines, "odometry row")
    meas_path = d / f"Robot{robot}_Measurement.dat"
    meas, meas_lines = read_numeric_table(
        meas_path, columns=("time", "barcode", "range", "bearing"), describe="MRCLAM measurements"
    )
    integer_ids(meas[:, 1], meas_lines, meas_path, "barcode")  # at its line, before sorting
    meas, kept_lines, nonpositive = _without_nonpositive_ranges(meas_path, meas, meas_lines)
    meas, reordered[meas_path.name] = _time_ordered(meas_path, meas, kept_lines, "measurement")
    gt_path = d / f"Robot{robot}_Groundtruth.dat"
    gt, gt_lines = read_numeric_table(
        gt_path, columns=("time", "x", "y", "theta"), describe="MRCLAM ground truth"
    )
    gt, reordered[gt_path.name] = _time_ordered(gt_path, gt, gt_lines, "ground-truth pose")
    code = meas[:, 1].astype(np.int64)
    table_codes = np.fromiter(barcodes.keys(), dtype=np.int64)
    table_subjects = np.fromiter(barcodes.values(), dtype=np.int64)
    row = rows_of(table_codes, code)
    known = row >= 0
    subject = np.where(known, table_subjects[row], -1)
    is_robot = known & (subject <= N_ROBOTS)
    landmark = known & ~is_robot
    unknown_codes, unknown_counts = np.unique(code[~known], return_counts=True)
    measurements = np.column_stack(
        (meas[landmark, 0], meas[landmark, 2], meas[landmark, 3], subject[landmark])
    )
    return MrclamRobot(
        robot=robot,
        controls=readonly(odo),
        measurements=readonly(measurements),
        groundtruth=Trajectory(gt[:, 0], gt[:, 1:4]),
        robot_sightings=int(is_robot.sum()),
        unknown_barcodes=dict(zip(unknown_codes.tolist(), unknown_counts.tolist())),
        reordered=reordered,
        nonpositive_ranges=nonpositive,
    )


def _without_nonpositive_ranges(
    path: Path, meas: NDArray[np.float64], lines: RowLines
) -> tuple[NDArray[np.float64], Callable[[int], int], int]:
    """The measurements (``time barcode range bearing``) with a positive range, their line
    numbers, and how many were left out (warned about, naming the first one's line)."""
    bad = np.flatnonzero(~(meas[:, 2] > 0))
    if not bad.size:
        return meas, lines, 0
    k = int(bad[0])
    warnings.warn(
        f"{path}: {bad.size} measurement(s) with a range of 0 or below left out (the first at "
        f"line {lines(k)}: range {float(meas[k, 2]):g}); a range-bearing model needs a "
        "positive range",
        InvalidMeasurementWarning,
        stacklevel=3,
    )
    keep = np.ones(meas.shape[0], dtype=bool)
    keep[bad] = False
    idx = np.flatnonzero(keep)
    return meas[keep], lambda j: lines(int(idx[j])), int(bad.size)


@dataclass(frozen=True)
class NoiseFit:
    """Noise parameters fitted from one robot's logs against its ground truth.

    Attributes
    ----------
    sigma_v, sigma_omega : float
        Per-row standard deviations of the velocity-model controls (docs/bundle.md ``velocity``
        model), from odometry vs. ground-truth motion over ``window`` seconds.
    bias_v, bias_omega : float
        Mean control errors (reported, not modelled).
    sigma_range, sigma_bearing : float
        Standard deviations of the measurement residuals against the ground truth within
        5 robust σ (1.4826 · MAD) of their median; ``outlier_fraction`` of the residuals lie
        beyond that. MRCLAM's residuals are heavy-tailed: the MAD alone would understate the
        spread of the accepted residuals and make the filter overconfident
        (benchmarks/README.md).
    alpha : tuple of float
        ``(α1, α2, α3, α4)`` of the speed-proportional velocity model (Probabilistic Robotics
        Table 5.3: ``σ_v² = α1 v² + α2 ω²``, ``σ_ω² = α3 v² + α4 ω²`` per row), fitted by
        iteratively reweighted non-negative least squares of the squared window errors on
        ``[Σ v_k² dt_k², Σ ω_k² dt_k²]`` (see :func:`_fit_variance`). Zero commands
        then move nothing, as the robots do: they stand still for long stretches of a run,
        where Vicon shows no motion (benchmarks/README.md).
    window : float
    check : FitCheck or None
        The fitted range-bearing noise judged on the residuals it was fitted on
        (:func:`check_fit`).
    """

    sigma_v: float
    sigma_omega: float
    bias_v: float
    bias_omega: float
    sigma_range: float
    sigma_bearing: float
    outlier_fraction: float
    window: float
    alpha: tuple[float, float, float, float]
    check: FitCheck | None = None
    #: :func:`fit_persisting`'s persisting part of the range-bearing noise (of the bearing
    #: residuals less their mean, ``bearing_offset``).
    persisting: PersistingError | None = None
    #: The mean bearing residual [rad] (within 5 robust σ): a sensor heading that is not the
    #: ground truth's, stated as ``sensor_model.mount`` ``[0, 0, −offset]`` with ``persisting``.
    bearing_offset: float = 0.0
    #: The share of ``d² = (r/σ_r)² + (b/σ_b)²`` beyond the χ²₂ 99.9 % bound with the bearings
    #: less ``bearing_offset`` (the residuals a bundle stating that mount sees; ``check``'s
    #: ``beyond_999`` is the same share of the residuals as they are). None: not measured.
    beyond_999_mounted: float | None = None

    def gross_share(self, *, mounted: bool) -> float:
        """The share of gross errors the bundle states (``sensor_model.outlier_share``): the
        residuals' share beyond the χ²₂ 99.9 % bound less the Gaussian's 0.1 %
        (:func:`~relation_metric.consistency.outlier_share_of_tail`) — the contamination the
        map–log lamp expects in its tail, measured at its own bound on the residuals the σ
        were fitted on (with the bearings less their mean when the bundle states that mount).
        Without a measured tail (a fit given by hand), ``outlier_fraction``."""
        tail = self.beyond_999_mounted if mounted else (
            None if self.check is None else self.check.beyond_999
        )  # fmt: skip
        return self.outlier_fraction if tail is None else outlier_share_of_tail(tail)


#: χ²₂ quantiles: the median and the 99 % and 99.9 % bounds (``−2 ln(1 − p)``).
_CHI2_2_MEDIAN = 2.0 * np.log(2.0)
_CHI2_2_BOUNDS = {0.99: -2.0 * np.log(0.01), 0.999: -2.0 * np.log(0.001)}


@dataclass(frozen=True)
class FitCheck:
    """The fitted range-bearing noise judged on the residuals it was fitted on.

    With Gaussian white residuals of the fitted σ, ``d² = (r/σ_r)² + (b/σ_b)²`` is χ²(2)
    (median ``2 ln 2 = 1.39``; 1 % beyond 9.21, 0.1 % beyond 13.8), and the residuals of
    successive sightings of one landmark are uncorrelated. MRCLAM's are neither (dataset 7:
    docs/verdict.md): a bulk narrower than the fitted σ with heavy tails, and errors that
    persist over seconds, which a white-noise filter counts as independent information.

    Attributes
    ----------
    median : float
        Median of ``d²`` (``_CHI2_2_MEDIAN`` expected).
    beyond_99, beyond_999 : float
        Shares of ``d²`` beyond the χ²₂ 99 % and 99.9 % bounds (0.01 and 0.001 expected).
    range_correlation, bearing_correlation : float
        Pearson correlation of the residuals of successive sightings of the same landmark
        at most ``lag`` seconds apart, both within 5 robust σ (0 expected; NaN: no pair).
    pairs : int
        Those pairs.
    lag : float
    """

    median: float
    beyond_99: float
    beyond_999: float
    range_correlation: float
    bearing_correlation: float
    pairs: int
    lag: float

    def describe(self) -> str:
        """One sentence for the bundle's description."""
        return (
            f"fit checked on its own residuals: median d^2 {self.median:.2f} (chi2_2 "
            f"{_CHI2_2_MEDIAN:.2f}), {100 * self.beyond_99:.2f}% beyond the 99% bound (1% "
            f"expected), {100 * self.beyond_999:.2f}% beyond the 99.9% bound (0.1%); "
            f"successive sightings of a landmark within {self.lag:g} s correlated "
            f"{self.range_correlation:.2f} in range, {self.bearing_correlation:.2f} in bearing "
            f"({self.pairs} pairs; 0 for white noise)"
        )


def _d2(residuals: NDArray[np.float64], sigma: tuple[float, float]) -> NDArray[np.float64]:
    """``d² = (r/σ_r)² + (b/σ_b)²`` of residuals ``(M, 2)`` (range, bearing)."""
    return np.sum((residuals / np.asarray(sigma)) ** 2, axis=1)


def _beyond_bound(d2: NDArray[np.float64], probability: float) -> float:
    """The share of ``d2`` beyond the χ²₂ ``probability`` bound (0 for no residual)."""
    return float((d2 > _CHI2_2_BOUNDS[probability]).sum() / max(d2.size, 1))


def check_fit(
    times: NDArray[np.float64],
    landmarks: NDArray[np.int64],
    residuals: NDArray[np.float64],
    sigma: tuple[float, float],
    bulk: NDArray[np.bool_],
    *,
    lag: float = 1.0,
) -> FitCheck:
    """:class:`FitCheck` of residuals ``(M, 2)`` (range, bearing) at ``times`` (increasing)
    of sightings of ``landmarks`` against the fitted ``sigma``; ``bulk`` marks the residuals
    within 5 robust σ, the only ones the correlation uses (a few outliers would rule it)."""
    d2 = _d2(residuals, sigma)
    order = np.lexsort((times, landmarks))  # by landmark, then time
    a, b = order[:-1], order[1:]
    pair = (landmarks[a] == landmarks[b]) & (times[b] - times[a] <= lag) & bulk[a] & bulk[b]

    def corr(x: NDArray[np.float64]) -> float:
        if pair.sum() < 3:
            return float("nan")
        return float(np.corrcoef(x[a[pair]], x[b[pair]])[0, 1])

    return FitCheck(
        median=float(np.median(d2)) if d2.size else float("nan"),
        beyond_99=_beyond_bound(d2, 0.99),
        beyond_999=_beyond_bound(d2, 0.999),
        range_correlation=corr(residuals[:, 0]),
        bearing_correlation=corr(residuals[:, 1]),
        pairs=int(pair.sum()),
        lag=lag,
    )


#: Edges [s] of the lags between two sightings of a landmark over which
#: :func:`fit_persisting` averages the residuals' correlation.
PERSISTING_LAGS = (0.0, 0.35, 0.7, 1.5, 3.0, 6.0, 12.0, 24.0, 48.0, 100.0)


def track_pairs(
    times: NDArray[np.float64], landmarks: NDArray[np.int64], max_lag: float
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Every pair ``(a, b)`` of sightings of one landmark with ``0 < t_b − t_a ≤ max_lag``
    (indices into ``times``), vectorised: for each sighting the later ones of its landmark
    within the lag, found by one sorted search."""
    order = np.lexsort((times, landmarks))
    t, lm = times[order], landmarks[order]
    key = lm.astype(np.float64) * (2.0 * (np.ptp(t) + max_lag + 1.0)) + (t - t.min())
    end = np.searchsorted(key, key + max_lag, side="right")
    count = end - np.arange(t.size) - 1
    a = np.repeat(np.arange(t.size), count)
    offset = np.arange(a.size) - np.repeat(np.cumsum(count) - count, count)
    b = a + 1 + offset
    keep = t[b] > t[a]
    return order[a[keep]], order[b[keep]]


def _fit_decay(lag: NDArray[np.float64], prod: NDArray[np.float64]) -> tuple[float, float]:
    """``(f, τ)`` of ``ρ(Δt) = f e^{−Δt/τ}`` fitted to the products ``prod`` of normalised
    residuals at lags ``lag``, averaged in the bins of :data:`PERSISTING_LAGS`, by least
    squares with every bin alike (their pairs are not independent: one visit's sightings pair
    with each other many times); ``f`` in ``[0.01, 0.98]``, ``τ`` in ``[0.05, 600]`` s."""
    from scipy.optimize import curve_fit

    edges = np.asarray(PERSISTING_LAGS)
    which = np.clip(np.digitize(lag, edges) - 1, 0, edges.size - 2)
    n = np.bincount(which, minlength=edges.size - 1).astype(np.float64)
    tot = np.bincount(which, weights=prod, minlength=edges.size - 1)
    use = n >= 10
    if use.sum() < 3:
        raise _NoFit()
    rho = tot[use] / n[use]

    def model(_: object, f: float, tau: float) -> NDArray[np.float64]:
        # the model averaged over each bin's own lags (not taken at the bin's mean lag: the
        # exponential is convex, and wide bins would lengthen τ)
        return f * (np.bincount(which, np.exp(-lag / tau), edges.size - 1)[use] / n[use])

    try:
        (f, tau), _ = curve_fit(
            model,
            np.zeros(int(use.sum())),
            np.clip(rho, 0.0, None),
            p0=(0.5, 2.0),
            bounds=((0.01, 0.05), (0.98, 600.0)),
        )
    except RuntimeError:  # no convergence
        raise _NoFit() from None
    return float(f), float(tau)


class _NoFit(Exception):
    """Too few pairs (or no convergence) to fit a persisting error."""


def fit_persisting(
    times: NDArray[np.float64],
    landmarks: NDArray[np.int64],
    residuals: NDArray[np.float64],
    sigma: tuple[float, float],
    bulk: NDArray[np.bool_],
) -> PersistingError | None:
    """The persisting part of residuals ``(M, 2)`` (range, bearing) against the fitted total
    ``sigma``: a Gauss–Markov bias common to every landmark and one per landmark track
    (:class:`~recovery.models.PersistingError`), from the pairs of ``bulk`` residuals up to
    100 s apart. Pairs of *different* landmarks see only the common bias:
    ``mean(e_a e_b)/σ² = f_c e^{−Δt/τ_c}``; pairs of one landmark see both, so the
    per-landmark bias is fitted to their correlation minus the common one's fit
    (:func:`_fit_decay` each), ``σ_b = √f σ``, the two shares scaled down together when they
    would leave less than 5 % of the variance white. Dataset 7: the bearing errors are mostly
    common (different landmarks at one time correlate 0.36–0.99 at lags below 0.35 s: the
    sensor's heading), the range errors mostly per landmark (docs/verdict.md). A
    calibration against the ground truth, as the noise fit is. ``None`` when fewer than three
    lag bins hold ten pairs each (or the fit does not converge): nothing to state.
    """
    try:
        return _fit_persisting(times, landmarks, residuals, sigma, bulk)
    except _NoFit:
        return None


def _fit_persisting(
    times: NDArray[np.float64],
    landmarks: NDArray[np.int64],
    residuals: NDArray[np.float64],
    sigma: tuple[float, float],
    bulk: NDArray[np.bool_],
) -> PersistingError:
    keep = np.flatnonzero(bulk)
    a, b = track_pairs(times[keep], np.zeros(keep.size, dtype=np.int64), PERSISTING_LAGS[-1])
    a, b = keep[a], keep[b]
    lag = times[b] - times[a]
    same = landmarks[a] == landmarks[b]
    per, com = [], []
    for comp in range(2):
        prod = residuals[a, comp] * residuals[b, comp] / sigma[comp] ** 2
        fc, tc = _fit_decay(lag[~same], prod[~same])
        own = prod[same] - fc * np.exp(-lag[same] / tc)
        fl, tl = _fit_decay(lag[same], own)
        shrink = min(1.0, 0.95 / (fc + fl))
        per.append((math.sqrt(shrink * fl) * sigma[comp], tl))
        com.append((math.sqrt(shrink * fc) * sigma[comp], tc))
    return PersistingError(
        per[0][0],
        per[1][0],
        per[0][1],
        per[1][1],
        common=PersistingError(com[0][0], com[1][0], com[0][1], com[1][1]),
    )


@dataclass(frozen=True)
class OdometryCalibration:
    """A delay and scale of the odometry, fitted against the ground truth.

    MRCLAM's odometry rows are velocity *commands*: the robot moves a fraction of a second
    after the command and a little slower than commanded (the values fitted on dataset 7:
    benchmarks/README.md). Both are systematic, not noise, so a Gaussian filter cannot
    absorb them; the bundle uses corrected controls
    ``[t + delay, scale_v · v, scale_omega · ω]`` and dead reckoning uses the same ones.

    Attributes
    ----------
    delay : float
        Seconds added to the odometry time stamps.
    scale_v, scale_omega : float
    rms_before, rms_after : float
        RMS of the along-track distance error over ``window`` seconds, metres, with the raw
        and with the corrected controls.
    window : float
    """

    delay: float
    scale_v: float
    scale_omega: float
    rms_before: float
    rms_after: float
    window: float

    def apply(self, controls: NDArray[np.float64]) -> NDArray[np.float64]:
        """Corrected copy of ``controls`` (rows ``[t, v, ω]``)."""
        c = np.array(controls, dtype=np.float64)
        c[:, 0] += self.delay
        c[:, 1] *= self.scale_v
        c[:, 2] *= self.scale_omega
        return c


def calibrate_odometry(
    robot: MrclamRobot, *, max_delay: float = 0.6, step: float = 0.025, window: float = 1.0
) -> OdometryCalibration:
    """Fit the odometry's delay and speed/turn-rate scales against the ground truth.

    Over consecutive windows of ``window`` seconds inside both logs, the odometry's travelled
    distance ``∫ v dt`` (sampled ``delay`` earlier) is compared with the ground truth's signed
    path length ``Σ cos θ Δx + sin θ Δy`` (at the ground truth's rate). For every delay on a grid of
    ``step`` over ``[−max_delay, max_delay]`` the speed scale is the least-squares
    ``k = Σ d_odo d_gt / Σ d_odo²``; the delay with the smallest residual RMS wins. The
    turn-rate scale is the least-squares fit of ``∫ ω dt`` to the heading change at that delay.
    All delays are evaluated at once (one ``np.interp`` over a (delays, windows) grid).
    """
    c = robot.controls
    gt = robot.groundtruth
    t = c[:, 0]
    dt = np.diff(t)
    cum_d = np.concatenate(([0.0], np.cumsum(c[:-1, 1] * dt)))
    cum_w = np.concatenate(([0.0], np.cumsum(c[:-1, 2] * dt)))
    lo = max(t[0], gt.timestamps[0]) + max_delay
    hi = min(t[-1], gt.timestamps[-1]) - max_delay
    edges = np.arange(lo, hi, window)
    if edges.size < 12:
        raise InputError(
            f"odometry and ground truth overlap for {max(hi - lo, 0.0):.1f} s; calibration "
            f"needs at least 11 windows of {window} s"
        )
    # signed path length of the ground truth: Σ (cos θ Δx + sin θ Δy) at its own rate, with
    # the heading of each segment's midpoint (so turning does not shorten it)
    g = gt.poses
    th_all = np.unwrap(g[:, 2])
    mid = 0.5 * (th_all[1:] + th_all[:-1])
    ds = np.cos(mid) * np.diff(g[:, 0]) + np.sin(mid) * np.diff(g[:, 1])
    s_gt = np.concatenate(([0.0], np.cumsum(ds)))
    along = np.diff(np.interp(edges, gt.timestamps, s_gt))
    turn = np.diff(np.interp(edges, gt.timestamps, th_all))
    n_step = int(np.floor(max_delay / step + 1e-9))
    delays = step * np.arange(-n_step, n_step + 1)
    sample = edges[None, :] - delays[:, None]  # odometry time of each window edge
    d_odo = np.diff(np.interp(sample, t, cum_d), axis=1)  # (delays, windows)
    w_odo = np.diff(np.interp(sample, t, cum_w), axis=1)
    k = np.einsum("dw,w->d", d_odo, along) / np.maximum(np.einsum("dw,dw->d", d_odo, d_odo), 1e-300)
    rms = np.sqrt(np.mean((k[:, None] * d_odo - along) ** 2, axis=1))
    best = int(np.argmin(rms))
    wo = w_odo[best]
    ww = float(wo @ wo)
    kw = float(wo @ turn) / ww if ww > 0 else 1.0
    zero = int(np.argmin(np.abs(delays)))
    return OdometryCalibration(
        delay=float(delays[best]),
        scale_v=float(k[best]),
        scale_omega=kw,
        rms_before=float(np.sqrt(np.mean((d_odo[zero] - along) ** 2))),
        rms_after=float(rms[best]),
        window=window,
    )


def resample_controls(
    controls: NDArray[np.float64], *, period: float | None = None
) -> NDArray[np.float64]:
    """Split rows held longer than 1.5 periods into equal rows of about one period.

    The bundle's velocity model holds each row's noise over its Δt, so a row's increment
    variance grows with Δt²: one 0.5 s gap in a 100 Hz log would carry the noise of 2500
    ordinary rows and a smoother would put every correction into it. Splitting (same
    ``v, ω``; ``period`` defaults to the median row spacing) makes the motion noise grow
    linearly with time, as for a continuous white-noise velocity error.

    Parameters
    ----------
    controls : ndarray, shape (K, 3)
        ``[t, v, ω]`` rows, time increasing.
    period : float, optional

    Returns
    -------
    ndarray, shape (K', 3)
        The same motion (same last row) on the finer grid.
    """
    c = np.asarray(controls, dtype=np.float64)
    if c.shape[0] < 2:
        return c.copy()
    dt = np.diff(c[:, 0])
    h = float(np.median(dt)) if period is None else float(period)
    if not h > 0:
        raise InputError(f"control period must be positive, got {h}")
    n = np.where(dt > 1.5 * h, np.maximum(np.round(dt / h), 1), 1).astype(np.int64)
    row = np.repeat(np.arange(dt.size), n)
    sub = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
    t = c[row, 0] + sub * (dt / n)[row]
    return np.vstack((np.column_stack((t, c[row, 1], c[row, 2])), c[-1:]))


@dataclass(frozen=True)
class ControlWindows:
    """The odometry against the ground truth over consecutive windows of ``window`` seconds
    inside the ground truth's span (the windows :func:`fit_noise` fits the motion noise on).
    Arrays over the windows that hold control rows, in time order.

    Attributes
    ----------
    index : ndarray of int
        Each window's number ``⌊(t − t_first) / window⌋``: windows ``i`` and ``i + L`` are
        ``L`` windows apart (some windows may be missing).
    dist_error, turn_error : ndarray
        ``|Σ v_k dt_k| − s_true`` and ``Σ ω_k dt_k − Δθ_true``: odometry less the ground
        truth's path length and heading change over the window's ``[t0, t1]``.
    true_dist : ndarray
        The ground truth's path length ``s_true`` [m].
    dt2, duration : ndarray
        ``Σ dt_k²`` and ``Σ dt_k`` of the window's rows.
    design : ndarray, shape (n, 2)
        ``[Σ v_k² dt_k², Σ ω_k² dt_k²]`` (the speed-proportional model's).
    window : float
    """

    index: NDArray[np.int64]
    dist_error: NDArray[np.float64]
    turn_error: NDArray[np.float64]
    true_dist: NDArray[np.float64]
    dt2: NDArray[np.float64]
    duration: NDArray[np.float64]
    design: NDArray[np.float64]
    window: float


def control_windows(robot: MrclamRobot, window: float) -> ControlWindows:
    """:class:`ControlWindows` of ``robot`` (vectorised: one ``bincount`` per sum)."""
    c = robot.controls
    gt = robot.groundtruth
    t = c[:, 0]
    dt = np.diff(t, append=t[-1])
    inside = (t >= gt.timestamps[0]) & (t + dt <= gt.timestamps[-1])
    w_id = np.floor((t - t[0]) / window).astype(np.int64)
    w_id = np.where(inside, w_id, -1)
    keep = w_id >= 0
    nw = int(w_id.max()) + 1 if keep.any() else 0

    def per_window(x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Sums of ``x`` over each window's rows, shape (nw,)."""
        # numpy's stubs type bincount as NDArray[intp] always; with weights it is float64.
        return np.bincount(w_id[keep], weights=x[keep], minlength=nw)  # type: ignore[return-value]

    dist = per_window(c[:, 1] * dt)
    turn = per_window(c[:, 2] * dt)
    dt2 = per_window(dt * dt)
    t0 = np.full(nw, np.inf)
    t1 = np.full(nw, -np.inf)
    np.minimum.at(t0, w_id[keep], t[keep])
    np.maximum.at(t1, w_id[keep], (t + dt)[keep])
    ok = np.isfinite(t0) & (dt2 > 0)
    # ground-truth path length and heading change over [t0, t1] of each window, sampled
    # at the ground truth's own rate
    s_gt = gt.path_length()
    th_gt = np.unwrap(gt.poses[:, 2])
    true_dist = np.interp(t1[ok], gt.timestamps, s_gt) - np.interp(t0[ok], gt.timestamps, s_gt)
    true_turn = np.interp(t1[ok], gt.timestamps, th_gt) - np.interp(t0[ok], gt.timestamps, th_gt)
    v2, w2 = c[:, 1] ** 2 * dt**2, c[:, 2] ** 2 * dt**2
    return ControlWindows(
        index=np.flatnonzero(ok),
        dist_error=np.abs(dist[ok]) - true_dist,  # odometry speed is signed; path length not
        turn_error=turn[ok] - true_turn,
        true_dist=true_dist,
        dt2=dt2[ok],
        duration=per_window(dt)[ok],
        design=np.column_stack((per_window(v2), per_window(w2)))[ok],
        window=float(window),
    )


def fit_noise(
    robot: MrclamRobot, landmarks: NDArray[np.float64], *, window: float = 1.0
) -> NoiseFit:
    """Fit velocity-model and range-bearing noise from data (how, in :class:`NoiseFit`).

    Controls: over consecutive windows of ``window`` seconds inside the ground truth's time
    span, the travelled distance ``Σ v_k dt_k`` and turn ``Σ ω_k dt_k`` of the odometry are
    compared with the ground truth's path length and heading change. With independent
    per-row errors held over ``dt_k``, ``Var(window error) = σ² Σ dt_k²``, so
    ``σ² = Var / mean(Σ dt_k²)``.

    Measurements: each landmark measurement against the range and bearing predicted from
    the interpolated ground-truth pose and the surveyed landmark (``landmarks``: rows
    ``[subject, x, y]``).
    """
    w = control_windows(robot, window)
    e_d, e_t = w.dist_error, w.turn_error
    mdt2 = float(np.mean(w.dt2))
    sigma_v = float(np.sqrt(np.var(e_d) / mdt2))
    sigma_w = float(np.sqrt(np.var(e_t) / mdt2))
    # speed-proportional model: E[e²] = Σ_k (α_a v_k² + α_b ω_k²) dt_k² per window
    alpha_v = _fit_variance(w.design, e_d)
    alpha_w = _fit_variance(w.design, e_t)
    gt = robot.groundtruth
    # measurements
    m = robot.measurements
    subj = landmarks[:, 0].astype(np.int64)
    row = rows_of(subj, m[:, 3].astype(np.int64))
    known = row >= 0
    in_gt = (m[:, 0] >= gt.timestamps[0]) & (m[:, 0] <= gt.timestamps[-1])
    use = known & in_gt
    poses = gt.poses_at(m[use, 0])
    lm_xy = landmarks[row[use], 1:3]
    k_p_l = se2.inverse_transform_points(poses, lm_xy)
    r_res = m[use, 1] - np.hypot(k_p_l[:, 0], k_p_l[:, 1])
    b_res = se2.wrap_angle(m[use, 2] - np.arctan2(k_p_l[:, 1], k_p_l[:, 0]))

    out = _beyond(r_res) | _beyond(b_res)
    sr = float(np.std(r_res[~out], ddof=1)) if (~out).sum() > 1 else float("nan")
    sb = float(np.std(b_res[~out], ddof=1)) if (~out).sum() > 1 else float("nan")
    duration = float(np.mean(w.duration))
    offset = float(np.mean(b_res[~out])) if (~out).any() else 0.0
    d2_mounted = _d2(np.column_stack((r_res, se2.wrap_angle(b_res - offset))), (sr, sb))
    return NoiseFit(
        sigma_v=sigma_v,
        sigma_omega=sigma_w,
        bias_v=float(np.mean(e_d) / duration),
        bias_omega=float(np.mean(e_t) / duration),
        sigma_range=sr,
        sigma_bearing=sb,
        outlier_fraction=float(out.mean()) if out.size else 0.0,
        window=window,
        alpha=(float(alpha_v[0]), float(alpha_v[1]), float(alpha_w[0]), float(alpha_w[1])),
        check=check_fit(
            m[use, 0],
            m[use, 3].astype(np.int64),
            np.column_stack((r_res, b_res)),
            (sr, sb),
            ~out,
        ),
        persisting=fit_persisting(
            m[use, 0],
            m[use, 3].astype(np.int64),
            np.column_stack((r_res, b_res - offset)),
            (sr, sb),
            ~out,
        ),
        bearing_offset=offset,
        beyond_999_mounted=_beyond_bound(d2_mounted, 0.999) if d2_mounted.size else None,
    )


#: Windows on which the robot moved less than this [m] (ground truth) carry no speed-scale or
#: turn-per-metre error :func:`fit_motion_persisting` could read (their ratio is noise).
MOVED_DISTANCE = 0.05


@dataclass(frozen=True)
class MotionPersistingFit:
    """:func:`fit_motion_persisting`'s fit and what it was fitted to.

    Attributes
    ----------
    persisting : MotionPersisting
    lags : ndarray of int
        The lags ``L`` (in windows) fitted.
    scale_covariance, turn_covariance : ndarray
        The autocovariance of the speed-scale [1] and turn-per-metre [rad²/m²] errors at
        ``lags`` (NaN: fewer than 10 pairs, not fitted).
    pairs : ndarray of int
        The pairs of moved windows at each lag (the same for both components, before their
        separate 5-robust-σ trims).
    windows : int
        Windows on which the robot moved.
    window : float
    """

    persisting: MotionPersisting
    lags: NDArray[np.int64]
    scale_covariance: NDArray[np.float64]
    turn_covariance: NDArray[np.float64]
    pairs: NDArray[np.int64]
    windows: int
    window: float

    def describe(self) -> str:
        """One sentence for the bundle's description."""
        p = self.persisting
        return (
            f"odometry error persisting (Gauss-Markov, fitted to the autocovariance of "
            f"{self.window:g} s windows at lags 1..{int(self.lags[-1])} over {self.windows} "
            f"moved windows): speed scale sigma {p.sigma_scale:.4g} tau {p.time_constant_scale:.3g}"
            f" s, turn per metre sigma {p.sigma_turn:.4g} rad/m tau {p.time_constant_turn:.3g} s"
        )


def _lag_covariance(
    index: NDArray[np.int64],
    err: NDArray[np.float64],
    dist: NDArray[np.float64],
    lags: NDArray[np.int64],
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """``Σ r_i r_j / Σ d_i d_j`` over the pairs of windows ``L`` apart, per lag ``L``, and
    the pairs: the autocovariance of the ratio ``r/d`` weighted by ``d_i d_j`` (a window's
    error is ``x d`` plus white noise, so this is unbiased for ``E[x_i x_j]`` and leans on
    the windows that moved far, where the white noise is small against ``x d``)."""
    cov = np.full(lags.size, np.nan)
    pairs = np.zeros(lags.size, dtype=np.int64)
    for k, lag in enumerate(lags):  # a handful of lags, each vectorised over the windows
        pos = np.searchsorted(index, index + lag)
        pos = np.minimum(pos, index.size - 1)
        hit = index[pos] == index + lag
        i, j = np.flatnonzero(hit), pos[hit]
        pairs[k] = i.size
        if i.size >= 10:
            cov[k] = float(np.sum(err[i] * err[j]) / np.sum(dist[i] * dist[j]))
    return cov, pairs


def _fit_gauss_markov(
    lags: NDArray[np.int64], cov: NDArray[np.float64], window: float
) -> tuple[float, float]:
    """``(σ, τ)`` of a stationary Gauss–Markov ``x`` from the autocovariance ``cov`` of its
    **window means** at lags of ``L`` windows of ``window`` (``W``) seconds:
    ``E[x̄_i x̄_{i+L}] = σ² q(a) e^{−L a}``, ``a = W/τ``, ``q(a) = (sinh(a/2) / (a/2))²`` (the
    double integral of ``σ² e^{−|t−t'|/τ}`` over two windows ``L`` apart, over ``W²``; ``q → 1``
    as ``τ ≫ W``). Least squares with every lag alike (``_fit_decay``'s reasoning: the pairs
    of successive lags share windows), ``τ`` in ``[0.05, 600]`` s, ``σ² ≥ 0`` (no persistence:
    0). :func:`_fit_decay` fits correlations of residuals binned by time, with the share
    bounded below 1; here the lags are whole windows and the variance is not a share of a
    known total, hence its own fit."""
    from scipy.optimize import curve_fit

    use = np.isfinite(cov)
    if use.sum() < 3:
        raise _NoFit()
    lag = lags[use].astype(np.float64)

    def model(_: object, var: float, tau: float) -> NDArray[np.float64]:
        a = window / tau
        q = (np.sinh(a / 2) / (a / 2)) ** 2 if a > 1e-8 else 1.0
        return var * q * np.exp(-lag * a)

    c1 = float(cov[use][0])
    try:
        (var, tau), _ = curve_fit(
            model,
            np.zeros(lag.size),
            cov[use],
            p0=(max(c1, 1e-12) * 1.5, 2.0 * window),
            bounds=((0.0, 0.05), (np.inf, 600.0)),
        )
    except RuntimeError:  # no convergence
        raise _NoFit() from None
    return math.sqrt(max(float(var), 0.0)), float(tau)


def fit_motion_persisting(
    robot: MrclamRobot, *, window: float = 1.0, max_lag: int = 30
) -> MotionPersistingFit | None:
    """The odometry's persisting error (:class:`~recovery.models.MotionPersisting`) against
    the ground truth, from the windows :func:`fit_noise` fits on (:func:`control_windows`).

    On the windows where the robot moved (ground-truth path length ``d`` above
    :data:`MOVED_DISTANCE`) a speed-scale error ``s`` (``v_true = v (1 + s)``) makes the
    distance error ``e_d ≈ −s d`` and a turn-per-metre error ``κ`` (``ω_true = ω + κ v``)
    the turn error ``e_t ≈ −κ d``. Each ratio ``e/d`` (less its mean, weighted by ``d²``,
    beyond 5 robust σ left out) has its autocovariance at lags of 1 … ``max_lag`` windows
    measured (:func:`_lag_covariance`; lag 0 is left out: it holds the white noise, which
    does not reach the next window) and a Gauss–Markov fitted to it
    (:func:`_fit_gauss_markov`). A calibration against the ground truth, as the noise fit
    is; the Vicon path length's own noise shared by adjacent windows' common edge adds a
    small negative covariance at lag 1. ``None`` when fewer than three lags hold ten pairs
    of moved windows (or a fit does not converge). ``max_lag`` 30 (s at 1 s windows): over
    10 the turn error's covariance has not decayed on robots 1 and 3 of dataset 7 (``τ`` at
    the 600 s bound); over 30 every ``τ`` of robots 1–5 lies within 4–40 s (docs/commands.md).
    """
    w = control_windows(robot, window)
    moved = w.true_dist > MOVED_DISTANCE
    index, dist = w.index[moved], w.true_dist[moved]
    lags = np.arange(1, max_lag + 1, dtype=np.int64)
    out: list[tuple[float, float]] = []
    covs: list[NDArray[np.float64]] = []
    for err in (w.dist_error[moved], w.turn_error[moved]):
        if err.size < 10:
            return None
        keep = ~_beyond(err / dist)
        e, d, i = err[keep], dist[keep], index[keep]
        r = e - (np.sum(e * d) / np.sum(d * d)) * d  # less the (d²-weighted) mean ratio
        cov, _ = _lag_covariance(i, r, d, lags)
        covs.append(cov)
        try:
            out.append(_fit_gauss_markov(lags, cov, window))
        except _NoFit:
            return None
    _, pairs = _lag_covariance(index, dist, dist, lags)
    return MotionPersistingFit(
        persisting=MotionPersisting(out[0][0], out[0][1], out[1][0], out[1][1]),
        lags=lags,
        scale_covariance=covs[0],
        turn_covariance=covs[1],
        pairs=pairs,
        windows=int(moved.sum()),
        window=float(window),
    )


def white_alpha(
    alpha: tuple[float, float, float, float],
    persisting: MotionPersisting,
    *,
    window: float,
    period: float,
) -> tuple[tuple[float, float, float, float], bool]:
    """The white part of ``alpha`` fitted over windows of ``window`` seconds, the persisting
    error's share (:meth:`~recovery.models.MotionPersisting.alpha_share`, control rows every
    ``period`` seconds) taken from ``α1`` and ``α3``, each clipped at 0; and whether one was
    clipped (the persisting error then states more than the fit saw)."""
    d1, d3 = persisting.alpha_share(window, period)
    a1, a3 = alpha[0] - d1, alpha[2] - d3
    return (max(a1, 0.0), alpha[1], max(a3, 0.0), alpha[3]), bool(a1 < 0 or a3 < 0)


def _fit_variance(design: NDArray[np.float64], e: NDArray[np.float64]) -> NDArray[np.float64]:
    """Non-negative ``a`` with ``E[e²] = design @ a``: iteratively reweighted NNLS.

    For Gaussian ``e``, ``Var(e²) = 2 (E[e²])²``, so after an unweighted first round each
    row is weighted by ``1 / predicted variance`` (the Gamma-GLM weights; at rest, where
    the prediction is zero, the rows carry no information and are left out). The errors
    are a scale mixture, so a global robust σ would trim the fast windows; each error is
    judged against its own predicted σ instead (beyond 5 σ: left out). Five rounds.
    """
    use = np.ones(e.size, dtype=bool)
    weight = np.ones(e.size)
    a = np.zeros(design.shape[1])
    for _ in range(5):
        if use.sum() <= design.shape[1]:
            break
        a = nnls(design[use] * weight[use, None], e[use] ** 2 * weight[use])[0]
        var = design @ a
        use = (var > 0) & (e**2 <= 25.0 * var)
        weight = np.divide(1.0, var, out=np.zeros_like(var), where=var > 0)
    return a


def _beyond(x: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Entries more than 5 robust σ (1.4826 · MAD) from the median."""
    d = np.abs(x - np.median(x))
    return d > 5.0 * 1.4826 * np.median(d)


def _motion_model(
    r: MrclamRobot, fit: NoiseFit, c: NDArray[np.float64], motion_noise: str, persisting: bool
) -> tuple[MotionModel, str]:
    """The bundle's velocity model and its description: the fitted ``alpha`` (``"speed"``) or
    ``σ_v, σ_ω``; with ``persisting`` and ``"speed"`` the odometry's persisting error
    (:func:`fit_motion_persisting`) and the white ``alpha`` left (:func:`white_alpha`)."""
    if motion_noise != "speed":
        return MotionModel("velocity", sigma=(fit.sigma_v, fit.sigma_omega)), ""
    if persisting:  # the odometry's persisting error, fitted
        mp = fit_motion_persisting(r)
        if mp is not None:
            period = float(np.median(np.diff(c[:, 0])))
            alpha, clipped = white_alpha(fit.alpha, mp.persisting, window=fit.window, period=period)
            motion = MotionModel("velocity", alpha=alpha, persisting=mp.persisting)
            return motion, _motion_persisting_text(mp, fit, alpha, period, clipped)
    return MotionModel("velocity", alpha=fit.alpha), ""


def mrclam_bundle(
    directory: PathLike,
    robot: int,
    *,
    noise: NoiseFit | None = None,
    window: float = 1.0,
    calibrate: bool = True,
    motion_noise: str = "speed",
    decorrelate: float = 0.0,
    persisting: bool = True,
) -> Bundle:
    """One robot of an MRCLAM dataset as a SLAM log bundle (velocity model, known association).

    The map is the surveyed landmarks (``Landmark_Groundtruth.dat``; subjects are the ids),
    the ground truth the Vicon trajectory. The controls are, in order: corrected with
    :func:`calibrate_odometry` (``calibrate=False`` keeps the raw commands), split at gaps
    with :func:`resample_controls`; then noise parameters are fitted from them with
    :func:`fit_noise` unless given. The log starts at the first control inside the ground
    truth's span; the initial pose is the ground truth there (a tight prior fixes the frame).
    ``motion_noise="speed"`` (default) gives the velocity model the fitted ``alpha`` (noise
    grows with the commanded speeds, zero at rest), ``"constant"`` the fitted ``σ_v, σ_ω``:
    with ``"constant"`` a robot that stands still much of the time wanders under its biased
    measurements while standing, and its recovery is no better than dead reckoning; with
    ``"speed"`` every robot of dataset 7 stays below dead reckoning (the figures:
    benchmarks/README.md). The bundle's description records all fitted values.

    ``decorrelate`` (seconds, 0: off) makes the white-noise models fit errors that persist
    (docs/verdict.md, "Real robots"): the motion noise is fitted over windows of that length
    (``window`` is then ignored), so it states the drift between independent updates, and
    only one sighting per landmark every ``decorrelate`` seconds is kept
    (:func:`thin_sightings`; the others counted in the description and left out), so the
    filter does not count one persisting error as many independent measurements.

    ``persisting`` states the range-bearing errors' persistence in the sensor model
    (``sensor_model.persisting``, :func:`fit_persisting`), which the recovery then models
    (:mod:`recovery.persisting`), and their constant bearing part as the sensor's heading
    (``sensor_model.mount``, the mean bearing residual: robot 4 of dataset 7, −0.62°); on by
    default (``False``: white range-bearing noise, as before 2026-12-06). With
    ``motion_noise="speed"`` it also states the odometry's persisting error
    (``motion_model.persisting``, :func:`fit_motion_persisting`: a Gauss–Markov speed-scale
    and turn-per-metre error) and, as the model's white ``alpha``, the fitted ``alpha`` less
    that error's share of it (:func:`white_alpha`, at the fit's window and the controls'
    median period; ``slamrel slam`` adds the share at 1 s back). ``window`` is the
    motion noise's fitting window: the odometry's errors persist too (dataset 7, robot 1:
    ``α1`` 3.5 over 1 s, 16.6 over 10 s). With the persisting error stated and recovered no
    lamp of the default import's ``slamrel run`` is red on dataset 7, and the white EKF-SLAM
    chain (``slamrel slam``) runs on the 1 s ``alpha`` as before. The figures:
    docs/verdict.md ("Real robots").
    Every bundle states the share of gross errors (``sensor_model.outlier_share``,
    :meth:`NoiseFit.gross_share`: the residuals against the ground truth beyond the χ²₂
    99.9 % bound of the fitted σ, less the 0.1 % a Gaussian puts there — the contamination
    the verdict's map–log lamp expects in its tail, measured at its own bound).
    """
    if motion_noise not in ("speed", "constant"):
        raise InputError(f"motion_noise must be 'speed' or 'constant', got {motion_noise!r}")
    if not (math.isfinite(decorrelate) and decorrelate >= 0):
        raise InputError(f"decorrelate must be 0 or a positive time, got {decorrelate!r}")
    window = decorrelate if decorrelate > 0 else window
    d = Path(directory)
    r = read_mrclam_robot(d, robot)
    lm_path = d / "Landmark_Groundtruth.dat"
    lm, lm_lines = read_numeric_table(
        lm_path, columns=("subject", "x", "y", "sx", "sy"), describe="MRCLAM landmarks"
    )
    _unique_subjects(lm_path, lm[:, 0], lm_lines)
    odo_path = d / f"Robot{robot}_Odometry.dat"
    gt_name = f"Robot{robot}_Groundtruth.dat"
    # the fits work on arrays: their errors name the files the arrays came from
    with _about(odo_path, f"compared with {gt_name}"):
        cal = calibrate_odometry(r) if calibrate else None
        controls = r.controls if cal is None else cal.apply(r.controls)
        r = replace(r, controls=readonly(resample_controls(controls)))
    with _about(d / f"Robot{robot}_Measurement.dat", f"with {gt_name}, {lm_path.name}"):
        fit = fit_noise(r, lm[:, :3], window=window) if noise is None else noise
    gt = r.groundtruth
    c = r.controls
    keep_c = (c[:, 0] >= gt.timestamps[0]) & (c[:, 0] <= gt.timestamps[-1])
    c = c[keep_c]
    m = r.measurements
    keep_m = (m[:, 0] >= c[0, 0]) & (m[:, 0] <= c[-1, 0])
    m = m[keep_m]
    x0 = gt.poses_at(np.array([c[0, 0]]))[0]
    ids = lm[:, 0].astype(np.int64)
    known = np.isin(m[:, 3].astype(np.int64), ids)
    unsurveyed = int((~known).sum())
    m = m[known]
    thin = thin_sightings(m[:, 0], m[:, 3].astype(np.int64), decorrelate)
    m = m[thin]
    share = fit.gross_share(mounted=bool(persisting and fit.persisting))
    with _about(odo_path, f"compared with {gt_name}"):
        motion, motion_text = _motion_model(r, fit, c, motion_noise, persisting)
    return Bundle(
        motion=motion,
        sensor=SensorModel(
            fit.sigma_range,
            fit.sigma_bearing,
            persisting=fit.persisting if persisting else None,
            # the bearings' constant part is the sensor's heading: z = h(x ∘ mount, l)
            mount=(0.0, 0.0, -fit.bearing_offset) if persisting and fit.persisting else None,
            # the data's gross errors, which σ does not describe: the residuals' excess
            # beyond the 99.9 % bound the verdict's map–log lamp counts at, against the
            # ground truth, with the mount the bundle states
            outlier_share=share if share < 0.5 else None,
        ),
        measurement_times=m[:, 0],
        measurements=m[:, 1:3],
        measurement_landmarks=m[:, 3].astype(np.int64),
        measurement_associated=np.ones(m.shape[0], dtype=bool),
        map_ids=ids,
        map_xy=lm[:, 1:3],
        map_marginals=np.stack([np.diag(np.square(s)) for s in lm[:, 3:5]]),
        map_source="independent",  # the surveyed landmarks, not estimated from this log
        initial_pose=x0,
        initial_covariance=np.diag([1e-4, 1e-4, 1e-4]),
        controls=c,
        groundtruth=gt,
        landmarks_groundtruth=(ids, lm[:, 1:3]),
        description=(
            f"MRCLAM {d.name} robot {robot}: {r.robot_sightings} robot sightings and "
            f"{sum(r.unknown_barcodes.values())} unknown barcodes left out, "
            f"{unsurveyed} sightings of unsurveyed subjects left out; "
            f"{int((~keep_c).sum())} controls and {int((~keep_m).sum())} measurements outside "
            "the time span covered by both odometry and ground truth left out; "
            + _decorrelated_text(decorrelate, int((~thin).sum()), thin.size)
            + _noise_text(fit, motion_noise)
            + motion_text
            + _share_text(share, mounted=bool(persisting and fit.persisting))
            + (
                "raw odometry"
                if cal is None
                else f"odometry calibrated (delay {cal.delay:+.3f} s, speed x{cal.scale_v:.3f}, "
                f"turn rate x{cal.scale_omega:.3f}; {cal.window:g} s along-track rms "
                f"{cal.rms_before:.4f} -> {cal.rms_after:.4f} m)"
            )
            + "; controls split at gaps; map = surveyed landmarks"
            + _reordered_text(r.reordered)
        ),
        reordered=dict(r.reordered),
    )


def thin_sightings(
    times: NDArray[np.float64], landmarks: NDArray[np.int64], spacing: float
) -> NDArray[np.bool_]:
    """Mask of the sightings kept when each landmark is kept at most once every ``spacing``
    seconds: its first sighting, then the first at least ``spacing`` after the last kept
    one (``times`` increasing; ``spacing`` 0 keeps all). One jump per kept sighting
    (``searchsorted``), not a loop over the sightings."""
    keep = np.zeros(times.size, dtype=bool)
    if not spacing > 0:
        keep[:] = True
        return keep
    for lm in np.unique(landmarks):
        rows = np.flatnonzero(landmarks == lm)
        t = times[rows]
        j = 0
        while j < t.size:
            keep[rows[j]] = True
            j = int(np.searchsorted(t, t[j] + spacing, side="left"))
    return keep


def _decorrelated_text(spacing: float, left: int, total: int) -> str:
    """The description's note on :func:`thin_sightings` (empty when off)."""
    if not spacing > 0:
        return ""
    return (
        f"decorrelated over {spacing:g} s: {left} of {total} landmark sightings left out (one "
        f"per landmark every {spacing:g} s kept: successive errors persist), motion noise "
        f"fitted over {spacing:g} s windows; "
    )


def _noise_text(fit: NoiseFit, motion_noise: str) -> str:
    """The description's account of the fitted noise and its check."""
    return (
        f"noise fitted over {fit.window:g} s windows ("
        + (
            "alpha " + " ".join(f"{a:.4g}" for a in fit.alpha)
            if motion_noise == "speed"
            else f"sigma_v {fit.sigma_v:.4f}, sigma_omega {fit.sigma_omega:.4f}"
        )
        + f", sigma_range {fit.sigma_range:.4f}, sigma_bearing {fit.sigma_bearing:.4f}, "
        f"{100 * fit.outlier_fraction:.1f}% of measurements beyond 5 robust sigma; "
        + (fit.check.describe() if fit.check is not None else "fit not checked")
        + "); "
    )


def _motion_persisting_text(
    mp: MotionPersistingFit,
    fit: NoiseFit,
    alpha: tuple[float, float, float, float],
    period: float,
    clipped: bool,
) -> str:
    """The description's account of the stated motion persisting error and the white rest."""
    share = mp.persisting.alpha_share(fit.window, period)
    return (
        mp.describe()
        + f", stated as motion_model.persisting; its share of the {fit.window:g} s alpha "
        f"(alpha1 {share[0]:.4g}, alpha3 {share[1]:.4g} at {period:.4g} s control rows) taken "
        "out: white alpha "
        + " ".join(f"{a:.4g}" for a in alpha)
        + (" (clipped at 0: the persisting share exceeds the fitted alpha)" if clipped else "")
        + "; "
    )


def _share_text(share: float, *, mounted: bool) -> str:
    """The description's account of the stated share of gross errors."""
    if not share < 0.5:
        return "no share of gross errors stated (half or more of the residuals are beyond); "
    return (
        f"gross errors stated as {100 * share:.2f}% of the measurements (sensor_model."
        "outlier_share: the residuals beyond the 99.9% bound"
        + (", bearings less their mean," if mounted else "")
        + " less the 0.1% a Gaussian puts there); "
    )


def _reordered_text(reordered: dict[str, int]) -> str:
    """The description's note on rows put in time order (empty when none were)."""
    moved = {name: n for name, n in reordered.items() if n}
    if not moved:
        return ""
    return f"; put in time order (steps back of at most {FILTER_TIME_TOLERANCE:g} s): " + ", ".join(
        f"{n} row(s) of {name}" for name, n in moved.items()
    )
