"""Rendering the camera image: scene preparation, the renderer, effects, ground truth."""

from .effects import DomainRandomization, Effects
from .pixels import Bonnet, PixelGeometry, pixel_geometry
from .renderer import Renderer
from .scene import Hall, Scene, build_scene
from .truth import FrameTruth, frame_truth

__all__ = ["Bonnet", "DomainRandomization", "Effects", "FrameTruth", "Hall", "PixelGeometry",
           "Renderer", "Scene", "build_scene", "frame_truth", "pixel_geometry"]
