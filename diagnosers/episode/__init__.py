"""The diagnosers' input: an :class:`Episode` of measurements, checked once where it is built.

The rooms:

=====================  ===========================================================================
``record``             :class:`Episode` and its constructors (``from_batch``, ``from_dataset``,
                       ``from_frame``)
``checks``             the checks behind every constructor: shapes, finiteness, channel names,
                       fault labels
``units``              each channel's unit: checked, and read from a dataset's sidecar or schema
=====================  ===========================================================================
"""

from diagnosers.episode.record import Episode

__all__ = ["Episode"]
