"""The model bank of the LRGF detectors: per relation a nominal network and an error model.

For each monitored relation ``output = s(inputs)`` a locally recurrent globally feed-forward
network (:class:`diagnosers.networks.lrgf_net.LRGF`) models the healthy process in simulation mode (it
never sees the measured output), and an NNARX model-error model
(:class:`diagnosers.networks.mem_net.NNARXErrorModel`, driven by the same inputs) models what the
network misses. :class:`RelationBank` holds the trained modules with the channels they read and
computes, over a record or sample by sample, the networks' outputs ``y_m`` and the band
centre ``y_m + y_e`` (``y_e`` only where the error model is kept,
:attr:`RelationBank.use_mem`). It knows nothing of alarms: the detectors
(:mod:`diagnosers.lrgf.lrgf_mem`, :mod:`diagnosers.lrgf.lrgf_glr`) put their alarm stage after it.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from diagnosers.bank.parallel import TrainedBank
from diagnosers.networks.lrgf_net import LRGF
from diagnosers.networks.lrgf_stepper import BankStepper
from diagnosers.networks.mem_net import NNARXErrorModel
from diagnosers.networks.mem_stepper import MEMBankStepper
from diagnosers.networks.modules import load_bank, save_bank

__all__ = ["RelationBank"]


class RelationBank:
    """The trained networks and error models of a bank of relations.

    Args:
        relations: ``(output, inputs)`` per relation (:func:`diagnosers.bank.relations.parse_relations`).
        channels: the measurement channels of the episodes, in order.

    Raises ValueError naming a relation channel that is not among ``channels``.

    Attributes:
        in_idx: per relation, the channel indices of its inputs.
        out_idx: the channel index of each relation's output, ``(k,)``.
        lrgf, mem: the networks and error models, one per relation (after :meth:`set_models`).
        use_mem: which relations add their error model to the centre, ``(k,)`` bool.
        v_paper: the standard deviation of each error model's output on its training data.
        train_fit_loss: each network's best validation loss.
    """

    def __init__(
        self, relations: Sequence[tuple[str, Sequence[str]]], channels: Sequence[str]
    ) -> None:
        idx = {c: i for i, c in enumerate(channels)}
        for out, ins in relations:
            for c in (out, *ins):
                if c not in idx:
                    raise ValueError(
                        f"relation channel {c!r} is not in the episodes' channels {list(idx)}"
                    )
        self.in_idx = [np.array([idx[c] for c in ins]) for _, ins in relations]
        self.out_idx = np.array([idx[o] for o, _ in relations])
        self.n_channels = len(channels)
        self.lrgf: list[LRGF] = []
        self.mem: list[NNARXErrorModel] = []
        self.use_mem = np.ones(len(relations), dtype=bool)
        self._stepper: BankStepper | None = None
        self._mem_used: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.out_idx)

    def set_models(self, trained: TrainedBank) -> None:
        """Take the modules of a trained bank (:func:`diagnosers.bank.parallel.train_banks`)."""
        self.lrgf, self.mem = list(trained.lrgf), list(trained.mem)
        self.v_paper = np.array(trained.v_paper)
        self.train_fit_loss = np.array([f.best_val_loss for f in trained.fits])
        self._stepper = None  # the streaming steppers are rebuilt from the new networks

    # ---- whole records -------------------------------------------------------------------------
    def outputs_and_centre(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The networks' outputs ``y_m`` and the centres ``y_m + y_e`` over a record ``y``
        ``(T, channels)``: two ``(T, k)`` arrays. The one place a record's centre is computed."""
        ym, cols = [], []
        for j in range(len(self.lrgf)):
            u = y[:, self.in_idx[j]]
            y_m = self.lrgf[j].predict(u)[:, 0]
            ym.append(y_m)
            cols.append(y_m + self.mem[j].predict(u)[:, 0] if self.use_mem[j] else y_m)
        return np.column_stack(ym), np.column_stack(cols)

    def centre(self, y: np.ndarray) -> np.ndarray:
        """``y_m + y_e`` for every relation over a record: ``(T, k)``."""
        return self.outputs_and_centre(y)[1]

    def remaining(self, y: np.ndarray) -> np.ndarray:
        """The remaining error ``y − (y_m + y_e)`` over a record: ``(T, k)``."""
        return y[:, self.out_idx] - self.centre(y)

    def parts(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(y_out − y_m, y_e)`` of every relation over a record, every error model included."""
        ym, ye = [], []
        for j in range(len(self.lrgf)):
            u = y[:, self.in_idx[j]]
            ym.append(self.lrgf[j].predict(u)[:, 0])
            ye.append(self.mem[j].predict(u)[:, 0])
        return y[:, self.out_idx] - np.column_stack(ym), np.column_stack(ye)

    # ---- streaming -----------------------------------------------------------------------------
    def reset(self) -> None:
        """Start a new record for :meth:`step`."""
        if self._stepper is None:
            self._stepper = BankStepper(self.lrgf, self.in_idx, self.n_channels)
            self._mem_used = None
        used = np.flatnonzero(self.use_mem)
        if self._mem_used is None or not np.array_equal(used, self._mem_used):
            # only the error models in use are stepped, all of them in one stacked pass
            self._mem_used = used
            self._mem_stepper = MEMBankStepper(
                [self.mem[j] for j in used], [self.in_idx[j] for j in used]
            )
        self._stepper.reset()
        self._mem_stepper.reset()

    def step(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(y_m, y_m + y_e)`` of every relation for one measurement ``y``: streaming
        :meth:`outputs_and_centre`."""
        assert self._stepper is not None and self._mem_used is not None, "call reset() first"
        y_m = self._stepper.step(y)
        if not len(self._mem_used):
            return y_m, y_m
        centre = y_m.copy()
        centre[self._mem_used] += self._mem_stepper.step(y)
        return y_m, centre

    # ---- persistence ---------------------------------------------------------------------------
    def get_state(self) -> dict[str, np.ndarray]:
        """The learned arrays (the modules are saved by :meth:`save_modules`)."""
        return {
            "out_idx": self.out_idx,
            "in_idx": np.concatenate(self.in_idx),
            "in_len": np.array([len(i) for i in self.in_idx]),
            "v_paper": self.v_paper,
            "use_mem": self.use_mem.astype(np.int8),
            "train_fit_loss": self.train_fit_loss,
        }

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Inverse of :meth:`get_state`; raises ValueError when the relations do not match."""
        try:
            out_idx = state["out_idx"].astype(int)
            splits = np.cumsum(state["in_len"])[:-1]
            in_idx = [a.astype(int) for a in np.split(state["in_idx"], splits)]
            v_paper, use_mem = state["v_paper"], state["use_mem"].astype(bool)
            train_fit_loss = state["train_fit_loss"]
        except KeyError as e:
            raise ValueError(f"saved state lacks array {e.args[0]!r}") from None
        if [len(i) for i in in_idx] != [len(i) for i in self.in_idx]:
            raise ValueError(
                f"the state holds relations with {[len(i) for i in in_idx]} inputs, the "
                f"settings {[len(i) for i in self.in_idx]}"
            )
        self.out_idx, self.in_idx = out_idx, in_idx
        self.v_paper, self.use_mem, self.train_fit_loss = v_paper, use_mem, train_fit_loss

    def save_modules(self, directory: Path) -> None:
        """Write the networks and error models (``models.json`` and ``weights.pt``)."""
        save_bank(
            directory, [{"lrgf": n, "mem": m} for n, m in zip(self.lrgf, self.mem, strict=True)]
        )

    def load_modules(self, directory: Path) -> None:
        """Read what :meth:`save_modules` wrote; a file never runs code."""
        bank = load_bank(directory)
        try:
            self.lrgf = [parts["lrgf"] for parts in bank]  # type: ignore[misc]
            self.mem = [parts["mem"] for parts in bank]  # type: ignore[misc]
        except KeyError as e:
            raise ValueError(
                f"{directory / 'models.json'} lacks the {e.args[0]!r} part of a relation"
            ) from None
        self._stepper = None
