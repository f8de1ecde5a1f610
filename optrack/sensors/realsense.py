"""Intel RealSense cameras (D400, L500, SR300) through pyrealsense2, an optional extra.

``realsense://<serial>`` opens the camera with that serial number (empty:
the first attached). pyrealsense2 is not one of optrack's pinned
dependencies: install it with ``.venv/bin/pip install pyrealsense2``. It is
imported only when a RealSense camera is opened or listed.

Streams: depth (uint16 with the device's depth scale), colour (RGB) and the
left infrared imager, which shares the depth camera's viewpoint. With
``align`` on, colour is re-projected into the depth camera (registered), so
every stream has the depth image's size and the depth intrinsics. Intrinsics
and distortion come from the device's calibration.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from optrack.params import Param, Schema, register
from optrack.recording.format import SensorInfo
from optrack.sensors.base import SensorError, stream_mode_params
from optrack.sensors.live import DeviceLost, LiveSensor, Mode, live_params, nearest_mode
from optrack.types import Intrinsics, RGBDFrame

__all__ = ["REALSENSE_PARAMS", "RealSenseSensor", "attached_devices", "import_pyrealsense2"]

log = logging.getLogger(__name__)

REALSENSE_PARAMS = register(
    Schema(
        "realsense",
        [
            *stream_mode_params(max_fps=300),
            Param("color", True, help="Capture colour when the device has a colour camera."),
            Param("infrared", False, help="Capture the left infrared image."),
            Param(
                "align",
                True,
                help="Re-project colour into the depth camera so that both are registered.",
            ),
            *live_params(),
        ],
        help="Intel RealSense cameras (realsense:// URIs).",
    )
)

_INSTALL = "install it into the project with '.venv/bin/pip install pyrealsense2'"


def import_pyrealsense2() -> Any:
    """The pyrealsense2 module, or a SensorError saying how to install it."""
    try:
        import pyrealsense2
    except ImportError:
        raise SensorError(
            f"RealSense cameras need the optional pyrealsense2 package, which is not installed; "
            f"{_INSTALL}."
        ) from None
    return pyrealsense2


def _info(device: Any, rs: Any, field: str) -> str:
    key = getattr(rs.camera_info, field)
    try:
        return str(device.get_info(key)) if device.supports(key) else ""
    except RuntimeError:
        return ""


def attached_devices() -> list[dict[str, str]]:
    """RealSense cameras librealsense sees: ``serial``, ``name``, ``product_id``, ``port``."""
    rs = import_pyrealsense2()
    out = []
    for device in rs.context().query_devices():
        out.append(
            {
                "serial": _info(device, rs, "serial_number"),
                "name": _info(device, rs, "name"),
                "product_id": _info(device, rs, "product_id").lower(),
                "port": _info(device, rs, "physical_port"),
            }
        )
    return out


def _intrinsics(rs: Any, intr: Any) -> Intrinsics:
    coeffs = tuple(float(c) for c in intr.coeffs)
    opencv_like = intr.model in (rs.distortion.brown_conrady, rs.distortion.modified_brown_conrady)
    dist: tuple[float, ...] = coeffs[:5] if opencv_like and any(coeffs) else ()
    if not opencv_like and any(coeffs):
        log.info("RealSense distortion model %s is not OpenCV's; it is left out.", intr.model)
    return Intrinsics(
        fx=float(intr.fx),
        fy=float(intr.fy),
        cx=float(intr.ppx),
        cy=float(intr.ppy),
        width=int(intr.width),
        height=int(intr.height),
        dist=dist,
    )


class RealSenseSensor(LiveSensor):
    """One RealSense camera (see the module docstring)."""

    backend = "RealSense"
    id_prefix = "realsense"

    schema = REALSENSE_PARAMS
    scheme = "realsense"

    def _init_backend(self) -> None:
        import_pyrealsense2()  # fail at once, with the sentence, when it is missing
        self.model = ""
        self.modes: dict[str, Mode] = {}
        self._pipeline: Any = None
        self._align: Any = None
        self._depth_scale = 0.001
        self._intrinsics: Intrinsics | None = None
        self._color_intrinsics: Intrinsics | None = None
        self._last_number: int | None = None
        self._seq = 0

    def _find(self, rs: Any) -> Any:
        devices = list(rs.context().query_devices())
        for device in devices:
            if not self.target or _info(device, rs, "serial_number") == self.target:
                return device
        from optrack.sensors.uri import attached_summary

        seen = ", ".join(
            f"{_info(d, rs, 'name')} (realsense://{_info(d, rs, 'serial_number')})" for d in devices
        )
        what = f" with serial '{self.target}'" if self.target else ""
        listed = f"librealsense sees: {seen}" if seen else attached_summary()
        raise SensorError(
            f"no RealSense camera{what} is attached ({listed}); check its cable, or use a URI "
            "that 'optrack sensors' lists."
        )

    def _profiles(self, rs: Any, device: Any, stream: Any, fmt: Any, index: int = -1) -> list[Mode]:
        modes = []
        for sensor in device.query_sensors():
            for profile in sensor.get_stream_profiles():
                if profile.stream_type() != stream or profile.format() != fmt:
                    continue
                if index >= 0 and profile.stream_index() != index:
                    continue
                video = profile.as_video_stream_profile()
                modes.append(Mode(video.width(), video.height(), float(profile.fps()), int(fmt)))
        return modes

    def _open_device(self) -> SensorInfo:
        rs = import_pyrealsense2()
        p = self.params
        device = self._find(rs)
        self.serial = _info(device, rs, "serial_number")
        self.model = _info(device, rs, "name") or "Intel RealSense"
        if self._id is None:
            self._id = self.sensor_id
        wanted = (int(p.width), int(p.height), float(p.fps))
        depth_modes = self._profiles(rs, device, rs.stream.depth, rs.format.z16)
        depth = nearest_mode(depth_modes, *wanted)
        if depth is None:
            raise SensorError(f"{self.describe()} offers no 16-bit depth stream.")
        self.modes = {"depth": depth}
        config = rs.config()
        config.enable_device(self.serial)
        config.enable_stream(
            rs.stream.depth, depth.width, depth.height, rs.format.z16, int(depth.fps)
        )
        self._enable_extra_streams(rs, device, config, depth)
        pipeline = rs.pipeline()
        try:
            profile = pipeline.start(config)
        except RuntimeError as error:
            raise SensorError(
                f"{self.describe()} could not start streaming ({error}); check that no other "
                "program uses it, or unplug and replug it."
            ) from None
        self._pipeline = pipeline
        self._depth_scale = float(profile.get_device().first_depth_sensor().get_depth_scale())
        depth_profile = profile.get_stream(rs.stream.depth).as_video_stream_profile()
        self._intrinsics = _intrinsics(rs, depth_profile.get_intrinsics())
        self._color_intrinsics = None
        self._align = None
        if "color" in self.modes:
            if p.align:
                self._align = rs.align(rs.stream.depth)
            else:
                color_profile = profile.get_stream(rs.stream.color).as_video_stream_profile()
                self._color_intrinsics = _intrinsics(rs, color_profile.get_intrinsics())
        self.clock.period = 1.0 / max(depth.fps, 1.0)
        self._last_number = None
        return SensorInfo(
            id=self.sensor_id,
            intrinsics=self._intrinsics,
            model=self.model,
            uri=self.uri,
            depth_scale=self._depth_scale,
            color_intrinsics=self._color_intrinsics,
            fps=float(depth.fps),
            streams=list(self.modes),
        )

    def _enable_extra_streams(self, rs: Any, device: Any, config: Any, depth: Mode) -> None:
        """Colour and infrared, where asked for, in the depth stream's mode and rate."""
        p = self.params
        if p.color:
            color = nearest_mode(
                [
                    m
                    for m in self._profiles(rs, device, rs.stream.color, rs.format.rgb8)
                    if m.fps == depth.fps
                ],
                depth.width,
                depth.height,
                depth.fps,
            )
            if color is not None:
                config.enable_stream(
                    rs.stream.color, color.width, color.height, rs.format.rgb8, int(color.fps)
                )
                self.modes["color"] = color
            else:
                log.warning("%s has no colour stream at %g Hz.", self.describe(), depth.fps)
        if p.infrared:
            ir = [
                m
                for m in self._profiles(rs, device, rs.stream.infrared, rs.format.y8, 1)
                if (m.width, m.height, m.fps) == (depth.width, depth.height, depth.fps)
            ]
            if ir:
                config.enable_stream(
                    rs.stream.infrared, 1, depth.width, depth.height, rs.format.y8, int(depth.fps)
                )
                self.modes["infrared"] = ir[0]
            else:
                log.warning("%s has no infrared stream in mode %s.", self.describe(), depth)

    def _close_device(self) -> None:
        pipeline, self._pipeline = self._pipeline, None
        if pipeline is not None:
            try:
                pipeline.stop()
            except RuntimeError:
                pass

    def _grab(self, timeout: float) -> RGBDFrame | None:
        if self._pipeline is None:
            raise DeviceLost("the device is closed")
        try:
            ok, frames = self._pipeline.try_wait_for_frames(max(int(timeout * 1000), 1))
        except RuntimeError as error:
            raise DeviceLost(str(error)) from None
        if not ok:
            return None
        if self._align is not None:
            frames = self._align.process(frames)
        depth_frame = frames.get_depth_frame()
        if not depth_frame:
            return None
        number = int(depth_frame.get_frame_number())
        if self._last_number is not None and number > self._last_number + 1:
            self.dropped += number - self._last_number - 1
        self._last_number = number
        depth = np.asanyarray(depth_frame.get_data()).copy()
        color = None
        if "color" in self.modes:
            color_frame = frames.get_color_frame()
            color = np.asanyarray(color_frame.get_data()).copy() if color_frame else None
        infrared = None
        if "infrared" in self.modes:
            ir_frame = frames.get_infrared_frame(1)
            infrared = np.asanyarray(ir_frame.get_data()).copy() if ir_frame else None
        seq = self._seq
        self._seq += 1
        assert self._intrinsics is not None
        return RGBDFrame(
            depth=depth,
            intrinsics=self._intrinsics,
            sensor_id=self.sensor_id,
            timestamp=self.clock.stamp(float(depth_frame.get_timestamp()) / 1000.0),
            depth_scale=self._depth_scale,
            color=color,
            infrared=infrared,
            color_intrinsics=self._color_intrinsics,
            seq=seq,
        )
