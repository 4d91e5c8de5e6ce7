"""Replay of a recorded drive in an endless loop through a lane detector (the second
seed's set-up): ``loop.replay`` and its command ``tfalda-sim replay``."""

from .loop import DEFAULT_FPS, Detector, HoughPreset, replay

__all__ = ["DEFAULT_FPS", "Detector", "HoughPreset", "replay"]
