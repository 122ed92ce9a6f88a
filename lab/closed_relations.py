"""Candidate relation banks for ``lrgf-glr-closed`` (issue 31), compared on validation seeds.

    python -m evaluation.leaderboard --track closed --test-seed-start 6000 \
        --import lab.closed_relations --diagnosers lrgf-glr-closed,lrgf-glr-closed-dilute \
        --out results/closed-relations

Registers ``lrgf-glr-closed-dilute``: the closed-loop bank plus the dilute-phase relations
(:data:`diagnosers.bank.relations.DILUTE_RELATIONS`), because under control f3 and f4 keep their
steady signature in T_d1 and T_dg while the held temperatures lose it (docs: Closed loop,
the masking table). Test seeds from 6000: validation seeds, never the test range.

Result (2026-11-27, this machine, 200 healthy + 20 per fault, seeds 6000+): the dilute
relations do not help, so the registered bank stays ``CLOSED_LOOP_RELATIONS``.

| bank | r_fd [95 %] | t_dt f1 / f2 / f3 / f4 | r_td f3 |
|---|---|---|---|
| lrgf-glr-closed | 0.0034 [0.0026, 0.0045] | 0 / 6 / 130 / 12 | 0.63 |
| + dilute relations | 0.0037 [0.0030, 0.0047] | 0 / 5 / 130 / 12 | 0.70 |
| perfect model (measured inputs) | 0.0027 [0.0025, 0.0031] | 0 / 4 / 17 / 5 | 0.99 |
"""

from __future__ import annotations

from diagnosers.bank.relations import CLOSED_LOOP_RELATIONS, DILUTE_RELATIONS
from diagnosers.lrgf.lrgf_glr import LRGFGLR
from diagnosers.presets import preset

LRGFGLRClosedDilute = preset(
    "lrgf-glr-closed-dilute",
    LRGFGLR,
    {},
    "lrgf-glr-closed with the dilute-phase relations added (lab candidate).",
    module=__name__,
    attributes={"DEFAULT_RELATIONS": [*CLOSED_LOOP_RELATIONS, *DILUTE_RELATIONS]},
)
