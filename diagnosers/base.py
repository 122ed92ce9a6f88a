"""The diagnoser contract: episodes in, alarms (with residuals and bands) out.

A diagnoser is trained on healthy episodes with :meth:`Diagnoser.fit`, then watches an episode
either sample by sample (:meth:`Diagnoser.reset` followed by :meth:`Diagnoser.update`) or all at
once (:meth:`Diagnoser.detect`). Both paths must give the same decisions; the conformance tests
check it.

Conventions follow scikit-learn's estimators: ``__init__`` stores keyword hyperparameters verbatim
and does nothing else, ``fit`` validates them and returns ``self``, learned attributes end in ``_``.
"""

from __future__ import annotations

import inspect
import json
import logging
import os
import sys
from abc import ABC, abstractmethod
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Self

import numpy as np

from diagnosers.episode import Episode
from fcc_env.io import atomic_open, atomic_write

if TYPE_CHECKING:  # annotations only: building episodes needs no simulator import
    pass

logger = logging.getLogger(__name__)

SAVE_FORMAT = "fcc-diagnoser"
SAVE_FORMAT_VERSION = 1
#: The diagnosis of an isolating diagnoser that is alarmed but fits none of its fault classes.
UNKNOWN = "unknown"
#: The diagnosis while not alarmed (no diagnosis).
NO_DIAGNOSIS = ""


def auto_progress(progress: bool | None) -> bool:
    """Resolve a ``progress`` option: ``None`` means "auto", a bar only when run interactively.

    Interactive: standard error is a terminal and this is the main process (a sweep's worker
    processes share the terminal, and their bars would garble the sweep's own).

    >>> auto_progress(True), auto_progress(False)
    (True, False)
    """
    if progress is not None:
        return bool(progress)
    import multiprocessing

    isatty = getattr(sys.stderr, "isatty", None)
    interactive = bool(isatty and isatty())
    return interactive and multiprocessing.parent_process() is None


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


class NotFittedError(RuntimeError):
    """Raised when a diagnoser is used before :meth:`Diagnoser.fit`."""


@dataclass(frozen=True)
class Decision:
    """What a diagnoser says about one sample.

    ``signal`` is what the diagnoser checks (a measured output for band detectors, a statistic such
    as Hotelling's T² for others), ``lower``/``upper`` the limits it checks it against
    (``-inf``/``inf`` when one-sided), ``residual`` the model residual (measured − predicted)
    where there is a model. All arrays have one entry per monitored quantity, named by
    :attr:`Diagnoser.signal_names_`.
    """

    alarm: bool
    signal: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    residual: np.ndarray
    #: isolating diagnosers (:attr:`Diagnoser.isolates`): one of the trained fault classes,
    #: :data:`UNKNOWN`, or :data:`NO_DIAGNOSIS` (``""``) while not alarmed
    diagnosis: str = NO_DIAGNOSIS
    #: isolating diagnosers: a score per class of :attr:`Detection.class_names` (higher = fits
    #: better), ``None`` for a diagnoser that only detects
    class_scores: np.ndarray | None = None


@dataclass(frozen=True)
class Detection:
    """Decisions over a whole episode: each array has a leading time axis of length n_samples.

    An isolating diagnoser also fills ``diagnosis`` (``(T,)`` str: a class of ``class_names``,
    :data:`UNKNOWN`, or ``""`` while not alarmed) and ``class_scores`` (``(T, C)``, one column
    per name of ``class_names``); a detector leaves them ``None`` and ``()``.
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

    def __post_init__(self) -> None:
        n = len(self.alarm)
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
    def isolates(self) -> bool:
        """Whether the detection carries a diagnosis per sample."""
        return self.diagnosis is not None

    @classmethod
    def from_decisions(
        cls,
        decisions: Sequence[Decision],
        signal_names: tuple[str, ...],
        class_names: tuple[str, ...] | None = None,
    ) -> Detection:
        """Stack per-sample decisions; with ``class_names`` also their diagnoses and scores."""
        iso: dict[str, Any] = {}
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
        )


def check_labelled(episodes: Sequence[Episode]) -> None:
    """Training episodes of an isolating diagnoser: one healthy at least, faults labelled."""
    if not any(ep.fault_onset is None for ep in episodes):
        raise ValueError(
            "an isolating diagnoser needs at least one healthy episode (fault_onset=None) "
            "among its training episodes, got none"
        )
    for ep in episodes:
        if ep.fault_onset is not None and ep.scenario in (UNKNOWN, NO_DIAGNOSIS, "nominal"):
            raise ValueError(
                f"faulty training episode (seed {ep.seed}) has scenario={ep.scenario!r}; a "
                f"labelled fault needs a class name other than {UNKNOWN!r}, '' and 'nominal'"
            )


class Diagnoser(ABC):
    """Base class of every diagnoser (template method: public methods check, ``_impl`` ones work).

    Subclasses implement ``_fit``, ``_reset``, ``_update`` and may override ``_detect`` with a
    vectorised version that must equal repeated ``_update`` calls.
    """

    #: registry name, set by :func:`diagnosers.register`.
    name: ClassVar[str] = ""
    #: whether the diagnoser also isolates: it is then trained on healthy *and* labelled faulty
    #: episodes (``fault_onset`` and ``scenario`` set) and its decisions carry a diagnosis
    isolates: ClassVar[bool] = False
    #: hyperparameters that say how to compute, never what: the fitted model is the same for
    #: every value (a progress bar, the number of worker processes). :meth:`result_params` leaves
    #: them out, so the result store's hashes do not change with them.
    execution_params: ClassVar[tuple[str, ...]] = ()

    # ---- scikit-learn style parameter handling -------------------------------------------------
    @classmethod
    def _param_names(cls) -> list[str]:
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
    def _test_params(cls) -> dict[str, Any]:
        """Deprecated alias of :meth:`fast_params`, kept for one release."""
        return cls.fast_params()

    @classmethod
    def _check_param_names(cls, names: Iterable[str]) -> None:
        """Raise ``ValueError`` naming any of ``names`` that ``__init__`` does not accept."""
        allowed = cls._param_names()
        unknown = sorted(set(names) - set(allowed))
        if unknown:
            label = cls.name or cls.__name__
            raise ValueError(
                f"Unknown hyperparameter(s) {unknown} for diagnoser {label!r}. Allowed: {allowed}"
            )

    def get_params(self) -> dict[str, Any]:
        """Hyperparameters as passed to ``__init__`` (JSON-serialisable by convention)."""
        return {k: getattr(self, k) for k in self._param_names()}

    def result_params(self) -> dict[str, Any]:
        """:meth:`get_params` without :attr:`execution_params`: what the fitted model depends on."""
        return {k: v for k, v in self.get_params().items() if k not in self.execution_params}

    def set_params(self, **params: Any) -> Self:
        """Set hyperparameters (scikit-learn style) and return ``self``.

        Names are checked against ``__init__``'s signature, as :func:`diagnosers.make` does;
        values are validated by the next :meth:`fit`, like those given to ``__init__``. A fitted
        diagnoser becomes unfitted (its learned state belongs to the old hyperparameters, and
        :meth:`save` would pair them with the new ones): call :meth:`fit` again.

        >>> import diagnosers
        >>> diagnosers.make("limits").set_params(alpha=0.05).get_params()["alpha"]
        0.05
        """
        self._check_param_names(params)
        for k, v in params.items():
            setattr(self, k, v)
        if params:
            self._fitted_ = False
        return self

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
        return f"{type(self).__name__}({args})"

    # ---- public API ----------------------------------------------------------------------------
    def fit(self, episodes: Sequence[Episode]) -> Self:
        """Learn from healthy episodes and return ``self``.

        An isolating diagnoser (:attr:`isolates`) also receives labelled faulty episodes
        (``fault_onset`` set, ``scenario`` the fault class); it needs at least one healthy one.
        """
        if isinstance(episodes, Episode):
            episodes = [episodes]
        if isinstance(episodes, np.ndarray | str | bytes) or not hasattr(episodes, "__iter__"):
            _as_episode(episodes, "fit")
        episodes = [_as_episode(ep, "fit") for ep in episodes]
        if not episodes:
            raise ValueError("fit needs at least one healthy episode, got none")
        if self.isolates:
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

    # ---- persistence ---------------------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> Path:
        """Write the fitted diagnoser to directory ``path``: ``config.json`` + ``state.npz``.

        ``state.npz`` holds plain numeric arrays (``allow_pickle=False`` on load); subclasses with
        torch modules also write ``weights.pt``, a state dict loaded with ``weights_only=True``.
        Files are written to temporaries and renamed, so an interrupted save leaves no torn file.
        """
        self._check_fitted()
        out = Path(path)
        out.mkdir(parents=True, exist_ok=True)
        config = {
            "format": SAVE_FORMAT,
            "format_version": SAVE_FORMAT_VERSION,
            "diagnoser": self.name,
            "class": f"{type(self).__module__}.{type(self).__qualname__}",
            "params": self.get_params(),
            "channels": list(self.channels_),
            "sample_time_s": self.sample_time_s_,
        }
        state = {k: np.asarray(v) for k, v in self._get_state().items()}
        with atomic_open(out / "state.npz", "wb") as fh:
            np.savez(fh, **state)
        self._save_extra(out)
        # config.json last: its presence marks a complete save
        atomic_write(out / "config.json", json.dumps(config, indent=2))
        return out

    @classmethod
    def load(cls, path: str | os.PathLike) -> Diagnoser:
        """Load a diagnoser written by :meth:`save`; never executes code from the files."""
        from diagnosers.registry import make  # local import: the registry imports this module

        src = Path(path)
        cfg_path = src / "config.json"
        if not cfg_path.is_file():
            raise ValueError(f"{src} is not a saved diagnoser: {cfg_path.name} is missing")
        try:
            config = json.loads(cfg_path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            raise ValueError(f"{cfg_path} is not valid JSON: {e}") from e
        if not isinstance(config, dict) or config.get("format") != SAVE_FORMAT:
            raise ValueError(
                f"{cfg_path} is not a saved diagnoser of this library "
                f"(expected format {SAVE_FORMAT!r}, got "
                f"{config.get('format') if isinstance(config, dict) else config!r})"
            )
        if config.get("format_version") != SAVE_FORMAT_VERSION:
            raise ValueError(
                f"{cfg_path}: format_version {config.get('format_version')!r} is not supported "
                f"(this library reads version {SAVE_FORMAT_VERSION})"
            )
        # A config with the right format tag can still be hand-edited or truncated: check the
        # fields used below so that it fails with ValueError, not KeyError/TypeError.
        for key, kind in (
            ("diagnoser", str),
            ("params", dict),
            ("channels", list),
            ("sample_time_s", (int, float)),
        ):
            if not isinstance(config.get(key), kind):
                raise ValueError(
                    f"{cfg_path}: field {key!r} is missing or of the wrong type "
                    f"(got {config.get(key)!r}); the file is corrupted"
                )
        if not all(isinstance(c, str) for c in config["channels"]):
            raise ValueError(f"{cfg_path}: channels must be names (str), got {config['channels']}")
        try:
            obj = make(config["diagnoser"], **config["params"])
            # a saved config is checked like constructor arguments: a hand-edited alpha=5 fails
            obj._validate_params()
        except (ValueError, TypeError) as e:
            raise ValueError(f"{cfg_path}: {e}") from e
        saved_class = config.get("class")
        actual_class = f"{type(obj).__module__}.{type(obj).__qualname__}"
        if saved_class is not None and saved_class != actual_class:
            raise ValueError(
                f"{cfg_path}: diagnoser {config['diagnoser']!r} is a {actual_class}, but the "
                f"file was saved by a {saved_class!r}; the config was edited or relabelled"
            )
        if cls is not Diagnoser and not isinstance(obj, cls):
            raise ValueError(
                f"{src} holds a {config['diagnoser']!r} diagnoser, not a {cls.__name__}"
            )
        state_path = src / "state.npz"
        try:
            with np.load(state_path, allow_pickle=False) as data:
                state = {k: data[k] for k in data.files}
        except Exception as e:  # BadZipFile, EOFError, zlib.error...: one clear message
            raise ValueError(
                f"{state_path} is missing, truncated or not a numeric state file "
                f"({type(e).__name__}); the saved diagnoser is corrupted: save it again"
            ) from e
        obj.channels_ = tuple(config["channels"])
        obj.sample_time_s_ = float(config["sample_time_s"])
        try:
            obj._set_state(state)
        except KeyError as e:
            raise ValueError(
                f"{state_path} lacks the array {e} that a {config['diagnoser']!r} "
                "diagnoser needs; the directory is corrupted or from another version"
            ) from e
        except (ValueError, TypeError, IndexError) as e:
            raise ValueError(
                f"{state_path} does not fit a {config['diagnoser']!r} diagnoser with the saved "
                f"settings ({e}); the directory is corrupted, edited or relabelled"
            ) from e
        obj._load_extra(src)
        obj._fitted_ = True
        obj.reset()
        return obj

    # ---- hooks ---------------------------------------------------------------------------------
    # A subclass implements _fit, _reset, _update, _get_state and _set_state; _detect,
    # _validate_params, _save_extra and _load_extra are optional. The public methods have
    # already checked their input when a hook runs (see each hook), so hooks do not re-check.
    def _validate_params(self) -> None:  # noqa: B027 - optional hook
        """Check hyperparameters; raise ValueError naming the value and the allowed range.

        Called by :meth:`fit` before :meth:`_fit` (never by ``__init__``): use
        :func:`fcc_env.validation.check_params` with a table of constraints.
        """

    @abstractmethod
    def _get_state(self) -> dict[str, np.ndarray]:
        """Learned numeric state as named arrays (everything ``_update`` needs besides params).

        Called by :meth:`save` on a fitted diagnoser. Returns ``{name: array}`` of plain numbers
        (no objects: the file is read with ``allow_pickle=False``); scalars become 0-d arrays.
        Streaming state (filter memories) is not learned state and stays out.
        """

    @abstractmethod
    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        """Inverse of :meth:`_get_state`: restore the learned attributes from ``state``.

        Called by :meth:`load` on a fresh instance built with the saved hyperparameters, after
        ``channels_`` and ``sample_time_s_`` are set; must also set ``signal_names_``. Returns
        nothing; a missing key raises ``KeyError`` (reported by ``load`` as a corrupted file).
        :meth:`load` calls :meth:`reset` afterwards.
        """

    def _save_extra(self, directory: Path) -> None:  # noqa: B027 - optional hook
        """Write extra files (e.g. torch ``weights.pt``) into ``directory``."""

    def _load_extra(self, directory: Path) -> None:  # noqa: B027 - optional hook
        """Read what :meth:`_save_extra` wrote; torch files with ``weights_only=True``."""

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

    def _check_fitted(self) -> None:
        if not getattr(self, "_fitted_", False):
            raise NotFittedError(
                f"{type(self).__name__} is not fitted yet; call fit(healthy_episodes) first"
            )
