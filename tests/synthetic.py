"""Small synthetic FCC-like episodes for fast diagnoser tests (no physics, no env needed).

Inputs ``R_ar``, ``T_ar``, ``T_fp`` are random steps around nominal values; the five outputs are
first-order linear responses to them (discretised at 10 s) plus white measurement noise:

* ``T_rg1`` <- ``R_ar``, ``T_ar``;   ``T_rg2`` <- ``T_rg1``, ``R_ar`` (slow);
* ``T_rx``  <- ``T_rg2``, ``T_fp``   (the paper's relation (14));
* ``T_d1``  <- ``T_rg1``;            ``T_dg`` <- ``T_d1``, ``T_rg2``.

Everything random comes from a seeded ``numpy.random.Generator``; global RNG is never touched.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from diagnosers.episode.record import Episode

CHANNELS: tuple[str, ...] = ("R_ar", "T_ar", "T_fp", "T_rx", "T_rg1", "T_rg2", "T_d1", "T_dg")
SAMPLE_TIME_S = 10.0

# Nominal operating point: R_ar [ton/h], temperatures [°C] (order of CHANNELS).
_NOMINAL = np.array([400.0, 190.0, 220.0, 520.0, 690.0, 700.0, 700.0, 705.0])
# Half-range of the input steps (R_ar, T_ar, T_fp).
_STEP_RANGE = np.array([20.0, 8.0, 15.0])


def _first_order(x: np.ndarray, tau: float) -> np.ndarray:
    """Unit-gain discrete first-order lag ``y(t) = a y(t-1) + (1-a) x(t-1)``, ``tau`` in samples.

    Starts at steady state ``x[0]``, so episodes start without transients.
    """
    a = np.exp(-1.0 / tau)
    y = np.empty_like(x)
    y[0] = x[0]
    for t in range(1, x.size):
        y[t] = a * y[t - 1] + (1.0 - a) * x[t - 1]
    return y


def _random_steps(rng: np.random.Generator, n: int, half_range: float) -> np.ndarray:
    """Piecewise-constant signal, hold times uniform in [30, 300] samples, levels uniform."""
    out = np.empty(n)
    t = 0
    while t < n:
        hold = int(rng.integers(30, 301))
        out[t : t + hold] = rng.uniform(-half_range, half_range)
        t += hold
    return out


def make_episode(
    n_samples: int = 2000,
    seed: int = 0,
    *,
    step_scale: float = 1.0,
    noise_std: float = 0.2,
) -> Episode:
    """One healthy episode.

    Args:
        n_samples: number of samples (10 s each).
        seed: seed of the episode's own ``numpy.random.Generator``.
        step_scale: multiplies the input step amplitudes; 0 gives a steady plant, whose
            measurements are then nominal values plus independent Gaussian noise.
        noise_std: standard deviation of the white measurement noise on every channel
            (°C for temperatures, ton/h for ``R_ar``).
    """
    rng = np.random.default_rng(seed)
    d_rar, d_tar, d_tfp = (step_scale * _random_steps(rng, n_samples, h) for h in _STEP_RANGE)
    # Deviations from nominal; the gains are loosely plausible signs/magnitudes, nothing more.
    d_rg1 = _first_order(0.5 * d_rar + 0.3 * d_tar, tau=20.0)
    d_rg2 = _first_order(0.8 * d_rg1 + 0.2 * d_rar, tau=40.0)
    d_rx = _first_order(0.6 * d_rg2 + 0.4 * d_tfp, tau=4.0)
    d_d1 = _first_order(0.9 * d_rg1, tau=10.0)
    d_dg = _first_order(0.5 * d_d1 + 0.5 * d_rg2, tau=15.0)
    clean = _NOMINAL + np.column_stack([d_rar, d_tar, d_tfp, d_rx, d_rg1, d_rg2, d_d1, d_dg])
    y = clean + noise_std * rng.standard_normal(clean.shape)
    return Episode(
        y=y,
        channels=CHANNELS,
        sample_time_s=SAMPLE_TIME_S,
        scenario="synthetic",
        seed=seed,
        y_clean=clean,
    )


def inject_step_fault(
    episode: Episode, onset: int, magnitude: float = 3.0, channel: str = "T_rx"
) -> Episode:
    """Copy of ``episode`` with an additive step of ``magnitude`` (channel units) on ``channel``
    from sample ``onset`` on, and ``fault_onset`` set (the clean signal is left fault-free)."""
    y = episode.y.copy()
    y[onset:, episode.channels.index(channel)] += magnitude
    return dataclasses.replace(episode, y=y, fault_onset=onset, scenario=f"step_{channel}")


#: Steps [°C] of :func:`with_fault_twins`' default fault: its direction in an ``lrgf-glr`` bank's
#: normalised remaining error is close to f3's as the detector learned it on the FCC plant
#: (-0.58, -0.74, -0.34 over T_rx, T_rg1, T_rg2), the direction the lrgf-glr tests were tuned on.
F3_LIKE_STEPS: dict[str, float] = {"T_rx": -1.5, "T_rg1": -0.75, "T_rg2": -1.9}


def with_fault_twins(
    healthy: list[Episode],
    scenario: str = "f3",
    *,
    onset: int = 600,
    steps: dict[str, float] | None = None,
) -> list[Episode]:
    """``healthy`` and, for each, its labelled faulty noise twin (the same record, seed and noise
    with ``steps`` {channel: step} from ``onset``, default :data:`F3_LIKE_STEPS`, labelled
    ``scenario``): what a detector that learns from faults (``lrgf-glr``'s directions) pairs."""
    twins = []
    for ep in healthy:
        y = ep.y.copy()
        for channel, step in (F3_LIKE_STEPS if steps is None else steps).items():
            y[onset:, ep.channels.index(channel)] += step
        twins.append(dataclasses.replace(ep, y=y, fault_onset=onset, scenario=scenario))
    return [*healthy, *twins]


def cell_record(
    label: str, scenario: str, seed: int, *, r_td: float, t_dt: float, r_fd: float, n_alarms: int
):
    """A scored cell (:class:`evaluation.sweep.records.CellResult`) of a 400-sample episode
    with its fault (if any) at sample 100, for table and ranking tests without simulation."""
    from evaluation.sweep.records import CellResult

    faulty = scenario != "nominal"
    return CellResult(
        diagnoser=label,
        diagnoser_name=label,
        scenario=scenario,
        seed=seed,
        fault_onset=100 if faulty else None,
        n_samples=400,
        n_samples_planned=400,
        n_fault_samples=300 if faulty else 0,
        terminated_at=None,
        termination_reason=None,
        r_fd=0.0 if faulty else r_fd,
        r_td=r_td,
        t_dt=t_dt,
        t_dt_s=t_dt * 10,
        n_alarms=n_alarms,
        sample_time_s=10.0,
        detect_wall_s=0.0,
    )
