"""TFALDA and Lane Inference System parameters: the thesis' numbers and the typed config.

Every number below comes from the thesis (``../shared/seeds/thesis_tfalda_lis_2008.txt``,
indexed in ``REFERENCE.md``); where its text and listings disagree, the choice is named here
and explained in ``docs/tfalda.md``. ``DetectorConfig.thesis()`` is the thesis' "mit LIS
alles aktiviert" run, ``DetectorConfig.without_lis()`` its "ohne LIS" comparison run and
``DetectorConfig.improved()`` switches on the fixes for the weaknesses of its section 5.1.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field, replace
from enum import Enum

import numpy as np

from ..camera import Camera, FisheyeCamera, load_camera
from .geometry import CameraGeometry, camera_geometry

# --------------------------------------------------------------------------- TFALDA
KP: float = 7.33
"""Weight of the start-point term of λ [1/px] (listing 3.1 / A.2, ``Kp``)."""
KD: float = 10.67
"""Weight of the direction term of λ [1/px] (listing 3.1 / A.2, ``Kd``)."""
KI: float = 1.0
"""Weight of the intensity term of λ [1/intensity unit] (listing 3.1 / A.2, ``Ki``)."""
RESAMPLE_FACTOR: float = 2.0
"""ROI down-sampling factor [source px per resampled px] (``cvResize`` in listing A.2;
the thesis never gives the value: 2 keeps a 20 mm line at ≥ 2 px in the upper ROIs and
quarters the candidate search)."""
SOBEL_SWITCH_ANGLE_DEG: float = 45.0
"""Lane angle from the vertical [deg] beyond which the Sobel manager switches to the kernel
that enhances horizontal edges (section 3.1.1)."""

# --------------------------------------------------------------------------- image / ROIs
IMAGE_WIDTH_PX: int = 752
"""Camera image width [px] (section 1.1). Section 2.3.2 writes 754 for the ROI border rule;
listing A.6 uses 752, which is the sensor's width, so 752 is used."""
IMAGE_HEIGHT_PX: int = 480
"""Camera image height [px] (section 1.1)."""
INITIAL_ROIS: tuple[tuple[int, int, int, int], ...] = (
    (195, 260, 150, 75), (365, 260, 150, 75), (80, 340, 180, 85), (429, 340, 180, 85))
"""Initial ROIs (x, y, width, height) [px], upper-left, upper-right, lower-left,
lower-right (table 2.4)."""
ROI_MARGIN_LEFT_PX: int = 50
"""New ROI starts this far left of the last lane's leftmost end [px] (listing A.6)."""
ROI_EXTRA_WIDTH_PX: int = 75
"""New ROI width = this + |D| [px] (listing A.6)."""
ROI_MIN_WIDTH_PX: int = 100
"""Narrowest ROI [px] (listing A.6)."""
ROI_MAX_WIDTH_PX: int = 275
"""Widest ROI [px] (listing A.6; its comment says 375, the code 275)."""
ROI_BORDER_PX: int = 1
"""ROIs keep this distance from the left and right image border [px] (listing A.6:
``x > 0`` and ``x < 752 − width − 1``)."""
LEFT_CURVE_RIGHT_ROI_X_PX: int = 325
"""Left curve: the ROIs of a row overlap and the right ROI starts left of this x [px]
(listing 3.5 / A.6)."""
RIGHT_CURVE_LEFT_ROI_END_PX: int = 425
"""Right curve: the ROIs of a row overlap and the left ROI ends right of this x [px]
(listing 3.5 / A.6)."""

# --------------------------------------------------------------------------- LIS
LOWPASS_RC: float = 85.0
"""Low-pass constant RC [px]: the largest apparent change of the upper lane width
(section 2.1.2, listing A.4)."""
LOWPASS_DT: float = 85.0 / 6.0
"""Low-pass interval Δt [px per frame] = 85 px over six frames (section 2.1.2, eq. 2.2;
α = Δt / (RC + Δt) ≈ 0.143). Listing A.2 passes the integer 14 (α ≈ 0.141); the text's
value is used."""
WIDTH_CHANGE_TOLERANCE_PX: float = 11.0
"""Largest accepted change of the filtered lane width between frames [px] (listing 2.2,
``threshold``; per-row ``get_tolerance()`` in listing A.4)."""
WIDTH_LIMITS_PX: tuple[tuple[float, float], ...] = ((45.0, 220.0), (200.0, 272.0),
                                                    (200.0, 272.0), (320.0, 520.0))
"""Lane width limits (min, max) [px] at the upper row's top and bottom edge and the lower
row's top and bottom edge (table 2.3). Listing A.4 has 40–240 and 180–292 for the upper
row; the table is used (it is the design, the listing a tuning left in the code)."""
WIDTH_LIMIT_ROWS_PX: tuple[float, float, float, float] = (260.0, 334.0, 340.0, 424.0)
"""Image rows [px] where table 2.3's limits apply: the upper ROI row's top and bottom row
and the lower row's (table 2.4: 260 + 75 − 1 = 334, 340 + 85 − 1 = 424)."""
VERTICAL_TOLERANCE_PX: float = 5.0
"""The lower lane's upper end is moved onto the upper lane's line when they differ by
more than this [px] (listing A.4, ``toleranz``)."""
FAULT_LIMIT: int = 10
"""Reset when the fault counter exceeds this (section 2.4, listing A.2: ``> 10``)."""


class EdgeMode(Enum):
    """What the 3×3 Sobel passes on to the candidate search."""

    RISING = "rising"
    """The thesis: ``cvSobel`` into an 8-bit image, so negative gradients clip to 0 and only
    the dark-to-bright edge of a marking counts (listing A.2)."""
    BOTH = "both"
    """|gradient|, saturated to 255: both edges of a marking count."""


class WidthCheck(Enum):
    """Which widths the width-change check compares (section 2.1.3 vs listing A.4)."""

    FILTERED = "filtered"
    """Listing A.4: the low-passed width against the last low-passed width."""
    MEASURED = "measured"
    """Listing 2.2 read literally: the measured width against the last low-passed width."""


@dataclass(frozen=True)
class TfaldaConfig:
    """The lane detector proper (pre-processing, candidate search, distance function)."""

    resample_factor: float = RESAMPLE_FACTOR
    kp: float = KP
    kd: float = KD
    ki: float = KI
    edge_mode: EdgeMode = EdgeMode.RISING
    sobel_manager: bool = True
    """Pick the Sobel kernel from the last lane's angle (section 3.1.1); off: always the
    kernel that enhances vertical edges."""
    sobel_switch_angle_deg: float = SOBEL_SWITCH_ANGLE_DEG

    def __post_init__(self) -> None:
        if not 1.0 <= self.resample_factor <= 8.0:
            raise ValueError(f"resample_factor must be in [1, 8], got {self.resample_factor}")
        for name in ("kp", "kd", "ki"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} must be ≥ 0, got {getattr(self, name)}")
        if not isinstance(self.edge_mode, EdgeMode):
            raise TypeError(f"edge_mode must be an EdgeMode, got {self.edge_mode!r}")


@dataclass(frozen=True)
class LisConfig:
    """The Lane Inference System, each stage switchable (section 2, listing A.4/A.6)."""

    lowpass: bool = True
    """Low-pass filter of the lane widths (section 2.1.2). The width-change check needs it."""
    min_max: bool = True
    """Min/max width check against ``width_limits_px`` (section 2.1.4)."""
    width_change: bool = True
    """Width-change check (section 2.1.3)."""
    vertical: bool = True
    """Vertical check (section 2.2, eq. 2.4)."""
    roi_reset: bool = True
    """Fault counter and reset (section 2.4)."""
    roi_placement: bool = True
    """ROIs follow the last lanes (listing A.6 ``adjust_total``); off: ROIs stay put."""
    curve_states: bool = True
    """Driving states that look into a curve (section 2.3.2)."""
    lane_change_state: bool = False
    """Improvement (section 5.2): a lane-change driving state that hands the lines over to
    the new lane when the car crosses the centre line."""
    gap_hold_ratio: float = 0.0
    """Improvement (section 5.1: a small ROI over a gap of the dashed centre line finds no
    marking for several frames): a lane whose I falls below this fraction of the ROI's
    last lane's I is not a marking, and the last lane is kept (0 = off, the thesis)."""
    lowpass_rc: float = LOWPASS_RC
    lowpass_dt: float = LOWPASS_DT
    width_check: WidthCheck = WidthCheck.FILTERED
    width_tolerance_px: float = WIDTH_CHANGE_TOLERANCE_PX
    width_limits_px: tuple[tuple[float, float], ...] = WIDTH_LIMITS_PX
    width_limit_rows_px: tuple[float, float, float, float] = WIDTH_LIMIT_ROWS_PX
    """Image rows [px] of ``width_limits_px``: the upper ROI row's top and bottom row and
    the lower row's (table 2.4's rows for table 2.3's limits); linear in between."""
    tolerance_scale: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    """This camera's pixels per thesis pixel on the ground at ``width_limit_rows_px``: the
    width-change and vertical tolerances (11 px, 5 px on the thesis' camera) are multiplied
    by it at each row (linear in between). 1 for the thesis camera."""
    vertical_tolerance_px: float = VERTICAL_TOLERANCE_PX
    vertical_weight: float = 1.0
    """Improvement (section 5.1): the lower lane's end moves this fraction of the way to
    the upper lane's line (1 = the thesis' overwriting correction)."""
    fault_limit: int = FAULT_LIMIT
    roi_from_current_lanes: bool = True
    """Place the next ROIs from this frame's lanes (section 2.3.2, "the last found lanes").
    Listing A.2 calls ``adjust_total`` before storing this frame's lanes, so its ROIs
    follow the lanes of the frame before (one frame late): ``False``."""

    def __post_init__(self) -> None:
        if self.width_change and not self.lowpass:
            raise ValueError("width_change needs lowpass=True (it compares filtered widths)")
        if not 0.0 < self.vertical_weight <= 1.0:
            raise ValueError(f"vertical_weight must be in (0, 1], got {self.vertical_weight}")
        if self.lowpass_rc < 0 or self.lowpass_dt <= 0:
            raise ValueError("lowpass_rc must be ≥ 0 and lowpass_dt > 0 "
                             f"(got {self.lowpass_rc}, {self.lowpass_dt})")
        rows = self.width_limit_rows_px
        if len(rows) != 4 or any(b < a for a, b in itertools.pairwise(rows)):
            raise ValueError(f"width_limit_rows_px needs four rows top to bottom, got {rows}")
        if len(self.tolerance_scale) != 4 or not all(s > 0 for s in self.tolerance_scale):
            raise ValueError(f"tolerance_scale needs four positive factors, got "
                             f"{self.tolerance_scale}")
        if len(self.width_limits_px) != 4 or any(lo >= hi for lo, hi in self.width_limits_px):
            raise ValueError("width_limits_px needs four (min, max) pairs with min < max: "
                             "upper row top, upper row bottom, lower row top, lower row bottom")
        if not 0.0 <= self.gap_hold_ratio < 1.0:
            raise ValueError(f"gap_hold_ratio must be in [0, 1), got {self.gap_hold_ratio}")
        if self.fault_limit < 0:
            raise ValueError(f"fault_limit must be ≥ 0, got {self.fault_limit}")
        if not isinstance(self.width_check, WidthCheck):
            raise TypeError(f"width_check must be a WidthCheck, got {self.width_check!r}")

    @property
    def alpha(self) -> float:
        """Low-pass coefficient α = Δt / (RC + Δt) (eq. 2.2)."""
        return self.lowpass_dt / (self.lowpass_rc + self.lowpass_dt)

    @classmethod
    def off(cls) -> LisConfig:
        """Every LIS stage off; the ROIs still follow the lanes (the thesis' "ohne LIS" run
        is the software of the Studienarbeit, whose ROIs moved with the lanes)."""
        return cls(lowpass=False, min_max=False, width_change=False, vertical=False,
                   roi_reset=False, curve_states=False)


from .geometry import Rect  # noqa: E402  (one name for an image rectangle)


@dataclass(frozen=True)
class RoiLayout:
    """Where the ROIs go, in pixels of one camera: ``rows`` ≥ 2 rows of (left, right) ROIs
    over the band the two rows of ``table_px`` cover, and the pixel sizes of ROI
    placement. The defaults are the thesis' literal numbers (table 2.4, listings A.6 and
    3.5); ``DetectorConfig.for_camera`` derives them for any camera from their
    ground-plane definitions. More rows approximate a curve with more segments (section
    5.1's second weakness); two rows reproduce ``table_px`` exactly."""

    rows: int = 2
    image_width: int = IMAGE_WIDTH_PX
    image_height: int = IMAGE_HEIGHT_PX
    table_px: tuple[Rect, Rect, Rect, Rect] = INITIAL_ROIS
    """The initial ROIs of two rows: upper-left, upper-right, lower-left, lower-right."""
    margin_left_px: int = ROI_MARGIN_LEFT_PX
    extra_width_px: int = ROI_EXTRA_WIDTH_PX
    min_width_px: int = ROI_MIN_WIDTH_PX
    max_width_px: int = ROI_MAX_WIDTH_PX
    border_px: int = ROI_BORDER_PX
    left_curve_right_roi_x_px: int = LEFT_CURVE_RIGHT_ROI_X_PX
    right_curve_left_roi_end_px: int = RIGHT_CURVE_LEFT_ROI_END_PX
    lambda_scale: tuple[float, float] = (1.0, 1.0)
    """This camera's pixels per thesis pixel on the ground at the upper and lower row of
    ``table_px`` (rows in between interpolated): λ's start-point and direction weights
    (``kp``, ``kd`` [1/px]) are divided by it, so that a metre of offset costs what it
    cost on the thesis' camera. 1 for the thesis camera."""

    def __post_init__(self) -> None:
        if not 2 <= self.rows <= 8:
            raise ValueError(f"rows must be in 2..8, got {self.rows}")
        if not 0 < self.min_width_px <= self.max_width_px:
            raise ValueError(f"ROI widths need 0 < min_width_px ≤ max_width_px, got "
                             f"{self.min_width_px}, {self.max_width_px}")
        if self.image_width < 2 * (self.max_width_px + self.border_px):
            raise ValueError(f"image width {self.image_width} px is too small for two ROIs of "
                             f"the widest {self.max_width_px} px")
        (_, uly, _, ulh), (_, ury, _, urh), (_, lly, _, llh), (_, lry, _, lrh) = self.table_px
        if uly != ury or ulh != urh or lly != lry or llh != lrh or uly + ulh > lly:
            raise ValueError("table_px: the two ROIs of a row share their rows, and the upper "
                             f"row lies above the lower one; got {self.table_px}")
        for x, y, w, h in self.table_px:
            if x < 0 or y < 0 or w < 1 or h < 2 or x + w > self.image_width \
                    or y + h > self.image_height:
                raise ValueError(f"table_px ROI {(x, y, w, h)} does not lie inside the "
                                 f"{self.image_width}×{self.image_height} image")
        if lly + llh - uly < 2 * self.rows:
            raise ValueError(f"the ROI band (rows {uly}–{lly + llh}) is too low for "
                             f"{self.rows} rows")
        if not all(s > 0 for s in self.lambda_scale):
            raise ValueError(f"lambda_scale must be positive, got {self.lambda_scale}")


@dataclass(frozen=True)
class DetectorConfig:
    """Everything the TFALDA + LIS detector needs; see the presets."""

    tfalda: TfaldaConfig = field(default_factory=TfaldaConfig)
    lis: LisConfig = field(default_factory=LisConfig)
    layout: RoiLayout = field(default_factory=RoiLayout)

    @classmethod
    def thesis(cls) -> DetectorConfig:
        """The thesis' system with every LIS stage on ("mit LIS alles aktiviert")."""
        return cls()

    @classmethod
    def without_lis(cls) -> DetectorConfig:
        """The thesis' comparison run without the LIS ("ohne LIS Stand Studienarbeit")."""
        return cls(lis=LisConfig.off())

    @classmethod
    def improved(cls, rows: int = 2) -> DetectorConfig:
        """The thesis' system plus fixes for the weaknesses its section 5 names: the gap
        hold (ratio 0.7), a weighted vertical correction (factor 0.5), the lane-change
        state, and ``rows`` ROI rows (more rows follow curves with more segments but each
        row gets lower, which section 5.1 warns costs TFALDA its stability; measured in
        docs/tfalda.md)."""
        return cls(lis=replace(LisConfig(), gap_hold_ratio=0.7, vertical_weight=0.5,
                               lane_change_state=True),
                   layout=RoiLayout(rows=rows))

    @classmethod
    def for_camera(cls, camera: Camera | str, base: DetectorConfig | None = None
                   ) -> DetectorConfig:
        """``base`` (default: the thesis preset) with every pixel number derived for
        ``camera`` (a camera, a profile name or a file) from its ground-plane definition
        (``perception.geometry``): the ROIs, the width limits and their rows, the ROI
        sizes, the curve thresholds, the LIS's tolerances and λ's weights. On the thesis
        camera it agrees with ``thesis()`` within ``geometry.THESIS_AGREEMENT_PX``.
        Raises ``CameraGeometryError`` naming what a camera cannot see."""
        base = base or cls.thesis()
        geo = geometry_of(load_camera(camera))
        layout = replace(
            base.layout, image_width=geo.width, image_height=geo.height, table_px=geo.table_px,
            margin_left_px=geo.margin_left_px, extra_width_px=geo.extra_width_px,
            min_width_px=geo.min_width_px, max_width_px=geo.max_width_px,
            left_curve_right_roi_x_px=geo.left_curve_right_roi_x_px,
            right_curve_left_roi_end_px=geo.right_curve_left_roi_end_px,
            lambda_scale=geo.lambda_scale)
        lis = replace(base.lis, width_limits_px=geo.width_limits_px,
                      width_limit_rows_px=geo.width_limit_rows_px,
                      tolerance_scale=geo.tolerance_scale)
        return cls(tfalda=base.tfalda, lis=lis, layout=layout)


    def on_camera(self, camera: Camera | str) -> DetectorConfig:
        """This configuration on ``camera``: unchanged on the thesis camera or when its
        layout is not the thesis' literal one (already derived, or the user's own); else
        its stages with the geometry derived for ``camera`` (``for_camera``)."""
        cam = load_camera(camera)
        if is_thesis_camera(cam) or self.layout.table_px != INITIAL_ROIS:
            return self
        return DetectorConfig.for_camera(cam, self)


def geometry_of(camera: Camera) -> CameraGeometry:
    """``camera``'s derived layout (computed once per camera object and cached)."""
    cached = _GEOMETRY_CACHE.get(id(camera))
    if cached is not None and cached[0] is camera:
        return cached[1]
    geo = camera_geometry(camera, ROI_BORDER_PX, WIDTH_CHANGE_TOLERANCE_PX)
    if len(_GEOMETRY_CACHE) >= 32:
        _GEOMETRY_CACHE.pop(next(iter(_GEOMETRY_CACHE)))
    _GEOMETRY_CACHE[id(camera)] = (camera, geo)
    return geo


_GEOMETRY_CACHE: dict[int, tuple[Camera, CameraGeometry]] = {}


def is_thesis_camera(camera: Camera) -> bool:
    """Whether ``camera`` is the thesis camera (``FisheyeCamera.default()``: same lens,
    size, mount and bonnet), whose pixel numbers are the thesis' own."""
    ref = _THESIS_CAMERA
    b, rb = camera.bonnet, ref.bonnet
    return (type(camera) is type(ref) and camera.width == ref.width
            and camera.height == ref.height and np.array_equal(camera.K, ref.K)
            and np.array_equal(camera.D, ref.D) and camera.mount == ref.mount
            and b.enabled == rb.enabled and b.polygon_px is None
            and (b.top_row, b.edge_drop_px) == (rb.top_row, rb.edge_drop_px))


_THESIS_CAMERA = FisheyeCamera.default()
