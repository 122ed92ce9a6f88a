"""The diagnoser contract: episodes in, alarms (with residuals and bands) out.

:class:`DiagnoserContract` holds what every diagnoser does (hyperparameters, ``fit``, ``reset``,
``update``, ``detect`` and the hooks behind them); :class:`diagnosers.diagnoser.Diagnoser`, the
class every diagnoser derives from, adds saving and loading.

A diagnoser is trained on healthy episodes with ``fit``, then watches an episode either sample by
sample (``reset`` followed by ``update``) or all at once (``detect``). Both paths must give the
same decisions; the conformance tests check it.

Conventions follow scikit-learn's estimators: ``__init__`` stores keyword hyperparameters verbatim
and does nothing else, ``fit`` validates them and returns ``self``, learned attributes end in ``_``.
"""

from __future__ import annotations

import inspect
import logging
from abc import ABC, abstractmethod
from collections.abc import Iterable, Sequence
from enum import StrEnum
from typing import Any, ClassVar, Self

import numpy as np

from diagnosers.detection import NO_DIAGNOSIS, UNKNOWN, Decision, Detection
from diagnosers.episode.record import Episode
from diagnosers.tuning.scorer import check_episode_labels, make_scorer

__all__ = ["DiagnoserContract", "NotFittedError", "Tier", "check_labelled", "require_varying"]

logger = logging.getLogger(__name__)


def _as_episode(obj: Any, what: str) -> Episode:
    """``obj`` if it is an :class:`Episode`; else a ValueError that says how to build one."""
    if isinstance(obj, Episode):
        return obj
    kind = type(obj).__module__.replace("builtins", "").strip(".")
    kind = f"{kind}.{type(obj).__qualname__}" if kind else type(obj).__qualname__
    shape = f" of shape {obj.shape}" if hasattr(obj, "shape") else ""
    raise ValueError(
        f"{what} takes Episode objects, got a {kind}{shape}: wrap the measurements as "
        "Episode(y, channels=..., sample_time_s=...) from diagnosers"
    )


def require_varying(y: np.ndarray, names: Sequence[str], who: str, *, every: bool = True) -> None:
    """Refuse constant training data (``y``: samples x the channels ``names``).

    ``every=True`` refuses when any of the channels never changes (a model output, whose band
    would have no spread to calibrate on: a non-finite band or alarms on every sample);
    ``every=False`` only when all of them are constant (a detector that can leave a flat channel
    out of its scale, but learns nothing from all-flat data).
    """
    y = np.asarray(y, dtype=np.float64)
    flat = [str(n) for n, col in zip(names, y.T, strict=True) if col.size and np.ptp(col) == 0.0]
    if flat and (every or len(flat) == len(names)):
        raise ValueError(
            f"{who} cannot be trained: the training data are constant in channel(s) {flat} "
            "(every sample has the same value); train on records in which they vary"
        )


def _training_episodes(episodes: Any, y: Any, isolates: bool) -> list[Episode]:
    """``fit``'s argument as a list of episodes; with labels ``y``, a detector's healthy ones."""
    if isinstance(episodes, Episode):
        episodes = [episodes]
    if isinstance(episodes, str | bytes) or not hasattr(episodes, "__iter__"):
        _as_episode(episodes, "fit")
    if isinstance(episodes, np.ndarray) and episodes.dtype != object:
        _as_episode(episodes, "fit")  # measurements, not episodes: say how to wrap them
    episodes = [_as_episode(ep, "fit") for ep in episodes]
    if y is None:
        return episodes
    check_episode_labels(episodes, y)
    if isolates:
        return episodes
    healthy = [ep for ep in episodes if ep.fault_onset is None]
    if episodes and not healthy:
        raise ValueError(
            f"fit(X, y): y marks none of the {len(episodes)} episodes healthy (0); a detector "
            "trains on healthy episodes"
        )
    return healthy


class Tier(StrEnum):
    """What a diagnoser may know of the plant (:attr:`DiagnoserContract.tier`; the tables rank
    within each tier).

    * ``black box``: the records alone (channels, sample time), whatever it learns from them;
    * ``grey box``: also the published model's structure (the spec's equations, the nominal
      parameters as a prior, the sensor noise model, the fault registry's parameter paths),
      never a parameter value of the plant it is scored on: it fits those from its training
      records (tested: ``tests/diagnosers/test_grey_box.py``).
    """

    BLACK_BOX = "black box"
    GREY_BOX = "grey box"


class NotFittedError(RuntimeError):
    """Raised when a diagnoser is used before :meth:`DiagnoserContract.fit`."""


def check_labelled(episodes: Sequence[Episode]) -> None:
    """Training episodes of a diagnoser that learns from labelled faults (it isolates, or
    :attr:`~DiagnoserContract.learns_from_faults`): one healthy at least, faults labelled."""
    if not any(ep.fault_onset is None for ep in episodes):
        raise ValueError(
            "a diagnoser that learns from labelled faults needs at least one healthy episode "
            "(fault_onset=None) among its training episodes, got none"
        )
    for ep in episodes:
        if ep.fault_onset is not None and ep.scenario in (UNKNOWN, NO_DIAGNOSIS, "nominal"):
            raise ValueError(
                f"faulty training episode (seed {ep.seed}) has scenario={ep.scenario!r}; a "
                f"labelled fault needs a class name other than {UNKNOWN!r}, '' and 'nominal'"
            )


class DiagnoserContract(ABC):
    """What every diagnoser does (template method: public methods check, ``_impl`` ones work).

    Subclasses implement ``_fit``, ``_reset``, ``_update`` and may override ``_detect`` with a
    vectorised version that must equal repeated ``_update`` calls. Diagnosers derive from
    :class:`diagnosers.diagnoser.Diagnoser`, which adds :meth:`~diagnosers.diagnoser.Diagnoser.save`
    and :meth:`~diagnosers.diagnoser.Diagnoser.load`.
    """

    #: registry name, set by :func:`diagnosers.register`.
    name: ClassVar[str] = ""
    #: what the diagnoser may know of the plant (:class:`Tier`)
    tier: ClassVar[Tier] = Tier.BLACK_BOX
    #: whether the diagnoser also isolates: it is then trained on healthy *and* labelled faulty
    #: episodes (``fault_onset`` and ``scenario`` set) and its decisions carry a diagnosis
    isolates: ClassVar[bool] = False
    #: whether the diagnoser learns from labelled faulty episodes without isolating (e.g.
    #: ``lrgf-glr``'s fault directions): the harness then passes them to ``fit`` beside the
    #: healthy ones (on the healthy training seeds' noise twins), and only healthy episodes
    #: train its models; it still works when none are given
    learns_from_faults: ClassVar[bool] = False
    #: hyperparameters that say how to compute, never what: the fitted model is the same for
    #: every value (a progress bar, the number of worker processes). :meth:`result_params` leaves
    #: them out, so the result store's hashes do not change with them.
    execution_params: ClassVar[tuple[str, ...]] = ()

    # ---- scikit-learn style parameter handling -------------------------------------------------
    @classmethod
    def param_names(cls) -> list[str]:
        """The hyperparameters' names, from the keyword-only parameters of ``__init__``."""
        sig = inspect.signature(cls.__init__)
        return [
            p.name for p in sig.parameters.values() if p.name != "self" and p.kind is p.KEYWORD_ONLY
        ]

    @classmethod
    def fast_params(cls) -> dict[str, Any]:
        """Small, fast hyperparameters for smoke runs, quick sweeps and tests (``{}``: defaults).

        A subclass whose defaults train for long (neural models) returns overrides that keep
        the model's structure but cut its cost, e.g. fewer epochs.
        """
        return {}

    @classmethod
    def check_param_names(cls, names: Iterable[str]) -> None:
        """Raise ``ValueError`` naming any of ``names`` that ``__init__`` does not accept."""
        allowed = cls.param_names()
        unknown = sorted(set(names) - set(allowed))
        if unknown:
            label = cls.name or cls.__name__
            raise ValueError(
                f"Unknown hyperparameter(s) {unknown} for diagnoser {label!r}. Allowed: {allowed}"
            )

    def validate_params(self) -> None:
        """Check the hyperparameters now (``fit`` does too); raise ``ValueError`` naming the
        value and the allowed range. Lets a sweep refuse a bad configuration before training."""
        self._validate_params()

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """Hyperparameters as passed to ``__init__`` (JSON-serialisable by convention).

        ``deep`` is scikit-learn's flag (so ``sklearn.base.clone`` works); it changes nothing
        here because no hyperparameter is itself an estimator (an isolator's inner detector is
        given by name and a dict of its hyperparameters).
        """
        return {k: getattr(self, k) for k in self.param_names()}

    def result_params(self) -> dict[str, Any]:
        """:meth:`get_params` without :attr:`execution_params`: what the fitted model depends on."""
        return {k: v for k, v in self.get_params().items() if k not in self.execution_params}

    def set_params(self, **params: Any) -> Self:
        """Set hyperparameters (scikit-learn style) and return ``self``.

        Names are checked against ``__init__``'s signature, as :func:`diagnosers.make` does;
        values are validated by the next :meth:`fit`, like those given to ``__init__``. A fitted
        diagnoser becomes unfitted (its learned state belongs to the old hyperparameters, and
        :meth:`~diagnosers.diagnoser.Diagnoser.save` would pair them with the new ones): call :meth:`fit` again.

        >>> import diagnosers
        >>> diagnosers.make("limits").set_params(alpha=0.05).get_params()["alpha"]
        0.05
        """
        self.check_param_names(params)
        for k, v in params.items():
            setattr(self, k, v)
        if params:
            self._fitted_ = False
        return self

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
        return f"{type(self).__name__}({args})"

    def __sklearn_tags__(self) -> Any:
        """scikit-learn's estimator tags (``GridSearchCV`` reads them, scikit-learn >= 1.6): no
        estimator type (neither classifier nor regressor), ``y`` optional, and an input of
        episodes that :meth:`fit` checks itself."""
        from sklearn.utils import InputTags, Tags, TargetTags

        return Tags(
            estimator_type=None,
            target_tags=TargetTags(required=False),
            input_tags=InputTags(two_d_array=False),
            no_validation=True,
        )

    def score(self, episodes: Sequence[Episode], y: Any = None) -> float:
        """scikit-learn's ``score``: the fitted diagnoser's detection score on labelled
        ``episodes``, healthy and faulty (:class:`diagnosers.tuning.scorer.DetectionScorer` at its
        defaults; higher is better). ``GridSearchCV`` uses it when given no ``scoring``."""
        return make_scorer()(self, episodes, y)

    # ---- public API ----------------------------------------------------------------------------
    def fit(self, episodes: Sequence[Episode], y: Any = None) -> Self:
        """Learn from healthy episodes and return ``self``.

        An isolating diagnoser (:attr:`isolates`) also receives labelled faulty episodes
        (``fault_onset`` set, ``scenario`` the fault class), and so may one that learns from
        faults (:attr:`learns_from_faults`); both need at least one healthy one.

        ``y`` is for scikit-learn (``GridSearchCV(...).fit(X, y)`` passes each split's part
        on): ``None``, or :func:`diagnosers.episode_labels` of ``episodes`` (1 faulty, 0
        healthy; one that disagrees is refused). Given, a detector trains on the episodes it
        marks healthy and leaves the faulty ones, which are there to be scored, out; an
        isolating diagnoser (or one that learns from faults) trains on all. Without it every
        episode is training data.
        """
        episodes = _training_episodes(episodes, y, self.isolates or self.learns_from_faults)
        if not episodes:
            raise ValueError("fit needs at least one healthy episode, got none")
        if self.isolates or self.learns_from_faults:
            check_labelled(episodes)
        channels = episodes[0].channels
        for ep in episodes:
            if ep.channels != channels:
                raise ValueError(
                    f"all training episodes must share channels; got {ep.channels} and {channels}"
                )
            if not np.isclose(ep.sample_time_s, episodes[0].sample_time_s, rtol=1e-9, atol=0.0):
                raise ValueError(
                    f"all training episodes must share one sample time; got sample_time_s="
                    f"{ep.sample_time_s!r} and {episodes[0].sample_time_s!r}"
                )
        self._validate_params()
        # A failed re-fit must not leave an object that looks fitted with half-updated state.
        self._fitted_ = False
        self.channels_ = channels
        self.sample_time_s_ = float(episodes[0].sample_time_s)
        logger.debug(
            "fitting %r on %d episodes (%d samples)",
            self,
            len(episodes),
            sum(ep.n_samples for ep in episodes),
        )
        self._fit(episodes)
        self._fitted_ = True
        self.reset()
        return self

    def reset(self) -> None:
        """Forget the current episode; call before streaming a new one."""
        self._check_fitted()
        self._reset()

    def update(self, measurement: np.ndarray) -> Decision:
        """Consume one sample (shape ``(n_channels,)``, order ``channels_``) and decide."""
        self._check_fitted()
        y = np.asarray(measurement, dtype=np.float64)
        if y.shape != (len(self.channels_),):
            raise ValueError(
                f"measurement must have shape ({len(self.channels_)},) in channel order "
                f"{self.channels_}; got {y.shape}"
            )
        if not np.isfinite(y).all():
            raise ValueError(f"measurement contains NaN or inf: {y}")
        return self._update(y)

    def _check_episode(self, episode: Episode) -> None:
        """Fitted, and ``episode`` has the training channels in the training order."""
        self._check_fitted()
        episode = _as_episode(episode, "detect")
        if episode.channels != self.channels_:
            raise ValueError(
                f"episode channels {episode.channels} differ from the training channels "
                f"{self.channels_}"
            )
        if not np.isclose(episode.sample_time_s, self.sample_time_s_, rtol=1e-9, atol=0.0):
            raise ValueError(
                f"episode sample_time_s={episode.sample_time_s!r} differs from the training "
                f"sample time {self.sample_time_s_!r} s: the models are discrete-time, so "
                "resample the record or train on data of this sample time"
            )

    def detect(self, episode: Episode) -> Detection:
        """Score a whole episode; equal to ``reset()`` then ``update`` on every sample."""
        self._check_episode(episode)
        self._reset()
        det = self._detect(episode.y)
        self._reset()
        return det

    def band_view(self, episode: Episode) -> Detection | None:
        """The measured outputs with the bands the diagnoser's models put around them, if any.

        For figures in the style of the paper's: a diagnoser whose :meth:`detect` reports a
        combined statistic (T² over several relations) can also show each model's band around its
        measured output. ``None`` (the default) when there is no such view, or when
        :meth:`detect` already is it.
        """
        self._check_episode(episode)
        return None

    # ---- hooks ---------------------------------------------------------------------------------
    # A subclass implements _fit, _reset and _update (and Diagnoser's _get_state and _set_state);
    # _detect and _validate_params are optional. The public methods have
    # already checked their input when a hook runs (see each hook), so hooks do not re-check.
    def _validate_params(self) -> None:  # noqa: B027 - optional hook
        """Check hyperparameters; raise ValueError naming the value and the allowed range.

        Called by :meth:`fit` before :meth:`_fit` (never by ``__init__``): use
        :func:`fcc_common.validation.check_params` with a table of constraints.
        """

    @abstractmethod
    def _fit(self, episodes: list[Episode]) -> None:
        """Learn from healthy ``episodes`` and set the learned attributes (names ending in ``_``).

        Receives a non-empty list of :class:`Episode` sharing one channel tuple; ``channels_``
        and ``sample_time_s_`` are already set and :meth:`_validate_params` has passed. Must set
        ``signal_names_`` (names of the monitored quantities, one per entry of
        :attr:`Decision.signal`). Returns nothing: :meth:`fit` returns ``self`` and then calls
        :meth:`reset`.
        """

    @abstractmethod
    def _reset(self) -> None:
        """Clear the streaming state (filter memories, counters) before a new episode.

        Called by :meth:`reset` and by :meth:`detect` before and after it scores; must not touch
        learned attributes. Returns nothing.
        """

    @abstractmethod
    def _update(self, y: np.ndarray) -> Decision:
        """Consume one sample and decide.

        Receives ``y``, float64 of shape ``(n_channels,)`` in ``channels_`` order, finite
        (checked by :meth:`update`). Returns a :class:`Decision` whose arrays have one entry per
        name of ``signal_names_``.
        """

    def _detect(self, y: np.ndarray) -> Detection:
        """Score a whole episode from a freshly reset state.

        Receives ``y``, float64 of shape ``(n_samples, n_channels)`` in ``channels_`` order,
        finite. Returns a :class:`Detection` equal to calling :meth:`_update` on every row (the
        default does exactly that; override with a vectorised version, which the conformance
        tests compare with the streaming path).
        """
        return Detection.from_decisions([self._update(row) for row in y], self.signal_names_)

    def check_is_fitted(self) -> None:
        """Raise :class:`NotFittedError` unless :meth:`fit` (or ``load``) has completed."""
        self._check_fitted()

    def _check_fitted(self) -> None:
        if not getattr(self, "_fitted_", False):
            raise NotFittedError(
                f"{type(self).__name__} is not fitted yet; call fit(healthy_episodes) first"
            )
