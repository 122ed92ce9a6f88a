"""The uncertainty band of eqs. (10)-(11) of the paper: ``y_m + y_e ± t_α v``, and its scale ``v``.

``y_m`` is the nominal model's output, ``y_e`` the model error model's
(:class:`diagnosers.networks.mem_net.NNARXErrorModel`), ``t_α`` the two-sided normal quantile
(:func:`diagnosers.stages.alarm.two_sided_normal_quantile`). Three definitions of the band half-width
scale ``v`` are offered by :func:`band_scale`:

* ``"paper"``: ``v = std(y_e)``, the paper's literal text ("v is the standard deviation of y_e"),
  over the records the error model was identified on.
  It measures how much the error model *moves*, not how wrong the corrected model is, so its
  coverage is not controlled.
* ``"paper-record"``: the same ``std(y_e)`` over the whole healthy training record, every
  episode a detector is given from its first sample (start-up included), the records held out
  for calibration too. The paper's protocol as far as it states it: Sec. 3 identifies the error
  model on "the data {u_i, r_i}_{i=1}^N", takes "y_e [as] the output of the error model on the
  input u" and "v [as] the standard deviation of y_e"; it holds no data out and cuts no start-up
  from the training data. Its coverage is no more controlled than ``"paper"``'s.
* ``"residual"``: ``v = std(y - y_m - y_e)`` on held-out healthy data: the spread of what the
  corrected model still misses. Under the paper's own normality assumption this gives a band with
  coverage ``1 - α``. Recommended.
"""

from __future__ import annotations

from enum import StrEnum

import numpy as np

from diagnosers.stages.alarm import two_sided_normal_quantile

__all__ = ["BandScale", "band", "band_scale"]


class BandScale(StrEnum):
    """Definition of ``v`` in eqs. (10)-(11); see the module docstring."""

    PAPER = "paper"
    PAPER_RECORD = "paper-record"
    RESIDUAL = "residual"


def band(
    y_m: np.ndarray, y_e: np.ndarray, v: np.ndarray | float, alpha: float = 0.01
) -> tuple[np.ndarray, np.ndarray]:
    """Uncertainty band of eqs. (10)-(11): ``y_m + y_e ∓ t_α v``.

    Args:
        y_m: nominal model output, shape ``(T, m)`` (or broadcastable), physical units.
        y_e: model-error-model output, same shape.
        v: band scale per output, shape ``(m,)`` or scalar (see :func:`band_scale`).
        alpha: significance level; the band has nominal coverage ``1 - α`` for Gaussian errors.

    Returns:
        ``(lower, upper)``, each of the broadcast shape of the inputs.
    """
    centre = np.asarray(y_m, dtype=np.float64) + np.asarray(y_e, dtype=np.float64)
    half = two_sided_normal_quantile(alpha) * np.asarray(v, dtype=np.float64)
    if np.any(half < 0):
        raise ValueError("band scale v must be non-negative")
    return centre - half, centre + half


def band_scale(
    y_e: np.ndarray,
    *,
    definition: BandScale | str = BandScale.RESIDUAL,
    y: np.ndarray | None = None,
    y_m: np.ndarray | None = None,
    ddof: int = 1,
) -> np.ndarray:
    """Band scale ``v`` per output channel.

    Args:
        y_e: MEM output on (held-out, healthy) data, shape ``(T, m)``; for ``"paper-record"``
            the records concatenated, each from its first sample.
        definition: ``"paper"`` and ``"paper-record"`` -> ``std(y_e)`` (they differ in the data
            the caller passes, see the module docstring); ``"residual"`` ->
            ``std(y - y_m - y_e)``, which needs ``y`` and ``y_m``; see the module docstring for
            why ``"residual"`` is recommended.
        y: measured outputs, shape ``(T, m)`` (``"residual"`` only).
        y_m: nominal model outputs, shape ``(T, m)`` (``"residual"`` only).
        ddof: delta degrees of freedom of the standard deviation.

    Returns:
        ``v``, shape ``(m,)``.
    """
    try:
        definition = BandScale(definition)
    except ValueError:
        raise ValueError(
            f"definition={definition!r}; choose one of {[d.value for d in BandScale]}"
        ) from None
    ye = np.asarray(y_e, dtype=np.float64)
    ye = ye[:, None] if ye.ndim == 1 else ye
    if definition in (BandScale.PAPER, BandScale.PAPER_RECORD):
        return ye.std(axis=0, ddof=ddof)
    if y is None or y_m is None:
        raise ValueError('definition="residual" needs the measured y and the nominal y_m')
    yy = np.asarray(y, dtype=np.float64).reshape(ye.shape)
    ym = np.asarray(y_m, dtype=np.float64).reshape(ye.shape)
    return (yy - ym - ye).std(axis=0, ddof=ddof)
