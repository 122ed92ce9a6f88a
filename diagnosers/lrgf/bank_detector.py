"""What every LRGF detector shares: the bank's hyperparameters, its training, its running and
persistence.

:class:`BankDetector` is the common part of the two LRGF families, ``lrgf-mem``
(:mod:`diagnosers.lrgf.lrgf_mem`) and ``lrgf-glr`` (:mod:`diagnosers.lrgf.lrgf_glr`): it owns a
:class:`diagnosers.bank.relation_bank.RelationBank` (``bank_``), trains it, saves and loads it,
shows its bands (:meth:`BankDetector.band_view`), and runs it with an alarm stage
(:class:`~diagnosers.stages.alarm_stage.AlarmStage`, ``stage_``): streaming, batch detection and
persistence are written here once. A family names its stage (``STAGE``), fills a few hooks (how
a remaining error is normalised, what else its stage reads and what else it saves) and declares
its hyperparameters as ``{**BANK_DEFAULTS, ..., **STAGE.DEFAULTS, ...}``; the registered names
are presets of the families (:func:`diagnosers.presets.preset`). The bank's hyperparameters are
documented on :class:`BankDetector` (defaults :data:`BANK_DEFAULTS` and :data:`RUN_DEFAULTS`,
constraints :data:`BANK_CONSTRAINTS`).
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Mapping
from enum import StrEnum
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from diagnosers.bank.parallel import BankSettings, TrainedBank, train_banks
from diagnosers.bank.relation_bank import RelationBank
from diagnosers.bank.relations import BANK_RELATIONS, parse_relations
from diagnosers.detection import Decision, Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.networks.lrgf_net import LRGF
from diagnosers.networks.mem_net import NNARXErrorModel, OutputActivation
from diagnosers.networks.optimisers import Method
from diagnosers.stages.alarm_stage import AlarmStage
from diagnosers.stages.band import band
from fcc_common.validation import Boolean, Integer, IntegerSequence, Options, Real, check, invalid

__all__ = [
    "BANK_CONSTRAINTS",
    "BANK_DEFAULTS",
    "DEFAULT_HIDDEN",
    "HIDDEN_BY_OUTPUT",
    "MIN_CALIBRATION_SAMPLES",
    "RUN_DEFAULTS",
    "BankDetector",
    "MemSelect",
    "holdout_split",
]


class MemSelect(StrEnum):
    """Which relations keep their error model: all, or those where it lowers the held-out error."""

    ALWAYS = "always"
    IF_BETTER = "if_better"


#: fewest healthy calibration samples (after the warm-up) that ``fit`` accepts
MIN_CALIBRATION_SAMPLES = 50
#: network sizes when ``n_hidden`` is None: by the relation's output, else DEFAULT_HIDDEN
HIDDEN_BY_OUTPUT: dict[str, int] = {"T_rg1": 10}
DEFAULT_HIDDEN = 5

#: the bank's hyperparameters and their defaults (``lrgf-mem``'s), in signature order
BANK_DEFAULTS: dict[str, Any] = {
    "relations": None,
    "n_hidden": 5,
    "order": 2,
    "n_linear": 0,
    "steady_window": 100,
    "mem_hidden": 5,
    "mem_input_delays": 15,
    "mem_output_delays": 15,
    "mem_output_activation": "linear",
    "mem_max_epochs": 200,
    "mem_select": "if_better",
    "method": "adam",
    "lr": 0.03,
    "max_epochs": 3000,
    "val_fraction": 0.25,
    "band_alpha": 0.01,
}
#: the execution and seed hyperparameters, last in every signature
RUN_DEFAULTS: dict[str, Any] = {"seed": 0, "progress": None, "n_jobs": None}

#: declarative constraints of the bank's hyperparameters, checked in ``fit``
BANK_CONSTRAINTS: dict[str, Any] = {
    "n_hidden": (Integer(1, 64), IntegerSequence(1, 64, unique=False), None),
    "order": Integer(1, 8),
    "n_linear": Integer(0, 64),
    "steady_window": Integer(1, 100_000),
    "mem_hidden": Integer(1, 256),
    "mem_input_delays": Integer(1, 100),
    "mem_output_delays": Integer(1, 100),
    "mem_output_activation": Options(OutputActivation),
    "mem_max_epochs": Integer(1, 100_000),
    "mem_select": Options(MemSelect),
    "method": Options(Method),
    "lr": Real(0, 1, closed="right"),
    "max_epochs": Integer(1, 100_000),
    "val_fraction": Real(0, 1, closed="left"),
    "band_alpha": Real(0, 0.5, closed="neither"),
    "seed": Integer(0),
    "progress": (Boolean(), None),
    "n_jobs": (Integer(1), None),
}


def holdout_split(episodes: list[Episode]) -> tuple[list[np.ndarray], list[np.ndarray], int]:
    """``lrgf-mem``'s split: (training records, calibration records, first calibration sample
    of each record). The first ``n − max(1, n // 3)`` episodes train, the rest calibrate; a
    single episode trains on its first 70 % and calibrates on the rest."""
    n = len(episodes)
    if n == 1:
        y = episodes[0].y
        cut = int(0.7 * y.shape[0])
        return [y[:cut]], [y], cut
    n_cal = max(1, n // 3)
    return [e.y for e in episodes[: n - n_cal]], [e.y for e in episodes[n - n_cal :]], 0


class BankDetector(Diagnoser):
    """A detector built on a :class:`RelationBank` (the shared part of the LRGF families).

    For each monitored relation ``output = s(inputs)`` a locally recurrent globally
    feed-forward network (:class:`diagnosers.networks.lrgf_net.LRGF`) models the healthy process in
    simulation mode (it never sees the measured output), and an NNARX model-error model
    (:class:`diagnosers.networks.mem_net.NNARXErrorModel`, driven by the same inputs) models what the
    network misses. The band of the paper (eqs 10-11) is ``y_m + y_e ± t_α·v``.

    A family sets ``DEFAULTS``, ``__init__ = keyword_init(DEFAULTS)`` and ``STAGE`` (its alarm
    stage's class, whose hyperparameters it passes through by name), implements ``_fit``
    (with :meth:`_new_bank`, :meth:`_train_banks`, :meth:`_new_stage`) and ``_finish`` (``v_``,
    the drawn band's scale, and ``signal_names_``), and may fill the hooks of the alarm stage.
    Every family has the hyperparameters below (defaults: ``lrgf-mem``'s; a family or preset
    may set others, see the detector reference's table).

    Args:
        relations: the monitored relations, ``[[output, [inputs...]], ...]`` in the channels'
            names. Default ``None``: the preset's relations (:attr:`DEFAULT_RELATIONS`,
            :data:`diagnosers.bank.relations.BANK_RELATIONS`: three relations; ``lrgf-mem-paper``:
            the paper's one relation T_rx = s1(T_rg2, T_fp)).
        n_hidden: neurons of each relation's network: an integer in [1, 64] for every
            relation, a list with one size per relation (e.g. ``[5, 10, 5]``), or ``None``:
            sizes by output (:data:`HIDDEN_BY_OUTPUT`: 10 for T_rg1, the slow, high-gain
            relation that alone carries f3; :data:`DEFAULT_HIDDEN` (5) for the others), which
            follows a user's own ``relations``. Default 5 (``lrgf-glr``: ``None``). Larger
            networks fit more and train longer.
        order: order of each neuron's IIR filter, an integer in [1, 8]; default 2.
        n_linear: how many of each network's neurons are linear (no tanh), an integer from 0
            to the smallest network's size; default 0.
        steady_window: the start-up window W [samples], in [1, 100000]; default 100. The
            networks start at steady state for the mean of the first W inputs
            (:class:`diagnosers.networks.lrgf_net.InitialState`) and the detector is silent for those
            W samples (no alarm; its statistics start at sample W; calibration skips them).
            100 matches FCC-v0, whose inputs stay at nominal for the first 100 samples.
        mem_hidden: hidden neurons of each NNARX error model, in [1, 256]; default 5.
        mem_input_delays: the error model's input delays [samples], in [1, 100]; default 15.
        mem_output_delays: the error model's output delays [samples], in [1, 100]; default 15.
        mem_output_activation: the error model's output, ``"linear"`` (default) or ``"tanh"``.
        mem_max_epochs: the error model's training epochs, in [1, 100000]; default 200.
        mem_select: which relations keep their error model: ``"always"``, or ``"if_better"``
            (default): only where it lowers the RMS of the remaining error on the calibration
            episodes (an NNARX that does not generalise adds its own error to the centre).
        method: the networks' optimiser, ``"adam"`` (default, backpropagation through time)
            or ``"spsa"`` (the paper's) (:class:`diagnosers.networks.optimisers.Method`).
        lr: the networks' learning rate, in (0, 1]; default 0.03.
        max_epochs: the networks' training epochs, in [1, 100000]; default 3000.
        val_fraction: the share at the end of every training episode that each network holds
            out to choose its epoch (early stopping, :func:`diagnosers.networks.training.fit_lrgf`),
            in [0, 1); default 0.25. ``0`` trains on every sample for ``max_epochs`` and keeps
            the parameters of the lowest training loss, at the same cost per epoch
            (``lrgf-glr-adaptive`` uses 0).
        band_alpha: α, the two-sided level of the band ``y_m + y_e ± t_α·v`` (t_α the
            standard normal quantile for 1 − α; 2.576 at 0.01), in (0, 0.5); default 0.01. It
            sets the band :meth:`band_view` draws and the band ``lrgf-mem-paper``'s rule
            (``alarm_filter="none"``) alarms on; with an alarm stage it moves no alarm
            (``false_alarm_target`` does).
        seed: every network's seed, an integer ≥ 0 (relation ``j`` uses ``seed + 101 j``);
            default 0.
        progress: a tqdm bar over the training epochs: ``None`` (default) when run
            interactively (standard error a terminal, in the main process;
            :func:`diagnosers.networks.optimisers.auto_progress`), ``True``/``False`` to force it.
            It does not change the fit.
        n_jobs: worker processes that train the relations (and ``lrgf-glr``'s cross-fit
            folds) at once (:mod:`diagnosers.bank.parallel`), an integer ≥ 1 or ``None`` (default,
            meaning 1, as in scikit-learn). Each relation trains with its own seed and one
            thread, so the models are the same bits for every ``n_jobs``. The default is 1
            because the leaderboard's sweep runs every relation job as a task of its own
            pool (:mod:`evaluation.sweep.training_stage`; ``n_jobs`` is not used there);
            ``python -m bench.detector_speed --bank`` uses 2.

    ``progress`` and ``n_jobs`` say how to compute, never what
    (:attr:`~diagnosers.contract.DiagnoserContract.execution_params`): the result store's
    model hash leaves both out, so changing them reuses a stored model.
    """

    DEFAULTS: ClassVar[dict[str, Any]] = {**BANK_DEFAULTS, **RUN_DEFAULTS}
    #: the family's alarm stage; its ``DEFAULTS`` are hyperparameters of the family too
    STAGE: ClassVar[type[AlarmStage]]
    #: the relations when ``relations`` is None (a preset may set its own)
    DEFAULT_RELATIONS: ClassVar[list[list[Any]]] = BANK_RELATIONS
    execution_params = ("progress", "n_jobs")

    # the hyperparameters every family has (set by its keyword_init)
    relations: list[list[Any]] | None
    n_hidden: int | list[int] | None
    n_linear: int
    steady_window: int
    band_alpha: float
    seed: int
    n_jobs: int | None
    max_epochs: int
    v_: np.ndarray
    stage_: AlarmStage

    @classmethod
    def fast_params(cls) -> dict[str, Any]:
        """Small, fast settings for smoke runs, quick sweeps and tests."""
        return {
            "max_epochs": 30,
            "mem_max_epochs": 5,
            "mem_input_delays": 3,
            "mem_output_delays": 3,
        }

    # ---- the bank as attributes (read by the isolators, the benchmark and tests) --------------
    @property
    def lrgf_(self) -> list[LRGF]:
        return self.bank_.lrgf

    @property
    def mem_(self) -> list[NNARXErrorModel]:
        return self.bank_.mem

    @property
    def in_idx_(self) -> list[np.ndarray]:
        return self.bank_.in_idx

    @property
    def out_idx_(self) -> np.ndarray:
        return self.bank_.out_idx

    @property
    def use_mem_(self) -> np.ndarray:
        return self.bank_.use_mem

    @property
    def residual_scale_(self) -> np.ndarray:
        """Each relation's scale ``v`` of the remaining error: ``residual / residual_scale_`` is
        the normalised remaining error (what the isolators classify)."""
        return self.v_residual_

    v_residual_: np.ndarray

    # ---- validation ----------------------------------------------------------------------------
    def _relations(self) -> list[tuple[str, tuple[str, ...]]]:
        rel = type(self).DEFAULT_RELATIONS if self.relations is None else self.relations
        return parse_relations(rel)

    def _hidden_sizes(self) -> tuple[int, ...]:
        """Neurons of each relation's network: ``n_hidden`` for every relation, one per relation
        when it is a sequence, or, when it is None, :data:`HIDDEN_BY_OUTPUT` by output."""
        relations = self._relations()
        k = len(relations)
        sizes = check("n_hidden", self.n_hidden, *BANK_CONSTRAINTS["n_hidden"])
        if sizes is None:
            return tuple(HIDDEN_BY_OUTPUT.get(out, DEFAULT_HIDDEN) for out, _ in relations)
        if isinstance(sizes, int):
            return (sizes,) * k
        if len(sizes) != k:
            raise invalid(
                "n_hidden",
                self.n_hidden,
                f"an integer in [1, 64] or {k} of them, one per relation",
                f"there are {k} relations",
            )
        return sizes

    def _check_sizes(self) -> None:
        """The networks' sizes (and the relations) and ``n_linear`` against the smallest."""
        sizes = self._hidden_sizes()
        if self.n_linear > min(sizes):
            raise invalid(
                "n_linear",
                self.n_linear,
                f"an integer from 0 to the smallest network's size ({min(sizes)})",
                f"the networks have {list(sizes)} neurons",
            )

    # ---- training ------------------------------------------------------------------------------
    def _new_bank(self) -> RelationBank:
        """An untrained bank of the relations on the fitted channels (``bank_``)."""
        self.bank_ = RelationBank(self._relations(), self.channels_)
        return self.bank_

    def _train_banks(
        self,
        sets: list[list[np.ndarray]],
        init: list[TrainedBank | None] | None = None,
        max_epochs: int | None = None,
    ) -> list[TrainedBank]:
        """Train the bank's relations on each training set of ``sets``, all relations and sets
        sharing the ``n_jobs`` processes (:func:`diagnosers.bank.parallel.train_banks`); ``init``
        warm-starts the networks of a set from a trained bank, ``max_epochs`` replaces the
        hyperparameter."""
        params = self.get_params()
        if max_epochs is not None:
            params["max_epochs"] = max_epochs
        settings = [
            BankSettings.from_params({**params, "n_hidden": h}) for h in self._hidden_sizes()
        ]
        n_jobs = 1 if self.n_jobs is None else self.n_jobs
        return train_banks(
            settings, sets, self.bank_.in_idx, self.bank_.out_idx, self.seed, n_jobs, init=init
        )

    # ---- views ---------------------------------------------------------------------------------
    def band_view(self, episode: Episode) -> Detection | None:
        """Each relation's measured output with its band ``y_m + y_e ± t_α·v`` (paper eqs
        10–11, α = ``band_alpha``), ``alarm`` where an output leaves its band after the warm-up.

        The same models seen the paper's way; the detector's own alarms come from :meth:`detect`.
        """
        self._check_episode(episode)
        y_out = episode.y[:, self.bank_.out_idx]
        centre = self.bank_.centre(episode.y)
        lower, upper = band(centre, 0.0, self.v_, self.band_alpha)
        lower[: self.steady_window], upper[: self.steady_window] = -np.inf, np.inf  # warm-up
        alarm = np.any((y_out < lower) | (y_out > upper), axis=1)
        names = tuple(o for o, _ in self._relations())  # units: the episode's, in figures
        return Detection(alarm, y_out, lower, upper, y_out - centre, names)

    # ---- the alarm stage: what a family fills -------------------------------------------------
    def _new_stage(self, **parts: Any) -> AlarmStage:
        """The family's unfitted alarm stage, its hyperparameters taken by name (``parts``: its
        other arguments)."""
        return self.STAGE(**{k: getattr(self, k) for k in self.STAGE.DEFAULTS}, **parts)

    @abstractmethod
    def _finish(self) -> None:
        """Derived state shared by ``_fit`` and :meth:`_set_state` (``v_``, ``signal_names_``)."""

    def _normalise(self, resid: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The normalised remaining error ``(T, k)`` of a record ``y`` whose remaining error is
        ``resid`` (what the stage reads): divided by its scale (a family may do more)."""
        return resid / self.v_residual_

    def _normalise_step(self, resid: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """:meth:`_normalise` of one sample, given the networks' outputs ``y_m``."""
        return resid / self.v_residual_

    def _features(self, y: np.ndarray, y_m: np.ndarray) -> np.ndarray | None:
        """A record's regressors for the stage's baseline (None: it has none)."""
        return None

    def _features_step(self, y: np.ndarray, y_m: np.ndarray) -> np.ndarray | None:
        """:meth:`_features` of one sample (called at every sample, the warm-up too)."""
        return None

    def _family_state(self) -> dict[str, np.ndarray]:
        """Learned arrays of the family's own besides the bank's, the stage's and ``v_residual``."""
        return {}

    def _set_family_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Inverse of :meth:`_family_state` (before the stage is rebuilt)."""

    # ---- detection -----------------------------------------------------------------------------
    def _reset(self) -> None:
        self.bank_.reset()
        self.stage_.reset()
        self._k = 0

    def _update(self, y: np.ndarray) -> Decision:
        y_m, centre = self.bank_.step(y)
        y_out = y[self.bank_.out_idx]
        warm = self._k < self.steady_window  # silent: the stage reads a zero error there
        self._k += 1
        resid = y_out - centre
        e, phi = self._normalise_step(resid, y_m), self._features_step(y, y_m)
        return self.stage_.step(e, warm=warm, residual=resid, output=y_out, centre=centre, phi=phi)

    def _detect(self, y: np.ndarray) -> Detection:
        y_m, centre = self.bank_.outputs_and_centre(y)
        y_out = y[:, self.bank_.out_idx]
        resid = y_out - centre
        e, phi, w = self._normalise(resid, y), self._features(y, y_m), self.steady_window
        names = self.signal_names_
        return self.stage_.detect(
            e, warm_up=w, residual=resid, names=names, output=y_out, centre=centre, phi=phi
        )

    # ---- persistence ---------------------------------------------------------------------------
    def _get_state(self) -> dict[str, np.ndarray]:
        state = {**self.bank_.get_state(), **self.stage_.get_state()}
        return {**state, "v_residual": self.v_residual_, **self._family_state()}

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.bank_ = RelationBank(self._relations(), self.channels_)
        try:
            self.bank_.set_state(state)
        except ValueError as e:
            raise ValueError(f"{e} of {self.name!r}") from None
        try:
            self.v_residual_ = state["v_residual"]
        except KeyError as e:
            raise ValueError(f"saved state lacks array {e.args[0]!r}") from None
        self._set_family_state(state)
        self.stage_ = self._new_stage()
        self.stage_.set_state(state)
        self._finish()

    def _save_extra(self, directory: Path) -> None:
        self.bank_.save_modules(directory)

    def _load_extra(self, directory: Path) -> None:
        self.bank_.load_modules(directory)
        # a model saved before ``n_linear`` existed has tanh neurons only, whatever the default
        # is now: the hyperparameter follows the networks that were loaded
        self.n_linear = min((int(net.n_linear) for net in self.bank_.lrgf), default=0)
        self._models_loaded()

    def _models_loaded(self) -> None:
        """What a family's parts read from the loaded networks (after :meth:`_load_extra`)."""
