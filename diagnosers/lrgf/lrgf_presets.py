"""The registered variants of the LRGF families: the same class with other defaults.

``lrgf-mem`` (:class:`diagnosers.lrgf.lrgf_mem.LRGFMEM`) and ``lrgf-glr``
(:class:`diagnosers.lrgf.lrgf_glr.LRGFGLR`) are registered by their classes; the variants below are
presets of them (:func:`diagnosers.presets.preset`): the same code, parameters and saved format,
other defaults. ``lrgf-glr-closed-novelty`` adds the novelty flag of
:func:`diagnosers.range_guard.novelty_variant`. ``diagnosers.make("lrgf-glr-adaptive")`` equals
``diagnosers.make("lrgf-glr", **PRESETS["lrgf-glr-adaptive"])``; ``lrgf-mem-paper`` also reads
``relations=None`` as the paper's one relation (:data:`diagnosers.bank.relations.PAPER_RELATIONS`).
"""

from __future__ import annotations

from typing import Any

from diagnosers.bank.relations import CLOSED_LOOP_RELATIONS, PAPER_RELATIONS
from diagnosers.lrgf.lrgf_glr import LRGFGLR
from diagnosers.lrgf.lrgf_mem import LRGFMEM
from diagnosers.presets import preset
from diagnosers.range_guard import novelty_variant

__all__ = [
    "PRESETS",
    "LRGFGLRAdaptive",
    "LRGFGLRClosed",
    "LRGFGLRClosedNovelty",
    "LRGFMEMPaper",
]

#: each variant's defaults that differ from its family's
PRESETS: dict[str, dict[str, Any]] = {
    "lrgf-mem-paper": {
        "n_hidden": 3,
        "mem_output_activation": "tanh",
        "mem_select": "always",
        "lr": 0.01,
        "band_definition": "paper-record",
        "alarm_filter": "none",
    },
    "lrgf-glr-adaptive": {
        "baseline_lambda": 1e-4,
        "baseline_hold": 1.0,
        "baseline_filters": [1, 10, 50],
        "baseline_ridge": 3.0,
        "false_alarm_target": 0.04,
        "val_fraction": 0.0,
    },
    "lrgf-glr-closed": {},
}

LRGFMEMPaper = preset(
    "lrgf-mem-paper",
    LRGFMEM,
    PRESETS["lrgf-mem-paper"],
    """The paper's detector (Sec. 5): relation T_rx = s1(T_rg2, T_fp), 3 hidden neurons, NNARX
    error model with a tanh output, the paper's band ``y_m + y_e ± t_α v`` and the paper's rule:
    alarm when the output leaves its band (``alarm_filter="none"``, α = ``band_alpha`` = 0.01,
    two-sided: "the 99% significance level was assumed (α = 0.01)"). ``lrgf-mem`` with these
    defaults.

    ``v`` follows the paper's protocol as far as it states it (``band_definition="paper-record"``):
    "v is the standard deviation of y_e", "y_e is the output of the error model on the input
    u", the error model identified on "the data {u_i, r_i}_{i=1}^N" collected from the
    benchmark (Sec. 3, 5.1). The paper names one healthy record, holds none of it out and cuts
    no start-up from it, so ``v`` is the spread of ``y_e`` over every healthy episode given to
    ``fit``, each from its first sample (``"paper"``, the error model's training part alone,
    differs by a fraction of a percent). The start-up convention of the filters
    (``steady_window=100``, a silent warm-up) is ``lrgf-mem``'s: the paper does not say how its
    filters start.

    It does not reach the paper's operating point: the error model of this replica moves far
    less than the output strays from ``y_m + y_e``, so the literal band is narrow and much of a
    healthy episode falls outside it (every reading measured: lab/results-history.md).""",
    module=__name__,
    # relations=None is the paper's one relation for this preset
    attributes={"DEFAULT_RELATIONS": PAPER_RELATIONS},
)

LRGFGLRAdaptive = preset(
    "lrgf-glr-adaptive",
    LRGFGLR,
    PRESETS["lrgf-glr-adaptive"],
    """``lrgf-glr`` with a held regression baseline (``baseline_lambda=1e-4``,
    ``baseline_hold=1``, ``baseline_filters=[1, 10, 50]``, ``baseline_ridge=3``), its networks
    trained on every sample (``val_fraction=0``) and a declared target of 0.04.

    For a plant that differs from the plants it was trained on (the ``uncertain`` track). While
    the plant is healthy, the baseline learns, per relation, the part of the normalised error
    that a constant and three low-pass filters (1, 10 and 50 samples) of the relation's inputs
    and network output explain (:mod:`diagnosers.stages.baseline`): another plant's offset *and* its
    gains. It holds while any statistic is over its limit. λ = 1e-4 makes it a regression on
    every held sample of an episode (a window of about 28 h at 10 s in a long streaming run).
    Everything else is ``lrgf-glr``'s (the larger T_rg1 network, the slow scale, the novelty
    scale).

    On a fixed plant like the training plants it raises the healthy alarms for no earlier
    detection (the calibration records are corrected more than fresh episodes are): use
    ``lrgf-glr`` there. ``baseline_filters=None, false_alarm_target=0.03`` gives the
    running-mean variant. The settings were chosen on validation seeds (lab/detector-lab.md).
    """,
    module=__name__,
)

LRGFGLRClosed = preset(
    "lrgf-glr-closed",
    LRGFGLR,
    PRESETS["lrgf-glr-closed"],
    """``lrgf-glr`` for the closed-loop plant (``FCC-closedloop-v0``, the ``closed`` tracks):
    its relations read the manipulated variables (``relations=None`` is
    :data:`diagnosers.bank.relations.CLOSED_LOOP_RELATIONS`: T_rx from the valve command, T_rg2 and
    T_fp; T_rg1 and T_rg2 with the air and the valve), and its fault directions are learned on
    faults simulated under control. Everything else is ``lrgf-glr``'s. It needs the channels
    ``u_F`` and ``R_ar``: on open-loop data (no ``u_F``) the harness skips it.""",
    module=__name__,
    attributes={"DEFAULT_RELATIONS": CLOSED_LOOP_RELATIONS},
)

#: ``lrgf-glr-closed-novelty``: ``lrgf-glr-closed``'s decisions, plus the samples outside its
#: training set-point range flagged as novel (:mod:`diagnosers.range_guard`; the ``regimes`` track)
LRGFGLRClosedNovelty = novelty_variant(LRGFGLRClosed, module=__name__)
