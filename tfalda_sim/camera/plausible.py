"""What a fitted mount may be: the mounts a camera on a 1:10 model car can have, narrower
than what a profile may hold (``limits``). A fit outside them found lines that are not
the road's markings — cables, the car's body, a wall, the horizon — and is refused, the
message naming the parameter, its value, the range and why; so is a clip whose frames
disagree about the mount by more than a camera on a driving car moves
(``CLIP_TOLERANCES``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

MIN_FIT_HEIGHT_M: float = 0.03
"""Lowest fitted camera above the road [m]: a 1:10 car's chassis is 1–3 cm above the
ground, a lens below it would scrape the road (a fit of 6.6 mm put the "lines" on cables
just in front of the lens)."""

MAX_FIT_HEIGHT_M: float = 1.0
"""Highest fitted camera above the road [m]: five times a 1:10 car's roof (0.2 m); a
mast higher than that would topple the car (a fit of 1.40 m put the "lines" on cables
whose spacing shrank the lane)."""

MIN_FIT_PITCH_RAD: float = math.radians(-5.0)
"""Least fitted pitch [rad]: a camera looking down at the road ahead (pitch > 0), or
level within a mount's tolerance; a camera looking up has the horizon below the image
middle and sees the road only at the bottom edge (a fit pitched 33° up was lines on
cables)."""

MAX_FIT_PITCH_RAD: float = math.radians(60.0)
"""Largest fitted pitch [rad]: steeper, the camera sees the road under the car and no
lane ahead for a lane keeper (the thesis camera: 5.5°, the reference car: 30.6°)."""

MAX_FIT_ROLL_RAD: float = math.radians(15.0)
"""Largest fitted |roll| [rad]: cameras are mounted level within a few degrees; beyond
15° the horizon slants visibly across the frame, and the three lines fitted that way are
not the lane's."""

MAX_FIT_YAW_RAD: float = math.radians(25.0)
"""Largest fitted |yaw| [rad] of a frame (the mount's yaw plus the car's heading on the
road at that moment): a camera looking ahead along the lane; a car turned further off
the road is not on a straight lane's markings."""

MIN_FIT_HORIZON_MARGIN_RAD: float = math.radians(0.5)
"""A marking's pixels must lie at least this far below the fitted horizon [rad]: the
road is below it; a great circle's part above it is a wall or the hall."""


@dataclass(frozen=True)
class ClipTolerance:
    """How much a mount's parameter may vary between the frames of one clip: the robust
    spread (1.4826 × the median absolute deviation, a normal distribution's σ) of the
    frames that agree, ``absolute`` in the parameter's unit or ``relative`` × its
    median, whichever is larger; ``unit`` and ``scale`` print it (degrees, millimetres)."""

    absolute: float
    relative: float
    unit: str
    scale: float
    why: str


CLIP_TOLERANCES: dict[str, ClipTolerance] = {
    "pitch": ClipTolerance(math.radians(1.0), 0.0, "°", math.degrees(1.0),
                           "a car's pitch on its springs changes by a degree or less when it "
                           "brakes or accelerates"),
    "roll": ClipTolerance(math.radians(1.0), 0.0, "°", math.degrees(1.0),
                          "a car's body rolls by a degree or less on a straight"),
    "height": ClipTolerance(0.005, 0.05, " mm", 1000.0,
                            "the springs move a camera by millimetres, and a pixel's error "
                            "in a line's angle costs a few per cent of the height"),
    "focal": ClipTolerance(0.0, 0.03, " px", 1.0,
                           "one lens: the focal lengths fitted per frame agree within a few "
                           "per cent"),
}
"""The spread of the agreeing frames a clip fit accepts, per parameter. A wider spread
means the frames are not of one camera on one car, or some "lines" are not the road's."""

CLIP_NOISE_FLOORS: dict[str, float] = {"pitch": math.radians(0.2),
                                       "roll": math.radians(0.3), "height": 0.002,
                                       "focal": 0.0}
"""The least spread a parameter is taken to have across a clip's frames (pitch, roll
[rad], height [m], focal length [px, relative to … none]): a frame's fit is good to a
fraction of a pixel, so frames agreeing better than this are no evidence for a narrower
band."""

CLIP_OUTLIER_SPREADS: float = 3.0
"""A frame whose parameter lies more than this many spreads (the frames' own robust σ,
at least ``CLIP_NOISE_FLOORS``) from the clip's median disagrees and is left out [1]: a
curve's entry fitted as a straight, a frame of other lines."""

MIN_CLIP_AGREEMENT: float = 0.5
"""At least this share of the fitted frames must agree on the mount [1]; fewer, and the
clip's "lines" are not one camera's view of one road."""


class ImplausibleMount(ValueError):
    """A fitted mount no camera on a 1:10 car has; ``parameter`` names what is outside."""

    def __init__(self, parameter: str, message: str) -> None:
        super().__init__(message)
        self.parameter = parameter


def length_text(value_m: float) -> str:
    """A height for a message: millimetres below 0.1 m, metres above [m]."""
    return f"{value_m * 1000:.1f} mm" if abs(value_m) < 0.1 else f"{value_m:.2f} m"


NOT_MARKINGS = "the lines found are not the road's markings"


def check_fitted_mount(height_m: float, pitch_rad: float, roll_rad: float,
                       yaw_rad: float) -> None:
    """Refuse (``ImplausibleMount``) a fitted height [m], pitch, roll or yaw [rad] outside
    what a camera on a 1:10 car can have, naming the parameter, the range and why."""
    if not math.isfinite(height_m) or not MIN_FIT_HEIGHT_M <= height_m <= MAX_FIT_HEIGHT_M:
        raise ImplausibleMount(
            "height", f"height {length_text(height_m)} is outside {MIN_FIT_HEIGHT_M:g}–"
                      f"{MAX_FIT_HEIGHT_M:g} m (a camera on a 1:10 car): {NOT_MARKINGS}")
    lo, hi = math.degrees(MIN_FIT_PITCH_RAD), math.degrees(MAX_FIT_PITCH_RAD)
    pitch = math.degrees(pitch_rad)
    if not MIN_FIT_PITCH_RAD <= pitch_rad <= MAX_FIT_PITCH_RAD:
        looks = (f"looking {-pitch:.0f}° up: the horizon would lie below the image middle"
                 if pitch < 0 else "looking steeply down: no road ahead in view")
        raise ImplausibleMount(
            "pitch", f"pitch {pitch:.1f}° ({looks}) is outside {lo:g}–{hi:g}° (a camera "
                     f"looking down at the road ahead): {NOT_MARKINGS}")
    if abs(roll_rad) > MAX_FIT_ROLL_RAD:
        raise ImplausibleMount(
            "roll", f"roll {math.degrees(roll_rad):.1f}° is outside ±"
                    f"{math.degrees(MAX_FIT_ROLL_RAD):g}° (a camera mounted level within a "
                    f"few degrees): {NOT_MARKINGS}")
    if abs(yaw_rad) > MAX_FIT_YAW_RAD:
        raise ImplausibleMount(
            "yaw", f"yaw {math.degrees(yaw_rad):.1f}° is outside ±"
                   f"{math.degrees(MAX_FIT_YAW_RAD):g}° (a camera looking ahead along the "
                   f"lane): {NOT_MARKINGS}, or the car is not driving along them")
