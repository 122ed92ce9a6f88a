"""Control-loop performance monitors: an oscillating loop and a sticking valve, from the loop's
own records (issue 43 item 6), the field's black-box methods for these faults.

=====================  ===========================================================================
``loop_indexes``       the signal algebra: the ACF regularity of Thornhill, Huang & Zhang
                       (2003) and the cross-correlation test of Horch (1999)
``loop_detectors``     ``oscillation-acf`` (an oscillating loop, no fault named) and
                       ``stiction-ccf`` (a sticking valve, named ``valve-stiction``)
``loop_offset``        ``loop-offset``: a loop that cannot hold its set point, its actuator short
                       (named ``blower-capacity`` on the air loop)
=====================  ===========================================================================
"""

from diagnosers.loops.loop_detectors import LOOP_CHANNELS, OscillationACF, StictionCCF
from diagnosers.loops.loop_indexes import acf_regularity, horch_phase
from diagnosers.loops.loop_offset import LoopOffset

__all__ = [
    "LOOP_CHANNELS",
    "LoopOffset",
    "OscillationACF",
    "StictionCCF",
    "acf_regularity",
    "horch_phase",
]
