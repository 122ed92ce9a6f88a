"""The FCC converter as a Gymnasium environment (``FCC-v0``)."""

from __future__ import annotations

import warnings
from collections import deque
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numba
import numpy as np
from gymnasium import spaces

from fcc_common.validation import Integer, check, invalid
from fcc_env import effects as fx
from fcc_env.actuator_faults import require_loops
from fcc_env.closed_loop import CHANNEL_UNITS, ControlSystem, observation_channels
from fcc_env.episode_setup import EpisodeStream, add_noise, setup_episode
from fcc_env.params import NOMINAL_INPUTS
from fcc_env.physics import AUX_NAMES
from fcc_env.plant import (
    AFTERBURN_WARNING_C,
    PlantConfig,
    afterburn_delta_C,
    plant_from_request,
    termination_reason,
)
from fcc_env.regulatory import SETPOINT_RANGES, RegulatoryLayer
from fcc_env.render import WINDOW_SAMPLES, TrendRenderer
from fcc_env.scenarios import (
    DEFAULT_N_SAMPLES,
    ENV_FAULT_KEYWORDS,
    RANDOM_SCENARIO,
    FaultSpec,
    fault_from_request,
    fault_time_range,
)
from fcc_env.simulation import N_SAMPLES_RANGE

#: Actuator limits on the applied inputs (program + action), as fractions of nominal.
U_F_LIMITS_REL = (0.5, 1.5)
R_AR_LIMITS_REL = (0.85, 1.15)
#: Physical size of a unit action (move relative to the program): catalyst valve kg/s, air t/h.
ACTION_SCALE = np.array([0.5 * NOMINAL_INPUTS[0], 0.15 * NOMINAL_INPUTS[1]])

OBS_LOW = np.array([0.0] + [-100.0] * 7, dtype=np.float32)
OBS_HIGH = np.array([500.0] + [1500.0] * 7, dtype=np.float32)
#: Closed loop (``FCC-closedloop-v0``): Table 1, the valve command (kg/s), the set points (°C).
CLOSED_OBS_LOW = np.concatenate(
    [OBS_LOW, [0.0], [SETPOINT_RANGES[n].low for n in ("T_rx_sp", "T_rg1_sp")]]
).astype(np.float32)
CLOSED_OBS_HIGH = np.concatenate(
    [OBS_HIGH, [1000.0], [SETPOINT_RANGES[n].high for n in ("T_rx_sp", "T_rg1_sp")]]
).astype(np.float32)
#: Closed loop: the set-point move of a unit action (°C), T_rx_sp and T_rg1_sp.
SETPOINT_ACTION_SCALE = np.array([15.0, 20.0])

#: The registered ids of the plant: open loop, and under its regulatory layer
#: (:class:`FCCClosedLoopEnv`).
ENV_ID = "FCC-v0"
CLOSED_LOOP_ENV_ID = "FCC-closedloop-v0"

#: The keys ``reset(options=...)`` takes.
RESET_OPTION_NAMES = ("fault", *ENV_FAULT_KEYWORDS, "plant_effects")


class FCCEnv(gym.Env):
    """Fluid catalytic cracking converter (riser, reactor/stripper, two-stage regenerator).

    ## Description
    The plant of the FCC model specification, fcc-model.md (after Moro & Odloak, 1995): an
    11-state model integrated with RK4 at the sample period, in open loop apart from the reactor
    level loop, with slide-valve hydraulics (``valve_beta = 0.3``). An operating program excites
    feed temperature, air temperature and air flow with random steps; the catalyst valve is held.
    A scenario may switch a fault (f1–f4 of Patan et al., 2005) on at a given sample. The env is
    a plant to diagnose, not a control task: the reward is always 0.

    ## Action Space
    ``Box(-1, 1, (2,))`` float32: moves of the manipulated variables relative to the operating
    program, normalised (Gymnasium's recommendation) and held from this step until the next.
    ``0`` follows the program (how diagnosers run episodes).

    | Index | Action                                  | 1.0 means          |
    |-------|-----------------------------------------|--------------------|
    | 0     | regenerated-catalyst valve command Δu_F | +208.3 kg/s (50 %) |
    | 1     | combustion air ΔR_ar                    | +22.26 t/h (15 %)  |

    Out-of-range finite actions are clipped to the box, and the applied inputs to the actuator
    limits (u_F 0.5–1.5 ×, R_ar 0.85–1.15 × nominal); ``info["action_saturated"]`` says so.
    ``info["inputs"]`` holds the inputs actually applied (``fcc_env.INPUT_NAMES``).

    ## Observation Space
    ``Box(8,)`` float32, the paper's Table 1 measurements with white noise:

    | Index | Variable | Unit | Low  | High | Noise std |
    |-------|----------|------|------|------|-----------|
    | 0     | R_ar     | t/h  | 0    | 500  | 0.5 %     |
    | 1     | T_ar     | °C   | -100 | 1500 | 0.3       |
    | 2     | T_fp     | °C   | -100 | 1500 | 0.3       |
    | 3     | T_rx     | °C   | -100 | 1500 | 0.3       |
    | 4     | T_rg1    | °C   | -100 | 1500 | 0.3       |
    | 5     | T_rg2    | °C   | -100 | 1500 | 0.3       |
    | 6     | T_d1     | °C   | -100 | 1500 | 0.5       |
    | 7     | T_dg     | °C   | -100 | 1500 | 0.5       |

    ## Faults
    ``nominal``; ``f1`` catalyst density +10 % (onset 1900); ``f2`` weir constants −15 % (1900);
    ``f3`` CO2/CO ratio constant −10 % (2020); ``f4`` reactor holdup +5 % (2000); any added by
    :func:`fcc_env.register_fault`. ``"random"`` draws scenario, onset and magnitude. Profiles:
    ``"abrupt"`` or ``"incipient"`` (ramp over ``ramp_samples``). Label: ``info["fault_active"]``.
    Sensor faults on a chosen channel (:mod:`fcc_env.sensor_faults`); actuator faults
    (:mod:`fcc_env.actuator_faults`: ``valve-stiction``, ``valve-bias``, ``valve-stuck``,
    ``blower-capacity``), acting between the command and the process (``info["inputs"]`` the
    inputs received; in closed loop the observation's ``u_F`` stays the command; a stuck or
    sticking valve needs the T_rx loop and is refused in open loop); ``"concurrent"``: two
    faults with their own onsets, ``fault=FaultSpec(scenario="concurrent", parts=(...))``,
    whose info adds ``fault_labels`` and ``fault_times``.

    ## Starting State
    The hot steady state at nominal inputs, found by a root solver (:func:`fcc_env.steady_state`).

    ## Episode End
    Termination when the plant leaves its envelope (well below 3 t, T_rg1 below 600 °C, an ignited
    d1 afterburn with T_d1 − T_rg1 above 80 °C, or a non-finite state);
    ``info["termination_reason"]`` names it. The spec's 40 °C afterburn limit (§2.8) is a flag,
    ``info["afterburn_warning"]``, not an end: with the spec's own excitation (§7.5) 15 % of healthy
    episodes cross 40 °C (measured over 1024 seeds; 99 % stay below 64 °C), while an ignited d1
    phase (about 0.4 % of healthy excited episodes, T_d1 ≈ 790 °C) sits 90–140 °C above T_rg1.
    Truncation by ``max_episode_steps`` (registered: 3999 steps, i.e. 4000 samples counting the
    reset observation as sample 0, the paper's horizon).

    ## Arguments
    | kwarg / reset option | default | meaning |
    |---|---|---|
    | fault | None | a :class:`fcc_env.FaultSpec` instead of the six options below (not both); |
    |  |  | as a reset option it replaces the make fault |
    | scenario | "nominal" | nominal, a registered fault (f1–f4 and added ones) or random |
    | fault_time | paper's | onset sample (int, inside the horizon) |
    | fault_magnitude | paper's | relative change ≥ 0 (direction fixed by the fault) |
    | fault_profile | "abrupt" | or "incipient" |
    | ramp_samples | 500 | incipient ramp length (samples, ``DEFAULT_RAMP_SAMPLES``) |
    | fault_channel | None | a sensor fault's measured channel (``sensor-bias`` and the others of |
    |  |  | :mod:`fcc_env.sensor_faults`; None: ``T_rx``); other faults refuse one. Info adds |
    |  |  | ``fault_channel`` and ``sensor_dropout`` (the channel held its last good value) |
    | plant | None | a :class:`fcc_env.PlantConfig` instead of the six options below (not both) |
    | valve_beta | 0.3 | slide-valve head share; 0 = flow mode, 0.15 = harder |
    | sample_time_s | 10.0 | sample period (s) |
    | rk4_substeps | 1 | RK4 steps per sample |
    | excitation | True | False = constant inputs; a dict overrides :class:`Excitation` |
    | noise_scale | 1.0 | multiplier on the noise stds; 0 = noise-free |
    | regulatory | None | closed loop: True, a :class:`fcc_env.RegulatoryLayer` or a dict of its fields |
    | plant_effects | () | undeclared plant effects (:mod:`fcc_env.effects`): library ids such as |
    |  |  | ``"heat_loss:stage1"`` or objects with ``d_state``/``measure``; never shown in info |
    | horizon | 4000 | samples the scenario is laid out on: onsets must fall inside it and random |
    |  |  | onsets are drawn from its middle half. ``max_episode_steps`` (``horizon − 1``) truncates; |
    |  |  | the env cannot see that wrapper, so pass both when you change the length. |
    | render_mode | None | "rgb_array": a trend frame of the last 500 samples, titled with the |
    |  |  | env id, the scenario, the time (sample and hours) and, once passed, the fault |
    |  |  | onset; every axis in its unit. Closed loop: T_rx and T_rg1 against their set |
    |  |  | points, the valve command u_F and the air R_ar under them |

    ## Closed loop (``FCC-closedloop-v0``, or ``regulatory=``)
    The plant runs under :class:`fcc_env.RegulatoryLayer` (T_rx on the valve, T_rg1 on the air).
    The observation adds ``u_F`` (kg/s) and the set points ``T_rx_sp``, ``T_rg1_sp`` (°C); the
    action moves the set points (1.0 = +15 / +20 °C, clipped to their ranges); info adds
    ``controller_saturated``, ``setpoint_clipped`` and ``setpoints`` (docs: Closed loop). On
    ``FCC-closedloop-v0`` and ``FCC-control-v0`` ``regulatory`` defaults to ``True``, and
    ``False`` or ``None`` (open loop) are refused by name (:class:`FCCClosedLoopEnv`).

    ## Version History
    * v0: first release (spec revision with slide-valve hydraulics and entrainment return).

    Example:
        >>> import gymnasium as gym, fcc_env
        >>> env = gym.make("FCC-v0", scenario="f2")
        >>> obs, info = env.reset(seed=0)
        >>> obs.shape, info["fault_active"]
        ((8,), False)
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}  # noqa: RUF012 (Gymnasium API)

    def __init__(
        self,
        *,
        fault: FaultSpec | None = None,
        plant: PlantConfig | None = None,
        scenario: str | None = None,
        fault_time: int | None = None,
        fault_magnitude: float | None = None,
        fault_profile: str | None = None,
        ramp_samples: int | None = None,
        fault_channel: str | None = None,
        valve_beta: float | None = None,
        sample_time_s: float | None = None,
        rk4_substeps: int | None = None,
        excitation: Any = None,
        noise_scale: float | None = None,
        regulatory: Any = None,
        horizon: int = DEFAULT_N_SAMPLES,
        plant_effects: Any = (),
        render_mode: str | None = None,
    ) -> None:
        self.horizon = check("horizon", horizon, N_SAMPLES_RANGE)
        plant, regulatory = _registered_closed_loop(plant, regulatory)
        self.config = plant_from_request(
            plant,
            {
                "valve_beta": valve_beta,
                "sample_time_s": sample_time_s,
                "rk4_substeps": rk4_substeps,
                "excitation": excitation,
                "noise_scale": noise_scale,
                "regulatory": regulatory,
            },
        )
        self.closed_loop = self.config.closed_loop
        #: The fault every episode asks for unless ``reset(options=...)`` overrides it.
        self.fault_spec = fault_from_request(
            fault,
            {
                "scenario": scenario,
                "fault_time": fault_time,
                "fault_magnitude": fault_magnitude,
                "fault_profile": fault_profile,
                "ramp_samples": ramp_samples,
                "fault_channel": fault_channel,
            },
        )
        self._plant_effects = fx.resolve(plant_effects)
        # Validate now so a bad make() fails at once, not at the first reset.
        if self.fault_spec.scenario != RANDOM_SCENARIO:
            require_loops(self.fault_spec.resolve(self.horizon), self.config.regulatory)
        elif self.fault_spec.onset is not None:
            # a random draw may pick a fault: its onset must fit every episode, not only some
            check("fault_time", self.fault_spec.onset, fault_time_range(self.horizon))
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode={render_mode!r} is not supported. Allowed: "
                f"{self.metadata['render_modes']} or None"
            )
        self.render_mode = render_mode
        low, high = (CLOSED_OBS_LOW, CLOSED_OBS_HIGH) if self.closed_loop else (OBS_LOW, OBS_HIGH)
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self._p_base = self.config.params.as_array()
        self._x0 = self.config.initial_state()
        self._history: deque[np.ndarray] = deque(maxlen=WINDOW_SAMPLES)
        self._renderer = TrendRenderer()

    # ---- Gymnasium API -------------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start a new episode at the steady operating point.

        Args:
            seed: seeds ``self.np_random`` (and through it the fault draw, the operating
                program and the measurement noise); ``None`` continues the current generator,
                so consecutive resets give new episodes. The same seed gives the same episode.
            options: per-episode overrides of the ``make`` keywords (``None``: none). Keys:

                * ``fault``: a whole :class:`fcc_env.FaultSpec` replacing the ``make`` fault
                  (not together with the keys below);
                * ``scenario`` (``"nominal"``, a registered fault or ``"random"``),
                  ``fault_time`` (onset sample), ``fault_magnitude`` (relative size),
                  ``fault_profile`` (``"abrupt"`` or ``"incipient"``), ``ramp_samples``
                  (incipient ramp length), ``fault_channel`` (the measured channel of a
                  sensor fault): change single fields of the ``make`` fault;
                * ``plant_effects``: undeclared plant effects for this episode
                  (:mod:`fcc_env.effects`), replacing those given to ``make``.

                Other keys raise ``ValueError`` naming them and the allowed keys.

        Returns:
            ``(observation, info)``: the eight Table 1 measurements of sample 0 (float32, with
            noise, order ``fcc_env.MEASUREMENT_NAMES``) and the info dict of :meth:`step`
            (``t``, ``time_s``, ``scenario``, ``fault_active``, ``fault_time`` (not in a healthy
            episode: vector envs mask it), ``fault_magnitude``, ``y_clean``, ``state``, ``inputs``,
            ``action_saturated``, ``afterburn_warning``, ``termination_reason``, auxiliaries).
        """
        seed = check("seed", seed, Integer(0), None)
        spec, effects = episode_request(options, self.fault_spec, self._plant_effects)
        super().reset(seed=seed)
        setup = setup_episode(self.np_random, self.config, spec, self.horizon, effects)
        self.fault = setup.fault
        self._episode = EpisodeStream(setup, self.config, self._p_base)
        self._k = 0
        self._x = self._x0.copy()
        self._action = np.zeros(2)
        self._saturated = False
        self._terminated_reason: str | None = None
        if self.config.regulatory is not None:
            self._control = ControlSystem(
                self.config.regulatory, self.config.sample_time_s, self._episode.setpoints
            )
        self._u = self._inputs(0)
        self._y_clean = self._measure(0)
        self._obs = self._make_obs(0)
        self._history = deque([self._obs], maxlen=WINDOW_SAMPLES)
        return self._obs, self._get_info()

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if not hasattr(self, "_x"):
            raise gym.error.ResetNeeded("call reset() before step()")
        a = check_action(action)
        clipped = np.clip(a, -1.0, 1.0)
        self._saturated = bool((clipped != a).any())
        k = self._k
        if self.closed_loop:
            # The supervisory move: set points of sample k; the controllers read sample k's
            # observation and their outputs hold from sample k + 1 (fcc_env.regulatory).
            self._action = clipped * SETPOINT_ACTION_SCALE
            x_next = self._episode.advance(self._x, self._u, k)
            self._control.supervise(k, self._action, self._obs[:8])
        else:
            self._action = clipped * ACTION_SCALE
            x_next = self._episode.advance(self._x, self._inputs(k), k)
        reason = termination_reason(x_next)
        self._k = k + 1
        if reason == "numerical_failure":
            # Keep the last finite sample: observations are never NaN.
            self._terminated_reason = reason
            self._history.append(self._obs)  # the frame's sample k + 1 holds the last one
            return self._obs, 0.0, True, False, self._get_info()
        self._x = x_next
        self._u = self._inputs(self._k)
        self._y_clean = self._measure(self._k)
        self._obs = self._make_obs(self._k)
        if reason is None and not self.observation_space.contains(self._obs):
            reason = "measurement_out_of_range"
            space = self.observation_space  # the 11 closed-loop bounds when closed loop
            self._obs = np.clip(self._obs, space.low, space.high)
        self._terminated_reason = reason
        self._history.append(self._obs)
        return self._obs, 0.0, reason is not None, False, self._get_info()

    def render(self) -> np.ndarray | None:
        """The ``rgb_array`` frame (``render_mode="rgb_array"``; ``None`` without a render mode):
        :func:`trend_frame` titled with the env's id."""
        if self.render_mode != "rgb_array":
            return None
        return trend_frame(self, env_id(self, CLOSED_LOOP_ENV_ID if self.closed_loop else ENV_ID))

    def close(self) -> None:
        self._renderer.close()  # frees the render figure; a later render() builds a new one
        super().close()

    # ---- helpers -------------------------------------------------------------------------------
    def _inputs(self, k: int) -> np.ndarray:
        """Sample ``k``'s applied inputs; the inputs as commanded go to ``self._command``
        (they differ under an actuator fault: :mod:`fcc_env.actuator_faults`)."""
        if self.closed_loop:
            self._command = self._control.inputs(self._episode.program(k))
        else:
            self._command, saturated = actuator_inputs(self._episode.program(k), self._action)
            self._saturated = self._saturated or saturated
        return self._episode.schedule.actuate(k, self._command)

    def _measure(self, k: int) -> np.ndarray:
        return self._episode.measure(self._x, self._u, k)

    def _make_obs(self, k: int) -> np.ndarray:
        obs = add_noise(self._y_clean, self._episode.noise(k), self.config.noise_scale)
        if not self.closed_loop:
            return obs
        return self._control.observe(k, obs, self._command[0])

    def _get_info(self) -> dict[str, Any]:
        aux = self._episode.aux(self._x, self._u, self._k)
        return {
            "t": self._k,
            "time_s": self._k * self.config.sample_time_s,
            "scenario": self.fault.scenario,
            "fault_active": self.fault.active(self._k),
            **({} if self.fault.nominal else {"fault_time": self.fault.onset}),
            "fault_magnitude": self.fault.magnitude,
            **self._fault_parts_info(),
            "y_clean": self._clean_observation(),
            "state": self._x.copy(),
            "inputs": self._u.copy(),
            "action_saturated": self._saturated,
            "afterburn_warning": bool(afterburn_delta_C(self._x) > AFTERBURN_WARNING_C),
            "termination_reason": self._terminated_reason,
            **(self._control.info() if self.closed_loop else {}),
            **{name: float(v) for name, v in zip(AUX_NAMES, aux, strict=True)},
        }

    def _fault_parts_info(self) -> dict[str, Any]:
        """A channel fault's channel and dropout flag; a concurrent fault's labels and onsets
        (its parts in onset order), with the dropout flag when a part is a channel fault."""
        f, out = self.fault, {}
        if f.channel is not None:
            out["fault_channel"] = f.channel
        if f.parts:
            out["fault_labels"] = f.labels
            out["fault_times"] = tuple(p.onset for p in f.parts)
        if any(c.channel is not None for c in f.components):
            out["sensor_dropout"] = self._episode.dropped
        return out

    def _clean_observation(self) -> np.ndarray:
        """The noise-free observation (the channels of the observation)."""
        if not self.closed_loop:
            return self._y_clean.copy()
        return self._control.observe(self._k, self._y_clean, self._command[0])


def env_id(env: gym.Env, default: str) -> str:
    """The id ``env`` was made as (its spec's, set by ``gym.make``), else ``default``."""
    return default if env.spec is None else env.spec.id


def trend_frame(
    env: FCCEnv,
    title_id: str,
    extra: Mapping[str, tuple[str, Sequence[float]]] | None = None,
) -> np.ndarray:
    """The ``rgb_array`` frame (H, W, 3) uint8 of ``env``'s last 500 samples, titled
    ``title_id``: its observation channels in their units (:data:`fcc_env.closed_loop.
    CHANNEL_UNITS`) and the ``extra`` channels, name → (unit, one value a sample ending at the
    env's current sample), e.g. the control task's reward."""
    if not hasattr(env, "_x"):
        raise gym.error.ResetNeeded("call reset() before render()")
    data = np.array(env._history)
    channels = {c: CHANNEL_UNITS[c] for c in observation_channels(env.config)}
    if extra:
        n = len(data)
        data = np.column_stack([data, *(np.asarray(v, float)[-n:] for _, v in extra.values())])
        channels |= {name: unit for name, (unit, _) in extra.items()}
    nominal = env.fault.nominal
    return env._renderer.frame(
        data,
        env._k,
        env.config.sample_time_s,
        channels=channels,
        env_id=title_id,
        scenario=env.fault.scenario,
        fault_onset=None if nominal else env.fault.onset,
    )


class OnsetHorizonCheck(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Warns on ``reset`` when a ``TimeLimit`` below it ends the episode before the fault onset.

    The env lays a scenario out on its own ``horizon`` (an onset outside it is an error), but a
    ``max_episode_steps`` given to ``gym.make`` lives in a ``TimeLimit`` wrapper the env never
    sees: ``gym.make("FCC-v0", scenario="f1", max_episode_steps=1000)`` would truncate every
    episode at sample 1000, before the onset at 1900, and give fault-free "f1" episodes. This
    wrapper, outside the ``TimeLimit``, reads its limit from the wrapped env's spec and raises a
    ``UserWarning`` naming the onset and the limit.
    """

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        limit = None if self.env.spec is None else self.env.spec.max_episode_steps
        onset = info.get("fault_time")
        # after max_episode_steps steps the last observation is sample max_episode_steps
        if limit is not None and onset is not None and onset > limit:
            warnings.warn(
                f"the episode ends at sample {limit} (max_episode_steps={limit}) before its "
                f"{info['scenario']} fault onset at sample {onset}: it will show no fault. Pass "
                f"max_episode_steps >= {onset}, or fault_time <= {limit}",
                UserWarning,
                stacklevel=2,
            )
        return obs, info


class FCCClosedLoopEnv(FCCEnv):
    """``FCC-closedloop-v0``: :class:`FCCEnv` under its regulatory layer (its section "Closed
    loop"; the keywords are :class:`FCCEnv`'s).

    ``regulatory`` defaults to ``True`` (the default :class:`fcc_env.RegulatoryLayer`) and may be
    a layer or a mapping of its fields; ``False`` or ``None`` (no layer) contradicts the id and is
    refused by name (the open-loop plant is ``FCC-v0``). A ``plant=PlantConfig(...)`` without a
    layer gets the default one.
    """

    def __init__(self, *, regulatory: Any = True, **kwargs: Any) -> None:
        super().__init__(regulatory=closed_loop_keyword(regulatory, CLOSED_LOOP_ENV_ID), **kwargs)


def closed_loop_keyword(regulatory: Any, env_id: str) -> Any:
    """``regulatory`` as a closed-loop id (``env_id``) takes it: ``True``, a
    :class:`~fcc_env.regulatory.RegulatoryLayer` or a mapping of its fields. ``False`` and
    ``None`` (open loop) contradict the id, and other types are refused, by name."""
    if regulatory is True or isinstance(regulatory, RegulatoryLayer | Mapping):
        return regulatory
    raise invalid(
        "regulatory",
        regulatory,
        "True, a RegulatoryLayer or a mapping of its fields",
        f"{env_id} is the plant under its regulatory layer; the open-loop plant is {ENV_ID}",
    )


def _registered_closed_loop(plant: Any, regulatory: Any) -> tuple[Any, Any]:
    """FCC-closedloop-v0 registers ``regulatory=True``: a plant given to it runs closed loop."""
    if plant is not None and regulatory is True and isinstance(plant, PlantConfig):
        if plant.regulatory is None:
            plant = plant.replace(regulatory=RegulatoryLayer())
        return plant, None
    return plant, regulatory


def episode_request(
    options: Any, fault: FaultSpec, plant_effects: list[Any]
) -> tuple[FaultSpec, list[Any]]:
    """The fault and plant effects of one episode: ``reset``'s ``options`` over the ``make`` ones.

    ``fault`` replaces the ``make`` fault whole; the env's fault keywords change single fields of
    it (``None`` restores a field's default); ``plant_effects`` replace the ``make`` effects.
    """
    if options is not None and not isinstance(options, Mapping):
        raise invalid(
            "options",
            options,
            f"a dict with keys from {list(RESET_OPTION_NAMES)}, or None",
            "e.g. options={'scenario': 'f1'}",
        )
    options = {} if options is None else dict(options)
    unknown = sorted(set(options) - set(RESET_OPTION_NAMES))
    if unknown:
        raise ValueError(f"Unknown reset option(s) {unknown}. Allowed: {list(RESET_OPTION_NAMES)}")
    effects = fx.resolve(options["plant_effects"]) if "plant_effects" in options else plant_effects
    keywords = {k: options[k] for k in ENV_FAULT_KEYWORDS if k in options}
    if options.get("fault") is not None:
        return fault_from_request(options["fault"], keywords), effects
    return fault.with_env_options(keywords), effects


def check_action(action: Any) -> np.ndarray:
    """``action`` as two finite float64 numbers; errors name the value and what is allowed."""
    raw = np.asarray(action)
    if raw.dtype.kind not in "biuf":
        raise invalid(
            "action", action, "two real numbers [Δu_F, ΔR_ar] in [-1, 1]", f"dtype {raw.dtype}"
        )
    a = raw.astype(np.float64)
    if a.shape != (2,):
        raise invalid("action", action, "shape (2,): [Δu_F, ΔR_ar] in [-1, 1]", f"shape {a.shape}")
    if not np.isfinite(a).all():
        raise invalid("action", a.tolist(), "finite values in [-1, 1] (larger are clipped)")
    return a


#: The actuator limits [[u_F low, R_ar low], [u_F high, R_ar high]] (kg/s, t/h).
ACTUATOR_BOUNDS = np.array([U_F_LIMITS_REL, R_AR_LIMITS_REL]).T * NOMINAL_INPUTS[:2]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def actuate(u: np.ndarray, move: np.ndarray, limits: np.ndarray) -> bool:
    """Add the action's ``move`` (kg/s, t/h) to u_F and R_ar of ``u`` in place, held within
    ``limits`` (:data:`ACTUATOR_BOUNDS`); True when a limit was hit. The env and the vector env
    both step through it."""
    u[0] += move[0]
    u[1] += move[1]
    if limits[0, 0] <= u[0] <= limits[1, 0] and limits[0, 1] <= u[1] <= limits[1, 1]:
        return False
    for i in range(2):
        u[i] = min(max(u[i], limits[0, i]), limits[1, i])
    return True


def actuator_inputs(program: np.ndarray, move: np.ndarray) -> tuple[np.ndarray, bool]:
    """The inputs applied: the program plus the action's ``move`` (kg/s, t/h) on u_F and R_ar,
    held within the actuator limits; and whether a limit was hit."""
    u = np.array(program, dtype=np.float64)
    return u, actuate(u, np.asarray(move, dtype=np.float64), ACTUATOR_BOUNDS)


__all__ = [
    "ACTUATOR_BOUNDS",
    "CLOSED_LOOP_ENV_ID",
    "ENV_ID",
    "RESET_OPTION_NAMES",
    "FCCClosedLoopEnv",
    "FCCEnv",
    "OnsetHorizonCheck",
    "actuate",
    "actuator_inputs",
    "check_action",
    "closed_loop_keyword",
    "env_id",
    "episode_request",
    "trend_frame",
]
