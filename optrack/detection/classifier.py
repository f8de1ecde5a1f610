"""Person confidence: OpenCV's default HOG people detector on each candidate's box.

Dalal and Triggs' HOG with their linear SVM (OpenCV's
``HOGDescriptor_getDefaultPeopleDetector``, a 64x128 window), evaluated
once per candidate on its full-body window as PCL's ``PersonClassifier``
does: the head-to-floor height in pixels fills ``hog_window_fill`` of the
window's height, the window is centred on the projected body centre, the
parts outside the image are black. The confidence is the SVM score
``w . x + b`` (Munaro et al. 2012, section 3.4).

The same window is used on the infrared image after histogram
equalisation (time-of-flight sensors, Munaro et al. 2016 section 4.2), and
on a candidate's depth silhouette for a depth-only confidence in dark
frames.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = [
    "HOG_WINDOW",
    "HogClassifier",
    "equalised_infrared",
    "hsv_histogram",
    "luminance",
    "person_window",
]

#: The default people detector's window (width, height), pixels.
HOG_WINDOW = (64, 128)
#: ITU-R BT.601 luma weights, as OpenPTrack's mean luminance.
LUMA = np.array([0.3, 0.59, 0.11])


class HogClassifier:
    """OpenCV's default people detector scoring one window per candidate."""

    def __init__(self) -> None:
        self.hog = cv2.HOGDescriptor()  # 64x128, 16x16 blocks, 8x8 cells, 9 bins, L2-Hys
        detector = np.asarray(cv2.HOGDescriptor_getDefaultPeopleDetector(), dtype=np.float64)
        self.w = detector[:-1].ravel()
        self.b = float(detector[-1])  # OpenCV's rho: the last coefficient

    def scores(self, windows: list[np.ndarray]) -> np.ndarray:
        """SVM scores of 64x128 uint8 windows (grey or 3-channel)."""
        if not windows:
            return np.empty(0)
        descriptors = np.stack(
            [self.hog.compute(np.ascontiguousarray(w)).ravel() for w in windows]
        ).astype(np.float64)
        return descriptors @ self.w + self.b


def window_geometry(
    top_px: np.ndarray, bottom_px: np.ndarray, center_px: np.ndarray, fill: float
) -> tuple[int, int, int, int]:
    """The HOG window (xmin, ymin, width, height) in image pixels of a person whose head
    and feet project to ``top_px`` and ``bottom_px`` (PCL's ``PersonClassifier::evaluate``)."""
    person = float(bottom_px[1] - top_px[1])
    height = max(int(math.floor(person / fill + 0.5)), 2)
    width = max(int(math.floor(person * HOG_WINDOW[0] / (fill * HOG_WINDOW[1]) + 0.5)), 1)
    xmin = int(math.floor(center_px[0] - width / 2 + 0.5))
    ymin = int(math.floor(center_px[1] - height / 2 + 0.5))
    return xmin, ymin, width, height


def person_window(
    image: np.ndarray,
    box: tuple[int, int, int, int],
    origin: tuple[int, int] = (0, 0),
    stride: int = 1,
) -> np.ndarray:
    """The 64x128 window of ``box`` (xmin, ymin, width, height; full-image pixels),
    black outside the image, sampled bilinearly (as PCL's ``PersonClassifier::resize``).

    ``image`` may be a strided crop of the full image whose pixel (0, 0) is the
    full image's ``origin`` (u, v) and whose pixels are ``stride`` apart.
    """
    xmin, ymin, width, height = box
    out_w, out_h = HOG_WINDOW
    u0, v0 = origin
    sx, sy = width / out_w, height / out_h
    # Window pixel (i, j) samples full-image pixel (xmin + (i + 0.5) sx - 0.5, ...).
    inverse = np.array(
        [
            [sx / stride, 0.0, (xmin + 0.5 * sx - 0.5 - u0) / stride],
            [0.0, sy / stride, (ymin + 0.5 * sy - 0.5 - v0) / stride],
        ]
    )
    return cv2.warpAffine(
        image,
        inverse,
        (out_w, out_h),
        flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=0,
    )


def luminance(image: np.ndarray) -> float:
    """Mean luminance (0-255) of an RGB image (OpenPTrack's 0.3 R + 0.59 G + 0.11 B)."""
    return float(np.asarray(cv2.mean(image)[:3]) @ LUMA)


def equalised_infrared(infrared: np.ndarray) -> np.ndarray:
    """An infrared image as 8-bit with its histogram equalised (OpenCV)."""
    if infrared.dtype != np.uint8:
        infrared = cv2.normalize(infrared, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    return cv2.equalizeHist(infrared)


def hsv_histogram(rgb_pixels: np.ndarray, hue_bins: int, saturation_bins: int) -> list[float]:
    """Normalised hue-saturation histogram (sums to 1) of Nx3 RGB pixels; [] when none."""
    if len(rgb_pixels) == 0:
        return []
    hsv = cv2.cvtColor(
        np.ascontiguousarray(rgb_pixels, dtype=np.uint8).reshape(-1, 1, 3), cv2.COLOR_RGB2HSV
    )
    hist = cv2.calcHist([hsv], [0, 1], None, [hue_bins, saturation_bins], [0, 180, 0, 256]).ravel()
    total = float(hist.sum())
    return [float(v) / total for v in hist] if total > 0 else []
