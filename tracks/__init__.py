"""Carolo-Cup tracks: model, rules, generator, files, rasterisation."""

from .fileformat import TrackFileError, load_track, save_track
from .generator import GeneratorParams, generate
from .model import Arc, Gap, Intersection, Lane, Line, Location, Obstacle, Pose, Straight, Track
from .named import NAMED_TRACKS, load_named
from .raster import VIRTUAL, Marking, MarkingMap, rasterize
from .rules import Violation, validate

__all__ = [
    "NAMED_TRACKS", "VIRTUAL", "Arc", "Gap", "GeneratorParams", "Intersection", "Lane", "Line",
    "Location", "Marking", "MarkingMap", "Obstacle", "Pose", "Straight", "Track",
    "TrackFileError", "Violation", "generate", "load_named", "load_track", "rasterize",
    "save_track", "validate",
]
