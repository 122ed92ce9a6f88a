"""The published tracks (:data:`TRACKS`) and how a command line names them.

>>> t = TRACKS["incipient"]
>>> t.test_cells()[:2], len(t.test_cells())
([('nominal', 0), ('nominal', 1)], 280)
>>> spec = t.fault_spec("f2", seed=3)
>>> spec == t.fault_spec("f2", seed=3), spec.profile.value, spec.onset + spec.ramp_samples <= 3800
(True, 'incipient', True)
>>> [t.name for t in parse_tracks("paper, small")]
['paper', 'small']
"""

from __future__ import annotations

from evaluation.tracks.distributions import Choice, Distribution, Fixed, Uniform
from evaluation.tracks.fault_templates import FaultTemplate
from evaluation.tracks.track import RAMP_LENGTHS, Track
from fcc_common.validation import Options, check, invalid
from fcc_env.params import MEASUREMENT_NAMES
from fcc_env.scenarios import PAPER_FAULTS, FaultProfile, fault_definition

__all__ = ["SMALL_MAGNITUDES", "TRACKS", "parse_tracks", "tracks_markdown"]


def _paper_scaled(low: float, high: float) -> dict[str, Distribution]:
    return {
        f: Uniform(
            low * fault_definition(f).default_magnitude,
            high * fault_definition(f).default_magnitude,
        )
        for f in PAPER_FAULTS
    }


#: Near-detectability magnitudes of the ``small`` track: the sizes at which the physical-limit
#: row's r_td is about 0.85-0.93, measured on 12 episodes with seeds 7000+ (never test seeds):
#: f1 0.005 → 0.93, f2 0.03 → 0.88, f3 0.012 → 0.92, f4 0.01 → 0.87
#: (``python lab/small_track_calibration.py``). About 1.1-1.5 noise stds of the most affected
#: temperature 50-200 samples after onset.
SMALL_MAGNITUDES: dict[str, float] = {"f1": 0.005, "f2": 0.03, "f3": 0.012, "f4": 0.01}

_TRACK_LIST = (
    Track(
        name="paper",
        description=(
            "The paper's set-up: each fault abrupt, at its paper magnitude and onset. Tests "
            "whether a detector reproduces the published comparison; the reference column."
        ),
    ),
    Track(
        name="small",
        description=(
            "Each fault abrupt at a size near its detectability limit (f1 0.5 %, f2 3 %, "
            "f3 1.2 %, f4 1 %: the physical-limit row's r_td is about 0.85-0.93), paper onsets. "
            "Tests sensitivity: the paper's faults are large enough that most detectors find "
            "them; small ones separate the good from the lucky."
        ),
        magnitudes={f: Fixed(m) for f, m in SMALL_MAGNITUDES.items()},
    ),
    Track(
        name="incipient",
        description=(
            "Paper magnitudes reached by a linear ramp of 500, 1000, 1500 or 2000 samples, onset "
            "uniform in 1000-1500 so every ramp completes. Tests drifting faults, which hide "
            "inside the slow operating changes a residual threshold must tolerate."
        ),
        onset=Uniform(1000, 1500),
        profiles=(FaultProfile.INCIPIENT,),
        ramp=Choice(RAMP_LENGTHS),
    ),
    Track(
        name="noisy",
        description=(
            "Paper faults with twice the measurement noise, in training and test. Tests whether "
            "detection survives poorer sensors without a flood of false alarms."
        ),
        noise_scale=2.0,
    ),
    Track(
        name="uncertain",
        description=(
            "Paper faults on a plant drawn per episode, training and test alike: kinetics ±2 %, "
            "heat-loss coefficients ±10 %, feed properties ±0.5 %, valve gain ±1 %, a slow "
            "feed-quality drift and a daily ambient cycle (fcc_env.uncertainty). Tests "
            "robustness to model mismatch, the paper's own subject: a detector that learns one "
            "plant may take another for a fault."
        ),
        plant_variation=True,
    ),
    Track(
        name="mismatch",
        description=(
            "Paper faults on the declared plant with undeclared effects drawn per episode, "
            "training and test alike: extra heat losses of up to 0.3 kW/K per vessel, a 30-90 s "
            "lag on one thermocouple, catalyst deactivation of up to 2 % a day "
            "(fcc_env.uncertainty.PlantMismatch). Tests what a real unit does to a model-based "
            "detector: it never matches its model, and no detector is told how."
        ),
        plant_mismatch=True,
    ),
    Track(
        name="random",
        description=(
            "Per faulty episode, fault type, size (uniform in 0.3-1.3 x paper), onset (uniform "
            "in 1000-3000) and profile (abrupt, or incipient with a ramp that completes) are "
            "drawn. Tests generalisation beyond the fixed cases a detector could be tuned to."
        ),
        magnitudes=_paper_scaled(0.3, 1.3),
        onset=Uniform(1000, 3000),
        profiles=(FaultProfile.ABRUPT, FaultProfile.INCIPIENT),
        ramp=Choice(RAMP_LENGTHS),
        draw_fault=True,
    ),
    Track(
        name="closed",
        description=(
            "The paper's faults, sizes and onsets on the closed-loop plant (FCC-closedloop-v0): "
            "T_rx held by the slide valve, T_rg1 by the air, set points and the valve command "
            "observed, excitation by disturbances and set-point moves. Tests diagnosis where "
            "every real unit runs: the loops mask the faults in the temperatures and move them "
            "into the valve and the air."
        ),
        closed_loop=True,
    ),
)
#: ``closed-random``: the ``random`` track's draws on the closed-loop plant.
_TRACK_LIST += (
    next(t for t in _TRACK_LIST if t.name == "random").replace(
        name="closed-random",
        description=(
            "The random track's draws (type, size 0.3-1.3 x paper, onset 1000-3000, abrupt or "
            "incipient) on the closed-loop plant. Tests generalisation under control."
        ),
        closed_loop=True,
    ),
)

#: ``regimes``: the ``closed`` track whose test episodes move the set points twice as widely.
_TRACK_LIST += (
    next(t for t in _TRACK_LIST if t.name == "closed").replace(
        name="regimes",
        description=(
            "The closed track's faults, sizes and onsets, trained on its set-point program "
            "(T_rx ± 4 °C, T_rg1 ± 6 °C) but tested on one twice as wide (± 8 °C, ± 12 °C). "
            "Tests operating regimes: operators move set points beyond any history a detector "
            "learned from, and learned relations do not extrapolate. A detector must hold its "
            "false-alarm rate there or flag the samples as novel (outside its training range), "
            "never as a fault."
        ),
        test_setpoint_halfranges=(8.0, 12.0),
    ),
)

#: The closed-loop faults of issue 43 (sensor, actuator, two at once): their columns are
#: :class:`FaultTemplate` s, each size range within the fault's registered one
#: (``fcc_env/sensor_faults.py``, ``lab/actuator-faults.md``).
_SENSOR_TEMPLATES = tuple(
    FaultTemplate(scenario=s, magnitude=m, channel=MEASUREMENT_NAMES)
    for s, m in (
        ("sensor-bias", Uniform(2.0, 10.0)),
        ("sensor-drift", Uniform(0.5, 2.0)),
        ("sensor-stuck", Fixed(1.0)),
        ("sensor-noise", Uniform(2.0, 20.0)),
        ("sensor-dropout", Uniform(0.2, 0.9)),
    )
)
_ACTUATOR_TEMPLATES = tuple(
    FaultTemplate(scenario=s, magnitude=m)
    for s, m in (
        ("valve-stiction", Uniform(0.02, 0.3)),
        ("valve-bias", Uniform(0.05, 0.2)),
        ("valve-stuck", Uniform(0.5, 1.0)),
        ("blower-capacity", Fixed(0.12)),
    )
)
#: The pairs measured together at their default sizes (``lab/actuator-faults.md``: none of
#: 20 episodes left the envelope), the first fault in 1000-2000, the second in 2000-3000.
_PAIRS = (
    ("sensor-bias", "valve-stiction"),
    ("valve-stiction", "sensor-drift"),
    ("valve-bias", "blower-capacity"),
    ("blower-capacity", "sensor-bias"),
    ("f1", "valve-stiction"),
)
_CONCURRENT_TEMPLATES = tuple(
    FaultTemplate(
        scenario="concurrent",
        parts=(
            FaultTemplate(scenario=a, onset=Uniform(1000, 2000)),
            FaultTemplate(scenario=b, onset=Uniform(2000, 3000)),
        ),
    )
    for a, b in _PAIRS
)
_TRACK_LIST += (
    Track(
        name="sensor",
        description=(
            "Sensor faults on the closed-loop plant: bias 2-10, drift 0.5-2 per hour, stuck, "
            "noise 2-20 x its own, dropouts 0.2-0.9 (held, as a DCS shows them), each on a "
            "measured channel drawn per episode, onset uniform in 1000-3000. Tests the faults "
            "operators meet first: on T_rx or T_rg1 the loop moves the true process to follow "
            "the wrong reading."
        ),
        closed_loop=True,
        onset=Uniform(1000, 3000),
        fault_templates=_SENSOR_TEMPLATES,
    ),
    Track(
        name="actuator",
        description=(
            "Actuator faults on the closed-loop plant: slide-valve stiction S 0.02-0.3 "
            "(Choudhury et al. 2005), valve bias 0.05-0.2, a valve stuck 0.5-1, the air blower "
            "at 0.12 capacity lost, onset uniform in 1000-3000. Tests the faults that make "
            "loops oscillate or saturate, where the loop hides the fault in its command."
        ),
        closed_loop=True,
        onset=Uniform(1000, 3000),
        fault_templates=_ACTUATOR_TEMPLATES,
    ),
    Track(
        name="concurrent",
        description=(
            "Two faults at once on the closed-loop plant, at their default sizes, the first "
            "with onset in 1000-2000, the second in 2000-3000: sensor-bias+valve-stiction, "
            "valve-stiction+sensor-drift, valve-bias+blower-capacity, "
            "blower-capacity+sensor-bias, f1+valve-stiction. Detection scores from the first "
            "onset; isolation must name both faults or say unknown."
        ),
        closed_loop=True,
        fault_templates=_CONCURRENT_TEMPLATES,
    ),
)

#: The published tracks by name.
TRACKS: dict[str, Track] = {t.name: t for t in _TRACK_LIST}


def parse_tracks(text: str) -> tuple[Track, ...]:
    """Tracks named in a CLI value: comma-separated names (``"paper,small"``) or ``"all"``.

    Unknown or empty names are rejected naming the value and the allowed set; repeats are
    dropped, the order of first mention is kept.
    """
    if not isinstance(text, str):
        raise invalid("tracks", text, f"a comma-separated string of {sorted(TRACKS)} or 'all'")
    if text.strip() == "all":
        return tuple(TRACKS.values())
    out: dict[str, Track] = {}
    for part in text.split(","):
        name = check("track", part.strip(), Options([*sorted(TRACKS), "all"]))
        if name == "all":
            raise invalid("tracks", text, "'all' alone or a list of track names")
        out.setdefault(name, TRACKS[name])
    return tuple(out.values())


def tracks_markdown(tracks: tuple[Track, ...] | None = None) -> str:
    """A Markdown table of tracks (name, episodes, description) for the track catalogue page.

    >>> print(tracks_markdown((TRACKS["paper"],)).splitlines()[2][:38])
    | `paper` | 200 healthy, 80 faulty | T
    """
    tracks = tuple(TRACKS.values()) if tracks is None else tracks
    lines = ["| track | test episodes | what it tests |", "|---|---|---|"]
    for t in tracks:
        episodes = f"{t.n_healthy} healthy, {t.n_faulty_total} faulty"
        lines.append(f"| `{t.name}` | {episodes} | {t.description} |")
    return "\n".join(lines)
