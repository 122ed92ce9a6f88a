"""The benchmark: its tracks, their reference rows and goals, and the per-track leaderboard.

===================  =============================================================================
``track``            :class:`Track`: a typed, validated definition of one benchmark question
``distributions``    :class:`Fixed`, :class:`Uniform`, :class:`Choice`: what a track draws from
``fault_templates``  :class:`FaultTemplate`: a track's fault as a spec template (channel, pairs)
``catalogue``        the published tracks (:data:`TRACKS`), :func:`parse_tracks`
``track_data``       :class:`TrackData`: a track's episodes as a sweep's data source
``oracle``           the reference rows: physical-limit observers that read the noise-free plant
``optimal``          the optimal-detector rows: a CUSUM and a GLR on each fault's exact signature
``filter_bound``     the reachable bound: a GLR on the innovations of a filter of the exact model
``sensor_bound``     how well the exact model names a biased sensor: per-channel bias hypotheses
``reference_runs``   the reference rows as tasks of the sweep's backend, stored like cells
``rows``             the rows of a track table: per diagnoser, intervals over the seeds (pure)
``goal``             the goal table: how far each detector is from its reference row
``board``            running a track (:func:`run_track`) into a :class:`TrackRun`
``board_tables``     a track's Markdown/CSV tables, isolation table, confusion figures, summary
===================  =============================================================================

The track definitions are re-exported here (``from evaluation.tracks import TRACKS, Track``);
the other rooms are imported by their own names.
"""

from evaluation.tracks.catalogue import SMALL_MAGNITUDES, TRACKS, parse_tracks, tracks_markdown
from evaluation.tracks.distributions import Choice, Distribution, Fixed, Uniform
from evaluation.tracks.track import (
    MIN_HEALTHY,
    RAMP_LENGTHS,
    RAMP_MARGIN,
    TEST_SEED_START,
    TRACKS_VERSION,
    TRAIN_SEED_START,
    VALIDATION_SEED_START,
    Track,
    stable_hash,
)

__all__ = [
    "MIN_HEALTHY",
    "RAMP_LENGTHS",
    "RAMP_MARGIN",
    "SMALL_MAGNITUDES",
    "TEST_SEED_START",
    "TRACKS",
    "TRACKS_VERSION",
    "TRAIN_SEED_START",
    "VALIDATION_SEED_START",
    "Choice",
    "Distribution",
    "Fixed",
    "Track",
    "Uniform",
    "parse_tracks",
    "stable_hash",
    "tracks_markdown",
]
