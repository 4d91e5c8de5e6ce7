"""The Hough baseline: the HSHL lane detector of DSB18 (Matlab) on numpy, OpenCV and numba.

The seed is ``../shared/seeds/hshl_dsb18_spurerkennung.txt`` (S. Topp, HSHL 2018; summarised
in ``REFERENCE.md``, "The Hough baseline"). Its loop runs once per frame and keeps nothing
from one frame to the next. ``HoughDetector.detect`` does the same steps with the same
numbers (the module constants below name each one and give its line in the seed):

1. **Crop**, ``imcrop(frame, [1 220 751 258])``: rows 220..478 (1-based) over the full
   width, 259 × 752 px.
2. **Binarise**, ``im2bw(roi, 0.9)``: white where the grey value > 0.9 · 255.
3. **Car mask**: four rectangles of the car's own body, Gyro and Lidar are set to 0.
4. **Sobel**, ``edge(bw, 'sobel', 0.2, 'vertical')``: the vertical edges of the markings,
   thinned as Matlab's ``edge`` does by default (see ``sobel_vertical_edges``).
5. **Merge double edges**: the seed's own loop marks the second of two edges that lie
   1 < gap < 25 px apart along a row. A marking's left and right edges become one pixel,
   just right of the marking.
6. **Hough transform**, ``hough(bw, 'Theta', -90:0.5:89)``: ρ = x·cos θ + y·sin θ, with
   1 px ρ bins.
7. **Peaks**, ``houghpeaks(H, 5, 'threshold', ceil(0.3*max(H(:))))``: at most 5 peaks.
   Each one found suppresses its neighbourhood.
8. **Segments**, ``houghlines(bw, theta, rho, P, 'FillGap', 120, 'MinLength', 3)``: the
   voting pixels of each peak, sorted along the line and split at gaps > 120 px.

Coordinates. Matlab counts from 1, this module from 0. The seed's index ranges are
converted once, in the constants (1-based inclusive ``a:b`` is 0-based half-open
``[a − 1, b)``). Inside the crop, x is the column and y the row, both 0-based, as in
Matlab's ``hough``, which also uses ``x = col − 1`` and ``y = row − 1``. So ρ and θ match
Matlab's numerically. ``HoughResult.segments`` is in full-image pixels: the crop's row
plus ``CROP_TOP_PX``.

Deviations from Matlab:

- Peaks with 0 votes are never taken. On an empty accumulator Matlab's threshold
  ``ceil(0.3·0) = 0`` lets ``houghpeaks`` return zero-vote peaks. Those peaks have no pixels,
  so ``houghlines`` draws nothing from them and the segments are the same either way.
- ``houghlines`` finds a peak's pixels with ``round(ρ − ρ₁ + 1)``, ``hough`` with
  ``floor(ρ − ρ₁ + 0.5) + 1``. Both mean nearest bin, but they can part in the last ulp. This
  module uses the accumulator's own binning for both, so a peak's pixels are exactly the
  pixels that voted for it.
- The input is already grey (uint8, 480 × 752). The seed's ``im2bw`` converts RGB frames
  with ``rgb2gray`` first; here colour conversion happens before ``detect``.
- H is int32 (Matlab: double holding the same integer counts).

Not deviations, though the seed does not spell them out: ``edge`` thins by default, and its
'vertical' thinning also keeps vertical local maxima of the gradient
(``sobel_vertical_edges``). Both are reproduced; ``sobel_thinning=False`` is 'nothinning'.
The merge counter runs on across row ends, and that is reproduced as well
(``merge_double_edges``). The tests compare every stage with a line-by-line transcription of
the Matlab code.

Known weak spots. The seed's "Ausblick" names three, and all three remain here:

- The centre line is found late in curves. A curve is no straight line, so the dashed
  centre line collects few votes in any one bin, and the continuous outer line takes the
  peaks.
- Intersections: the crossing road's markings add lines at other angles. They compete for
  the five peaks and can give false segments.
- Reflections brighter than 0.9 of full scale become markings.

Two more weak spots concern the simulator. Its markings render below 230 (0.9 · 255) under
the default lighting, so the seed's threshold can leave nothing to detect; ``binarise_level``
is the setting to change. The car mask is the HSHL car's, and on the simulator's camera it
blanks road, marking pixels included; ``car_mask=()`` turns it off.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit

from ..camera import Camera, load_camera
from .detector import check_frame
from .params import IMAGE_HEIGHT_PX, IMAGE_WIDTH_PX

# --------------------------------------------------------------------------- the seed's numbers
CROP_TOP_PX: int = 219
"""First row of the region of interest, 0-based [px]. The seed's ``area = [1 220 751 258]``
is imcrop's ``[xmin ymin width height]`` in Matlab's spatial coordinates, in which the
1-based pixel (row r, column c) is centred on (x = c, y = r). The rectangle spans
y ∈ [220, 478], so imcrop takes the 1-based rows 220..478, which are the 0-based rows
219..477."""
CROP_HEIGHT_PX: int = 259
"""Rows of the region of interest [px]: the 1-based rows 220..478 inclusive, so 478 − 220 + 1.
The seed's own ``zeros(259, 752)`` for the merged image and its loop ``for y = 1:259``
confirm it. The crop is ``frame[219:478]``. Its x span [1, 752] takes all 752 columns."""
BINARISE_LEVEL: float = 0.9
"""``im2bw(roi, 0.9)`` [fraction of full scale]: a uint8 pixel is white when its value is
> 0.9 · 255 = 229.5, so ≥ 230 (im2bw compares ``A > 255·level`` for integer images)."""
CAR_MASK: tuple[tuple[int, int, int, int], ...] = (
    (194, 258, 154, 625),  # Matlab bwframe(195:258, 155:625) = 0: "Bereich 1"
    (159, 195, 209, 445),  # Matlab bwframe(160:195, 210:445) = 0: "Bereich 2"
    (124, 195, 109, 215),  # Matlab bwframe(125:195, 110:215) = 0: "Bereich 3: Gyro"
    (109, 160, 344, 430),  # Matlab bwframe(110:160, 345:430) = 0: "Bereich 4: Lidar"
)
"""The car's own parts, blanked after binarising. Each entry is (row_start, row_stop,
col_start, col_stop) in crop pixels, 0-based and half-open, as the slice
``[row_start:row_stop, col_start:col_stop]``. The seed gives 1-based inclusive ranges
``r0:r1, c0:c1``, which become ``(r0 − 1, r1, c0 − 1, c1)``. The seed's rows 195:258 end one
row above the crop's last row (1-based row 259). That row stays unmasked here too."""
SOBEL_THRESHOLD: float = 0.2
"""``edge(bw, 'sobel', 0.2, 'vertical')`` [Matlab gradient units]. Matlab filters with
``fspecial('sobel')/8``, so a 0→1 step in the binary image gives 0.5. It keeps pixels whose
squared gradient exceeds 0.2². OpenCV's integer Sobel is 8 times larger, so the test here is
gx² > (8 · 0.2)² = 2.56. On a 0/1 image gx is an integer, so the test means |gx| ≥ 2: Matlab's
|bx| ≥ 0.25."""
MERGE_MAX_GAP_PX: int = 25
"""``maxgap = 25`` [px]: the second of two edge pixels is marked when fewer than 25 non-edge
pixels lie between them (the seed's ``counter < maxgap``)."""
MERGE_MIN_COUNT: int = 1
"""The seed's ``counter > 1`` [px]: at least 2 non-edge pixels must separate the two edges.
Adjacent edge pixels (0 or 1 apart) are never merged."""
THETA_MIN_DEG: float = -90.0
"""First Hough angle [deg] (``'Theta', -90:0.5:89``)."""
THETA_MAX_DEG: float = 89.0
"""Last Hough angle [deg] (``-90:0.5:89``; Matlab's hough needs θ < 90)."""
THETA_STEP_DEG: float = 0.5
"""Hough angle step [deg] (``-90:0.5:89``, so 359 angles)."""
RHO_RESOLUTION_PX: float = 1.0
"""Hough ρ bin width [px] (``hough``'s default ``RhoResolution``)."""
NUM_PEAKS: int = 5
"""Peaks taken from the accumulator (``houghpeaks(H, 5, ...)``)."""
PEAK_THRESHOLD_RATIO: float = 0.3
"""Peak threshold as a fraction of the accumulator maximum [1]
(``'threshold', ceil(0.3*max(H(:)))``)."""
FILL_GAP_PX: float = 120.0
"""``houghlines(..., 'FillGap', 120)`` [px]: pixels of one peak closer than this stay in
one segment."""
MIN_LENGTH_PX: float = 3.0
"""``houghlines(..., 'MinLength', 3)`` [px]: shorter segments are dropped."""

Rect = tuple[int, int, int, int]

# --------------------------------------------------------------------------- our camera
SIMULATOR_BINARISE_LEVEL: float = 0.7
"""``binarise_level`` for the simulator's frames [fraction of full scale]: its markings
render at 180–215 DN under the default light (the seed's 0.9 keeps grey ≥ 230, which
real frames reach in their saturated near field, ``../shared/reference/``, and ours never),
its road at 20–60 DN. 0.7 (≥ 179 DN) keeps the markings and leaves the road."""
SIMULATOR_CAR_MASK: tuple[Rect, ...] = ((222, CROP_HEIGHT_PX, 0, IMAGE_WIDTH_PX),)
"""The simulator car's own parts in crop pixels (0-based, half-open): its bonnet, whose
edge is at image row 440 in the middle (``rendering.Bonnet.top_row``: image row 441 is the
first on the bonnet, crop row 441 − 219 = 222) and lower towards the borders, over the
full width. The bonnet mirrors
the markings, the "reflections" the seed names as a weak spot; the HSHL car's Gyro and
Lidar do not exist on this car."""


REAL_FRAME_BINARISE_LEVEL: float = 0.6
"""``binarise_level`` for the reference car's real frames (``../shared/reference/``)
[fraction of full scale]: their markings peak at 204–249 DN near the car and ≈ 180 DN at
the far dashes, the road's brightest non-marking pixels (p99) at ≈ 124 DN; 0.6 (≥ 153 DN)
keeps the markings and leaves the road. The seed's 0.9 keeps nothing of
``start-road.png``, whose markings stay below 230 DN."""
CROP_FAR_M: float = 5.0
"""Where ``HoughConfig.for_camera`` starts the crop [m ahead of the camera]. The seed's
crop starts just below its camera's horizon (row 219; 9.5 m ahead on the thesis camera);
a straight-line model gains nothing from further than 5 m — a curve at the rules'
tightest radius leaves a straight line by a lane width within ≈ 1.5 m — and there all
lines converge on the vanishing point and outvote the near ones: from 9.5 m the branching
line of ``../shared/reference/start-road.png`` gets no peak, from 5 m it does (measured,
docs/cameras.md). Row 226 on the thesis camera."""
MASK_BANDS: int = 16
"""Column bands of the derived car mask [1]: each masks from the bonnet's highest row in
its columns (the seed masks its car with rectangles too)."""


# --------------------------------------------------------------------------- configuration
@dataclass(frozen=True)
class HoughConfig:
    """The Hough baseline's settings. The defaults are the seed's values."""

    crop_top_px: int = CROP_TOP_PX
    """First row of the region of interest, 0-based [px]."""
    image_width_px: int = IMAGE_WIDTH_PX
    """Frame width [px] (the seed's camera: 752)."""
    image_height_px: int = IMAGE_HEIGHT_PX
    """Frame height [px] (the seed's camera: 480)."""
    crop_height_px: int = CROP_HEIGHT_PX
    """Rows of the region of interest [px]. It always spans the full image width."""
    binarise_level: float = BINARISE_LEVEL
    """White where grey > level · 255 [fraction of full scale, 0..1]."""
    car_mask: tuple[Rect, ...] = CAR_MASK
    """Rectangles (row_start, row_stop, col_start, col_stop) [crop px, 0-based, half-open]
    set to 0 after binarising. An empty tuple masks nothing."""
    sobel_threshold: float = SOBEL_THRESHOLD
    """Matlab ``edge`` threshold on the /8-scaled Sobel gradient [Matlab gradient units]."""
    sobel_thinning: bool = True
    """Matlab's default edge thinning (``'thinning'``); False is ``'nothinning'``."""
    merge_max_gap_px: int = MERGE_MAX_GAP_PX
    """Largest non-edge run + 1 between two edges that are merged [px]."""
    theta_min_deg: float = THETA_MIN_DEG
    """First Hough angle [deg], ≥ −90."""
    theta_max_deg: float = THETA_MAX_DEG
    """Last Hough angle [deg], < 90 (included when on the step grid, as Matlab's colon)."""
    theta_step_deg: float = THETA_STEP_DEG
    """Hough angle step [deg]."""
    rho_resolution_px: float = RHO_RESOLUTION_PX
    """Hough ρ bin width [px]."""
    num_peaks: int = NUM_PEAKS
    """Most peaks taken from the accumulator [1]."""
    peak_threshold_ratio: float = PEAK_THRESHOLD_RATIO
    """Peaks need ≥ ceil(ratio · max(H)) votes [fraction of the maximum, 0..1]."""
    peak_nhood: tuple[int, int] | None = None
    """Suppression neighbourhood (ρ bins, θ bins), both odd. ``None`` uses houghpeaks'
    default: ``2·ceil(size(H)/50/2) + 1`` per axis, (33, 9) for the seed's accumulator."""
    fill_gap_px: float = FILL_GAP_PX
    """houghlines' FillGap [px]."""
    min_length_px: float = MIN_LENGTH_PX
    """houghlines' MinLength [px]."""

    @classmethod
    def simulator(cls) -> HoughConfig:
        """The seed's settings for the simulator's camera: the binarising level of its
        markings and its car's bonnet as the mask (``SIMULATOR_*``); all else the seed's."""
        return cls(binarise_level=SIMULATOR_BINARISE_LEVEL, car_mask=SIMULATOR_CAR_MASK)

    @classmethod
    def for_camera(cls, camera: Camera | str, binarise_level: float = BINARISE_LEVEL
                   ) -> HoughConfig:
        """The seed's settings with its crop and car mask derived for ``camera`` (a
        camera, profile name or file): the crop from ``CROP_FAR_M`` ahead down to the
        lowest row where road is seen, the mask over
        the camera's bonnet in ``MASK_BANDS`` column bands. ``binarise_level`` is a
        property of the frames, not the camera: ``REAL_FRAME_BINARISE_LEVEL`` for the
        reference car's real frames, ``SIMULATOR_BINARISE_LEVEL`` for the simulator's
        renders (default: the seed's 0.9)."""
        from .geometry import CameraGeometryError, row_at

        cam = load_camera(camera)
        top = row_at(cam, CROP_FAR_M)
        if not math.isfinite(top) or top > cam.height - 2:
            raise CameraGeometryError(f"the camera does not see the road {CROP_FAR_M:.1f} m "
                                      "ahead (the top of the Hough baseline's crop)")
        top_px = max(0, round(top))
        cols = np.arange(cam.width)
        edge = cam.bonnet.edge(cols, cam.width, cam.height)
        lowest_road = cam.height if not np.isfinite(edge).all() else math.ceil(edge.max())
        bottom = min(cam.height, lowest_road)
        height = bottom - top_px
        if height < 2:
            raise CameraGeometryError("the car's body hides the whole Hough crop")
        mask = []
        bounds = np.linspace(0, cam.width, MASK_BANDS + 1).round().astype(int)
        for c0, c1 in itertools.pairwise(bounds):
            band = edge[c0:c1]
            if not np.isfinite(band).any():
                continue
            r0 = max(0, math.ceil(float(np.min(band))) - top_px)
            if r0 < height:
                mask.append((r0, height, int(c0), int(c1)))
        return cls(crop_top_px=top_px, crop_height_px=height, image_width_px=cam.width,
                   image_height_px=cam.height, binarise_level=binarise_level,
                   car_mask=tuple(mask))

    def __post_init__(self) -> None:
        for name in ("crop_top_px", "crop_height_px", "merge_max_gap_px", "num_peaks",
                     "image_width_px", "image_height_px"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
                raise ValueError(f"{name} must be an integer, got {v!r}")
        H = self.image_height_px
        if not (isinstance(H, (int, np.integer)) and 16 <= H <= 8192 and isinstance(
                self.image_width_px, (int, np.integer)) and 16 <= self.image_width_px <= 8192):
            raise ValueError(f"image size must be integers in [16, 8192] px, got "
                             f"{self.image_width_px}×{H}")
        if not 0 <= self.crop_top_px < H:
            raise ValueError(f"crop_top_px must be in [0, {H}), got "
                             f"{self.crop_top_px}")
        if not 2 <= self.crop_height_px <= H - self.crop_top_px:
            raise ValueError(f"crop_height_px must be in [2, {H} − crop_top_px = "
                             f"{H - self.crop_top_px}], got "
                             f"{self.crop_height_px}; lower it or move crop_top_px up")
        if not 0.0 <= self.binarise_level <= 1.0:
            raise ValueError(f"binarise_level must be in [0, 1] (fraction of full scale), got "
                             f"{self.binarise_level}; e.g. 0.9 for the seed's im2bw(roi, 0.9)")
        object.__setattr__(self, "car_mask", self._checked_mask(self.car_mask))
        if not self.sobel_threshold >= 0.0:
            raise ValueError(f"sobel_threshold must be ≥ 0, got {self.sobel_threshold}")
        if self.merge_max_gap_px <= MERGE_MIN_COUNT + 1:
            raise ValueError(f"merge_max_gap_px must be > {MERGE_MIN_COUNT + 1} (the seed "
                             f"merges when {MERGE_MIN_COUNT} < gap < max), got "
                             f"{self.merge_max_gap_px}")
        if not -90.0 <= self.theta_min_deg <= self.theta_max_deg < 90.0:
            raise ValueError("theta_min_deg and theta_max_deg must satisfy −90 ≤ min ≤ max "
                             f"< 90, got {self.theta_min_deg}, {self.theta_max_deg}")
        if not self.theta_step_deg > 0.0:
            raise ValueError(f"theta_step_deg must be > 0, got {self.theta_step_deg}")
        if not self.rho_resolution_px > 0.0:
            raise ValueError(f"rho_resolution_px must be > 0, got {self.rho_resolution_px}")
        if self.num_peaks < 1:
            raise ValueError(f"num_peaks must be ≥ 1, got {self.num_peaks}")
        if not 0.0 <= self.peak_threshold_ratio <= 1.0:
            raise ValueError(f"peak_threshold_ratio must be in [0, 1], got "
                             f"{self.peak_threshold_ratio}")
        if self.peak_nhood is not None and (
                len(self.peak_nhood) != 2
                or any(int(v) != v or v < 1 or v % 2 == 0 for v in self.peak_nhood)):
            raise ValueError(f"peak_nhood must be two odd integers ≥ 1 (ρ bins, θ bins) or "
                             f"None for houghpeaks' default, got {self.peak_nhood}")
        if self.peak_nhood is not None:
            object.__setattr__(self, "peak_nhood", tuple(int(v) for v in self.peak_nhood))
        if not self.fill_gap_px > 0.0:
            raise ValueError(f"fill_gap_px must be > 0, got {self.fill_gap_px}")
        if not self.min_length_px > 0.0:
            raise ValueError(f"min_length_px must be > 0, got {self.min_length_px}")

    def _checked_mask(self, mask: object) -> tuple[Rect, ...]:
        try:
            rects = [tuple(r) for r in mask]  # type: ignore[union-attr]
        except TypeError:
            raise ValueError(f"car_mask must be a tuple of (row_start, row_stop, col_start, "
                             f"col_stop) rectangles, got {mask!r}") from None
        out = []
        for k, r in enumerate(rects):
            if len(r) != 4 or not all(isinstance(v, (int, np.integer))
                                      and not isinstance(v, bool) for v in r):
                raise ValueError(f"car_mask[{k}] must be four integers (row_start, row_stop, "
                                 f"col_start, col_stop), got {r!r}")
            r0, r1, c0, c1 = (int(v) for v in r)
            if not (0 <= r0 < r1 <= self.crop_height_px and 0 <= c0 < c1 <= self.image_width_px):
                raise ValueError(
                    f"car_mask[{k}] = {r!r} must satisfy 0 ≤ row_start < row_stop ≤ "
                    f"crop_height_px = {self.crop_height_px} and 0 ≤ col_start < col_stop ≤ "
                    f"{self.image_width_px} (0-based, half-open crop coordinates; a Matlab "
                    "range a:b is a − 1, b)")
            out.append((r0, r1, c0, c1))
        return tuple(out)


# --------------------------------------------------------------------------- result
@dataclass(frozen=True)
class HoughResult:
    """One frame's result. All images are crop-sized (crop_height_px × 752) bool."""

    segments: np.ndarray
    """(N, 4) float64: the segments (x1, y1, x2, y2) [full-image px, 0-based pixel centres,
    integer valued]. Point 1 is the first pixel along the line: the top for steep lines, the
    left for flat ones."""
    segment_theta_deg: np.ndarray
    """(N,) float64: θ of each segment's peak [deg]."""
    segment_rho_px: np.ndarray
    """(N,) float64: ρ of each segment's peak [crop px] (normal form in crop coordinates)."""
    peaks: np.ndarray
    """(K, 2) int64, K ≤ num_peaks: (ρ index, θ index) into ``accumulator``, 0-based, in
    the order houghpeaks found them."""
    peak_votes: np.ndarray
    """(K,) int32: each peak's votes."""
    peak_threshold: int
    """ceil(peak_threshold_ratio · max(H)) [votes] (≥ 1; see the module's deviations)."""
    accumulator: np.ndarray
    """(n_ρ, n_θ) int32: Matlab's H (1591 × 359 for the seed)."""
    theta_deg: np.ndarray
    """(n_θ,) float64: the accumulator's angles [deg]."""
    rho_px: np.ndarray
    """(n_ρ,) float64: the accumulator's ρ bins [px]."""
    binary: np.ndarray
    """im2bw of the crop, before the car mask (the seed's panel 1)."""
    masked: np.ndarray
    """``binary`` with the car mask applied (the Sobel's input)."""
    sobel: np.ndarray
    """The vertical Sobel edges (panel 2)."""
    merged: np.ndarray
    """The merged double edges (panel 3), the Hough transform's input."""
    crop_top_px: int
    """Full-image row of crop row 0 [px]."""
    car_mask: tuple[Rect, ...] = ()
    """The mask rectangles that were applied [crop px] (for the stage view)."""


# --------------------------------------------------------------------------- kernels
@njit(cache=True)
def _thin_vertical(gx: np.ndarray, gy: np.ndarray, cutoff: float, thinning: bool
                   ) -> np.ndarray:
    """Matlab ``edge(..., 'vertical')``'s decision from the integer Sobel responses
    (b = gx², kx = 1, ky = 0; see ``sobel_vertical_edges``)."""
    m, n = gx.shape
    out = np.zeros((m, n), np.bool_)
    for r in range(m):
        for c in range(n):
            g = np.int32(gx[r, c])
            b = g * g
            if not b > cutoff:
                continue
            if not thinning:
                out[r, c] = True
                continue
            if r > 0:
                g = np.int32(gx[r - 1, c])
                up_ok = g * g <= b
            else:
                up_ok = True
            if r < m - 1:
                g = np.int32(gx[r + 1, c])
                down_ok = b > g * g
            else:
                down_ok = True
            if up_ok and down_ok:
                out[r, c] = True
                continue
            if abs(np.int32(gx[r, c])) < abs(np.int32(gy[r, c])):
                continue
            if c > 0:
                g = np.int32(gx[r, c - 1])
                left_ok = g * g <= b
            else:
                left_ok = True
            if c < n - 1:
                g = np.int32(gx[r, c + 1])
                right_ok = b > g * g
            else:
                right_ok = True
            out[r, c] = left_ok and right_ok
    return out


@njit(cache=True)
def _merge(edges: np.ndarray, min_count: int, max_gap: int
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The seed's merge loop, verbatim: one counter over the whole image, row by row.
    Returns the merged image and its pixels' columns and rows (row-major order)."""
    m, n = edges.shape
    out = np.zeros((m, n), np.bool_)
    xs = np.empty(m * n, np.int32)
    ys = np.empty(m * n, np.int32)
    count = 0
    counter = 0
    for y in range(m):
        for x in range(n):
            if edges[y, x]:
                if min_count < counter < max_gap:
                    out[y, x] = True
                    xs[count] = x
                    ys[count] = y
                    count += 1
                counter = 0
            else:
                counter += 1
    return out, xs[:count].copy(), ys[:count].copy()


@njit(cache=True)
def _accumulate(xs: np.ndarray, ys: np.ndarray, cos_t: np.ndarray, sin_t: np.ndarray,
                first_rho: float, slope: float, n_rho: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Votes as (n_θ, n_ρ): H transposed, so that its C order is H's column-major order.
    Also returns each θ's largest vote count and its first ρ index (from the bins voted
    in; an unvoted θ has 0 at index 0)."""
    n_theta = cos_t.shape[0]
    n = xs.shape[0]
    acc = np.zeros((n_theta, n_rho), np.int32)
    col_max = np.zeros(n_theta, np.int64)
    col_arg = np.zeros(n_theta, np.int64)
    bins = np.empty(n, np.int64)
    for k in range(n_theta):  # θ outermost: each θ's votes stay in one row of acc
        c = cos_t[k]
        s = sin_t[k]
        for i in range(n):
            rho = float(xs[i]) * c + float(ys[i]) * s
            b = int(slope * (rho - first_rho) + 0.5)
            acc[k, b] += 1
            bins[i] = b
        best = 0
        arg = 0
        for i in range(n):
            v = acc[k, bins[i]]
            if v > best or (v == best and bins[i] < arg):
                best = v
                arg = bins[i]
        col_max[k] = best
        col_arg[k] = arg
    return acc, col_max, col_arg


@njit(cache=True)
def _column_max(acc_t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each θ's largest vote count and its first ρ index, by a full scan."""
    n_theta, n_rho = acc_t.shape
    col_max = np.zeros(n_theta, np.int64)
    col_arg = np.zeros(n_theta, np.int64)
    for q in range(n_theta):
        best = acc_t[q, 0]
        arg = 0
        for p in range(1, n_rho):
            if acc_t[q, p] > best:
                best = acc_t[q, p]
                arg = p
        col_max[q] = best
        col_arg[q] = arg
    return col_max, col_arg


@njit(cache=True)
def _lines(xs: np.ndarray, ys: np.ndarray, cos_t: np.ndarray, sin_t: np.ndarray,
           first_rho: float, slope: float, peaks: np.ndarray, fill_sq: float, min_sq: float,
           n_rows: int, n_cols: int) -> tuple[np.ndarray, np.ndarray]:
    """houghlines (see ``hough_lines``); a peak's pixels are found with ``_accumulate``'s
    own binning, so they are exactly the pixels that voted for it."""
    segs = np.empty((0, 4), np.int64)
    owner = np.empty(0, np.int64)
    found_segs = []
    found_owner = []
    for k in range(peaks.shape[0]):
        p = peaks[k, 0]
        c = cos_t[peaks[k, 1]]
        s = sin_t[peaks[k, 1]]
        count = 0
        sel = np.empty(xs.shape[0], np.int64)
        for i in range(xs.shape[0]):
            rho = float(xs[i]) * c + float(ys[i]) * s
            if int(slope * (rho - first_rho) + 0.5) == p:
                sel[count] = i
                count += 1
        if count == 0:
            continue
        r = ys[sel[:count]].astype(np.int64)
        col = xs[sel[:count]].astype(np.int64)
        # sortrows([r c], [1 2]) when the rows span more than the columns, else [2 1]
        # (the keys are distinct: any sort gives this order). Merge sort: numba names its
        # quicksort helpers per process, so a cached argsort's could be linked to the
        # in-place sort of another cached kernel (scene._propagate, np.unique) with the
        # same name: it then returned garbage (tests/test_numba_sorts.py).
        if r.max() - r.min() > col.max() - col.min():
            order = np.argsort(r * n_cols + col, kind="mergesort")
        else:
            order = np.argsort(col * n_rows + r, kind="mergesort")
        r = r[order]
        col = col[order]
        start = 0
        for i in range(count):
            last = i == count - 1
            if not last:
                dx = col[i + 1] - col[i]
                dy = r[i + 1] - r[i]
            if last or dx * dx + dy * dy > fill_sq:
                dx = col[i] - col[start]
                dy = r[i] - r[start]
                if dx * dx + dy * dy >= min_sq:
                    found_segs.append((col[start], r[start], col[i], r[i]))
                    found_owner.append(k)
                start = i + 1
    if len(found_segs) > 0:
        segs = np.empty((len(found_segs), 4), np.int64)
        owner = np.empty(len(found_segs), np.int64)
        for j in range(len(found_segs)):
            x1, y1, x2, y2 = found_segs[j]
            segs[j, 0] = x1
            segs[j, 1] = y1
            segs[j, 2] = x2
            segs[j, 3] = y2
            owner[j] = found_owner[j]
    return segs, owner


@njit(cache=True)
def _rescan(acc_t: np.ndarray, q: int, found: np.ndarray, count: int, half_rho: int,
            half_theta: int) -> tuple[int, int]:
    """Largest value and its first ρ index in column q of H = acc_t.T, not counting the
    entries zeroed by the neighbourhoods of the first ``count`` peaks in ``found``."""
    n_theta, n_rho = acc_t.shape
    zeroed = np.zeros(n_rho, np.bool_)
    for j in range(count):
        bp = found[j, 0]
        bq = found[j, 1]
        lo = max(bp - half_rho, 0)
        hi = min(bp + half_rho, n_rho - 1)
        if bq - half_theta <= q <= bq + half_theta:
            zeroed[lo:hi + 1] = True
        # wrapped across θ = ±90°: column q0 ± n_θ, with ρ mirrored
        if bq - half_theta <= q - n_theta <= bq + half_theta or \
                bq - half_theta <= q + n_theta <= bq + half_theta:
            zeroed[n_rho - 1 - hi:n_rho - lo] = True
    best = 0
    arg = 0
    first = True
    for p in range(n_rho):
        v = 0 if zeroed[p] else acc_t[q, p]
        if first or v > best:
            best = v
            arg = p
            first = False
    return best, arg


@njit(cache=True)
def _peaks(acc_t: np.ndarray, col_max: np.ndarray, col_arg: np.ndarray, num_peaks: int,
           threshold: int, half_rho: int, half_theta: int) -> np.ndarray:
    """houghpeaks on H = acc_t.T, given each column's maximum and first index.

    Each round takes the first maximum in H's column-major order (lowest θ index, then
    lowest ρ index) and stops when it is below ``threshold``. The peak's neighbourhood then
    counts as zeroed. Across θ = ±90° the neighbourhood wraps with ρ mirrored, as
    houghpeaks' "H is antisymmetric" rule does. H itself is not modified: only the columns
    a neighbourhood touched are rescanned, with the zeroed entries skipped.
    """
    n_theta = acc_t.shape[0]
    cmax = col_max.copy()
    carg = col_arg.copy()
    found = np.empty((num_peaks, 2), np.int64)
    count = 0
    while count < num_peaks:
        bq = 0
        for q in range(1, n_theta):
            if cmax[q] > cmax[bq]:
                bq = q
        if cmax[bq] < threshold:
            break
        found[count, 0] = carg[bq]
        found[count, 1] = bq
        count += 1
        for q0 in range(bq - half_theta, bq + half_theta + 1):
            q = q0 % n_theta
            cmax[q], carg[q] = _rescan(acc_t, q, found, count, half_rho, half_theta)
    return found[:count]


# --------------------------------------------------------------------------- the stages
def binarise(crop: np.ndarray, level: float = BINARISE_LEVEL) -> np.ndarray:
    """``im2bw(crop, level)`` for a uint8 image: True where value > level · 255."""
    if crop.dtype != np.uint8:
        raise ValueError(f"crop must be uint8, got dtype {crop.dtype}")
    # For integer values, v > level·255 is the same as v > floor(level·255).
    return crop > math.floor(level * 255.0)


def apply_car_mask(binary: np.ndarray, rects: tuple[Rect, ...] = CAR_MASK) -> np.ndarray:
    """A copy of ``binary`` with each (row_start, row_stop, col_start, col_stop) slice set to
    False."""
    out = binary.copy()
    for r0, r1, c0, c1 in rects:
        out[r0:r1, c0:c1] = False
    return out


def sobel_vertical_edges(binary: np.ndarray, threshold: float = SOBEL_THRESHOLD,
                         thinning: bool = True) -> np.ndarray:
    """Matlab's ``edge(binary, 'sobel', threshold, 'vertical')`` on a bool image.

    Matlab convolves with ``fspecial('sobel')/8`` using 'replicate' borders (replicated here
    by clamped indices) and computes b = bx². It keeps b > threshold². OpenCV's integer
    kernel is 8 × Matlab's, so the cutoff here is (8 · threshold)²; see ``SOBEL_THRESHOLD``.
    Thinning is on by default, as in Matlab, and follows ``edge.m``'s
    computeEdgesWithThinning with kx = 1, ky = 0. A pixel is kept when b exceeds the cutoff
    and either

    - |bx| ≥ |by| and b is a horizontal local maximum, b(c−1) ≤ b(c) > b(c+1), or
    - b is a vertical local maximum, b(r−1) ≤ b(r) > b(r+1). Matlab's other condition,
      |by| ≥ ky·|bx|, is always true for ky = 0.

    A neighbour outside the image counts as passed. On a step the two equal responses are
    decided by the ≤ / >: a marking keeps its first white pixel (rising edge) and the first
    dark pixel after it (falling edge).
    """
    bw = np.ascontiguousarray(binary, dtype=np.bool_).view(np.uint8)
    # OpenCV's ksize-3 Sobel is [-1 0 1; -2 0 2; -1 0 1] (and its transpose); the sign is
    # Matlab's flipped, which |·| and squares ignore. BORDER_REPLICATE is imfilter's
    # 'replicate'.
    gx = cv2.Sobel(bw, cv2.CV_16S, 1, 0, ksize=3, borderType=cv2.BORDER_REPLICATE)
    gy = cv2.Sobel(bw, cv2.CV_16S, 0, 1, ksize=3, borderType=cv2.BORDER_REPLICATE)
    cutoff = 64.0 * float(threshold) ** 2  # (8·t)², the power-of-two factor is exact
    return _thin_vertical(gx, gy, cutoff, bool(thinning))


def merge_double_edges(edges: np.ndarray, max_gap_px: int = MERGE_MAX_GAP_PX) -> np.ndarray:
    """The seed's double-edge merge (its ``for y … for x …`` loop), exactly.

    One counter counts the non-edge pixels since the last edge pixel. At an edge pixel, the
    pixel is marked if ``MERGE_MIN_COUNT < counter < max_gap_px``, and the counter goes
    back to 0. As in the seed, the counter is never reset at a row start: it carries over
    from the end of one row to the start of the next, and it starts at 0 for the first row.
    """
    merged, _, _ = _merge(np.ascontiguousarray(edges, dtype=np.bool_), MERGE_MIN_COUNT,
                          int(max_gap_px))
    return merged


def theta_grid(theta_min_deg: float = THETA_MIN_DEG, theta_max_deg: float = THETA_MAX_DEG,
               theta_step_deg: float = THETA_STEP_DEG) -> np.ndarray:
    """Matlab's ``theta_min:theta_step:theta_max`` [deg]."""
    n = int(math.floor((theta_max_deg - theta_min_deg) / theta_step_deg + 1e-10)) + 1
    return theta_min_deg + theta_step_deg * np.arange(n, dtype=np.float64)


def rho_grid(shape: tuple[int, int], rho_resolution_px: float = RHO_RESOLUTION_PX
             ) -> np.ndarray:
    """``hough``'s ρ bins [px] for an image of ``shape`` (rows, cols). D is the diagonal
    √((M−1)² + (N−1)²), q = ceil(D / res), and the bins are linspace(−q·res, q·res, 2q + 1)."""
    m, n = shape
    d = math.sqrt((m - 1) ** 2 + (n - 1) ** 2)
    q = math.ceil(d / rho_resolution_px)
    return np.linspace(-q * rho_resolution_px, q * rho_resolution_px, 2 * q + 1)


def _trig(theta_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cos θ and sin θ for the whole grid (always computed on the full array, so that the
    accumulator and houghlines see identical values)."""
    t = theta_deg * np.pi / 180.0  # Matlab's theta*pi/180, in that order
    return np.cos(t), np.sin(t)


def _slope(rho_px: np.ndarray) -> float:
    """hough's ρ-to-bin factor (n_ρ − 1) / (ρ_last − ρ_first) = 1 / resolution."""
    return float((len(rho_px) - 1) / (rho_px[-1] - rho_px[0]))


def hough_transform(bw: np.ndarray, theta_deg: np.ndarray | None = None,
                    rho_resolution_px: float = RHO_RESOLUTION_PX
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Matlab's ``[H, theta, rho] = hough(bw, 'Theta', theta_deg)``.

    Each nonzero pixel (x = col, y = row, 0-based) votes once per θ, in the bin
    ``floor((x·cos θ + y·sin θ − ρ₁) / res + 0.5)``, as Matlab's standardHoughTransform does.
    H is (n_ρ, n_θ) int32. It is a transposed view of a C-contiguous (n_θ, n_ρ) array.
    """
    theta = theta_grid() if theta_deg is None else np.asarray(theta_deg, dtype=np.float64)
    rho = rho_grid(bw.shape, rho_resolution_px)
    ys, xs = np.nonzero(bw)
    cos_t, sin_t = _trig(theta)
    acc, _, _ = _accumulate(xs, ys, cos_t, sin_t, float(rho[0]), _slope(rho), len(rho))
    return acc.T, theta, rho


def default_nhood(shape: tuple[int, int]) -> tuple[int, int]:
    """houghpeaks' default NHoodSize for an accumulator of ``shape``:
    ``max(2·ceil(size(H)/50/2) + 1, 1)``. This is odd, and is (33, 9) for 1591 × 359."""
    return tuple(max(2 * math.ceil(s / 50 / 2) + 1, 1) for s in shape)  # type: ignore[return-value]


def peak_threshold(accumulator: np.ndarray, ratio: float = PEAK_THRESHOLD_RATIO) -> int:
    """The seed's ``ceil(ratio*max(H(:)))`` [votes], at least 1 (zero-vote bins are never
    peaks; see the module's deviations)."""
    top = int(accumulator.max()) if accumulator.size else 0
    return max(math.ceil(ratio * top), 1)


def hough_peaks(accumulator: np.ndarray, num_peaks: int = NUM_PEAKS,
                threshold: int | None = None, nhood: tuple[int, int] | None = None
                ) -> np.ndarray:
    """Matlab's ``houghpeaks(H, num_peaks, 'threshold', threshold, 'NHoodSize', nhood)``.

    ``accumulator`` is H, (n_ρ, n_θ). ``threshold`` defaults to ``peak_threshold(H)`` and
    ``nhood`` to ``default_nhood``. Returns (K, 2) int64 peaks, each (ρ index, θ index),
    0-based, in the order found.
    """
    if threshold is None:
        threshold = peak_threshold(accumulator)
    nh = default_nhood(accumulator.shape) if nhood is None else nhood
    if nh[0] > accumulator.shape[0] or nh[1] > accumulator.shape[1]:
        raise ValueError(f"nhood {tuple(nh)} must not exceed the accumulator's shape "
                         f"{accumulator.shape}")
    acc_t = np.ascontiguousarray(accumulator.T)
    col_max, col_arg = _column_max(acc_t)
    return _peaks(acc_t, col_max, col_arg, int(num_peaks), int(threshold),
                  (int(nh[0]) - 1) // 2, (int(nh[1]) - 1) // 2)


def hough_lines(bw: np.ndarray, theta_deg: np.ndarray, rho_px: np.ndarray, peaks: np.ndarray,
                fill_gap_px: float = FILL_GAP_PX, min_length_px: float = MIN_LENGTH_PX
                ) -> tuple[np.ndarray, np.ndarray]:
    """Matlab's ``houghlines(bw, theta, rho, peaks, 'FillGap', …, 'MinLength', …)``.

    For each peak in turn: take the pixels of ``bw`` that voted for its bin and sort them
    along the line. houghlines sorts by row then column when the rows span more than the
    columns, and by column then row otherwise. Split where two consecutive pixels are more
    than ``fill_gap_px`` apart, and keep the pieces whose end points are ≥ ``min_length_px``
    apart. Returns (segments (N, 4) int64 (x1, y1, x2, y2) in ``bw``'s 0-based pixels,
    the (N,) index of each segment's peak).
    """
    ys, xs = np.nonzero(bw)
    cos_t, sin_t = _trig(np.asarray(theta_deg, dtype=np.float64))
    peaks = np.ascontiguousarray(np.asarray(peaks, dtype=np.int64).reshape(-1, 2))
    return _lines(xs, ys, cos_t, sin_t, float(rho_px[0]), _slope(rho_px), peaks,
                  float(fill_gap_px) ** 2, float(min_length_px) ** 2, bw.shape[0], bw.shape[1])


# --------------------------------------------------------------------------- detector
class HoughDetector:
    """The seed's Hough lane detector, frame by frame and without state between frames."""

    def __init__(self, config: HoughConfig | None = None) -> None:
        self.config = config or HoughConfig()
        c = self.config
        self.theta_deg = theta_grid(c.theta_min_deg, c.theta_max_deg, c.theta_step_deg)
        self.rho_px = rho_grid((c.crop_height_px, c.image_width_px), c.rho_resolution_px)
        self._cos, self._sin = _trig(self.theta_deg)
        for a in (self.theta_deg, self.rho_px, self._cos, self._sin):
            a.flags.writeable = False
        shape = (len(self.rho_px), len(self.theta_deg))
        self.nhood: tuple[int, int] = c.peak_nhood or default_nhood(shape)
        if self.nhood[0] > shape[0] or self.nhood[1] > shape[1]:
            raise ValueError(f"peak_nhood {self.nhood} must not exceed the accumulator's "
                             f"shape {shape} (ρ bins, θ bins); make it smaller")

    def detect(self, frame: np.ndarray) -> HoughResult:
        """The seed's steps on one (480, 752) uint8 grey frame."""
        c = self.config
        frame = check_frame(frame, c.image_width_px, c.image_height_px)
        crop = frame[c.crop_top_px:c.crop_top_px + c.crop_height_px]
        binary = binarise(crop, c.binarise_level)
        masked = apply_car_mask(binary, c.car_mask)
        sobel = sobel_vertical_edges(masked, c.sobel_threshold, c.sobel_thinning)
        # The stage functions' kernels, called directly: the merge hands over its pixels
        # and the accumulator its column maxima, which saves two full-image scans.
        merged, xs, ys = _merge(sobel, MERGE_MIN_COUNT, c.merge_max_gap_px)
        rho0, slope = float(self.rho_px[0]), _slope(self.rho_px)
        acc_t, col_max, col_arg = _accumulate(xs, ys, self._cos, self._sin, rho0, slope,
                                              len(self.rho_px))
        threshold = max(math.ceil(c.peak_threshold_ratio * int(col_max.max())), 1)
        peaks = _peaks(acc_t, col_max, col_arg, c.num_peaks, threshold,
                       (self.nhood[0] - 1) // 2, (self.nhood[1] - 1) // 2)
        segs, owner = _lines(xs, ys, self._cos, self._sin, rho0, slope, peaks,
                             float(c.fill_gap_px) ** 2, float(c.min_length_px) ** 2,
                             merged.shape[0], merged.shape[1])
        accumulator = acc_t.T
        segments = segs.astype(np.float64)
        segments[:, [1, 3]] += c.crop_top_px
        return HoughResult(
            segments=segments,
            segment_theta_deg=self.theta_deg[peaks[owner, 1]].copy(),
            segment_rho_px=self.rho_px[peaks[owner, 0]].copy(),
            peaks=peaks,
            peak_votes=accumulator[peaks[:, 0], peaks[:, 1]].astype(np.int32),
            peak_threshold=threshold,
            accumulator=accumulator,
            theta_deg=self.theta_deg,
            rho_px=self.rho_px,
            binary=binary,
            masked=masked,
            sobel=sobel,
            merged=merged,
            crop_top_px=c.crop_top_px,
            car_mask=c.car_mask,
        )
