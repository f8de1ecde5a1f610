"""What every simulated sensor model shares: the colour camera, noise helpers, flying
pixels at depth edges, and the :class:`SensorModel` base that turns a ray-cast
:class:`~optrack.sim.render.RenderResult` into a sensor's images (the models
themselves are in optrack/sim/models.py)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING, ClassVar

import cv2
import numpy as np

from optrack.params import Param, Params, Schema, register
from optrack.types import Intrinsics

if TYPE_CHECKING:
    from optrack.sim.render import RenderResult

UINT16_MAX = 65535
_KERNEL3 = np.ones((3, 3), np.uint8)

COLOR_PARAMS = register(
    Schema(
        "sim_color",
        [
            Param(
                "exposure",
                0.9,
                0.01,
                10.0,
                0.01,
                "",
                "Fraction of full scale a white, fully lit surface reaches.",
            ),
            Param(
                "gamma",
                2.2,
                1.0,
                3.0,
                0.1,
                "",
                "Display gamma applied to the linear image (sRGB-like).",
            ),
            Param(
                "read_noise", 1.5, 0.0, 20.0, 0.1, "DN", "Colour read noise, grey levels (1 sigma)."
            ),
            Param(
                "shot_noise",
                0.25,
                0.0,
                5.0,
                0.05,
                "DN",
                "Colour shot noise: variance per grey level of signal.",
            ),
        ],
        help="The colour cameras of the simulated sensors.",
    )
)


@dataclasses.dataclass
class Measurement:
    """The images one sensor delivers for one frame."""

    depth: np.ndarray  # uint16 millimetres, 0 invalid
    color: np.ndarray | None = None
    infrared: np.ndarray | None = None
    confidence: np.ndarray | None = None


def gaussian(shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
    """Standard normal float32 samples. OpenCV's generator (several times faster than
    NumPy's here), seeded from ``rng`` so that a seed still fixes every frame."""
    out = np.empty(shape, dtype=np.float32)
    cv2.setRNGSeed(int(rng.integers(1, 2**31 - 1)))
    cv2.randn(out, 0.0, 1.0)
    return out


def to_millimetres(z: np.ndarray, valid: np.ndarray) -> np.ndarray:
    out = np.zeros(z.shape, dtype=np.uint16)
    np.rint(z * 1000.0, out=out, where=valid, casting="unsafe")
    return out


def expose_color(
    radiance: np.ndarray, params: Params, rng: np.random.Generator, noise: bool
) -> np.ndarray:
    """An 8-bit RGB image from linear radiance (1 = a white, fully lit surface):
    shot and read noise in linear grey levels, then gamma encoding."""
    linear = radiance * (params.exposure * 255.0)
    if noise:
        sigma = np.sqrt(params.read_noise**2 + params.shot_noise * np.maximum(linear, 0.0))
        linear = linear + sigma * gaussian(linear.shape, rng)
    encoded = 255.0 * (np.clip(linear, 0.0, 255.0) / 255.0) ** (1.0 / params.gamma)
    return np.rint(encoded).astype(np.uint8)


def flying_pixels(
    z: np.ndarray,
    far: float,
    threshold: float,
    relative: float,
    probability: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """Time-of-flight mixed pixels: where a 3x3 neighbourhood spans a depth jump wider
    than ``threshold`` metres and ``relative`` times its nearest depth (a discontinuity,
    not a steep but continuous surface such as a far floor), a pixel (with
    ``probability``) returns a depth between the foreground and the background
    (Lefloch et al., "Technical foundation and calibration methods for time-of-flight
    cameras", LNCS 8200, 2013, section 4). No return (inf) counts as ``far``."""
    finite = np.minimum(z, np.float32(far))
    high = cv2.dilate(finite, _KERNEL3)
    low = cv2.erode(finite, _KERNEL3)
    jump = cv2.subtract(high, low)
    edges = np.flatnonzero((jump > threshold) & (jump > np.float32(relative) * low))
    chosen = edges[rng.random(len(edges)) < probability]
    if len(chosen) == 0:
        return z
    mix = rng.random(len(chosen), dtype=np.float32)
    out = z.copy()
    near = low.reshape(-1)[chosen]
    out.reshape(-1)[chosen] = near + mix * (high.reshape(-1)[chosen] - near)
    return out


PixelFunction = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def _flat(render: RenderResult, index: np.ndarray) -> tuple[np.ndarray, ...]:
    infrared = render.infrared_albedo
    return (
        render.depth.ravel()[index],
        render.cos_incidence.ravel()[index],
        np.ones(len(index), np.float32) if infrared is None else infrared.ravel()[index],
        render.ray_scale.ravel()[index],
    )


class SensorModel:
    """A sensor model: its parameters (a registered schema) and its noise."""

    name: ClassVar[str]
    schema: ClassVar[Schema]
    streams: ClassVar[tuple[str, ...]]
    width: ClassVar[int]
    height: ClassVar[int]

    def __init__(self, params: Params | None = None, color: Params | None = None) -> None:
        self.params = params if params is not None else self.schema.create()
        self.color_params = color if color is not None else COLOR_PARAMS.create()
        self._venue_cache: dict[tuple[str, int], tuple[RenderResult, np.ndarray]] = {}

    def per_pixel(self, render: RenderResult, name: str, function: PixelFunction) -> np.ndarray:
        """``function(depth, cos_incidence, infrared_albedo, ray_scale)`` of every pixel
        (flat arrays in, flat array out), as an image. What depends only on the venue
        is computed once per renderer and reused; only changed pixels are recomputed."""
        venue = render.venue
        key = (name, id(venue))
        entry = self._venue_cache.get(key)
        if entry is None or entry[0] is not venue:
            entry = (venue, function(*_flat(venue, np.arange(venue.depth.size))))
            self._venue_cache[key] = entry
        out = entry[1].copy()
        if render is not venue and len(render.changed):
            out[render.changed] = function(*_flat(render, render.changed))
        return out.reshape(render.depth.shape)

    # What the renderer must produce for this model.
    @property
    def needs_radiance(self) -> bool:
        return "color" in self.streams

    @property
    def needs_infrared(self) -> bool:
        return "infrared" in self.streams

    @property
    def depth_needs_radiance(self) -> bool:
        """Whether depth itself depends on the image (passive stereo matches texture)."""
        return False

    @property
    def second_view(self) -> float | None:
        """Offset (m, camera x) of a second viewpoint that must also see a point: the
        projector of a structured-light sensor, the right camera of a stereo pair."""
        return None

    @property
    def intrinsics(self) -> Intrinsics:
        p = self.params
        return Intrinsics(p.fx, p.fy, p.cx, p.cy, self.width, self.height)

    @property
    def fps(self) -> float:
        return float(self.params.fps)

    @property
    def min_range(self) -> float:
        return float(self.params.min_range)

    @property
    def max_range(self) -> float:
        return float(self.params.max_range)

    @property
    def jitter(self) -> float:
        return float(self.params.timestamp_jitter)

    def depth_sigma(
        self,
        z: np.ndarray,
        cos_incidence: np.ndarray | float = 1.0,
        albedo: np.ndarray | float = 1.0,
    ) -> np.ndarray:
        """Axial depth noise, metres (1 sigma), at depth ``z``."""
        raise NotImplementedError

    def in_range(self, z: np.ndarray) -> np.ndarray:
        return (z >= self.min_range) & (z <= self.max_range)

    def measure(
        self, render: RenderResult, rng: np.random.Generator, noise: bool = True
    ) -> Measurement:
        raise NotImplementedError

    def _color(
        self, render: RenderResult, rng: np.random.Generator, noise: bool
    ) -> np.ndarray | None:
        if render.radiance is None:
            return None
        return expose_color(render.radiance, self.color_params, rng, noise)
