"""Control-valve stiction: the two-parameter data-driven model of Choudhury, Thornhill & Shah.

M. A. A. Shoukat Choudhury, N. F. Thornhill, S. L. Shah, "Modelling valve stiction", *Control
Engineering Practice* 13 (2005) 641–658. The model maps the controller output ``x`` (the
valve command) to the valve position ``y`` with two parameters, both in the unit of ``x``:

* ``S``, deadband plus stickband: how far the command must move back before a valve that has
  reversed breaks away;
* ``J``, the slip jump: how far the valve jumps when it breaks away (the static friction
  released as the dynamic friction takes over).

The valve sticks when it comes to rest (the command stops or reverses). A stuck valve stays
where it is until the command has moved past the point where it stuck, ``x_ss``, by more than
``S`` in the reverse direction, or by more than ``J`` (the stickband alone) when it goes on in
the direction it moved before. It then slips to ``y = x − sign·(S − J)/2`` and follows the
command with that offset while the command keeps moving the same way. The four cases of the
paper's phase plots (command against position, under a sinusoidal command):

=================  ==========  ==================================================
case               parameters  moving valve against the command
=================  ==========  ==================================================
pure deadband      J = 0       lags by S/2; no jump (a backlash parallelogram)
stiction           J < S       lags by (S − J)/2 after a jump of J (undershoot)
no offset          J = S       meets the command after a jump of J
overshoot          J > S       leads by (J − S)/2 after a jump of J
=================  ==========  ==================================================

In a PI loop the stiction cases (J > 0) cycle on a self-regulating process while a pure
deadband settles; on an integrating process a pure deadband cycles too (the paper's
closed-loop section; ``tests/fcc_env/test_stiction.py`` checks all of it numerically).

**One reading of the flowchart, stated.** ``x_ss`` is latched when the valve sticks and held
until it slips. A measured loop's controller output reverses every few samples with the
measurement noise; re-latching ``x_ss`` at each of those reversals would keep a valve inside
its band stuck for good however far the integral moves the command, which no valve does
(Kano, Maruta, Kugemoto & Shimizu's 2004 variant of the model latches it the same way).
"""

from __future__ import annotations

import numpy as np

from fcc_common.validation import Real, check

__all__ = ["StictionValve", "valve_response"]


def _sign(v: float) -> int:
    return int(v > 0.0) - int(v < 0.0)


class StictionValve:
    """One sticking valve's state machine (Choudhury et al. 2005, module docstring).

    ``x0``: the command the valve rests at when the model starts (its position too: a valve
    that starts to stick where it stands, so its first breakaway needs the whole band ``S``
    in either direction). :meth:`move` takes the next command and returns the position; ``S``
    and ``J`` may change between calls (an incipient fault grows them).

    >>> v = StictionValve(0.0)
    >>> [v.move(x, S=2.0, J=1.0) for x in (1.0, 2.0, 3.0, 4.0, 3.5, 1.0)]
    [0.0, 0.0, 2.5, 3.5, 3.5, 1.5]
    """

    def __init__(self, x0: float) -> None:
        self.x_prev = float(x0)  # the previous command
        self.direction = 0  # the sign of the valve's motion (0: at rest from the start)
        self.stuck = True
        self.x_stuck = float(x0)  # the command at which the valve stuck (x_ss)
        self.stuck_direction = 0  # the direction it moved before it stuck
        self.y = float(x0)  # the valve position

    def move(self, x: float, S: float, J: float) -> float:
        """The valve position for command ``x`` (``S``, ``J`` ≥ 0, in the unit of ``x``)."""
        x = float(x)
        v = _sign(x - self.x_prev)
        if not self.stuck and v != self.direction:  # comes to rest or reverses: it sticks
            self.stuck, self.x_stuck, self.stuck_direction = True, self.x_prev, self.direction
        if self.stuck:
            e = x - self.x_stuck
            s = _sign(e)
            # on in the same direction only the stickband J holds it; a reversal needs S
            band = J if s == self.stuck_direction else S
            if s != 0 and abs(e) > band:
                self.stuck, self.direction = False, s
                self.y = x - s * (S - J) / 2.0
        else:
            self.y = x - v * (S - J) / 2.0
        self.x_prev = x
        return self.y

    def copy(self) -> StictionValve:
        """An independent copy of the state (to recompute a sample from it)."""
        other = StictionValve.__new__(StictionValve)
        other.__dict__.update(self.__dict__)
        return other


def valve_response(commands: np.ndarray, S: float, J: float) -> np.ndarray:
    """The positions ``(n,)`` of a sticking valve under ``commands`` ``(n,)``, resting at the
    first command when it starts (:class:`StictionValve`): the model's input-output map, for
    phase plots and tests.

    >>> valve_response(np.array([0.0, 1.0, 2.0, 3.0]), S=2.0, J=2.0).tolist()
    [0.0, 0.0, 0.0, 3.0]
    """
    S = check("S", S, Real(0.0, why="deadband plus stickband, in the command's unit"))
    J = check("J", J, Real(0.0, why="slip jump, in the command's unit"))
    x = np.asarray(commands, dtype=np.float64)
    if x.ndim != 1 or x.shape[0] == 0:
        raise ValueError(f"commands must be a non-empty 1-D array; got shape {x.shape}")
    valve = StictionValve(x[0])
    return np.array([valve.move(xi, S, J) for xi in x])
