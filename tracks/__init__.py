"""Carolo-Cup tracks: model, rules, generator, files, rasterisation."""

if __name__ != "tfalda_sim.tracks":  # pragma: no cover - a set-up error, checked in tests
    # The repository root on sys.path makes this folder importable as a top-level
    # `tracks` too; two names for one package would split its state and its numba cache.
    raise ImportError("tfalda-sim's tracks package is tfalda_sim.tracks; import it under that "
                      "name (the repository root is on sys.path ahead of the installed "
                      "package)")


from .fileformat import TrackFileError, load_track, save_track
from .generator import GeneratorParams, generate, seed_name
from .model import (
    Arc,
    Gap,
    Intersection,
    Lane,
    Line,
    Location,
    Obstacle,
    Pose,
    Straight,
    Track,
    printable,
)
from .named import NAMED_TRACKS, load_named
from .raster import VIRTUAL, Marking, MarkingMap, rasterize
from .rules import Violation, validate

__all__ = [
    "NAMED_TRACKS", "VIRTUAL", "Arc", "Gap", "GeneratorParams", "Intersection", "Lane", "Line",
    "Location", "Marking", "MarkingMap", "Obstacle", "Pose", "Straight", "Track",
    "TrackFileError", "Violation", "generate", "load_named", "load_track", "printable",
    "rasterize", "save_track", "seed_name", "validate",
]
