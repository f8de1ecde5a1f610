"""USB discovery: the VID:PID table, the shipped udev rules, listing and hot-plug on real pyusb."""

from __future__ import annotations

import re
import threading
from pathlib import Path

import pytest

from optrack.sensors import usb
from optrack.sensors.usb import KNOWN_CAMERAS, KnownCamera, UsbCamera, UsbWatcher

REPO = Path(__file__).resolve().parents[2]
RULES = REPO / usb.UDEV_RULES_FILE


def test_known_camera_ids_are_unique_and_16_bit():
    keys = [(c.vendor_id, c.product_id) for c in KNOWN_CAMERAS]
    assert len(keys) == len(set(keys))
    assert all(0 < v <= 0xFFFF and 0 < p <= 0xFFFF for v, p in keys)


@pytest.mark.parametrize(
    ("ids", "model", "backend"),
    [
        ((0x045E, 0x02AE), "Kinect for Xbox 360", "openni"),
        ((0x045E, 0x02C4), "Kinect v2", ""),
        ((0x1D27, 0x0601), "Xtion PRO LIVE", "openni"),
        ((0x1D27, 0x0600), "Carmine 1.08", "openni"),
        ((0x2BC5, 0x0401), "Orbbec Astra", "openni"),
        ((0x8086, 0x0B07), "RealSense D435", "realsense"),
        ((0x8086, 0x0B3A), "RealSense D435i", "realsense"),
        ((0x8086, 0x0B5C), "RealSense D455", "realsense"),
        ((0x8086, 0x0B64), "RealSense L515", "realsense"),
    ],
)
def test_lookup_names_the_model_and_backend(ids, model, backend):
    camera = usb.lookup(*ids)
    assert camera is not None
    assert model in camera.model
    assert camera.backend == backend


def test_lookup_of_an_unknown_id_is_none():
    assert usb.lookup(0x046D, 0xC52B) is None  # a Logitech receiver
    assert usb.lookup(0x8086, 0x0B37) is None  # RealSense T265: tracking, no depth


def test_shipped_udev_rules_are_the_generated_ones():
    assert RULES.read_text(encoding="utf-8") == usb.udev_rules()


def test_udev_rules_cover_exactly_the_table():
    pairs = re.findall(
        r'ATTR\{idVendor\}=="([0-9a-f]{4})", ATTR\{idProduct\}=="([0-9a-f]{4})"',
        RULES.read_text(encoding="utf-8"),
    )
    assert sorted((int(v, 16), int(p, 16)) for v, p in pairs) == sorted(
        (c.vendor_id, c.product_id) for c in KNOWN_CAMERAS
    )


def test_permission_message_gives_the_rule_line_of_that_camera():
    camera = UsbCamera(usb.lookup(0x1D27, 0x0601), bus=3, address=9, access="denied")
    message = usb.permission_message(camera)
    assert "Asus Xtion PRO LIVE" in message and "bus 3" in message
    assert usb.udev_rule(camera.known) in message
    assert usb.udev_rule(camera.known) in RULES.read_text(encoding="utf-8")
    assert "udevadm" in message


def test_discovered_camera_uris_match_each_backend():
    xtion = UsbCamera(usb.lookup(0x1D27, 0x0601), bus=1, address=5)
    realsense = UsbCamera(usb.lookup(0x8086, 0x0B07), bus=2, address=4, serial="817612070123")
    kinect2 = UsbCamera(usb.lookup(0x045E, 0x02C4), bus=2, address=6)
    assert xtion.uri == "openni://1d27/0601@1/5"
    assert realsense.uri == "realsense://817612070123"
    assert kinect2.uri == ""
    assert xtion.as_dict()["vendor_id"] == "1d27" and xtion.as_dict()["product_id"] == "0601"


def test_list_cameras_on_the_real_bus_returns_only_known_cameras():
    cameras = usb.list_cameras()
    assert isinstance(cameras, list)
    for camera in cameras:
        assert usb.lookup(camera.known.vendor_id, camera.known.product_id) is camera.known
        assert camera.access in ("ok", "denied", "unknown")
    if not Path("/dev/bus/usb").exists():
        assert cameras == []  # no USB bus (CI containers): empty, and no error


def _camera(address: int) -> UsbCamera:
    return UsbCamera(KnownCamera(0x1D27, 0x0601, "PrimeSense", "Xtion", "openni"), 1, address)


def test_diff_reports_plugged_in_and_pulled_out_cameras():
    a, b, c = _camera(2), _camera(3), _camera(4)
    added, removed = usb.diff_cameras([a, b], [b, c])
    assert added == [c] and removed == [a]
    assert usb.diff_cameras([a], [a]) == ([], [])


def test_same_camera_replugged_at_a_new_address_is_removed_then_added():
    added, removed = usb.diff_cameras([_camera(2)], [_camera(7)])
    assert [c.address for c in added] == [7] and [c.address for c in removed] == [2]


def test_watcher_calls_back_on_hot_plug():
    listings = iter([[], [_camera(2)], [_camera(2), _camera(3)], [_camera(3)]])
    events: list[tuple[str, int]] = []
    watcher = UsbWatcher(
        on_added=lambda c: events.append(("added", c.address)),
        on_removed=lambda c: events.append(("removed", c.address)),
        source=lambda: next(listings),
    )
    for _ in range(4):
        watcher.poll()
    assert events == [("added", 2), ("added", 3), ("removed", 2)]
    assert [c.address for c in watcher.cameras] == [3]


def test_watcher_thread_polls_the_real_bus_and_stops():
    polled = threading.Event()

    def source():
        polled.set()
        return usb.list_cameras(read_serials=False)

    with UsbWatcher(interval=0.05, source=source) as watcher:
        assert polled.wait(5.0)
        assert watcher.running
    assert not watcher.running
    assert watcher.error is None


def test_poll_interval_is_a_registered_parameter():
    from optrack.params import REGISTRY

    assert REGISTRY["usb"]["poll_interval"].unit == "s"
    assert UsbWatcher().interval == REGISTRY["usb"]["poll_interval"].default
