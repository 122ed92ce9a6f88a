"""A diagnoser of your own in ~80 lines: a two-sided CUSUM on one channel (``cusum-example``).

Importing this module registers it, so from the repository root::

    python -m evaluation.leaderboard --quick --import examples.cusum_diagnoser \\
        --diagnosers cusum-example,limits

puts it on the leaderboard beside the baselines (the module is imported, not run: it needs no
``if __name__ == "__main__"`` guard). In Python::

    import diagnosers, fcc_env
    import examples.cusum_diagnoser  # registers "cusum-example"

    train = diagnosers.Episode.from_batch(fcc_env.simulate_episodes(range(1000, 1003), 4000))
    det = diagnosers.make("cusum-example", channel="T_rx").fit(train)

The statistic (Page, 1954) on the standardised channel ``z = (y - mean_) / std_``::

    s+_k = max(0, s+_{k-1} + z_k - k),   s-_k = max(0, s-_{k-1} - z_k - k),   alarm: s± > h

with slack ``k`` and limit ``h`` in units of the healthy standard deviation. It is a teaching
example: on FCC-v0 the operating program moves T_rx by several σ, so a CUSUM on the raw
measurement false-alarms often; a useful detector runs it on a model residual instead.

What ``diagnosers.check_diagnoser`` requires, and where this class does it (the full table is in
docs/diagnosers.md, *Your own diagnoser*):

* registered with a name: ``@diagnosers.register`` (step 0);
* keyword-only hyperparameters stored verbatim, nothing else in ``__init__`` (step 1);
  validation in ``_validate_params`` (step 2);
* ``channels_`` and ``sample_time_s_``: set by the base class's ``fit`` and ``load``;
* ``signal_names_`` (a non-empty tuple of str, one per signal) and the other learned attributes
  ending in ``_``: set in ``_fit`` and again in ``_set_state``, through ``_finish`` (steps 3, 4);
* ``_get_state`` / ``_set_state``: every learned number as plain arrays (step 4);
* ``_reset`` / ``_update``: streaming, a ``Decision`` per sample whose alarm means a signal is
  outside ``[lower, upper]`` (step 5); ``_detect`` equal to it (step 6);
* not isolating (``isolates`` stays False): no diagnosis (an isolating diagnoser also sets
  ``classes_``, its fault labels, in ``_fit`` and ``_set_state``);
* it learns from healthy episodes only (``learns_from_faults`` stays False: a detector that sets
  it is also handed labelled faulty episodes, each with its healthy twin of the same seed).

It is a scikit-learn estimator as it is: ``GridSearchCV(diagnosers.make("cusum-example"),
{"h": [4, 8, 16]}, scoring=diagnosers.make_scorer(), cv=StratifiedKFold(3)).fit(X,
diagnosers.episode_labels(X))`` (docs: *Tuning with scikit-learn*).
"""

from __future__ import annotations

import math

import numpy as np

import diagnosers
from diagnosers import Decision, Detection, Diagnoser, Episode
from fcc_common.validation import Real, check


# 0. Registered by name: the leaderboard's --diagnosers and Diagnoser.load find it by it.
@diagnosers.register("cusum-example")
class CUSUMDiagnoser(Diagnoser):
    """Two-sided CUSUM on one channel, standardised by its healthy mean and deviation.

    Args:
        channel: the monitored channel.
        k: slack, in healthy standard deviations (half the shift to detect fastest).
        h: alarm limit on each CUSUM, in healthy standard deviations.

    Decision arrays (``signal_names_`` = ``("<channel> cusum+", "<channel> cusum-")``):
        signal = the two sums, lower = ``-inf``, upper = ``h``, residual = ``y - mean_``.

    Attributes:
        mean_, std_: the channel's healthy mean and standard deviation (ddof=1).
    """

    # 1. __init__ stores keyword hyperparameters verbatim, nothing else.
    def __init__(self, *, channel: str = "T_rx", k: float = 0.5, h: float = 8.0) -> None:
        self.channel = channel
        self.k = k
        self.h = h

    # 2. Validation runs in fit, with the project's one message format.
    def _validate_params(self) -> None:
        check("k", self.k, Real(0, math.inf))
        check("h", self.h, Real(0, math.inf, closed="neither"))

    # 3. Learn from healthy episodes: attributes ending in "_".
    def _fit(self, episodes: list[Episode]) -> None:
        y = np.concatenate([ep.channel(self.channel) for ep in episodes])
        if y.size < 2:
            raise ValueError(f"cusum-example needs at least 2 training samples, got {y.size}")
        self.mean_ = float(y.mean())
        self.std_ = max(float(y.std(ddof=1)), 1e-12)
        self._finish()

    def _finish(self) -> None:
        # what _fit and _set_state both need: a loaded model never runs _fit, and
        # check_diagnoser requires signal_names_ on either (one name per signal column)
        self.index_ = self.channels_.index(self.channel)
        self.signal_names_ = (f"{self.channel} cusum+", f"{self.channel} cusum-")

    # 4. Persistence: learned numbers only (save/load come from the base class).
    def _get_state(self) -> dict[str, np.ndarray]:
        return {"mean": np.array(self.mean_), "std": np.array(self.std_)}

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.mean_ = float(state["mean"])
        self.std_ = float(state["std"])
        self._finish()

    # 5. Streaming: reset the sums, then one sample at a time.
    def _reset(self) -> None:
        self._hi = 0.0
        self._lo = 0.0

    def _update(self, y: np.ndarray) -> Decision:
        r = y[self.index_] - self.mean_
        z = r / self.std_
        self._hi = max(0.0, self._hi + z - self.k)
        self._lo = max(0.0, self._lo - z - self.k)
        return Decision(
            alarm=self._hi > self.h or self._lo > self.h,
            signal=np.array([self._hi, self._lo]),
            lower=np.full(2, -np.inf),
            upper=np.full(2, float(self.h)),
            residual=np.array([r, r]),
        )

    # 6. Optional: a whole-episode version; it must equal the streaming one (tested).
    def _detect(self, y: np.ndarray) -> Detection:
        r = y[:, self.index_] - self.mean_
        z = r / self.std_
        sums = np.empty((z.size, 2))
        hi = lo = 0.0
        for t, zt in enumerate(z.tolist()):  # the recursion is sequential; floats are fast
            hi = max(0.0, hi + zt - self.k)
            lo = max(0.0, lo - zt - self.k)
            sums[t] = hi, lo
        n = z.size
        return Detection(
            alarm=(sums > self.h).any(axis=1),
            signal=sums,
            lower=np.full((n, 2), -np.inf),
            upper=np.full((n, 2), float(self.h)),
            residual=np.column_stack([r, r]),
            signal_names=self.signal_names_,
        )
