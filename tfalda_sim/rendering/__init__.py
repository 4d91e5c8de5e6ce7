"""Rendering the camera image: scene preparation, the renderer, effects, ground truth."""

from .effects import DomainRandomization, Effects
from .renderer import Bonnet, PixelGeometry, Renderer, pixel_geometry
from .scene import Hall, Scene, build_scene
from .truth import FrameTruth, frame_truth

__all__ = ["Bonnet", "DomainRandomization", "Effects", "FrameTruth", "Hall", "PixelGeometry",
           "Renderer", "Scene", "build_scene", "frame_truth", "pixel_geometry"]
