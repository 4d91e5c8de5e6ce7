"""A PID lane keeper that steers from the TFALDA + LIS lanes alone (no ground truth).

Each step it decodes the four lanes of the ``"lanes"`` observation
(``tfalda_sim.envs.observation``),
takes their ends back to the ground through the car's own camera model (a calibration,
not track knowledge) and, per ROI row, forms the lane centre between the left and right
line and the lane direction. A lane model — the lane centre ``y(x) = y0 + ψ0·x + κ·x²/2``
ahead of the rear axle — is tracked over the frames with the car's odometry (its speed
and wheel angle, also in the observation); rows that disagree with the prediction, and
the frames of an LIS reset, are not believed. The car steers along the model:

    δ = atan(L κ)  +  K_p · (y0 + ψ0·x_c)  +  K_d · ψ0  +  K_i · ∫ (y0 + ψ0·x_c) dt

- feed-forward: the model's curvature ``κ`` (the upper row sees the curve coming) is the
  whole steering a car on the lane centre needs;
- P: the lateral offset, ``x_c`` (0.5 m) ahead of the rear axle, of the lane centre's
  *tangent* at the axle (left positive) — not of the lane itself, which in a curve of
  curvature κ lies κ·x_c²/2 aside even for a car on the centre line: controlling that
  point holds the car up to κ·(x_c²/2 + K_d·x_c/K_p) off centre (14 cm in a 2 m curve;
  the integrator took some back: 11–12 cm measured);
- D: the lane direction at the axle (the offset's rate is ``v sin ψ0``: its measured
  derivative, no differencing of noisy offsets);
- I: removes the steady offset the servo's lag leaves when a curve begins.

With the tangent, the equilibrium in a curve of constant curvature is ``y0 = ψ0 = 0``:
the car on the lane centre, steering ``atan(L κ)``.

``δ`` is sent as ``δ / max_steer`` clipped to [−1, 1]. docs/agents.md has the results.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tfalda_sim.camera import Camera, FisheyeCamera
from tfalda_sim.envs.observation import LaneVector, read_lane_vector
from tfalda_sim.tracks.dimensions import LANE_WIDTH_M
from tfalda_sim.tracks.rules import min_centre_radius_m
from tfalda_sim.vehicle import CarParams

LANE_WIDTH_TOLERANCE_M: float = 0.12
"""A row's two lines count as one lane when their distance is within this of the lane
width [m]."""


CONTROL_DISTANCE_M: float = 0.5
"""Distance ahead of the rear axle where the offset of the lane centre's tangent is
controlled [m] (about the lower ROI row)."""

_SIGMA_Y_M = 0.03  # lane-centre measurement noise [m]
_SIGMA_PSI_RAD = 0.1  # lane-direction measurement noise [rad]
# Per-frame uncertainty of the odometry-moved model: y0 [m], ψ0 [rad], κ [1/m]. The lane
# at the axle barely changes from frame to frame (the odometry moves the model), its
# curvature jumps where a curve begins: tight on y0 and ψ0, so lanes that slide onto the
# wrong line over a few frames (the LIS losing a line) do not drag the model along.
_PRIOR_SIGMA = np.array([0.005, 0.015, 0.1])
_MODEL_SAMPLES_M = np.linspace(0.0, 1.4, 8)
# No lane bends tighter than the rules allow (its right lane's centre: 0.2 m further out
# in a left curve, in); 10 % spare for measurement noise.
_MAX_KAPPA = 1.1 / (min_centre_radius_m() - 0.5 * LANE_WIDTH_M)


def _basis(x: np.ndarray) -> np.ndarray:
    """Rows ``[1, x, x² / 2]``: the lane model's basis at distances ``x`` [m]."""
    x = np.asarray(x, np.float64)
    return np.column_stack([np.ones_like(x), x, 0.5 * x * x])


@dataclass(frozen=True)
class PidGains:
    """Gains of the lane keeper (units in brackets); tuned on generated tracks at
    1.5 m/s (docs/agents.md)."""

    k_p: float = 2.0
    """Steering per metre of lateral offset of the lane centre's tangent at
    ``control_distance_m`` [rad/m]."""
    k_d: float = 0.6
    """Steering per radian of lane direction at the rear axle (the offset's derivative /
    speed) [rad/rad]."""
    k_i: float = 0.3
    """Steering per metre-second of integrated offset [rad/(m·s)]."""
    i_limit: float = 0.15
    """Largest integral contribution [rad] (anti-windup)."""
    feed_forward: float = 1.0
    """Share of the curvature feed-forward from the upper row [-]."""
    gate_m: float = 0.10
    """A row's lane centre that lies farther than this from where the last one, moved by
    the car's odometry, predicts it is rejected for the prediction [m]."""
    control_distance_m: float = CONTROL_DISTANCE_M
    """Where ahead of the rear axle the offset of the lane's tangent is controlled [m]."""
    coast_on_reset: bool = True
    """Ignore the lanes of an LIS reset frame and the first frame after it."""
    max_coast_frames: int = 25
    """After this many rejected frames in a row the measurement is believed again [-]."""


class LanePid:
    """``act(obs)`` → action, for ``TfaldaTrack-v0``'s "lanes" observations (or the
    ``"lanes"`` entry of a dict observation); ``reset()`` at every episode start."""

    def __init__(self, gains: PidGains | None = None, *, camera: Camera | None = None,
                 car: CarParams | None = None, frame_rate_hz: float | None = None) -> None:
        self.gains = gains or PidGains()
        self.camera = camera or FisheyeCamera.default()
        self.car = car or CarParams()
        self.dt_s = 1.0 / (frame_rate_hz or self.camera.frame_rate_hz)  # the camera's by default
        self.reset()

    def use_camera(self, camera: Camera) -> None:
        """Back-project through ``camera`` (and step at its frame rate) from now on: the
        drive hands the env's camera to the PID."""
        self.camera = camera
        self.dt_s = 1.0 / camera.frame_rate_hz

    def reset(self) -> None:
        self._integral = 0.0
        self._last_centres: np.ndarray | None = None
        self._model: np.ndarray | None = None
        self._coast = 0

    def read(self, obs: np.ndarray | dict[str, np.ndarray]) -> LaneVector:
        """The observation decoded (``tfalda_sim.envs.observation.read_lane_vector``)."""
        return read_lane_vector(obs, image_width=self.camera.width,
                                image_height=self.camera.height)

    def lane_geometry(self, obs: np.ndarray | LaneVector) -> tuple[np.ndarray, np.ndarray]:
        """Per ROI row (top first): the lane centre ``(R, 2)`` and unit direction
        ``(R, 2)`` in the car frame [m], from the observation vector; NaN for a row whose
        two lanes are both missing."""
        decoded = obs if isinstance(obs, LaneVector) else self.read(obs)
        rows = decoded.rows
        n = 2 * rows
        # A missing lane is NaN: it must not go through the camera model as a pixel.
        lanes = decoded.lanes
        ends = self.camera.pixels_to_ground(lanes.reshape(2 * n, 2)).reshape(n, 2, 2)
        top, bottom = ends[:, 0], ends[:, 1]
        mid = 0.5 * (top + bottom)
        direction = top - bottom
        centres = np.empty((rows, 2))
        dirs = np.empty((rows, 2))
        for r in range(rows):
            left, right = 2 * r, 2 * r + 1
            seen = [i for i in (left, right) if np.all(np.isfinite(direction[i]))]
            if not seen:
                centres[r] = dirs[r] = np.nan
                continue
            d = sum(direction[i] for i in seen)
            d = d / max(np.hypot(*d), 1e-9)
            normal = np.array([-d[1], d[0]])  # to the left
            width = float(np.dot(mid[left] - mid[right], normal))
            centre = 0.5 * (mid[left] + mid[right])
            if not (np.all(np.isfinite(centre)) and abs(width - LANE_WIDTH_M)
                    <= LANE_WIDTH_TOLERANCE_M):
                # One line lost: the centre half a lane from the line that agrees with
                # the last good centre (or the right line, the side line, at the start).
                options = [mid[left] - 0.5 * LANE_WIDTH_M * normal,
                           mid[right] + 0.5 * LANE_WIDTH_M * normal]
                options = [o for o in options if np.all(np.isfinite(o))]
                last = None if self._last_centres is None else self._last_centres[r]
                ref = last if last is not None and np.all(np.isfinite(last)) else options[-1]
                centre = min(options, key=lambda o: float(np.hypot(*(o - ref))))
            centres[r], dirs[r] = centre, d
        return centres, dirs

    def _predict(self, odometry: tuple[float, float]) -> np.ndarray:
        """The lane model moved into this frame's car frame by one frame of the car's own
        motion (speed, wheel angle): sampled, moved, fitted again."""
        speed, steer = odometry
        ds = speed * self.dt_s
        turn = ds * math.tan(steer) / self.car.wheelbase_m
        x = _MODEL_SAMPLES_M
        pts = np.column_stack([x, _basis(x) @ self._model])
        c, s = math.cos(turn), math.sin(turn)
        shift = np.array([ds * math.cos(0.5 * turn), ds * math.sin(0.5 * turn)])
        moved = (pts - shift) @ np.array([[c, s], [-s, c]]).T
        return np.linalg.lstsq(_basis(moved[:, 0]), moved[:, 1], rcond=None)[0]

    def _track(self, centres: np.ndarray, dirs: np.ndarray, odometry: tuple[float, float]
               ) -> np.ndarray:
        """Update the lane model ``(y0 [m], ψ0 [rad], κ [1/m])`` — the lane centre
        ``y(x) = y0 + ψ0 x + κ x² / 2`` in the car frame — with the rows that agree with
        its prediction (a fixed-gain Kalman filter); rows that do not are left out, and
        after ``max_coast_frames`` without any agreeing row the model starts afresh."""
        g = self.gains
        ok = np.all(np.isfinite(centres), axis=1) & np.all(np.isfinite(dirs), axis=1)
        psi = np.arctan2(dirs[:, 1], dirs[:, 0])
        if self._model is None:
            prior = predicted = None
        else:
            prior = predicted = self._predict(odometry)
            y_pred = _basis(centres[:, 0]) @ prior
            ok &= np.abs(centres[:, 1] - y_pred) <= g.gate_m
            if not ok.any():
                self._coast += 1
                if self._coast <= g.max_coast_frames:
                    self._model = prior
                    return prior
                prior = None  # lost: believe the measurement again
                ok = np.all(np.isfinite(centres), axis=1)
        self._coast = 0
        rows, rhs, weights = [], [], []
        for r in np.flatnonzero(ok):
            x = float(centres[r, 0])
            rows += [[1.0, x, 0.5 * x * x], [0.0, 1.0, x]]
            rhs += [float(centres[r, 1]), float(psi[r])]
            weights += [1.0 / _SIGMA_Y_M**2, 1.0 / _SIGMA_PSI_RAD**2]
        if prior is not None:
            rows += np.eye(3).tolist()
            rhs += prior.tolist()
            weights += (1.0 / _PRIOR_SIGMA**2).tolist()
        if not rows:  # nothing seen (a reset frame) and nothing to coast on any more
            self._model = predicted if predicted is not None else self._model
            return self._model if self._model is not None else np.zeros(3)
        a = np.array(rows) * np.sqrt(weights)[:, None]
        b = np.array(rhs) * np.sqrt(weights)
        model = np.linalg.lstsq(a, b, rcond=None)[0]
        model[2] = np.clip(model[2], -_MAX_KAPPA, _MAX_KAPPA)
        self._model = model
        return model

    def act(self, obs: np.ndarray) -> np.ndarray:
        """The steering action in [−1, 1] for one observation."""
        g = self.gains
        decoded = self.read(obs)
        odometry = (decoded.speed_ratio * self.car.max_speed_m_s,
                    decoded.steer_ratio * self.car.max_steer_rad)
        centres, dirs = self.lane_geometry(decoded)
        if self.gains.coast_on_reset and (decoded.roi_reset or decoded.first_frame) and (
                self._model is not None):
            # An LIS reset and the first frame after it pick the strongest edges, often
            # the wrong lines in a curve: coast on the model instead.
            centres = np.full_like(centres, np.nan)
        y0, psi0, kappa = self._track(centres, dirs, odometry)
        self._last_centres = centres
        x = self.gains.control_distance_m
        offset = y0 + psi0 * x
        heading = psi0
        self._integral += offset * self.dt_s
        i_term = float(np.clip(g.k_i * self._integral, -g.i_limit, g.i_limit))
        self._integral = i_term / g.k_i if g.k_i > 0 else 0.0
        delta = (g.feed_forward * math.atan(self.car.wheelbase_m * kappa) + g.k_p * offset
                 + g.k_d * heading + i_term)
        return np.array([np.clip(delta / self.car.max_steer_rad, -1.0, 1.0)], np.float32)

    __call__ = act
