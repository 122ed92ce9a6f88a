"""What a diagnoser says: a :class:`Decision` per sample, a :class:`Detection` per episode.

An isolating diagnoser also names the fault class it diagnoses: one of its trained classes,
:data:`UNKNOWN`, or :data:`NO_DIAGNOSIS` while not alarmed.

Both carry a normalised ``score`` (:func:`normalised_score`): the largest exceedance of any
signal over its limits, scaled so that a limit sits at :data:`SCORE_THRESHOLD` (1). ``score >
1`` marks the samples where some signal is outside ``[lower, upper]`` (the raw limit test);
``alarm`` is the diagnoser's decision, which equals that test for every registered diagnoser at
its defaults, and is a filtered subset of it where an alarm filter is set (``lrgf-glr``'s
``on_delay`` > 1: an alarm only after that many exceedances in a row).

>>> import numpy as np
>>> det = Detection(
...     alarm=np.array([False, True, False]),
...     signal=np.array([[0.5, 1.0], [3.0, 2.0], [-1.0, 0.0]]),
...     lower=np.array([[-1.0, -np.inf], [-1.0, -np.inf], [-1.0, -np.inf]]),
...     upper=np.array([[1.0, 4.0], [1.0, 4.0], [1.0, 4.0]]),
...     residual=np.zeros((3, 2)),
...     signal_names=("two-sided", "upper limit"),
... )
>>> det.score.tolist()
[0.5, 3.0, 1.0]
>>> bool(np.array_equal(det.alarm, det.score > det.threshold))
True
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

__all__ = [
    "NO_DIAGNOSIS",
    "SCORE_THRESHOLD",
    "UNKNOWN",
    "Decision",
    "Detection",
    "exceedance",
    "normalised_score",
]

#: The diagnosis of an isolating diagnoser that is alarmed but fits none of its fault classes.
UNKNOWN = "unknown"
#: The diagnosis while not alarmed (no diagnosis).
NO_DIAGNOSIS = ""
#: The normalised score of a signal on its limit: ``score > SCORE_THRESHOLD`` is "outside".
SCORE_THRESHOLD = 1.0
# the smallest float above the threshold: an exceedance that rounding brought down to 1
_JUST_OVER = float(np.nextafter(SCORE_THRESHOLD, np.inf))


def exceedance(signal: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Each signal's normalised exceedance of its limits (same shape, float64), 1 on a limit.

    Per entry, with ``s`` the signal and ``l``/``u`` its limits:

    * both finite (a band): ``|2(s − m)/(u − l)|``, ``m = (l + u)/2``: 0 at the band's centre,
      1 on either edge (a band of zero width: 1 on it, ``inf`` off it);
    * only ``u`` finite (an upper limit, e.g. T² ≤ h): ``s/u`` if ``u > 0``, ``2 − s/u`` if
      ``u < 0`` (both ``1 + (s − u)/|u|``), ``1 + s`` if ``u = 0`` (signal units);
    * only ``l`` finite (a lower limit): ``s/l`` if ``l < 0``, ``2 − s/l`` if ``l > 0``,
      ``1 − s`` if ``l = 0``;
    * neither (no limit, e.g. a detector's silent warm-up): 0.

    A one-sided score is negative where the signal is on the far side of zero. The exact
    limit test decides the side of 1 where rounding could blur it: an entry is above 1 if and
    only if ``s < l or s > u``.
    """
    s, lo, hi = np.broadcast_arrays(
        *(np.asarray(a, dtype=np.float64) for a in (signal, lower, upper))
    )
    has_lo, has_hi = np.isfinite(lo), np.isfinite(hi)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        band = np.abs(2.0 * (s - (lo + hi) / 2.0) / (hi - lo))
        above = np.where(hi > 0, s / hi, np.where(hi < 0, 2.0 - s / hi, 1.0 + s))
        below = np.where(lo < 0, s / lo, np.where(lo > 0, 2.0 - s / lo, 1.0 - s))
    ratio = np.select([has_lo & has_hi, has_hi, has_lo], [band, above, below], default=0.0)
    outside = (s < lo) | (s > hi)
    # fmin: a zero-width band's 0/0 on its edge is on the limit (1), not NaN
    return np.where(outside, np.maximum(ratio, _JUST_OVER), np.fmin(ratio, SCORE_THRESHOLD))


def normalised_score(signal: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """The largest :func:`exceedance` over the signals (the last axis): ``(T, k) -> (T,)``,
    ``(k,) -> ()``. Above :data:`SCORE_THRESHOLD` exactly where some signal is outside its
    limits (``-inf`` with no signal at all)."""
    e = exceedance(signal, lower, upper)
    if e.shape[-1] == 0:
        return np.full(e.shape[:-1], -np.inf)
    return e.max(axis=-1)


@dataclass(frozen=True)
class Decision:
    """What a diagnoser says about one sample.

    ``signal`` is what the diagnoser checks (a measured output for band detectors, a statistic such
    as Hotelling's T² for others), ``lower``/``upper`` the limits it checks it against
    (``-inf``/``inf`` when one-sided), ``residual`` the model residual (measured − predicted)
    where there is a model. All arrays have one entry per monitored quantity, named by
    :attr:`diagnosers.Diagnoser.signal_names_`.
    """

    alarm: bool
    signal: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    residual: np.ndarray
    #: isolating diagnosers (:attr:`diagnosers.Diagnoser.isolates`): one of the trained fault classes,
    #: :data:`UNKNOWN`, or :data:`NO_DIAGNOSIS` (``""``) while not alarmed
    diagnosis: str = NO_DIAGNOSIS
    #: isolating diagnosers: a score per class of :attr:`Detection.class_names` (higher = fits
    #: better), ``None`` for a diagnoser that only detects
    class_scores: np.ndarray | None = None
    #: a probabilistic diagnoser (``mmae``): the probability of each hypothesis of
    #: :attr:`Detection.hypothesis_names` (summing to 1), ``None`` for the others
    posterior: np.ndarray | None = None
    #: the score on a limit (:data:`SCORE_THRESHOLD`)
    threshold: ClassVar[float] = SCORE_THRESHOLD

    @property
    def score(self) -> float:
        """The normalised score (:func:`normalised_score`): above :attr:`threshold` (1) exactly
        when some signal is outside its limits."""
        return float(normalised_score(self.signal, self.lower, self.upper))


@dataclass(frozen=True)
class Detection:
    """Decisions over a whole episode: each array has a leading time axis of length n_samples.

    An isolating diagnoser also fills ``diagnosis`` (``(T,)`` str: a class of ``class_names``,
    :data:`UNKNOWN`, or ``""`` while not alarmed) and ``class_scores`` (``(T, C)``, one column
    per name of ``class_names``); a detector leaves them ``None`` and ``()``.

    A probabilistic diagnoser (a bank of filters, ``mmae``) also fills ``posterior`` (``(T, H)``:
    the probability of each hypothesis of ``hypothesis_names`` after sample k, each row summing
    to 1; the healthy hypothesis is named ``"nominal"``); the others leave ``None`` and ``()``.

    :attr:`score` ``(T,)`` is the normalised score (:func:`normalised_score`, computed from
    ``signal``/``lower``/``upper``), and ``score > threshold`` (:data:`SCORE_THRESHOLD`, 1)
    the raw limit test: some signal outside its limits. For every registered diagnoser at
    its defaults ``alarm`` equals it sample for sample; an alarm filter makes ``alarm`` a
    subset of it: ``lrgf-glr``'s ``on_delay`` (and its presets', and an isolator's around
    such a detector) alarms only after ``on_delay`` raw exceedances in a row. An EWMA or
    T² stage (``lrgf-mem``'s ``alarm_filter``) filters the *signal* instead, so its alarm is
    the raw test of the filtered signal and equals ``score > 1``.

    ``novelty`` ``(T,)`` bool marks the samples the diagnoser declares outside its training
    range (an operating point no training episode reached, where a learned model
    extrapolates): its own outcome, "novel", not a fault. The scoring
    (:func:`evaluation.metrics.detection_metrics.episode_scores`) counts no novel sample as a
    false alarm and reports the novel share beside ``r_fd``. ``None`` (the default, every
    diagnoser that flags nothing) reads as all False (:attr:`novel`).
    """

    alarm: np.ndarray  # (T,) bool
    signal: np.ndarray  # (T, k)
    lower: np.ndarray  # (T, k)
    upper: np.ndarray  # (T, k)
    residual: np.ndarray  # (T, k)
    signal_names: tuple[str, ...]
    diagnosis: np.ndarray | None = None  # (T,) str, isolating diagnosers only
    class_scores: np.ndarray | None = None  # (T, C), isolating diagnosers only
    class_names: tuple[str, ...] = ()
    posterior: np.ndarray | None = None  # (T, H), probabilistic diagnosers only
    hypothesis_names: tuple[str, ...] = ()
    novelty: np.ndarray | None = None  # (T,) bool, samples outside the training range
    #: the score on a limit (:data:`SCORE_THRESHOLD`): ``score > threshold`` is the raw test
    threshold: ClassVar[float] = SCORE_THRESHOLD

    def __post_init__(self) -> None:
        n = len(self.alarm)
        if self.posterior is not None:
            post = np.asarray(self.posterior, dtype=np.float64)
            names = tuple(self.hypothesis_names)
            if post.shape != (n, len(names)) or not names:
                raise ValueError(
                    f"Detection.posterior must have shape ({n}, {len(names)}) for "
                    f"hypothesis_names {names} (at least one), got {post.shape}"
                )
            total = post.sum(axis=1)
            if not (np.all(post >= 0.0) and np.allclose(total, 1.0, rtol=0.0, atol=1e-9)):
                bad = int(np.argmax(np.abs(total - 1.0) + (post < 0).any(axis=1)))
                raise ValueError(
                    "Detection.posterior rows must be probabilities summing to 1; row "
                    f"{bad} is {post[bad].tolist()}"
                )
            object.__setattr__(self, "posterior", post)
            object.__setattr__(self, "hypothesis_names", names)
        elif self.hypothesis_names:
            raise ValueError(
                f"Detection.hypothesis_names {self.hypothesis_names} given without a posterior"
            )
        if self.novelty is not None:
            nov = np.asarray(self.novelty)
            if nov.dtype != np.bool_ or nov.shape != (n,):
                raise ValueError(
                    f"Detection.novelty must be a bool array of shape ({n},), got dtype "
                    f"{nov.dtype} and shape {nov.shape}"
                )
            object.__setattr__(self, "novelty", nov)
        if self.diagnosis is not None:
            diag = np.asarray(self.diagnosis, dtype=str)
            if diag.shape != (n,):
                raise ValueError(f"Detection.diagnosis must have shape ({n},), got {diag.shape}")
            object.__setattr__(self, "diagnosis", diag)
        if self.class_scores is not None:
            cs = np.asarray(self.class_scores, dtype=np.float64)
            if cs.shape != (n, len(self.class_names)):
                raise ValueError(
                    f"Detection.class_scores must have shape ({n}, {len(self.class_names)}) for "
                    f"class_names {self.class_names}, got {cs.shape}"
                )
            object.__setattr__(self, "class_scores", cs)

    @property
    def score(self) -> np.ndarray:
        """The normalised score per sample ``(T,)`` (:func:`normalised_score`): above
        :attr:`threshold` (1) exactly where some signal is outside its limits."""
        return normalised_score(self.signal, self.lower, self.upper)

    @property
    def probabilistic(self) -> bool:
        """Whether the detection carries a posterior over hypotheses per sample."""
        return self.posterior is not None

    @property
    def novel(self) -> np.ndarray:
        """``(T,)`` bool: the samples flagged outside the training range (all False when the
        diagnoser flags none)."""
        if self.novelty is None:
            return np.zeros(len(self.alarm), dtype=bool)
        return self.novelty

    @property
    def isolates(self) -> bool:
        """Whether the detection carries a diagnosis per sample."""
        return self.diagnosis is not None

    @classmethod
    def from_decisions(
        cls,
        decisions: Sequence[Decision],
        signal_names: tuple[str, ...],
        class_names: tuple[str, ...] | None = None,
        hypothesis_names: tuple[str, ...] | None = None,
    ) -> Detection:
        """Stack per-sample decisions; with ``class_names`` also their diagnoses and scores,
        with ``hypothesis_names`` their posteriors."""
        iso: dict[str, Any] = {}
        if hypothesis_names is not None:
            iso["posterior"] = np.stack([d.posterior for d in decisions]).reshape(
                len(decisions), len(hypothesis_names)
            )
            iso["hypothesis_names"] = tuple(hypothesis_names)
        if class_names is not None:
            scores = [d.class_scores for d in decisions]
            iso = {
                "diagnosis": np.array([d.diagnosis for d in decisions], dtype=str).reshape(-1),
                "class_scores": (
                    np.stack(scores).reshape(len(decisions), len(class_names))
                    if all(s is not None for s in scores)
                    else None
                ),
                "class_names": tuple(class_names),
            }
        return cls(
            alarm=np.array([d.alarm for d in decisions], dtype=bool),
            signal=np.stack([d.signal for d in decisions]),
            lower=np.stack([d.lower for d in decisions]),
            upper=np.stack([d.upper for d in decisions]),
            residual=np.stack([d.residual for d in decisions]),
            signal_names=signal_names,
            **iso,
        )

    def decision(self, k: int) -> Decision:
        return Decision(
            alarm=bool(self.alarm[k]),
            signal=self.signal[k],
            lower=self.lower[k],
            upper=self.upper[k],
            residual=self.residual[k],
            diagnosis=NO_DIAGNOSIS if self.diagnosis is None else str(self.diagnosis[k]),
            class_scores=None if self.class_scores is None else self.class_scores[k],
            posterior=None if self.posterior is None else self.posterior[k],
        )
