"""Photometric appearance of a rendered frame: named parameters and their randomisation.

Grey levels are in digital numbers (DN, 0–255) of the 8-bit sensor before gain. Defaults
are read off ``shared/reference/*.png``: dark mat (≈ 35 DN), lines ≈ 210 DN, brighter
walls, a dark bonnet with faint line reflections, vignetting toward the corners, floor
sheen near the horizon. Shadows, glare spots, wear and motion blur are off by default and
drawn by ``DomainRandomization``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from tfalda_sim.timing import TimingRandomization


@dataclass(frozen=True)
class Effects:
    """Every photometric parameter of the renderer (units in brackets)."""

    mat_dn: float = 35.0
    """Grey level of the black mat [DN]."""
    line_dn: float = 210.0
    """Grey level of fresh white paint [DN]."""
    wall_dn: float = 100.0
    """Mean grey level of the walls above the horizon [DN]."""
    gain: float = 1.0
    """Exposure × analogue gain [-]: 1 nominal, < 1 under-, > 1 overexposed."""
    vignetting: float = 0.35
    """Brightness lost in the image corners [-] (cos⁴-like falloff; 0 = none)."""
    noise_dn: float = 2.0
    """Standard deviation of the sensor's Gaussian read noise [DN]."""
    glare: float = 20.0
    """Floor sheen at grazing view angles, strongest near the horizon [DN]."""
    glare_spots: int = 0
    """Number of bright reflections of ceiling lights lying on the mat [-]."""
    glare_spot_dn: float = 60.0
    """Peak brightness added by one glare spot [DN]."""
    shadows: int = 0
    """Number of soft shadows lying on the mat [-]."""
    shadow_depth: float = 0.4
    """Fraction of light a shadow takes away at its centre [-]."""
    motion_blur_s: float = 0.0
    """Exposure time for motion blur [s] (0 = sharp); blur length = speed × time."""
    wear: float = 0.0
    """Worn markings: fraction of paint missing in the most worn patches [-]."""
    bonnet_dn: float = 18.0
    """Grey level of the car's bonnet [DN]."""
    bonnet_reflectivity: float = 0.12
    """Share of the scene mirrored on the bonnet (faint line reflections) [-]."""

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
                raise ValueError(f"Effects.{f.name} must be a number, got {v!r}")
            if not np.isfinite(v) or v < 0:
                raise ValueError(f"Effects.{f.name} must be finite and ≥ 0, got {v!r}")
        for name in ("glare_spots", "shadows"):  # counts: 2.5 spots is no number of spots
            v = getattr(self, name)
            if not float(v).is_integer():
                raise ValueError(f"Effects.{name} counts spots, so it must be a whole number, "
                                 f"got {v!r}")
            object.__setattr__(self, name, int(v))
        for name in ("vignetting", "shadow_depth", "wear", "bonnet_reflectivity"):
            if getattr(self, name) > 1:
                raise ValueError(f"Effects.{name} must be in [0, 1], got {getattr(self, name)}")

    @classmethod
    def off(cls) -> Effects:
        """No photometric effects: clean paint on a uniform mat (for tests and truth)."""
        return cls(vignetting=0.0, noise_dn=0.0, glare=0.0, glare_spots=0, shadows=0,
                   motion_blur_s=0.0, wear=0.0, bonnet_reflectivity=0.0)


@dataclass(frozen=True)
class DomainRandomization:
    """Ranges ``(low, high)`` from which ``sample`` draws an ``Effects``; every range is
    declared here. Integer parameters are drawn inclusive of both ends."""

    mat_dn: tuple[float, float] = (20.0, 55.0)
    line_dn: tuple[float, float] = (150.0, 240.0)
    wall_dn: tuple[float, float] = (70.0, 180.0)
    gain: tuple[float, float] = (0.6, 1.5)
    vignetting: tuple[float, float] = (0.1, 0.55)
    noise_dn: tuple[float, float] = (0.5, 6.0)
    glare: tuple[float, float] = (0.0, 60.0)
    glare_spots: tuple[int, int] = (0, 6)
    glare_spot_dn: tuple[float, float] = (20.0, 140.0)
    shadows: tuple[int, int] = (0, 4)
    shadow_depth: tuple[float, float] = (0.2, 0.7)
    motion_blur_s: tuple[float, float] = (0.0, 0.006)
    wear: tuple[float, float] = (0.0, 0.6)
    bonnet_dn: tuple[float, float] = (8.0, 40.0)
    bonnet_reflectivity: tuple[float, float] = (0.0, 0.25)
    timing: TimingRandomization | None = None
    """The pipeline's timing, drawn per episode by the env (from a generator seeded from
    ``np_random``; ``sample`` draws only the photometric effects): None keeps the env's
    ``timing``."""

    def sample(self, rng: np.random.Generator) -> Effects:
        """Draw one ``Effects`` from the ranges with ``rng`` (the env's ``np_random``)."""
        values: dict[str, float | int] = {}
        for f in fields(self):
            if f.name == "timing":
                continue
            lo, hi = getattr(self, f.name)
            if isinstance(lo, int) and isinstance(hi, int):
                values[f.name] = int(rng.integers(lo, hi + 1))
            else:
                values[f.name] = float(rng.uniform(lo, hi))
        return Effects(**values)
