"""Sensor models: what a real RGB-D sensor makes of the ideal ray-cast image.

Each model has intrinsics, a frame rate, a working range, timestamp jitter
and a noise model with its sources in its docstring. ``measure`` turns a
:class:`~optrack.sim.render.RenderResult` (true depth, incidence, albedo,
radiance) into the images the sensor delivers: depth in millimetres
(uint16, 0 invalid) and, as the device has them, colour (RGB uint8,
registered to the depth image), infrared (uint16) and confidence (uint16).
With ``noise=False`` a model is ideal: exact depth inside its range and
clean images, for tests against ground truth.

``depth_sigma`` is each model's axial noise formula (metres, 1 sigma); the
rendered noise follows it (tests hold it to within 20 %).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from optrack.params import Param, Params, Schema, register
from optrack.sim.sensor_model import (
    COLOR_PARAMS,
    UINT16_MAX,
    Measurement,
    SensorModel,
    flying_pixels,
    gaussian,
    to_millimetres,
)
from optrack.types import Intrinsics

__all__ = [
    "COLOR_PARAMS",
    "MODELS",
    "Kinect1",
    "Kinect2",
    "Measurement",
    "SR4500",
    "SensorModel",
    "Stereo",
    "TimeOfFlight",
    "make_model",
]


# ----------------------------------------------------------------- Kinect v1

KINECT1_PARAMS = register(
    Schema(
        "sim_kinect1",
        [
            Param(
                "resolution",
                "640x480",
                choices=("640x480", "320x240"),
                help="Depth and colour image size.",
            ),
            Param("fx", 525.0, 100, 2000, 0.1, "px", "Focal length at 640x480."),
            Param("fy", 525.0, 100, 2000, 0.1, "px", "Focal length at 640x480."),
            Param("cx", 319.5, 0, 640, 0.1, "px", "Principal point at 640x480."),
            Param("cy", 239.5, 0, 480, 0.1, "px", "Principal point at 640x480."),
            Param("fps", 30.0, 1, 60, 1, "Hz", "Frame rate."),
            Param("min_range", 0.8, 0.3, 5, 0.05, "m", "Nearest valid depth."),
            Param("max_range", 8.0, 1, 15, 0.1, "m", "Farthest valid depth."),
            Param(
                "baseline", 0.075, 0.01, 0.5, 0.001, "m", "Projector to infrared camera distance."
            ),
            Param("disparity_noise", 0.05, 0.0, 2.0, 0.005, "px", "Disparity noise (1 sigma)."),
            Param(
                "disparity_step", 0.125, 0.0, 1.0, 0.005, "px", "Disparity quantisation (1/8 px)."
            ),
            Param("timestamp_jitter", 0.002, 0.0, 0.05, 0.0005, "s", "Timestamp jitter (1 sigma)."),
        ],
        help="Simulated Kinect v1 (structured light).",
    )
)


class Kinect1(SensorModel):
    """Microsoft Kinect v1 / PrimeSense Carmine: structured light.

    * Intrinsics 640x480, fx = fy = 525 px, principal point at the centre: the
      default calibration of ROS's openni_camera driver (also used by the TUM
      RGB-D benchmark for uncalibrated Kinects); 320x240 is the same camera halved.
    * Depth comes from disparity against a projected pattern over a baseline of
      7.5 cm, in 1/8 pixel steps: K. Konolige and P. Mihelich, "Technical
      description of Kinect calibration", ROS wiki (2011); K. Khoshelham and
      S. O. Elberink, "Accuracy and resolution of Kinect depth data for indoor
      mapping applications", Sensors 12 (2012), eq. 9-10.
    * Axial noise: Gaussian disparity noise, so depth noise grows with the square
      of the distance, sigma_z = z^2 / (f b) * sqrt(sigma_d^2 + q^2 / 12), with q
      the 1/8 px quantisation. sigma_d = 0.05 px reproduces Khoshelham and
      Elberink's ~4 cm at 5 m and Nguyen, Izadi and Lovell's fit
      (0.0012 + 0.0019 (z - 0.4)^2 m, 3DIMPVT 2012) within 10 % from 2 to 6 m.
    * Range 0.8-8 m (Microsoft specifies 0.8-4 m; OpenNI returns depth to ~8 m);
      30 fps; pixels the projector cannot light (its shadow) have no depth.
    """

    name = "kinect1"
    schema = KINECT1_PARAMS
    streams = ("depth", "color")

    @property
    def scale(self) -> float:
        return 0.5 if self.params.resolution == "320x240" else 1.0

    @property
    def width(self) -> int:  # type: ignore[override]
        return round(640 * self.scale)

    @property
    def height(self) -> int:  # type: ignore[override]
        return round(480 * self.scale)

    @property
    def intrinsics(self) -> Intrinsics:
        p = self.params
        return Intrinsics(p.fx, p.fy, p.cx, p.cy, 640, 480).scaled(self.scale)

    @property
    def second_view(self) -> float | None:
        return float(self.params.baseline)

    def _fb(self) -> float:
        return self.intrinsics.fx * self.params.baseline

    def depth_sigma(self, z, cos_incidence=1.0, albedo=1.0):  # noqa: ANN001, ANN201
        p = self.params
        return (
            np.asarray(z) ** 2
            / self._fb()
            * math.sqrt(p.disparity_noise**2 + p.disparity_step**2 / 12)
        )

    def measure(self, render, rng, noise=True):  # noqa: ANN001, ANN201
        p = self.params
        z = render.depth
        valid = np.isfinite(z)
        if render.second_view_blocked is not None:
            valid &= ~render.second_view_blocked
        if noise:
            fb = self._fb()
            with np.errstate(divide="ignore", invalid="ignore"):
                disparity = fb / z + p.disparity_noise * gaussian(z.shape, rng)
                if p.disparity_step > 0:
                    disparity = np.rint(disparity / p.disparity_step) * p.disparity_step
                z = fb / disparity
            valid &= np.isfinite(z) & (z > 0)
        valid &= self.in_range(z)
        return Measurement(to_millimetres(z, valid), color=self._color(render, rng, noise))


def _time_of_flight_edges(flying_probability: float) -> list[Param]:
    """The grazing-angle and mixed-pixel parameters of the time-of-flight models."""
    return [
        Param(
            "max_incidence_deg",
            80.0,
            30,
            89,
            1,
            "deg",
            "Grazing surfaces beyond this give no depth.",
        ),
        Param(
            "flying_threshold",
            0.1,
            0.01,
            2.0,
            0.01,
            "m",
            "Depth jump that makes an edge for mixed pixels.",
        ),
        Param(
            "flying_relative",
            0.05,
            0.0,
            1.0,
            0.01,
            "",
            "The jump must also exceed this fraction of the nearer depth.",
        ),
        Param(
            "flying_probability",
            flying_probability,
            0.0,
            1.0,
            0.05,
            "",
            "Chance an edge pixel is a mixed (flying) pixel.",
        ),
    ]


# ----------------------------------------------------------------- Kinect v2

KINECT2_PARAMS = register(
    Schema(
        "sim_kinect2",
        [
            Param("fx", 365.5, 100, 2000, 0.1, "px", "Depth camera focal length."),
            Param("fy", 365.5, 100, 2000, 0.1, "px", "Depth camera focal length."),
            Param("cx", 254.9, 0, 512, 0.1, "px", "Principal point."),
            Param("cy", 205.4, 0, 424, 0.1, "px", "Principal point."),
            Param("fps", 30.0, 1, 60, 1, "Hz", "Frame rate."),
            Param("min_range", 0.4, 0.1, 5, 0.05, "m", "Nearest valid depth."),
            Param("max_range", 10.0, 1, 20, 0.1, "m", "Farthest valid depth."),
            Param("noise_a", 0.0015, 0.0, 0.05, 0.0001, "m", "Axial noise: constant term."),
            Param("noise_b", -0.0005, -0.05, 0.05, 0.0001, "m/m", "Axial noise: linear term."),
            Param("noise_c", 0.0003, 0.0, 0.05, 0.0001, "m/m2", "Axial noise: quadratic term."),
            Param(
                "noise_angle", 0.0001, 0.0, 0.05, 0.0001, "m", "Axial noise: incidence-angle term."
            ),
            *_time_of_flight_edges(0.5),
            Param(
                "ir_gain",
                20000.0,
                100,
                65535,
                100,
                "DN",
                "Infrared value of a white target at 1 m.",
            ),
            Param(
                "ir_noise",
                1.0,
                0.0,
                20.0,
                0.1,
                "DN",
                "Infrared shot noise: sigma = ir_noise * sqrt(value).",
            ),
            Param("min_amplitude", 20.0, 0.0, 1000, 1, "DN", "Weaker returns give no depth."),
            Param("timestamp_jitter", 0.002, 0.0, 0.05, 0.0005, "s", "Timestamp jitter (1 sigma)."),
        ],
        help="Simulated Kinect v2 (time of flight).",
    )
)


class TimeOfFlight(SensorModel):
    """What the time-of-flight models share: amplitude falling as albedo x
    cos(theta) / r^2, invalid weak or grazing returns, Gaussian axial noise from
    :meth:`pixel_sigma`, mixed pixels at depth edges, shot noise on the amplitude."""

    def pixel_sigma(
        self, z: np.ndarray, cos: np.ndarray, albedo: np.ndarray, scale: np.ndarray
    ) -> np.ndarray:
        raise NotImplementedError

    def pixel_amplitude(
        self, z: np.ndarray, cos: np.ndarray, albedo: np.ndarray, scale: np.ndarray
    ) -> np.ndarray:
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            r = z * scale
            amplitude = np.float32(self.params.ir_gain) * albedo * cos / (r * r)
        amplitude[~np.isfinite(amplitude)] = 0.0
        return amplitude.astype(np.float32)

    def pixel_valid(
        self, z: np.ndarray, cos: np.ndarray, albedo: np.ndarray, scale: np.ndarray
    ) -> np.ndarray:
        p = self.params
        return (
            np.isfinite(z)
            & (self.pixel_amplitude(z, cos, albedo, scale) >= p.min_amplitude)
            & (cos >= math.cos(math.radians(p.max_incidence_deg)))
        )

    def _sigma_of_valid(
        self, z: np.ndarray, cos: np.ndarray, albedo: np.ndarray, scale: np.ndarray
    ) -> np.ndarray:
        valid = np.isfinite(z) & (albedo > 0)
        sigma = np.zeros(z.shape, dtype=np.float32)
        sigma[valid] = self.pixel_sigma(z[valid], cos[valid], albedo[valid], scale[valid])
        return sigma

    def measure(self, render, rng, noise=True):  # noqa: ANN001, ANN201
        p = self.params
        z = render.depth
        amplitude = self.per_pixel(render, "amplitude", self.pixel_amplitude)
        valid = self.per_pixel(render, "valid", self.pixel_valid)
        if noise:
            sigma = self.per_pixel(render, "sigma", self._sigma_of_valid)
            z = z + sigma * gaussian(z.shape, rng)
            z = flying_pixels(
                z, 2 * p.max_range, p.flying_threshold, p.flying_relative, p.flying_probability, rng
            )
            amplitude += p.ir_noise * np.sqrt(amplitude) * gaussian(z.shape, rng)
        valid &= self.in_range(z)
        amplitude = np.clip(amplitude, 0, UINT16_MAX)
        return Measurement(
            to_millimetres(z, valid),
            color=self._color(render, rng, noise),
            infrared=amplitude.astype(np.uint16),
            confidence=self.confidence(amplitude, valid),
        )

    def confidence(self, amplitude: np.ndarray, valid: np.ndarray) -> np.ndarray | None:
        return None


class Kinect2(TimeOfFlight):
    """Microsoft Kinect v2 (Kinect for Xbox One): continuous-wave time of flight.

    * Depth 512x424, 70.6 x 60 degrees, 30 fps (Microsoft's specification);
      intrinsics are typical factory values read by libfreenect2
      (fx = fy ~ 365.5 px, cx ~ 254.9, cy ~ 205.4). Colour is the 512x424
      image registered to depth, as libfreenect2's ``Registration`` gives.
    * Range 0.4-10 m: Microsoft specifies 0.5-4.5 m, libfreenect2 reads returns
      from 0.4 m and far beyond 4.5 m with the limit lifted.
    * Axial noise nearly constant with distance (millimetres over the whole
      range): the fit of P. Fankhauser et al., "Kinect v2 for mobile robot
      navigation: evaluation and modeling", ICAR 2015, eq. 2,
      sigma_z = 1.5 mm - 0.5 mm z + 0.3 mm z^2 + 0.1 mm z^1.5 theta^2 / (pi/2 - theta)^2,
      with theta the incidence angle.
    * Flying (mixed) pixels at depth edges, where a pixel integrates light from
      both the foreground and the background (Fankhauser et al., section III-E;
      Lefloch et al. 2013).
    * Infrared amplitude: active illumination falls off as albedo x cos(theta)
      / r^2; weak returns are invalid.
    """

    name = "kinect2"
    schema = KINECT2_PARAMS
    streams = ("depth", "color", "infrared")
    width = 512
    height = 424

    def depth_sigma(self, z, cos_incidence=1.0, albedo=1.0):  # noqa: ANN001, ANN201
        p = self.params
        z = np.asarray(z, dtype=np.float32)
        theta = np.minimum(
            np.arccos(np.clip(np.asarray(cos_incidence, dtype=np.float32), 0.0, 1.0)),
            np.float32(math.radians(p.max_incidence_deg)),
        )
        angle = z * np.sqrt(z) * theta**2 / (np.float32(math.pi / 2) - theta) ** 2
        return p.noise_a + p.noise_b * z + p.noise_c * z * z + p.noise_angle * angle

    def pixel_sigma(self, z, cos, albedo, scale):  # noqa: ANN001, ANN201
        return self.depth_sigma(z, cos)


# -------------------------------------------------------------------- SR4500

SR4500_PARAMS = register(
    Schema(
        "sim_sr4500",
        [
            Param("fx", 128.0, 20, 1000, 0.1, "px", "Focal length (69 degrees over 176 px)."),
            Param("fy", 138.0, 20, 1000, 0.1, "px", "Focal length (55 degrees over 144 px)."),
            Param("cx", 87.5, 0, 176, 0.1, "px", "Principal point."),
            Param("cy", 71.5, 0, 144, 0.1, "px", "Principal point."),
            Param("fps", 13.0, 1, 60, 0.5, "Hz", "Frame rate."),
            Param("min_range", 0.4, 0.1, 5, 0.05, "m", "Nearest valid depth."),
            Param("max_range", 9.0, 1, 15, 0.1, "m", "Farthest valid depth."),
            Param(
                "noise_ref",
                0.004,
                0.0,
                0.1,
                0.0005,
                "m",
                "Axial noise (1 sigma) at the reference distance.",
            ),
            Param("noise_ref_distance", 2.0, 0.5, 10, 0.1, "m", "Reference distance of noise_ref."),
            Param(
                "noise_ref_albedo",
                0.8,
                0.05,
                1.0,
                0.05,
                "",
                "Reference (white target) infrared albedo.",
            ),
            *_time_of_flight_edges(0.6),
            Param("ir_gain", 30000.0, 100, 65535, 100, "DN", "Amplitude of a white target at 1 m."),
            Param(
                "ir_noise",
                1.0,
                0.0,
                20.0,
                0.1,
                "DN",
                "Amplitude shot noise: sigma = ir_noise * sqrt(value).",
            ),
            Param("min_amplitude", 30.0, 0.0, 1000, 1, "DN", "Weaker returns give no depth."),
            Param(
                "confidence_half",
                500.0,
                1.0,
                65535,
                1,
                "DN",
                "Amplitude at which confidence is one half.",
            ),
            Param(
                "timestamp_jitter",
                0.004,
                0.0,
                0.05,
                0.0005,
                "s",
                "Timestamp jitter (1 sigma), Ethernet.",
            ),
        ],
        help="Simulated MESA SwissRanger SR4500 (time of flight).",
    )
)


class SR4500(TimeOfFlight):
    """MESA Imaging SwissRanger SR4500: time of flight, no colour camera.

    * 176x144 pixels over 69 x 55 degrees, range to 9 m (MESA SR4500 data
      sheet); near limit 0.4 m and about 13 fps as run in OpenPTrack networks
      (optrack issue 3).
    * Axial noise of a continuous-wave ToF pixel is inversely proportional to
      the received amplitude (R. Lange and P. Seitz, "Solid-state time-of-flight
      range camera", IEEE J. Quantum Electronics 37(3), 2001, eq. 13), and the
      amplitude falls as albedo x cos(theta) / r^2, so
      sigma_z = sigma_ref (r / r_ref)^2 (albedo_ref / albedo) / cos(theta);
      sigma_ref = 4 mm at 2 m on a white target matches the data sheet's
      repeatability.
    * Confidence image: amplitude / (amplitude + confidence_half), 16-bit,
      larger is better, as MESA's driver gives a confidence map; mixed pixels at
      depth edges as every ToF camera.
    """

    name = "sr4500"
    schema = SR4500_PARAMS
    streams = ("depth", "infrared", "confidence")
    width = 176
    height = 144

    def depth_sigma(self, z, cos_incidence=1.0, albedo=None):  # noqa: ANN001, ANN201
        p = self.params
        albedo = p.noise_ref_albedo if albedo is None else albedo
        cos_incidence = np.maximum(np.asarray(cos_incidence, dtype=np.float32), 0.05)
        ratio = np.asarray(z, dtype=np.float32) / np.float32(p.noise_ref_distance)
        return (
            p.noise_ref
            * ratio
            * ratio
            * (p.noise_ref_albedo / np.maximum(albedo, 0.01))
            / cos_incidence
        )

    def pixel_sigma(self, z, cos, albedo, scale):  # noqa: ANN001, ANN201
        return self.depth_sigma(z * scale, cos, albedo)

    def confidence(self, amplitude: np.ndarray, valid: np.ndarray) -> np.ndarray:
        half = np.float32(self.params.confidence_half)
        confidence = np.where(valid, amplitude / (amplitude + half), 0.0)
        return np.rint(confidence * UINT16_MAX).astype(np.uint16)


# -------------------------------------------------------------------- stereo

STEREO_PARAMS = register(
    Schema(
        "sim_stereo",
        [
            Param("fx", 494.0, 100, 3000, 0.1, "px", "Focal length (66 degrees over 640 px)."),
            Param("fy", 494.0, 100, 3000, 0.1, "px", "Focal length."),
            Param("cx", 319.5, 0, 640, 0.1, "px", "Principal point."),
            Param("cy", 239.5, 0, 480, 0.1, "px", "Principal point."),
            Param("fps", 20.0, 1, 60, 1, "Hz", "Frame rate."),
            Param("baseline", 0.12, 0.02, 1.0, 0.005, "m", "Distance between the two cameras."),
            Param(
                "min_range",
                0.5,
                0.1,
                5,
                0.05,
                "m",
                "Nearest valid depth (largest disparity searched).",
            ),
            Param("max_range", 10.0, 1, 30, 0.1, "m", "Farthest valid depth."),
            Param(
                "disparity_noise", 0.2, 0.0, 2.0, 0.01, "px", "Disparity matching noise (1 sigma)."
            ),
            Param(
                "disparity_step",
                0.0625,
                0.0,
                1.0,
                0.0025,
                "px",
                "Disparity quantisation (1/16 px).",
            ),
            Param("block_size", 9, 3, 31, 2, "px", "Matching window size."),
            Param(
                "texture_snr",
                1.0,
                0.0,
                20.0,
                0.1,
                "",
                "A window must vary this many times the image noise to match.",
            ),
            Param("timestamp_jitter", 0.001, 0.0, 0.05, 0.0005, "s", "Timestamp jitter (1 sigma)."),
        ],
        help="Simulated stereo camera pair (passive, block matching).",
    )
)


class Stereo(SensorModel):
    """A passive stereo pair with block matching, e.g. a Point Grey Bumblebee2
    (640x480, 12 cm baseline, 66 degrees; Point Grey data sheet).

    * Depth from disparity, so a Gaussian disparity error gives the quadratic
      law sigma_z = z^2 / (f b) * sqrt(sigma_d^2 + q^2 / 12) (L. Matthies and
      S. Shafer, "Error modeling in stereo navigation", IEEE J. Robotics and
      Automation 3(3), 1987); sigma_d = 0.2 px is typical of semi-global
      matching (H. Hirschmueller, IEEE PAMI 30(2), 2008), q = 1/16 px is OpenCV's
      fixed-point disparity.
    * Holes where the matching window has no texture: a pixel is valid only
      when the local standard deviation of the (noise-free) left image exceeds
      ``texture_snr`` times the image noise, as OpenCV's StereoBM
      ``textureThreshold`` rejects flat windows; and where the right camera
      cannot see the point (occlusion, the left-right check).
    * The colour stream is the left image.
    """

    name = "stereo"
    schema = STEREO_PARAMS
    streams = ("depth", "color")
    width = 640
    height = 480

    @property
    def depth_needs_radiance(self) -> bool:
        return True

    @property
    def second_view(self) -> float | None:
        return float(self.params.baseline)

    def depth_sigma(self, z, cos_incidence=1.0, albedo=1.0):  # noqa: ANN001, ANN201
        p = self.params
        return (
            np.asarray(z) ** 2
            / (p.fx * p.baseline)
            * math.sqrt(p.disparity_noise**2 + p.disparity_step**2 / 12)
        )

    def textured(self, radiance: np.ndarray) -> np.ndarray:
        """Pixels whose matching window holds enough texture to match."""
        c = self.color_params
        grey = (radiance @ np.array([0.299, 0.587, 0.114], dtype=np.float32)) * np.float32(
            c.exposure * 255.0
        )
        size = (int(self.params.block_size),) * 2
        mean = cv2.boxFilter(grey, -1, size)
        mean_sq = cv2.boxFilter(grey * grey, -1, size)
        local_std = np.sqrt(np.maximum(mean_sq - mean * mean, 0.0))
        noise = np.sqrt(c.read_noise**2 + c.shot_noise * np.maximum(mean, 0.0))
        return local_std >= self.params.texture_snr * noise

    def measure(self, render, rng, noise=True):  # noqa: ANN001, ANN201
        p = self.params
        z = render.depth
        valid = np.isfinite(z) & self.textured(render.radiance)
        if render.second_view_blocked is not None:
            valid &= ~render.second_view_blocked
        if noise:
            fb = p.fx * p.baseline
            with np.errstate(divide="ignore", invalid="ignore"):
                disparity = fb / z + p.disparity_noise * gaussian(z.shape, rng)
                if p.disparity_step > 0:
                    disparity = np.rint(disparity / p.disparity_step) * p.disparity_step
                z = fb / disparity
            valid &= np.isfinite(z) & (z > 0)
        valid &= self.in_range(z)
        return Measurement(to_millimetres(z, valid), color=self._color(render, rng, noise))


MODELS: dict[str, type[SensorModel]] = {m.name: m for m in (Kinect2, Kinect1, SR4500, Stereo)}


def make_model(name: str, params: Params | None = None) -> SensorModel:
    """A sensor model by name (kinect2, kinect1, sr4500, stereo)."""
    try:
        return MODELS[name](params)
    except KeyError:
        from optrack.sim.scenario import ScenarioError

        raise ScenarioError(
            f"unknown sensor model '{name}'; use one of {', '.join(MODELS)}."
        ) from None
