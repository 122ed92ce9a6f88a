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
import os
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Self

import numpy as np

from fcc_env.io import atomic_open, atomic_write

SAVE_FORMAT = "fcc-diagnoser"
SAVE_FORMAT_VERSION = 1
#: The diagnosis of an isolating diagnoser that is alarmed but fits none of its fault classes.
UNKNOWN = "unknown"
#: The diagnosis while not alarmed (no diagnosis).
NO_DIAGNOSIS = ""


class NotFittedError(RuntimeError):
    """Raised when a diagnoser is used before :meth:`Diagnoser.fit`."""


@dataclass(frozen=True)
class Episode:
    """One record of measurements, as a plant historian would hold it.

    Attributes:
        y: measurements, shape ``(n_samples, n_channels)``, physical units.
        channels: channel names, one per column of ``y`` (for FCC-v0:
            ``fcc_env.MEASUREMENT_NAMES``).
        sample_time_s: sample period in seconds.
        fault_onset: ground-truth onset sample, or ``None`` for a healthy record. Used to
            score; the harness passes faulty training records (labelled by ``scenario``) only
            to diagnosers that isolate (:attr:`Diagnoser.isolates`).
        scenario: scenario name (``"nominal"``, ``"f1"``... or a file stem for external data);
            for an isolating diagnoser's faulty training records, the fault class.
        seed: seed the episode was simulated with, if any.
        y_clean: optional noise-free measurements (simulation only; for plots and diagnostics).
    """

    y: np.ndarray
    channels: tuple[str, ...]
    sample_time_s: float
    fault_onset: int | None = None
    scenario: str = "unknown"
    seed: int | None = None
    y_clean: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        y = np.asarray(self.y, dtype=np.float64)
        if y.ndim != 2 or y.shape[1] != len(self.channels):
            raise ValueError(
                f"Episode.y must have shape (n_samples, {len(self.channels)}) to match channels "
                f"{self.channels}; got {y.shape}"
            )
        if not np.isfinite(y).all():
            raise ValueError("Episode.y contains NaN or inf; clean or drop those samples first")
        if not (np.isfinite(self.sample_time_s) and self.sample_time_s > 0):
            raise ValueError(f"sample_time_s must be a positive number, got {self.sample_time_s!r}")
        if self.fault_onset is not None and not 0 <= self.fault_onset < y.shape[0]:
            raise ValueError(
                f"fault_onset={self.fault_onset} outside the episode [0, {y.shape[0]})"
            )
        object.__setattr__(self, "y", y)

    @property
    def n_samples(self) -> int:
        return int(self.y.shape[0])

    def channel(self, name: str) -> np.ndarray:
        """Column of ``y`` named ``name``, shape ``(n_samples,)``."""
        try:
            return self.y[:, self.channels.index(name)]
        except ValueError:
            raise ValueError(
                f"Unknown channel {name!r}. Available: {list(self.channels)}"
            ) from None


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

    def get_params(self) -> dict[str, Any]:
        """Hyperparameters as passed to ``__init__`` (JSON-serialisable by convention)."""
        return {k: getattr(self, k) for k in self._param_names()}

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
        episodes = list(episodes)
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
        self._validate_params()
        # A failed re-fit must not leave an object that looks fitted with half-updated state.
        self._fitted_ = False
        self.channels_ = channels
        self.sample_time_s_ = float(episodes[0].sample_time_s)
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
        if episode.channels != self.channels_:
            raise ValueError(
                f"episode channels {episode.channels} differ from the training channels "
                f"{self.channels_}"
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
        obj = make(config["diagnoser"], **config["params"])
        if cls is not Diagnoser and not isinstance(obj, cls):
            raise ValueError(
                f"{src} holds a {config['diagnoser']!r} diagnoser, not a {cls.__name__}"
            )
        try:
            with np.load(src / "state.npz", allow_pickle=False) as data:
                state = {k: data[k] for k in data.files}
        except (OSError, ValueError) as e:
            raise ValueError(
                f"{src / 'state.npz'} is missing or not a numeric state file: {e}"
            ) from e
        obj.channels_ = tuple(config["channels"])
        obj.sample_time_s_ = float(config["sample_time_s"])
        try:
            obj._set_state(state)
        except KeyError as e:
            raise ValueError(
                f"{src / 'state.npz'} lacks the array {e} that a {config['diagnoser']!r} "
                "diagnoser needs; the directory is corrupted or from another version"
            ) from e
        obj._load_extra(src)
        obj._fitted_ = True
        obj.reset()
        return obj

    # ---- hooks ---------------------------------------------------------------------------------
    def _validate_params(self) -> None:  # noqa: B027 - optional hook
        """Check hyperparameters; raise ValueError naming the value and the allowed range."""

    @abstractmethod
    def _get_state(self) -> dict[str, np.ndarray]:
        """Learned numeric state as named arrays (everything ``_update`` needs besides params)."""

    @abstractmethod
    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        """Inverse of :meth:`_get_state` (also sets ``signal_names_``)."""

    def _save_extra(self, directory: Path) -> None:  # noqa: B027 - optional hook
        """Write extra files (e.g. torch ``weights.pt``) into ``directory``."""

    def _load_extra(self, directory: Path) -> None:  # noqa: B027 - optional hook
        """Read what :meth:`_save_extra` wrote; torch files with ``weights_only=True``."""

    @abstractmethod
    def _fit(self, episodes: list[Episode]) -> None: ...

    @abstractmethod
    def _reset(self) -> None: ...

    @abstractmethod
    def _update(self, y: np.ndarray) -> Decision: ...

    def _detect(self, y: np.ndarray) -> Detection:
        return Detection.from_decisions([self._update(row) for row in y], self.signal_names_)

    def _check_fitted(self) -> None:
        if not getattr(self, "_fitted_", False):
            raise NotFittedError(
                f"{type(self).__name__} is not fitted yet; call fit(healthy_episodes) first"
            )
