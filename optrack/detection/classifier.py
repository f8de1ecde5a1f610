"""Person confidence: OpenCV's default HOG people detector on each candidate's box.

Dalal and Triggs' HOG with their linear SVM (OpenCV's
``HOGDescriptor_getDefaultPeopleDetector``, a 64x128 window), evaluated
once per candidate on its full-body window as PCL's ``PersonClassifier``
does: the person, head to floor, fills ``hog_window_fill`` of the window's
height, centred; the parts outside the image are black. The window is seen
by a virtual level camera turned towards the person (:func:`level_window`),
so that a tilted sensor's people stand upright in it. The confidence is the
SVM score ``w . x + b`` (Munaro et al. 2012, section 3.4).

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
    "level_window",
    "person_window",
    "window_footprint",
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

    def score(self, window: np.ndarray) -> float:
        """SVM score of one 64x128 uint8 window (grey or 3-channel)."""
        descriptor = self.hog.compute(np.ascontiguousarray(window)).ravel()
        return float(descriptor.astype(np.float64) @ self.w + self.b)

    def scores(self, windows: list[np.ndarray]) -> np.ndarray:
        """SVM scores of 64x128 uint8 windows (grey or 3-channel)."""
        return np.array([self.score(w) for w in windows], dtype=np.float64)


def level_window(
    center: np.ndarray, height: float, up: np.ndarray, K: np.ndarray, fill: float
) -> np.ndarray:
    """Homography (3x3) from HOG window pixels to image pixels for a person.

    The window is what a virtual camera would see at the sensor's optical
    centre, level (its y axis down along the floor's normal ``up``) and
    turned towards the person's ``center`` (camera frame, half way up); its
    focal length makes the ``height`` fill ``fill`` of the window's height,
    centred (PCL's ``PersonClassifier`` window, Munaro et al. 2012 section
    3.4, with the sensor's tilt taken out: a rotation-only homography
    ``K R K_v^-1``, Hartley and Zisserman eq. 8.8).
    """
    down = -np.asarray(up, dtype=np.float64)
    horizontal = center - (center @ down) * down
    distance = float(np.linalg.norm(horizontal))
    if distance < 1e-6:  # straight below the camera: look along the camera's own z
        horizontal = np.array([0.0, 0.0, 1.0]) - down[2] * down
        distance = float(np.linalg.norm(horizontal))
    z = horizontal / distance
    x = np.array(
        [
            down[1] * z[2] - down[2] * z[1],
            down[2] * z[0] - down[0] * z[2],
            down[0] * z[1] - down[1] * z[0],
        ]
    )  # down x z
    camera_R_virtual = np.column_stack([x, down, z])
    out_w, out_h = HOG_WINDOW
    f = fill * out_h * distance / max(height, 1e-6)
    below = float(center @ down)  # how far the centre is below the optical centre
    cx, cy = (out_w - 1) / 2.0, (out_h - 1) / 2.0 - f * below / distance
    K_virtual_inverse = np.array(
        [[1.0 / f, 0.0, -cx / f], [0.0, 1.0 / f, -cy / f], [0.0, 0.0, 1.0]]
    )
    return np.asarray(K, dtype=np.float64) @ camera_R_virtual @ K_virtual_inverse


def window_footprint(
    window_to_image: np.ndarray, shape: tuple[int, int]
) -> tuple[int, int, int, int]:
    """The image pixels (u0, v0, u1, v1), half-open and clipped, a window covers."""
    out_w, out_h = HOG_WINDOW
    h = window_to_image.tolist()  # four corners: plain floats beat small numpy arrays
    us, vs = [], []
    for x, y in ((0, 0), (out_w - 1, 0), (0, out_h - 1), (out_w - 1, out_h - 1)):
        w = h[2][0] * x + h[2][1] * y + h[2][2]
        us.append((h[0][0] * x + h[0][1] * y + h[0][2]) / w)
        vs.append((h[1][0] * x + h[1][1] * y + h[1][2]) / w)
    rows, cols = shape
    u0 = int(min(max(math.floor(min(us)), 0), cols))
    u1 = int(min(max(math.ceil(max(us)) + 1, 0), cols))
    v0 = int(min(max(math.floor(min(vs)), 0), rows))
    v1 = int(min(max(math.ceil(max(vs)) + 1, 0), rows))
    return u0, v0, u1, v1


def person_window(
    image: np.ndarray,
    window_to_image: np.ndarray,
    origin: tuple[int, int] = (0, 0),
    stride: int = 1,
    mirror: bool = False,
    outside: int = 0,
) -> np.ndarray:
    """The 64x128 window, sampled bilinearly from ``image``, ``outside`` (black) outside
    it (``mirror``: the image mirrored at its borders outside it).

    ``image`` may be a strided crop of the full image whose pixel (0, 0) is the
    full image's ``origin`` (u, v) and whose pixels are ``stride`` apart.
    """
    u0, v0 = origin
    if (u0, v0, stride) != (0, 0, 1):
        full_to_crop = np.array(
            [[1.0 / stride, 0.0, -u0 / stride], [0.0, 1.0 / stride, -v0 / stride], [0.0, 0.0, 1.0]]
        )
        window_to_image = full_to_crop @ window_to_image
    return cv2.warpPerspective(
        image,
        window_to_image,
        HOG_WINDOW,
        flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
        borderMode=cv2.BORDER_REFLECT if mirror else cv2.BORDER_CONSTANT,
        borderValue=outside,
    )


def luminance(image: np.ndarray) -> float:
    """Mean luminance (0-255) of an RGB image (OpenPTrack's 0.3 R + 0.59 G + 0.11 B)."""
    pixels = max(image.shape[0] * image.shape[1], 1)
    # cv2.sumElems over cv2.mean: the same means, a tenth of the time on 3 channels.
    return float(np.asarray(cv2.sumElems(image)[:3]) @ LUMA) / pixels


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
    return (hist.astype(np.float64) / total).tolist() if total > 0 else []
