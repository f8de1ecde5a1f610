"""OpenNI2 cameras (Kinect v1, Asus Xtion, PrimeSense Carmine, Orbbec Astra) on Debian's libopenni2.

``openni://<serial, OpenNI URI or Dummy>`` opens a camera by its serial
number, by the URI OpenNI2 gives it (``1d27/0601@1/5``: vendor/product@bus/
address, as ``optrack sensors`` lists it), or OpenNI2's built-in test device
``Dummy`` (320x240 depth and colour at 30 fps). An empty target opens the
first camera attached.

What it does: depth (millimetres or 100 um, as uint16), colour (RGB) and
infrared when the device has them; the video mode nearest the ``openni``
parameters; depth-to-colour registration and depth/colour frame sync where
the device supports them; colour frames paired with depth frames by device
timestamp; intrinsics from the device's fields of view (or nominal PrimeSense
values when the driver reports none); reconnection after an unplug (see
:class:`~optrack.sensors.live.LiveSensor`).

Clean exit: Debian's OpenNI2 drivers keep a frame thread running shortly
after a stream is stopped, so destroying the stream at once (as the ``openni``
binding's exit hook does) can crash the process, and so can ``oniShutdown``
after the Dummy device streamed. This module replaces the binding's hook: at
exit it closes every open sensor and leaves the rest to the process exit.
Closing a sensor stops its streams (no sooner than three frame periods after
starting them: the Dummy driver crashes otherwise), waits two frame periods,
then destroys them and closes the device.

Closing from another thread: OpenNI2's ``oniWaitForAnyStream`` starts its
wait again whenever any stream in the process signals a frame, so one long
wait was seen never to return (a sensor reopened after another was closed
from a second thread). A read therefore waits in slices of
:data:`WAIT_SLICE_S`, checking between them whether the sensor is closing,
and ends within a few milliseconds of ``close()``.
"""

from __future__ import annotations

import collections
import ctypes
import logging
import math
import time
from typing import Any

import numpy as np

from optrack.params import Param, Schema, register
from optrack.recording.format import SensorInfo
from optrack.sensors.base import SensorError, stream_mode_params
from optrack.sensors.live import DeviceLost, LiveSensor, Mode, live_params, nearest_mode
from optrack.sensors.openni_library import (
    DUMMY,
    Library,
    attached_devices,
    error_text,
    initialize,
    intrinsics_from_fov,
    modules,
    open_failure,
    resolve_uri,
    serial_of,
    stream_fov,
    text,
)
from optrack.types import Intrinsics, RGBDFrame

__all__ = [
    "NOMINAL_FOV_DEG",
    "OPENNI_PARAMS",
    "OpenNISensor",
    "attached_devices",
    "intrinsics_from_fov",
]

log = logging.getLogger(__name__)

OPENNI_PARAMS = register(
    Schema(
        "openni",
        [
            *stream_mode_params(max_fps=120),
            Param("color", True, help="Capture colour when the device has a colour camera."),
            Param(
                "infrared",
                False,
                help=(
                    "Capture infrared when the device has it (PrimeSense cameras cannot send "
                    "infrared and colour together: turn colour off)."
                ),
            ),
            Param(
                "registration",
                True,
                help="Register depth to the colour camera when the device supports it.",
            ),
            Param(
                "sync", True, help="Ask for depth/colour frame sync when the device supports it."
            ),
            Param("mirror", False, help="Mirror the images left to right."),
            *live_params(),
            Param(
                "library_dir",
                "",
                help="Folder holding libOpenNI2.so (empty: the system's library folders).",
            ),
        ],
        help="OpenNI2 cameras (openni:// URIs).",
    )
)

#: Nominal fields of view (horizontal, vertical) in degrees from PrimeSense's
#: PS1080 data sheet (Kinect v1, Xtion, Carmine); used only when the driver
#: reports none (the Dummy device).
NOMINAL_FOV_DEG = (58.0, 45.0)

#: Longest single wait inside OpenNI2 for a frame (s); see ``OpenNISensor._grab``.
WAIT_SLICE_S = 0.005


class _Stream:
    """One started OpenNI2 stream of a sensor and its pixel conversion."""

    def __init__(self, kind: str, stream: Any, mode: Mode) -> None:
        self.kind = kind
        self.stream = stream
        self.mode = mode
        self.frames: collections.deque[tuple[int, np.ndarray]] = collections.deque(maxlen=4)


class OpenNISensor(LiveSensor):
    """One OpenNI2 camera (see the module docstring)."""

    backend = "OpenNI2"
    id_prefix = "openni"

    schema = OPENNI_PARAMS
    scheme = "openni"

    def _init_backend(self) -> None:
        self.device: Any = None
        self.model = ""
        self.intrinsics_source = ""
        self.registered = False
        self.synced = False
        self.modes: dict[str, Mode] = {}
        self._streams: dict[str, _Stream] = {}
        self._depth_scale = 0.001
        self._intrinsics: Intrinsics | None = None
        self._color_intrinsics: Intrinsics | None = None
        self._last_index: int | None = None
        self._seq = 0
        self._started_at: float | None = None

    # ------------------------------------------------------------ device
    def _open_device(self) -> SensorInfo:
        openni2 = initialize(str(self.params.library_dir))
        _, c_api = modules()
        uri = resolve_uri(self.target, openni2, c_api)
        try:
            device = openni2.Device(uri)
        except Exception as error:  # OpenNIError and friends
            raise SensorError(open_failure(uri, error)) from None
        self.device = device
        try:
            return self._configure(openni2, c_api, device, uri)
        except SensorError:
            self._close_device()
            raise
        except Exception as error:  # OpenNIError: the device went away meanwhile
            self._close_device()
            raise SensorError(
                f"{self.describe()} failed while starting ({error_text(error)}); unplug and "
                "replug it, then try again."
            ) from None
        except BaseException:
            self._close_device()
            raise

    def _configure(self, openni2: Any, c_api: Any, device: Any, uri: bytes) -> SensorInfo:
        from optrack.sensors.usb import lookup

        info = device.get_device_info()
        self.serial = serial_of(device, c_api) or self.serial
        if self._id is None:
            self._id = self.sensor_id
        self.modes = {}
        known = lookup(int(info.usbVendorId), int(info.usbProductId))
        vendor_name = f"{text(info.vendor)} {text(info.name)}".strip()
        if known is not None:
            self.model = known.model
        elif uri == DUMMY.encode():
            self.model = f"OpenNI2 Dummy device ({vendor_name or 'test pattern'})"
        else:
            self.model = vendor_name or "OpenNI2 device"
        if not device.has_sensor(openni2.SENSOR_DEPTH):
            raise SensorError(f"{self.describe()} has no depth sensor; it cannot be used here.")

        self._create_streams(openni2, device)
        depth_mode = self.modes["depth"]
        self._depth_scale = (
            0.0001 if int(depth_mode.format) == int(openni2.PIXEL_FORMAT_DEPTH_100_UM) else 0.001
        )
        self.clock.period = 1.0 / max(depth_mode.fps, 1.0)

        self._set_options(openni2, c_api, device)
        self._start_streams()
        self._started_at = time.monotonic()
        Library.sensors.add(self)
        self._last_index = None
        self._intrinsics, self._color_intrinsics = self._compute_intrinsics()
        return SensorInfo(
            id=self.sensor_id,
            intrinsics=self._intrinsics,
            model=self.model,
            uri=self.uri,
            depth_scale=self._depth_scale,
            color_intrinsics=self._color_intrinsics,
            fps=float(depth_mode.fps),
            streams=list(self._streams),
        )

    def _create_streams(self, openni2: Any, device: Any) -> None:
        """Depth, and colour and infrared where asked for and present, in the modes
        nearest the parameters."""
        p = self.params
        depth_formats = (
            openni2.PIXEL_FORMAT_DEPTH_1_MM,
            openni2.PIXEL_FORMAT_DEPTH_100_UM,
        )
        color_formats = (
            openni2.PIXEL_FORMAT_RGB888,
            openni2.PIXEL_FORMAT_YUV422,
            openni2.PIXEL_FORMAT_YUYV,
            openni2.PIXEL_FORMAT_JPEG,
        )
        ir_formats = (
            openni2.PIXEL_FORMAT_GRAY16,
            openni2.PIXEL_FORMAT_GRAY8,
            openni2.PIXEL_FORMAT_RGB888,
        )
        wanted = (int(p.width), int(p.height), float(p.fps))
        self._streams = {}
        self._add_stream(openni2, device, "depth", openni2.SENSOR_DEPTH, depth_formats, wanted)
        if p.color and device.has_sensor(openni2.SENSOR_COLOR):
            self._add_stream(openni2, device, "color", openni2.SENSOR_COLOR, color_formats, wanted)
        if p.infrared:
            if device.has_sensor(openni2.SENSOR_IR):
                self._add_stream(openni2, device, "infrared", openni2.SENSOR_IR, ir_formats, wanted)
            else:
                log.warning("%s has no infrared sensor; recording without it.", self.describe())

    def _set_options(self, openni2: Any, c_api: Any, device: Any) -> None:
        """Registration, frame sync and mirroring, where the device supports them."""
        p = self.params
        self.registered = False
        if "color" in self._streams and p.registration:
            mode = openni2.IMAGE_REGISTRATION_DEPTH_TO_COLOR
            try:
                if device.is_image_registration_mode_supported(mode):
                    device.set_image_registration_mode(mode)
                    self.registered = True
            except Exception as error:  # unsupported: unregistered colour
                log.warning("%s: registration refused (%s).", self.describe(), error)
        self.synced = False
        if "color" in self._streams and p.sync:
            try:
                device.set_depth_color_sync_enabled(True)
                self.synced = True
            except Exception:  # not supported: frames are paired by time
                self.synced = False
        for stream in self._streams.values():
            if stream.stream.is_property_supported(c_api.ONI_STREAM_PROPERTY_MIRRORING):
                try:
                    stream.stream.set_mirroring_enabled(bool(p.mirror))
                except Exception:  # mirroring is cosmetic
                    pass

    def _start_streams(self) -> None:
        for kind, stream in self._streams.items():
            try:
                stream.stream.start()
            except Exception as error:
                hint = (
                    " (this camera cannot send infrared and colour together: set color=false)"
                    if kind in ("infrared", "color") and "infrared" in self._streams
                    else ""
                )
                raise SensorError(
                    f"{self.describe()} refused to start its {kind} stream "
                    f"({error_text(error)}){hint}."
                ) from None

    def _add_stream(
        self,
        openni2: Any,
        device: Any,
        kind: str,
        sensor_type: Any,
        formats: tuple[Any, ...],
        wanted: tuple[int, int, float],
    ) -> None:
        sensor_info = device.get_sensor_info(sensor_type)
        modes = [
            Mode(m.resolutionX, m.resolutionY, float(m.fps), int(m.pixelFormat))
            for m in (sensor_info.videoModes if sensor_info else [])
        ]
        if kind != "depth" and "depth" in self.modes:
            # Colour and infrared at the depth image's size and rate where possible.
            depth = self.modes["depth"]
            wanted = (depth.width, depth.height, depth.fps)
        mode = nearest_mode(modes, *wanted, formats=[int(f) for f in formats])
        if mode is None:
            offered = ", ".join(sorted({str(m) for m in modes})) or "none"
            if kind == "depth":
                raise SensorError(
                    f"{self.describe()} offers no depth mode in millimetres (it offers: {offered})."
                )
            log.warning("%s: no usable %s mode (offers %s).", self.describe(), kind, offered)
            return
        if (mode.width, mode.height, mode.fps) != wanted:
            log.info("%s: %s mode %s (wanted %dx%d@%g).", self.describe(), kind, mode, *wanted)
        try:
            stream = device.create_stream(sensor_type)
        except Exception as error:
            raise SensorError(
                f"{self.describe()} could not create its {kind} stream ({error_text(error)})."
            ) from None
        try:
            current = stream.get_video_mode()
            if (
                current.resolutionX,
                current.resolutionY,
                float(current.fps),
                int(current.pixelFormat),
            ) != (mode.width, mode.height, mode.fps, mode.format):
                stream.set_video_mode(
                    openni2.VideoMode(
                        resolutionX=mode.width,
                        resolutionY=mode.height,
                        fps=int(mode.fps),
                        pixelFormat=mode.format,
                    )
                )
        except Exception as error:
            stream.close()
            raise SensorError(
                f"{self.describe()} refused the {kind} mode {mode} ({error_text(error)})."
            ) from None
        self.modes[kind] = mode
        self._streams[kind] = _Stream(kind, stream, mode)

    def _compute_intrinsics(self) -> tuple[Intrinsics, Intrinsics | None]:
        nominal = tuple(math.radians(a) for a in NOMINAL_FOV_DEG)
        depth = self._streams["depth"]
        color = self._streams.get("color")
        depth_fov = stream_fov(depth.stream)
        color_fov = stream_fov(color.stream) if color else None
        reported = depth_fov is not None and (color is None or color_fov is not None)
        self.intrinsics_source = "device" if reported else "nominal"
        if not reported:
            log.info(
                "%s reports no field of view; using the nominal %gx%g degrees.",
                self.describe(),
                *NOMINAL_FOV_DEG,
            )
        d = depth.mode
        if self.registered and color is not None:
            # Depth is re-projected into the colour camera: both share its intrinsics.
            fov = color_fov or nominal
            color_k = intrinsics_from_fov(color.mode.width, color.mode.height, *fov)
            depth_k = intrinsics_from_fov(d.width, d.height, *fov)
            same_size = (color.mode.width, color.mode.height) == (d.width, d.height)
            return depth_k, None if same_size else color_k
        depth_k = intrinsics_from_fov(d.width, d.height, *(depth_fov or nominal))
        if color is None:
            return depth_k, None
        color_k = intrinsics_from_fov(color.mode.width, color.mode.height, *(color_fov or nominal))
        return depth_k, color_k

    def _close_device(self) -> None:
        streams = list(self._streams.values())
        self._streams = {}
        fps = max(min((s.mode.fps for s in streams), default=30.0), 1.0)
        if streams and self._started_at is not None:
            # Stopping a stream within a frame of starting it crashes the Dummy driver's thread.
            time.sleep(max(0.0, self._started_at + 3.0 / fps - time.monotonic()))
        self._started_at = None
        for stream in streams:
            try:
                stream.stream.stop()
            except Exception:  # a pulled-out device fails to stop
                pass
        if streams:
            # The driver's frame thread may still touch a stopped stream for up to a frame.
            time.sleep(2.0 / fps)
        for stream in streams:
            try:
                stream.stream.close()
            except Exception:
                pass
        if self.device is not None:
            try:
                self.device.close()
            except Exception:
                pass
            self.device = None
        Library.sensors.discard(self)

    # ------------------------------------------------------------ frames
    def _grab(self, timeout: float) -> RGBDFrame | None:
        openni2, _ = modules()
        deadline = time.monotonic() + timeout
        by_handle = {id(s.stream): s for s in self._streams.values()}
        handles = [s.stream for s in self._streams.values()]
        if not handles:
            raise DeviceLost("the device is closed")
        while not self._closing.is_set():
            frame = self._pair()
            if frame is not None:
                return frame
            remaining = deadline - time.monotonic()
            # The binding passes whole milliseconds, and a wait of 0 ms (ONI_TIMEOUT_NONE)
            # was seen to block for ever on Debian's OpenNI2: never ask for less than 1 ms.
            if remaining < 0.001:
                return None
            try:
                # OpenNI2 starts its wait again whenever any stream of the process has a
                # new frame, so a long wait may never end while other streams run: wait
                # in slices shorter than a frame period, checking for close in between.
                ready = openni2.wait_for_any_stream(handles, min(remaining, WAIT_SLICE_S))
                if ready is None:
                    continue
                stream = by_handle[id(ready)]
                self._take(stream)
            except DeviceLost:
                raise
            except Exception as error:  # OpenNIError: the device failed
                raise DeviceLost(error_text(error)) from None
        return None

    def _take(self, stream: _Stream) -> None:
        oni_frame = stream.stream.read_frame()
        try:
            timestamp = int(oni_frame.timestamp)
            index = int(oni_frame.frameIndex)
            image = self._convert(stream, oni_frame)
        finally:
            oni_frame.close()
        if stream.kind == "depth":
            if self._last_index is not None and index > self._last_index + 1:
                self.dropped += index - self._last_index - 1
            self._last_index = index
        stream.frames.append((timestamp, image))

    def _convert(self, stream: _Stream, oni_frame: Any) -> np.ndarray:
        import cv2
        from openni import openni2

        width, height, stride = oni_frame.width, oni_frame.height, oni_frame.stride
        fmt = int(oni_frame.videoMode.pixelFormat)
        raw = np.ctypeslib.as_array(
            (ctypes.c_uint8 * int(oni_frame.dataSize)).from_address(oni_frame.data)
        )
        if fmt in (
            int(openni2.PIXEL_FORMAT_DEPTH_1_MM),
            int(openni2.PIXEL_FORMAT_DEPTH_100_UM),
            int(openni2.PIXEL_FORMAT_GRAY16),
        ):
            rows = raw[: height * stride].reshape(height, stride)[:, : width * 2]
            return rows.copy().view(np.uint16)
        if fmt == int(openni2.PIXEL_FORMAT_GRAY8):
            return raw[: height * stride].reshape(height, stride)[:, :width].copy()
        if fmt == int(openni2.PIXEL_FORMAT_RGB888):
            rgb = raw[: height * stride].reshape(height, stride)[:, : width * 3]
            rgb = rgb.reshape(height, width, 3)
            return rgb[:, :, 0].copy() if stream.kind == "infrared" else rgb.copy()
        if fmt in (int(openni2.PIXEL_FORMAT_YUV422), int(openni2.PIXEL_FORMAT_YUYV)):
            packed = raw[: height * stride].reshape(height, stride)[:, : width * 2]
            packed = np.ascontiguousarray(packed).reshape(height, width, 2)
            code = (
                cv2.COLOR_YUV2RGB_UYVY
                if fmt == int(openni2.PIXEL_FORMAT_YUV422)
                else cv2.COLOR_YUV2RGB_YUYV
            )
            return cv2.cvtColor(packed, code)
        if fmt == int(openni2.PIXEL_FORMAT_JPEG):
            bgr = cv2.imdecode(raw.copy(), cv2.IMREAD_COLOR)
            if bgr is None:
                raise DeviceLost("the camera sent a damaged JPEG frame")
            return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        raise DeviceLost(f"the camera sent pixel format {fmt}, which optrack cannot read")

    def _pair(self) -> RGBDFrame | None:
        """The oldest depth frame with its colour and infrared, once they can be matched.

        A companion frame matches when its device time is within half a
        frame period; while one may still come the depth frame waits (at
        most three frames), then goes with the newest companion available.
        """
        depth = self._streams.get("depth")
        if depth is None or not depth.frames:
            return None
        t_depth, depth_image = depth.frames[0]
        tolerance_us = 0.5e6 / max(depth.mode.fps, 1.0)
        companions: dict[str, np.ndarray | None] = {}
        for kind in ("color", "infrared"):
            stream = self._streams.get(kind)
            if stream is None:
                continue
            match = min(
                (f for f in stream.frames if abs(f[0] - t_depth) <= tolerance_us),
                key=lambda f: abs(f[0] - t_depth),
                default=None,
            )
            if match is None:
                may_come = not stream.frames or stream.frames[-1][0] < t_depth + tolerance_us
                if may_come and len(depth.frames) < 3:
                    return None
                match = stream.frames[-1] if stream.frames else None
            if match is not None:
                while stream.frames and stream.frames[0][0] < match[0]:
                    stream.frames.popleft()
            companions[kind] = match[1] if match is not None else None
        depth.frames.popleft()
        return self._frame(t_depth, depth_image, companions)

    def _frame(
        self, t_depth_us: int, depth: np.ndarray, companions: dict[str, np.ndarray | None]
    ) -> RGBDFrame:
        import cv2

        h, w = depth.shape
        infrared = companions.get("infrared")
        if infrared is not None and infrared.shape != (h, w):
            infrared = cv2.resize(infrared, (w, h), interpolation=cv2.INTER_NEAREST)
        seq = self._seq
        self._seq += 1
        assert self._intrinsics is not None
        return RGBDFrame(
            depth=depth,
            intrinsics=self._intrinsics,
            sensor_id=self.sensor_id,
            timestamp=self.clock.stamp(t_depth_us * 1e-6),
            depth_scale=self._depth_scale,
            color=companions.get("color"),
            infrared=infrared,
            color_intrinsics=self._color_intrinsics,
            seq=seq,
        )
