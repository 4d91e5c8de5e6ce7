"""Perception: TFALDA with the Lane Inference System (thesis 2008) and the Hough baseline."""

from .detector import LaneObservation, TfaldaDetector, check_frame
from .hough import HoughConfig, HoughDetector, HoughResult
from .lis import LaneInferenceSystem, LisResult
from .params import DetectorConfig, EdgeMode, LisConfig, RoiLayout, TfaldaConfig, WidthCheck
from .rois import Roi, StateKind
from .segment import LaneSegment

__all__ = [
           "DetectorConfig",
           "EdgeMode",
           "HoughConfig",
           "HoughDetector",
           "HoughResult",
           "LaneInferenceSystem",
           "LaneObservation",
           "LaneSegment",
           "LisConfig",
           "LisResult",
           "Roi",
           "RoiLayout",
           "StateKind",
           "TfaldaConfig",
           "TfaldaDetector",
           "WidthCheck",
           "check_frame",
]
