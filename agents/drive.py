"""Closed-loop drives: an agent steers TfaldaTrack-v0 for a number of laps.

``drive`` runs one car on one track from the start line and reports lap times, the
lateral error, departures from the road and LIS resets; with ``recover`` a car that left
the road is put back on its lane where it left and the drive goes on (the departure is
counted), otherwise the drive ends there. ``make_agent`` builds the PID or loads a PPO
policy (the ``rl`` extra).
"""

from __future__ import annotations

import contextlib
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from tqdm import tqdm

from tfalda_sim.camera import Camera
from tfalda_sim.dynamics import DynamicsParams
from tfalda_sim.envs import StartInCarton, TfaldaTrackEnv
from tfalda_sim.interrupts import INTERRUPTS, is_interrupt
from tfalda_sim.timing import Timing
from tfalda_sim.tracks import Track
from tfalda_sim.video import VideoWriter

from .pid import LanePid
from .policy_file import PolicyFileError, load_policy
from .record import run_recorder
from .train import distribution_checks_off


class Agent(Protocol):
    """What ``drive`` steers with: ``reset()`` at the start, ``act(obs)`` every frame."""

    def reset(self) -> None: ...

    def act(self, obs: np.ndarray) -> np.ndarray: ...


class PpoAgent:
    """A trained PPO policy (deterministic actions), from a file ``tfalda-sim train`` wrote
    (``agents/policy_file.py``: the architecture as JSON, the weights as tensors; nothing
    is unpickled). A file with pickled objects (a stable-baselines3 save) is code when
    loaded: refused (``UntrustedPolicyError``) unless ``trust``."""

    def __init__(self, path: str | Path, trust: bool = False) -> None:
        try:
            import stable_baselines3  # noqa: F401
            import torch
        except ImportError as exc:
            raise ImportError("the PPO agent needs the rl extra: pip install torch==2.13.0 "
                              "&& pip install -e '.[rl]'") from exc
        # One thread: a policy this small gains nothing from more, and evaluations run
        # one process per core.
        torch.set_num_threads(1)
        self.path = Path(path)
        self.policy = load_policy(self.path, trust=trust)

    def check_spaces(self, observation_space: Any, action_space: Any) -> None:
        """Raise ``PolicyFileError`` unless the policy takes observations and gives actions
        of the env's shapes (a policy of another env, mode or version would fail at its
        first step)."""
        given = self.policy.observation_space.shape, self.policy.action_space.shape
        if given != (observation_space.shape, action_space.shape):
            raise PolicyFileError(
                f"{self.path} is a policy for observations of shape {given[0]} and actions of "
                f"shape {given[1]}; the env gives {observation_space.shape} and takes "
                f"{action_space.shape}: give a policy `tfalda-sim train` wrote")

    def reset(self) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        with distribution_checks_off():  # the same action, sooner (train.py)
            action, _ = self.policy.predict(obs, deterministic=True)
        return np.clip(np.asarray(action, np.float32), -1.0, 1.0)


RECOVERY_STEP_M: float = 0.05
"""How far along the road a recovery moves the car on while the place where it left the
road is taken by a carton (it ran into one) [m]: it starts again just past it."""

DEFAULT_POLICY = Path(__file__).resolve().parent / "policies" / "ppo.zip"
"""The committed PPO policy (see docs/agents.md for the command that trained it)."""


def check_agent(kind: str, policy: str | Path | None = None, camera: Camera | None = None,
                *, trust_policy: bool = False) -> None:
    """Fail now, as ``drive`` would at its start, on an agent that cannot drive the env with
    ``camera``: ``make_agent``'s errors, and a policy of other shapes than the env's
    (``PolicyFileError``)."""
    agent = make_agent(kind, policy, camera, trust_policy=trust_policy)
    if isinstance(agent, PpoAgent):
        with contextlib.closing(TfaldaTrackEnv(camera=camera or "thesis")) as env:
            agent.check_spaces(env.observation_space, env.action_space)


def make_agent(kind: str, policy: str | Path | None = None, camera: Camera | None = None,
               *, trust_policy: bool = False) -> Agent:
    """``"pid"`` (back-projecting through ``camera``, default the thesis') or ``"ppo"``
    (from ``policy``, default ``DEFAULT_POLICY``). A policy file with pickled objects is
    refused unless ``trust_policy`` (``PpoAgent``)."""
    if kind == "pid":
        if policy is not None:
            raise ValueError("--policy is for the ppo agent only")
        return LanePid(camera=camera)
    if kind == "ppo":
        return PpoAgent(policy or DEFAULT_POLICY, trust=trust_policy)
    raise ValueError(f"unknown agent {kind!r}; use pid or ppo")


@dataclass
class DriveResult:
    """The figures of one drive (units in the names); the per-step figures are NaN when
    no step was driven (``summary``'s JSON output gives null)."""

    track: str
    laps_completed: int
    lap_times_s: list[float]
    departures: int
    roi_resets: int
    mean_abs_cross_track_m: float
    max_abs_cross_track_m: float
    mean_hit_rate: float
    distance_m: float
    steps: int
    wall_time_s: float
    ended: str  # "laps", "departure", "steps", "interrupted" (Ctrl-C)

    def summary(self) -> dict[str, Any]:
        """JSON-ready figures (without the per-step trace)."""
        out = asdict(self)
        out["lap_times_s"] = [round(t, 3) for t in self.lap_times_s]
        out["steps_per_s"] = self.steps / self.wall_time_s if self.wall_time_s > 0 else None
        return out


def _recover(env: TfaldaTrackEnv, track: Track, s_m: float, lateral_m: float,
             speed_m_s: float) -> tuple[Any, dict[str, Any]]:
    """Put the car back on ``track`` at arc length ``s_m`` [m], ``lateral_m`` [m], heading
    along the road, or at the first place after it, every ``RECOVERY_STEP_M``, that no
    carton takes; the reset's observation and info there."""
    for k in range(math.ceil(track.length_m / RECOVERY_STEP_M)):
        start = ((s_m + k * RECOVERY_STEP_M) % track.length_m, lateral_m, 0.0)
        with contextlib.suppress(StartInCarton):
            return env.reset(options={"track": track, "speed_m_s": speed_m_s, "start": start})
    raise StartInCarton(f"no place on {track.name or 'the track'} at lateral offset "
                        f"{lateral_m} m is free of cartons")


def drive(agent: Agent, track: Track, *, laps: int = 2, speed_m_s: float = 1.5,
          recover: bool = True, video: Path | None = None, camera_video: Path | None = None,
          max_steps: int | None = None,
          label: str = "", progress: bool = False, env: TfaldaTrackEnv | None = None,
          camera: Camera | str = "thesis", vehicle: str | DynamicsParams = "kinematic",
          timing: str | Path | Timing = "ideal", mcap: Path | None = None,
          rosbag: Path | None = None) -> DriveResult:
    """Drive ``laps`` laps of ``track`` from its start line at ``speed_m_s``. ``video``
    records the visualiser (lanes, ROIs, map), ``camera_video`` the bare grey camera
    frames (for ``tfalda-sim replay``). A Ctrl-C ends the drive early (``ended ==
    "interrupted"``) and keeps the videos of the frames driven so far. ``camera``: the
    car's camera (a profile name, file or camera), ``vehicle`` its model and ``timing``
    its pipeline's timing (the env's arguments) when no ``env`` is given. ``mcap`` /
    ``rosbag``: the drive as an MCAP file or a ROS 2 bag (``record.py``: every frame the
    detector processed, its lanes and LIS state, pose, speed, ground truth, the map)."""
    if laps < 1:
        raise ValueError(f"laps must be ≥ 1, got {laps}")
    if not track.closed:
        raise ValueError(f"{track.name or 'the track'} is not a loop: laps need a closed track")
    if video and camera_video and Path(video).resolve() == Path(camera_video).resolve():
        raise ValueError("video and camera_video name the same file; give each its own")
    env = env or TfaldaTrackEnv(track=track, speed_m_s=speed_m_s, camera=camera,
                                render_mode="rgb_array" if video else None,
                                vehicle=vehicle, timing=timing)
    rate_hz = env.camera.frame_rate_hz
    if isinstance(agent, LanePid) and agent.camera is not env.camera:
        agent.use_camera(env.camera)  # the PID back-projects through the car's camera
    if isinstance(agent, PpoAgent):
        agent.check_spaces(env.observation_space, env.action_space)
    lane = -0.5 * track.lane_width_m
    start_s = track.start_line_s_m or 0.0
    steps_budget = max_steps or int(3 * laps * track.length_m / speed_m_s * rate_hz)
    obs, info = env.reset(seed=0, options={"track": track, "start": (start_s, lane, 0.0),
                                           "speed_m_s": speed_m_s})
    agent.reset()
    total = track.length_m
    # Running sums, not per-step lists: memory stays flat however many laps are asked.
    distance, lap_times = 0.0, []
    abs_error_sum = hit_sum = max_abs_error = 0.0
    departures = resets = steps = 0
    ended = "steps"
    t0 = time.perf_counter()
    # The writers replace an existing file only when the drive ends without an error.
    with contextlib.ExitStack() as stack:
        run_rec = run_recorder(mcap, rosbag, f"drive {label or track.name or ''}".strip())
        if run_rec is not None:
            stack.enter_context(run_rec)
            run_rec.step(env, info)  # the start's frame: the detector's first
        writer = stack.enter_context(VideoWriter(video, rate_hz)) if video else None
        camera_writer = (stack.enter_context(VideoWriter(camera_video, rate_hz))
                         if camera_video else None)
        bar = stack.enter_context(tqdm(total=laps, desc=label or "laps",
                                       disable=not progress, unit="lap"))
        try:
            while steps < steps_budget:
                obs, _, terminated, _, info = env.step(agent.act(obs))
                steps += 1
                if writer is not None:
                    writer.write(env.render()[..., ::-1])
                if camera_writer is not None:
                    camera_writer.write(env.camera_frame())
                if run_rec is not None:
                    run_rec.step(env, info)
                abs_error_sum += abs(info["cross_track_m"])
                max_abs_error = max(max_abs_error, abs(info["cross_track_m"]))
                hit_sum += info["detector_hit_rate"]
                resets += info["roi_reset"]
                # Distance over all episodes of the drive (a recovery starts a new episode).
                lap_now = math.floor((distance + info["distance_m"]) / total)
                while len(lap_times) < lap_now:
                    lap_times.append(steps / rate_hz - math.fsum(lap_times))
                    bar.update(1)
                if len(lap_times) >= laps:
                    ended = "laps"
                    break
                if terminated:
                    departures += 1
                    if not recover:
                        ended = "departure"
                        break
                    obs, fresh = _recover(env, track, info["s_m"], lane, speed_m_s)
                    # Only now: a Ctrl-C in the recovery must not count the episode twice.
                    distance += info["distance_m"]
                    info = fresh  # the new episode's (0 m so far)
                    agent.reset()
        except INTERRUPTS as exc:
            if not is_interrupt(exc):
                raise
            # Ctrl-C ends the drive like its budget would: the videos so far are kept
            # (the writers are closed without an error) and the figures cover the frames
            # driven.
            ended = "interrupted"
    return DriveResult(
        track=label or track.name or "", laps_completed=len(lap_times), lap_times_s=lap_times,
        departures=departures, roi_resets=resets,
        # No step driven (a Ctrl-C before the first): no figure, not a perfect 0.
        mean_abs_cross_track_m=abs_error_sum / steps if steps else math.nan,
        max_abs_cross_track_m=max_abs_error if steps else math.nan,
        mean_hit_rate=hit_sum / steps if steps else math.nan,
        distance_m=distance + info["distance_m"], steps=steps,
        wall_time_s=time.perf_counter() - t0, ended=ended)
