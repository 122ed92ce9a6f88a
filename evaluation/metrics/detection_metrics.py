"""Fault-detection performance indexes of Patan & Parisini-style benchmarks (paper section 3).

All functions are pure and work on one episode's boolean alarm sequence, one entry per sample.
Times are sample indices (integers); to get seconds multiply by the episode's ``sample_time_s``.

* :func:`r_fd` - false detection rate, eq. (12): share of ``[t_on, t_from)`` spent in alarm.
* :func:`r_td` - true detection rate, eq. (13): share of ``[t_from, t_hor)`` spent in alarm.
* :func:`t_dt` - detection time: samples from ``t_from`` to the first alarm at or after it.
* :func:`novelty_rate` - share of ``[t_on, t_from)`` a diagnoser flagged as outside its training
  range (``Detection.novelty``): its own outcome, never counted as a false alarm.
* :func:`censored_delay` - the detection time with a miss counted: ``min(t_dt, horizon)``, a
  miss (``nan``) at ``horizon``, the samples scored from the onset on.

The paper sums the durations ``t_fd^i`` of the false (true) detection periods; with sampled alarms
that sum is the number of alarmed samples in the window, so the rates are window means.

>>> import numpy as np
>>> a = np.array([False, True, False, False, True, True])
>>> r_fd(a, t_from=4), r_td(a, t_from=4), t_dt(a, t_from=2)
(0.25, 1.0, 2.0)
"""

from __future__ import annotations

import numbers

import numpy as np

__all__ = [
    "censored_delay",
    "check_sample_index",
    "episode_scores",
    "novelty_rate",
    "r_fd",
    "r_td",
    "t_dt",
]


def _check_alarms(alarms: np.ndarray) -> np.ndarray:
    """Return ``alarms`` as a 1-D bool array; refuse anything that is not boolean already.

    Integer or float arrays are rejected rather than coerced: a score array passed by mistake
    (e.g. a T² statistic) would otherwise silently become "alarm wherever non-zero".
    """
    a = np.asarray(alarms)
    if a.dtype != np.bool_:
        raise ValueError(
            f"alarms must be a boolean array (dtype bool), got dtype {a.dtype}; "
            "threshold your scores first, e.g. alarms = score > limit"
        )
    if a.ndim != 1:
        raise ValueError(f"alarms must be 1-D (one entry per sample), got shape {a.shape}")
    if a.size == 0:
        raise ValueError("alarms is empty; an episode needs at least one sample")
    return a


def check_sample_index(name: str, value: object) -> int:
    """``value`` as an ``int`` sample index; ``ValueError`` naming ``name`` if it is not an integer."""
    # bool is an int subclass but True/False as a time is always a bug.
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an integer sample index, got {value!r}")
    return int(value)


def r_fd(alarms: np.ndarray, t_from: int, t_on: int = 0) -> float:
    """False detection rate, eq. (12): alarmed share of the fault-free window ``[t_on, t_from)``.

    Args:
        alarms: bool, shape ``(t_hor,)``, one decision per sample.
        t_from: fault onset sample; for a healthy episode pass ``len(alarms)`` (the horizon), so
            the result is the share of the whole episode in alarm. Allowed: ``0 < t_from <= t_hor``.
        t_on: benchmark start-up time (samples before it are not scored), ``0 <= t_on < t_from``.

    Returns:
        Fraction in ``[0, 1]`` (dimensionless).
    """
    a = _check_alarms(alarms)
    t_hor = a.size
    t_from = check_sample_index("t_from", t_from)
    t_on = check_sample_index("t_on", t_on)
    if not 0 < t_from <= t_hor:
        raise ValueError(f"t_from={t_from} outside the allowed range 0 < t_from <= {t_hor} (t_hor)")
    if not 0 <= t_on < t_from:
        raise ValueError(f"t_on={t_on} outside the allowed range 0 <= t_on < {t_from} (t_from)")
    return float(np.count_nonzero(a[t_on:t_from]) / (t_from - t_on))


def r_td(alarms: np.ndarray, t_from: int) -> float:
    """True detection rate, eq. (13): alarmed share of ``[t_from, t_hor)``, ``t_hor = len(alarms)``.

    Args:
        alarms: bool, shape ``(t_hor,)``.
        t_from: fault onset sample, ``0 <= t_from < t_hor``.

    Returns:
        Fraction in ``[0, 1]`` (dimensionless).
    """
    a = _check_alarms(alarms)
    t_from = _check_from(a, t_from)
    return float(np.count_nonzero(a[t_from:]) / (a.size - t_from))


def t_dt(alarms: np.ndarray, t_from: int) -> float:
    """Detection time: samples from ``t_from`` to the first alarm at or after ``t_from``.

    Args:
        alarms: bool, shape ``(t_hor,)``.
        t_from: fault onset sample, ``0 <= t_from < t_hor``.

    Returns:
        Delay in samples (``0.0`` when the onset sample itself is alarmed), or ``nan`` when the
        fault is never detected. A float so that undetected episodes can be represented.
    """
    a = _check_alarms(alarms)
    t_from = _check_from(a, t_from)
    hits = np.flatnonzero(a[t_from:])
    return float(hits[0]) if hits.size else float("nan")


def _check_from(a: np.ndarray, t_from: object, name: str = "t_from") -> int:
    t = check_sample_index(name, t_from)
    if not 0 <= t < a.size:
        raise ValueError(f"{name}={t} outside the allowed range 0 <= {name} < {a.size} (t_hor)")
    return t


def novelty_rate(novelty: np.ndarray, t_from: int, t_on: int = 0) -> float:
    """Share of the fault-free window ``[t_on, t_from)`` flagged novel (outside the diagnoser's
    training range); arguments as :func:`r_fd`, ``novelty`` a bool ``(t_hor,)``.

    >>> novelty_rate(np.array([True, True, False, False]), t_from=4)
    0.5
    """
    return r_fd(novelty, t_from, t_on)


def episode_scores(
    alarms: np.ndarray,
    fault_onset: int | None,
    t_on: int = 0,
    novelty: np.ndarray | None = None,
) -> dict[str, float]:
    """All three indexes of one episode (and the novelty rate where novelty is flagged).

    Args:
        alarms: bool, shape ``(t_hor,)``.
        fault_onset: onset sample of the fault, or ``None`` for a healthy episode.
        t_on: start-up samples not scored for false alarms, ``0 <= t_on < t_hor``.
        novelty: bool ``(t_hor,)``, the samples the diagnoser flagged outside its training
            range (``Detection.novelty``), or ``None`` (none flagged). Before the onset a novel
            sample is not a false alarm: ``r_fd`` counts the alarms on the other samples
            (over the whole window, so flagging nothing changes no figure) and
            ``"novelty"`` reports the novel share of the window (:func:`novelty_rate`).
            After the onset the alarms are scored as they are: a fault is still detected.

    Returns:
        ``{"r_fd", "r_td", "t_dt"}``, and ``"novelty"`` when ``novelty`` is given. Healthy
        episode: ``r_fd`` over ``[t_on, t_hor)``, ``r_td`` and ``t_dt`` are ``nan``. Faulty
        episode: ``r_fd`` over ``[t_on, fault_onset)`` (``nan`` when the fault starts at or
        before ``t_on``, so no fault-free sample is scored), ``r_td`` and ``t_dt`` from
        ``fault_onset`` on.

    >>> a = np.array([True, True, False, False])
    >>> episode_scores(a, None, novelty=np.array([True, False, False, False]))["r_fd"]
    0.25
    """
    if novelty is not None:
        a = _check_alarms(alarms)
        nov = _check_alarms(novelty)
        if nov.shape != a.shape:
            raise ValueError(f"novelty has shape {nov.shape}; allowed: {a.shape}, as alarms")
        out = episode_scores(a, fault_onset, t_on)
        end = a.size if fault_onset is None else _check_from(a, fault_onset, "fault_onset")
        fault_free = a.copy()
        fault_free[:end] &= ~nov[:end]
        nan = float("nan")
        scored = end > t_on
        out["r_fd"] = r_fd(fault_free, end, t_on) if scored else nan
        out["novelty"] = novelty_rate(nov, end, t_on) if scored else nan
        return out
    a = _check_alarms(alarms)
    t_on = check_sample_index("t_on", t_on)
    if not 0 <= t_on < a.size:
        raise ValueError(f"t_on={t_on} outside the allowed range 0 <= t_on < {a.size} (t_hor)")
    nan = float("nan")
    if fault_onset is None:
        return {"r_fd": r_fd(a, a.size, t_on), "r_td": nan, "t_dt": nan}
    onset = _check_from(a, fault_onset, "fault_onset")
    return {
        "r_fd": r_fd(a, onset, t_on) if onset > t_on else nan,
        "r_td": r_td(a, onset),
        "t_dt": t_dt(a, onset),
    }


def censored_delay(t_dt: float, horizon: int) -> float:
    """The detection time of one faulty episode with a miss counted: ``min(t_dt, horizon)``,
    and ``horizon`` when the fault was missed (``t_dt`` is ``nan``).

    A mean of ``t_dt`` over the detected seeds only rewards a detector that misses its slow
    seeds; censoring at the end of the episode charges a miss the whole post-onset time it
    stayed silent, a lower bound on its true delay (the alarm would come, if ever, later).

    Args:
        t_dt: samples from the onset to the first alarm at or after it, ``nan`` when missed.
        horizon: the samples scored from the onset on (``T - onset``, cut where the plant
            ended the episode), an integer ≥ 1.

    >>> censored_delay(12.0, 300), censored_delay(float("nan"), 300)
    (12.0, 300.0)
    """
    h = check_sample_index("horizon", horizon)
    if h < 1:
        raise ValueError(f"horizon={horizon!r}; allowed: an integer ≥ 1 (samples after the onset)")
    t = float(t_dt)
    if np.isnan(t):
        return float(h)
    if t < 0:
        raise ValueError(f"t_dt={t_dt!r}; allowed: a delay ≥ 0 samples, or nan for a miss")
    return min(t, float(h))
