"""A person classifier trained on depth alone (OpenPTrack's paper, section 5.3).

Kinect v1 cannot stream infrared and depth at once, so in the dark the
detector has depth only. A candidate's window is made as for colour (a
virtual level camera turned towards the person, who fills
``hog_window_fill`` of a 64x128 window) twice:

- its **silhouette**: the window's pixels near the person's axis, above the
  floor and below their head, white on black;
- its **relative depth**: every pixel's depth relative to the median depth of
  the person's own pixels, clipped to +-``RELATIVE_RANGE`` and scaled to
  0-255 (the person mid-grey, what is in front of them darker, what is behind
  them lighter; pixels without depth count as far), so that the window looks
  the same at any distance and on any sensor.

The features are the relative depth's HOG descriptor (OpenCV's
``HOGDescriptor`` with non-overlapping 16x16 blocks: 1152 values) and the
silhouette's score by OpenCV's default people detector (Dalal and Triggs'
SVM, trained on photographs of real people); a linear model on them is
trained here on simulated recordings (:mod:`optrack.sim.depth_training`, ``optrack train
depth-classifier``): logistic regression, so the score is the log-odds of a
person and ``min_depth_model_confidence`` is its threshold.

Why these two: trained on simulated depth, the silhouette's own HOG did not
carry over to real Kinect frames (PCL's five_people.pcd and office1.pcd: a
non-person scored above a person), the relative depth's did, and the people
detector's score of the silhouette, made from real people, adds to it
(docs/detection.md has the figures).

The shipped model is ``optrack/resources/models/depth_classifier.npz``
(weights, bias and what it was trained on).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from optrack.detection.classifier import HogClassifier
from optrack.errors import UserError
from optrack.resources import resource_path

__all__ = [
    "DESCRIPTOR_SIZE",
    "FEATURES",
    "DepthClassifier",
    "default_depth_classifier",
    "feature_hog",
    "depth_descriptor",
    "relative_depth",
]

#: The shipped model, inside the package's resources.
MODEL_PARTS = ("models", "depth_classifier.npz")
#: What the features are: a model trained on other features is refused.
FEATURES = "hog16-relative-depth-0.6m+silhouette-people-detector"
#: Depth relative to the person's median, clipped to this (metres) either side.
RELATIVE_RANGE = 0.6
#: HOG on the 64x128 window: 16x16 blocks without overlap, 8x8 cells, 9 bins.
_HOG_LAYOUT = ((64, 128), (16, 16), (16, 16), (8, 8), 9)


def feature_hog() -> cv2.HOGDescriptor:
    """The HOG of the relative depth window (see the module docstring)."""
    return cv2.HOGDescriptor(*_HOG_LAYOUT)


#: Values of one descriptor: the relative depth's HOG and the silhouette's score.
DESCRIPTOR_SIZE = feature_hog().getDescriptorSize() + 1


def relative_depth(z: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """An 8-bit image of depths ``z`` (metres, NaN where none) relative to the median of
    the ``mask`` pixels: 128 at the median, 0 nearer by ``RELATIVE_RANGE``, 255 farther
    by it or without depth."""
    own = z[mask]
    if own.size == 0:
        return np.full(z.shape, 255, dtype=np.uint8)
    median = float(np.median(own))
    with np.errstate(invalid="ignore"):
        scaled = (z - median) * (127.5 / RELATIVE_RANGE) + 127.5
    scaled = np.nan_to_num(scaled, nan=255.0)
    return np.clip(scaled, 0.0, 255.0).astype(np.uint8)


def depth_descriptor(
    hog: cv2.HOGDescriptor, people: HogClassifier, silhouette: np.ndarray, relative: np.ndarray
) -> np.ndarray:
    """The classifier's features (float32, ``DESCRIPTOR_SIZE``) of one candidate's two
    64x128 windows: the relative depth's HOG, the silhouette's people-detector score."""
    out = np.empty(DESCRIPTOR_SIZE, dtype=np.float32)
    out[:-1] = hog.compute(np.ascontiguousarray(relative)).ravel()
    out[-1] = people.score(silhouette)
    return out


class DepthClassifier:
    """A linear model on the HOG descriptors of a candidate's depth windows."""

    def __init__(self, weights: np.ndarray, bias: float, info: dict[str, Any] | None = None):
        self.weights = np.asarray(weights, dtype=np.float64).ravel()
        self.bias = float(bias)
        self.info = dict(info or {})
        self.hog = feature_hog()
        self.people = HogClassifier()
        if len(self.weights) != DESCRIPTOR_SIZE:
            raise UserError(
                f"depth classifier has {len(self.weights)} weights, not the "
                f"{DESCRIPTOR_SIZE} of its features; train it again."
            )

    def descriptor(self, silhouette: np.ndarray, relative: np.ndarray) -> np.ndarray:
        return depth_descriptor(self.hog, self.people, silhouette, relative)

    def score(self, silhouette: np.ndarray, relative: np.ndarray) -> float:
        """The log-odds that the windows show a person."""
        return float(self.descriptor(silhouette, relative) @ self.weights + self.bias)

    def scores(self, descriptors: np.ndarray) -> np.ndarray:
        """Log-odds of descriptors (N x ``DESCRIPTOR_SIZE``)."""
        return np.asarray(descriptors, dtype=np.float64) @ self.weights + self.bias

    def save(self, path: str | Path) -> None:
        """Write the model (NumPy .npz: weights, bias, and its description as JSON)."""
        info = json.dumps({**self.info, "features": FEATURES}, sort_keys=True)
        with open(path, "wb") as out:
            np.savez_compressed(
                out, weights=self.weights.astype(np.float32), bias=self.bias, info=info
            )

    @classmethod
    def load(cls, path: str | Path) -> DepthClassifier:
        """A model written by :meth:`save`; a missing or foreign file is a UserError."""
        try:
            with np.load(path, allow_pickle=False) as data:
                weights, bias = data["weights"], float(data["bias"])
                info = json.loads(str(data["info"]))
        except FileNotFoundError:
            raise UserError(f"depth classifier {path} does not exist.") from None
        except (OSError, ValueError, KeyError) as error:
            raise UserError(
                f"depth classifier {path} is not a model written by "
                f"'optrack train depth-classifier' ({error})."
            ) from None
        if info.get("features") != FEATURES:
            raise UserError(
                f"depth classifier {path} was trained on '{info.get('features')}', "
                f"not '{FEATURES}'; train it again."
            )
        return cls(weights, bias, info)


_LOADED: dict[str, DepthClassifier] = {}


def default_depth_classifier(path: str = "") -> DepthClassifier:
    """The model in ``path``, or the shipped one for "" (each read once)."""
    if path not in _LOADED:
        _LOADED[path] = DepthClassifier.load(path or resource_path(*MODEL_PARTS))
    return _LOADED[path]
