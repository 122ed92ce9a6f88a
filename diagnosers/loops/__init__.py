"""Control-loop performance monitors: an oscillating loop and a sticking valve, from the loop's
own records (issue 43 item 6): the field's black-box methods for these faults, and a fast
model-based test of the valve against its command.

=====================  ===========================================================================
``loop_indexes``       the signal algebra: the ACF regularity of Thornhill, Huang & Zhang
                       (2003) and the cross-correlation test of Horch (1999)
``loop_detectors``     ``oscillation-acf`` (an oscillating loop, no fault named) and
                       ``stiction-ccf`` (a sticking valve, named ``valve-stiction``)
``valve_statistics``   the windowed GLRs of a valve that stopped following its command (a stuck
                       phase, a bias) on a quasi-steady loop's residual
``valve_glr``          ``valve-glr``: the riser outlet regressed on the valve command and the
                       riser's measured inputs, the GLRs on its residual (a model's redundancy:
                       it sees the first stuck samples, not a limit cycle)
``loop_offset``        ``loop-offset``: a loop that cannot hold its set point, its actuator short
                       (named ``blower-capacity`` on the air loop)
``air_deficit``        ``air-deficit``: the metered air short of the air loop's command, computed
                       again from the recorded error through the published PI law (grey box;
                       named ``blower-capacity``)
=====================  ===========================================================================
"""

from diagnosers.loops.air_deficit import AirDeficit
from diagnosers.loops.loop_detectors import LOOP_CHANNELS, OscillationACF, StictionCCF
from diagnosers.loops.loop_indexes import acf_regularity, horch_phase
from diagnosers.loops.loop_offset import LoopOffset
from diagnosers.loops.valve_glr import ValveGLR

__all__ = [
    "LOOP_CHANNELS",
    "AirDeficit",
    "LoopOffset",
    "OscillationACF",
    "StictionCCF",
    "ValveGLR",
    "acf_regularity",
    "horch_phase",
]
