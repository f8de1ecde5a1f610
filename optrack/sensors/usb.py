"""USB discovery of depth cameras (pyusb over libusb-1.0), hot-plug polling, udev rules.

:data:`KNOWN_CAMERAS` maps USB vendor:product ids to models and to the
optrack backend that captures them. :func:`list_cameras` finds the attached
ones; :class:`UsbWatcher` polls for cameras plugged in or pulled out. A
camera the current user may not open (Linux: no udev rule) is still listed,
with ``access == "denied"`` and :func:`permission_message` saying what to
install. ``packaging/udev/99-optrack-cameras.rules`` is :func:`udev_rules`
written out (``optrack sensors --udev-rules``); a test keeps them equal.
"""

from __future__ import annotations

import dataclasses
import errno
import logging
import threading
from collections.abc import Callable, Iterable, Sequence

from optrack.params import Param, Schema, register
from optrack.sensors.base import SensorError

__all__ = [
    "KNOWN_CAMERAS",
    "UDEV_RULES_FILE",
    "USB_PARAMS",
    "KnownCamera",
    "UsbCamera",
    "UsbWatcher",
    "diff_cameras",
    "list_cameras",
    "lookup",
    "permission_message",
    "udev_rule",
    "udev_rules",
]

log = logging.getLogger(__name__)

USB_PARAMS = register(
    Schema(
        "usb",
        [
            Param(
                "poll_interval",
                1.0,
                min=0.05,
                max=60.0,
                step=0.05,
                unit="s",
                help="How often the hot-plug watcher looks for cameras plugged in or pulled out.",
            ),
        ],
        help="USB camera discovery.",
    )
)

# Backends: the URI scheme that captures the camera, or "" when optrack has none yet.
OPENNI = "openni"
REALSENSE = "realsense"
UNSUPPORTED = ""


@dataclasses.dataclass(frozen=True)
class KnownCamera:
    """One USB vendor:product id of a depth camera."""

    vendor_id: int
    product_id: int
    vendor: str
    model: str
    backend: str = UNSUPPORTED
    note: str = ""

    @property
    def ids(self) -> str:
        """``"vvvv:pppp"`` in lower-case hexadecimal, as ``lsusb`` prints them."""
        return f"{self.vendor_id:04x}:{self.product_id:04x}"


def _table(
    vendor_id: int, vendor: str, backend: str, rows: Iterable[tuple[int, str]], note: str = ""
):
    return [KnownCamera(vendor_id, pid, vendor, model, backend, note) for pid, model in rows]


_KINECT1_NOTE = "OpenNI2 needs libfreenect's OpenNI2 driver for this camera"
_UNSUPPORTED_NOTE = "optrack has no capture backend for this camera yet"

#: Depth cameras by USB id. Sources: Debian's libopenni2-0 udev rules (PrimeSense,
#: Kinect v1), libfreenect (Kinect v1 camera ids), libfreenect2 (Kinect v2),
#: Orbbec's astra_camera udev rules, librealsense (d400-private.h, l500-private.h,
#: 99-realsense-libusb.rules). Only the camera function of composite devices is
#: listed (not the Kinect's motor or microphone array).
KNOWN_CAMERAS: tuple[KnownCamera, ...] = tuple(
    _table(
        0x1D27,
        "PrimeSense",
        OPENNI,
        [
            (0x0600, "PrimeSense Carmine 1.08 / Asus Xtion PRO"),
            (0x0601, "Asus Xtion PRO LIVE"),
            (0x0609, "PrimeSense Carmine 1.09"),
        ],
    )
    + _table(
        0x045E,
        "Microsoft",
        OPENNI,
        [
            (0x02AE, "Microsoft Kinect for Xbox 360 (v1)"),
            (0x02BF, "Microsoft Kinect for Windows (v1)"),
        ],
        _KINECT1_NOTE,
    )
    + _table(
        0x045E,
        "Microsoft",
        UNSUPPORTED,
        [
            (0x02C4, "Microsoft Kinect v2 (Kinect for Windows v2 / Xbox One)"),
            (0x02D8, "Microsoft Kinect v2"),
            (0x097C, "Microsoft Azure Kinect DK"),
        ],
        _UNSUPPORTED_NOTE,
    )
    + _table(
        0x2BC5,
        "Orbbec",
        OPENNI,
        [
            (0x0401, "Orbbec Astra"),
            (0x0402, "Orbbec Astra S"),
            (0x0403, "Orbbec Astra Pro"),
            (0x0404, "Orbbec Astra Mini"),
            (0x0407, "Orbbec Astra Mini S"),
        ],
        "needs Orbbec's OpenNI2 driver (Debian's libopenni2 has none)",
    )
    + _table(
        0x8086,
        "Intel",
        REALSENSE,
        [
            (0x0A66, "Intel RealSense F200"),
            (0x0AA5, "Intel RealSense SR300"),
            (0x0AD1, "Intel RealSense D400"),
            (0x0AD2, "Intel RealSense D410"),
            (0x0AD3, "Intel RealSense D415"),
            (0x0AD4, "Intel RealSense D430"),
            (0x0AD6, "Intel RealSense D4xx (USB 2)"),
            (0x0AF6, "Intel RealSense D420"),
            (0x0B07, "Intel RealSense D435"),
            (0x0B3A, "Intel RealSense D435i"),
            (0x0B4B, "Intel RealSense D430i"),
            (0x0B5B, "Intel RealSense D405"),
            (0x0B5C, "Intel RealSense D455"),
            (0x0B0D, "Intel RealSense L500"),
            (0x0B3D, "Intel RealSense L515 (pre-production)"),
            (0x0B64, "Intel RealSense L515"),
            (0x0B68, "Intel RealSense L535"),
        ],
    )
)

_BY_IDS = {(c.vendor_id, c.product_id): c for c in KNOWN_CAMERAS}


def lookup(vendor_id: int, product_id: int) -> KnownCamera | None:
    """The known camera with these USB ids, or None."""
    return _BY_IDS.get((vendor_id, product_id))


# ------------------------------------------------------------------ udev

UDEV_RULES_FILE = "packaging/udev/99-optrack-cameras.rules"
UDEV_INSTALL = (
    f"sudo cp {UDEV_RULES_FILE} /etc/udev/rules.d/ && sudo udevadm control --reload-rules "
    "&& sudo udevadm trigger"
)


def udev_rule(camera: KnownCamera) -> str:
    """The udev rule line that lets every local user open this camera."""
    return (
        f'SUBSYSTEM=="usb", ATTR{{idVendor}}=="{camera.vendor_id:04x}", '
        f'ATTR{{idProduct}}=="{camera.product_id:04x}", MODE="0666"'
    )


def udev_rules() -> str:
    """The whole rules file, one commented block per vendor (generated from the table)."""
    lines = [
        "# optrack: let local users open USB depth cameras (generated from",
        "# optrack/sensors/usb.py KNOWN_CAMERAS; regenerate with `optrack sensors --udev-rules`).",
        f"# Install: {UDEV_INSTALL}; then replug the cameras.",
    ]
    vendor = None
    for camera in KNOWN_CAMERAS:
        if camera.vendor != vendor:
            vendor = camera.vendor
            lines += ["", f"# {vendor}"]
        lines.append(f"# {camera.model}")
        lines.append(udev_rule(camera))
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------- discovery


@dataclasses.dataclass(frozen=True)
class UsbCamera:
    """A known camera found on the USB bus.

    ``access`` is ``"ok"`` when its string descriptors could be read,
    ``"denied"`` when the operating system refused (install the udev rule),
    ``"unknown"`` when reading failed for another reason.
    """

    known: KnownCamera
    bus: int
    address: int
    port_path: str = ""
    serial: str | None = None
    access: str = "unknown"

    @property
    def key(self) -> tuple[int, int, int, int]:
        """What tells one plugged-in device from another (changes when replugged)."""
        return (self.bus, self.address, self.known.vendor_id, self.known.product_id)

    @property
    def model(self) -> str:
        return self.known.model

    @property
    def uri(self) -> str:
        """The sensor URI that opens this camera ("" when optrack cannot capture it)."""
        if self.known.backend == OPENNI:
            # OpenNI2's PS1080 driver names devices "vid/pid@bus/address".
            return (
                f"openni://{self.known.vendor_id:04x}/{self.known.product_id:04x}"
                f"@{self.bus}/{self.address}"
            )
        if self.known.backend == REALSENSE:
            return f"realsense://{self.serial or ''}"
        return ""

    def as_dict(self) -> dict[str, object]:
        return {
            "uri": self.uri,
            "model": self.model,
            "vendor": self.known.vendor,
            "vendor_id": f"{self.known.vendor_id:04x}",
            "product_id": f"{self.known.product_id:04x}",
            "bus": self.bus,
            "address": self.address,
            "port": self.port_path,
            "serial": self.serial,
            "access": self.access,
            "backend": self.known.backend or None,
            "note": self.known.note,
        }


def permission_message(camera: UsbCamera) -> str:
    """One sentence for a camera this user may not open: what to install."""
    return (
        f"the {camera.model} on USB bus {camera.bus} (device {camera.address}) cannot be opened "
        f"by this user; install optrack's udev rules ({UDEV_INSTALL}) and replug it, or add "
        f"this line to /etc/udev/rules.d/99-optrack-cameras.rules: {udev_rule(camera.known)}"
    )


def _libusb_backend():
    try:
        import usb.backend.libusb1
        import usb.core  # noqa: F401
    except ImportError:
        raise SensorError(
            "USB discovery needs the pyusb package; install it with '.venv/bin/pip install pyusb'."
        ) from None
    backend = usb.backend.libusb1.get_backend()
    if backend is None:
        raise SensorError(
            "USB discovery needs libusb-1.0, which is not installed; install the Debian package "
            "libusb-1.0-0 (sudo apt-get install libusb-1.0-0)."
        )
    return backend


def _read_serial(device) -> tuple[str | None, str]:
    """(serial or None, access) of a pyusb device; opening it may be refused."""
    import usb.core
    import usb.util

    try:
        if not device.iSerialNumber:
            device.langids  # noqa: B018 - opens the device: tells whether access is allowed
            return None, "ok"
        return usb.util.get_string(device, device.iSerialNumber), "ok"
    except usb.core.USBError as error:
        if error.errno in (errno.EACCES, errno.EPERM):
            return None, "denied"
        return None, "unknown"
    except ValueError:
        # pyusb: "The device has no langid (permission issue, ...)"
        return None, "denied"
    except NotImplementedError:
        return None, "unknown"
    finally:
        usb.util.dispose_resources(device)


def list_cameras(read_serials: bool = True) -> list[UsbCamera]:
    """The known depth cameras on the USB bus (empty when there are none or no bus).

    ``read_serials`` opens each camera to read its serial number and learn
    whether this user may open it; the hot-plug watcher skips that.
    """
    import usb.core

    backend = _libusb_backend()
    try:
        devices = list(
            usb.core.find(
                find_all=True,
                backend=backend,
                custom_match=lambda d: (d.idVendor, d.idProduct) in _BY_IDS,
            )
        )
    except usb.core.NoBackendError:
        raise SensorError(
            "USB discovery needs libusb-1.0, which is not installed; install the Debian package "
            "libusb-1.0-0 (sudo apt-get install libusb-1.0-0)."
        ) from None
    cameras = []
    for device in devices:
        ports = getattr(device, "port_numbers", None) or ()
        port_path = f"{device.bus}-" + ".".join(str(p) for p in ports) if ports else ""
        serial, access = _read_serial(device) if read_serials else (None, "unknown")
        cameras.append(
            UsbCamera(
                known=_BY_IDS[(device.idVendor, device.idProduct)],
                bus=int(device.bus or 0),
                address=int(device.address or 0),
                port_path=port_path,
                serial=serial,
                access=access,
            )
        )
    cameras.sort(key=lambda c: c.key)
    return cameras


def diff_cameras(
    before: Sequence[UsbCamera], after: Sequence[UsbCamera]
) -> tuple[list[UsbCamera], list[UsbCamera]]:
    """(plugged in, pulled out) between two listings, each in listing order."""
    old = {c.key for c in before}
    new = {c.key for c in after}
    return [c for c in after if c.key not in old], [c for c in before if c.key not in new]


class UsbWatcher:
    """Polls the USB bus and calls back when known cameras are plugged in or pulled out.

    ``on_added(camera)`` and ``on_removed(camera)`` run on the watcher's
    thread. Cameras already attached when the watcher starts are reported as
    added on the first poll. ``source`` lists the cameras (default: the USB
    bus, without opening devices).
    """

    def __init__(
        self,
        on_added: Callable[[UsbCamera], None] | None = None,
        on_removed: Callable[[UsbCamera], None] | None = None,
        interval: float | None = None,
        source: Callable[[], list[UsbCamera]] | None = None,
    ) -> None:
        self.on_added = on_added
        self.on_removed = on_removed
        self.interval = float(
            interval if interval is not None else USB_PARAMS.create().poll_interval
        )
        self.source = source or (lambda: list_cameras(read_serials=False))
        self.cameras: list[UsbCamera] = []
        self.error: SensorError | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def poll(self) -> tuple[list[UsbCamera], list[UsbCamera]]:
        """Look once; call the callbacks; return (added, removed)."""
        current = self.source()
        added, removed = diff_cameras(self.cameras, current)
        self.cameras = list(current)
        for camera in removed:
            if self.on_removed is not None:
                self.on_removed(camera)
        for camera in added:
            if self.on_added is not None:
                self.on_added(camera)
        return added, removed

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self.poll()
            except SensorError as error:  # libusb missing: say it once and stop
                self.error = error
                log.warning("USB hot-plug watcher stopped: %s", error)
                return
            self._stop.wait(self.interval)

    def start(self) -> UsbWatcher:
        if self._thread is None or not self._thread.is_alive():
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="usb-watcher", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def __enter__(self) -> UsbWatcher:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
