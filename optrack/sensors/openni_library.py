"""OpenNI2 itself: loading Debian's libOpenNI2, initialising it once, listing the
attached cameras, and the exit hook that closes every open sensor (see
optrack/sensors/openni.py for why the binding's own hook is replaced)."""

from __future__ import annotations

import atexit
import ctypes
import logging
import math
import os
import re
import sysconfig
import threading
import weakref
from pathlib import Path
from typing import Any

from optrack.sensors.base import SensorError
from optrack.types import Intrinsics

log = logging.getLogger("optrack.sensors.openni")

DUMMY = "Dummy"
_SERIAL_BYTES = 64
_USB_PATH = re.compile(r"^([0-9a-fA-F]{4})/([0-9a-fA-F]{4})@(\d+)/(\d+)$")

# ------------------------------------------------------------- the library


class Library:
    """The OpenNI2 library, initialised once per process."""

    lock = threading.Lock()
    initialized = False
    sensors: weakref.WeakSet[Any] = weakref.WeakSet()  # the open OpenNISensor objects


def modules() -> tuple[Any, Any]:
    try:
        from openni import _openni2 as c_api
        from openni import openni2
    except ImportError:
        raise SensorError(
            "openni:// needs the openni Python package; install it with "
            "'.venv/bin/pip install openni'."
        ) from None
    return openni2, c_api


def library_dirs(configured: str) -> list[Path]:
    if configured:
        return [Path(configured)]
    dirs = [os.environ.get("OPENNI2_REDIST64", ""), os.environ.get("OPENNI2_REDIST", "")]
    multiarch = sysconfig.get_config_var("MULTIARCH") or ""
    if multiarch:
        dirs.append(f"/usr/lib/{multiarch}")
    dirs += ["/usr/lib", "/usr/local/lib", "/usr/lib64", "/lib"]
    return [Path(d) for d in dirs if d]


def initialize(configured_dir: str = "") -> Any:
    """Load and initialise OpenNI2 (once); return the ``openni2`` module."""
    openni2, c_api = modules()
    with Library.lock:
        if Library.initialized and openni2.is_initialized():
            return openni2
        dirs = library_dirs(configured_dir)
        found = next((d for d in dirs if (d / "libOpenNI2.so").is_file()), None)
        if found is None:
            # Only the runtime package (libOpenNI2.so.0, no -dev symlink): load it by name.
            versioned = next((d for d in dirs if (d / "libOpenNI2.so.0").is_file()), None)
            if versioned is None:
                searched = ", ".join(str(d) for d in dirs)
                raise SensorError(
                    f"OpenNI2 is not installed (no libOpenNI2.so in {searched}); install the "
                    "Debian packages libopenni2-0 and libopenni2-dev, or set openni.library_dir."
                )
            if not openni2.loaded_dll_directory:
                c_api.load_dll(str(versioned / "libOpenNI2.so.0"))
                openni2.loaded_dll_directory = str(versioned)
            found = versioned
        try:
            openni2.initialize(str(found))
        except Exception as error:  # the binding raises bare Exceptions
            raise SensorError(
                f"OpenNI2 in {found} could not be initialised ({error}); reinstall libopenni2-0."
            ) from None
        if not Library.initialized:
            atexit.unregister(openni2.unload)
            atexit.register(shutdown)
        Library.initialized = True
        return openni2


def shutdown() -> None:
    """Exit hook: close our sensors gracefully (stop, wait, destroy, close).

    OpenNI2 itself is left to the process exit: with every device closed
    ``oniShutdown`` has nothing to release, and Debian's crashes now and then
    after the Dummy device streamed.
    """
    for sensor in list(Library.sensors):
        try:
            sensor.close()
        except Exception as error:  # exiting: report, go on
            log.warning("closing %s at exit failed: %s", sensor.describe(), error)


def text(value: bytes | str) -> str:
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace").strip("\x00").strip()
    return str(value).strip()


def error_text(error: Exception) -> str:
    args = getattr(error, "args", ())
    if len(args) >= 2 and args[1]:
        return text(args[1])
    return text(str(error)) or type(error).__name__


def serial_of(device: Any, c_api: Any) -> str:
    prop = c_api.ONI_DEVICE_PROPERTY_SERIAL_NUMBER
    try:
        if not device.is_property_supported(prop):
            return ""
        return text(device.get_property(prop, ctypes.c_char * _SERIAL_BYTES).value)
    except Exception:  # no serial is not an error
        return ""


def enumerate_uris(openni2: Any) -> list[str]:
    """OpenNI2's device URIs, less the Dummy device (listed once it has been opened)."""
    return [u for u in (text(u) for u in openni2.Device.enumerate_uris()) if u != DUMMY]


def attached_devices(library_dir: str = "") -> list[dict[str, str]]:
    """Cameras OpenNI2 sees: ``uri`` (OpenNI's), ``serial`` (when readable), ``name``.

    The Dummy device is never listed (OpenNI2 opens it on request only).
    """
    openni2 = initialize(library_dir)
    _, c_api = modules()
    out = []
    for uri in enumerate_uris(openni2):
        entry = {"uri": uri, "serial": "", "name": ""}
        try:
            device = openni2.Device(uri.encode())
        except Exception:  # busy or not permitted: list it without serial
            out.append(entry)
            continue
        try:
            info = device.get_device_info()
            entry["serial"] = serial_of(device, c_api)
            entry["name"] = f"{text(info.vendor)} {text(info.name)}".strip()
        finally:
            device.close()
        out.append(entry)
    return out


# ---------------------------------------------------------------- intrinsics


def intrinsics_from_fov(width: int, height: int, hfov: float, vfov: float) -> Intrinsics:
    """Pinhole intrinsics of a ``width`` x ``height`` image with fields of view in radians.

    The fields of view span the whole image (pixel edges), the principal
    point is the image centre in the pixel-centre convention.
    """
    return Intrinsics(
        fx=(width / 2.0) / math.tan(hfov / 2.0),
        fy=(height / 2.0) / math.tan(vfov / 2.0),
        cx=(width - 1) / 2.0,
        cy=(height - 1) / 2.0,
        width=width,
        height=height,
    )


def stream_fov(stream: Any) -> tuple[float, float] | None:
    try:
        hfov, vfov = stream.get_horizontal_fov(), stream.get_vertical_fov()
    except Exception:  # ONI_STATUS_NOT_IMPLEMENTED on the Dummy device
        return None
    if not (0 < hfov < math.pi and 0 < vfov < math.pi):
        return None
    return hfov, vfov


# -------------------------------------------------------------- the sensor


def resolve_uri(target: str, openni2: Any, c_api: Any) -> bytes:
    """The OpenNI2 URI of the camera a target names (serial, URI, USB path, Dummy or
    empty for the first attached)."""
    if target.lower() == DUMMY.lower():
        return DUMMY.encode()
    uris = enumerate_uris(openni2)
    if not target:
        if uris:
            return uris[0].encode()
        raise SensorError(nothing_attached(target))
    if target in uris:
        return target.encode()
    match = _USB_PATH.match(target)
    if match:
        # A replugged camera gets a new address: take the one camera with these ids.
        ids = f"{match.group(1)}/{match.group(2)}@".lower()
        same = [u for u in uris if u.lower().startswith(ids)]
        if len(same) == 1:
            return same[0].encode()
    for uri in uris:
        try:
            device = openni2.Device(uri.encode())
        except Exception:  # busy: cannot be the one we may open
            continue
        try:
            if serial_of(device, c_api) == target:
                return uri.encode()
        finally:
            device.close()
    raise SensorError(nothing_attached(target))


def nothing_attached(target: str) -> str:
    """The sentence for a camera that is not attached."""
    from optrack.sensors.uri import attached_summary

    what = f"no OpenNI2 camera with serial or URI '{target}'" if target else ("no OpenNI2 camera")
    return (
        f"{what} is attached ({attached_summary()}); check its cable, or use a URI that "
        "'optrack sensors' lists (openni://Dummy is OpenNI2's test device)."
    )


def open_failure(uri: bytes, error: Exception) -> str:
    """The sentence for a camera OpenNI2 could not open (permissions named when that is why)."""
    from optrack.sensors import usb

    match = _USB_PATH.match(text(uri))
    if match:
        try:
            cameras = usb.list_cameras()
        except SensorError:
            cameras = []
        for camera in cameras:
            if (
                camera.access == "denied"
                and camera.bus == int(match.group(3))
                and camera.address == int(match.group(4))
            ):
                return usb.permission_message(camera)
    return (
        f"OpenNI2 could not open camera '{text(uri)}' ({error_text(error)}); check that no "
        "other program is using it, or unplug and replug it."
    )
