"""Zenoh key expressions of a site (docs/runtime.md).

::

    optrack/<site>/detections/<sensor>   DetectionBatch of one sensor (tracker time)
    optrack/<site>/tracks                TrackBatch from the tracker
    optrack/<site>/calibration           NetworkCalibration for every node
    optrack/<site>/params/<node>         live parameter updates for one node
    optrack/<site>/status/<node>         a node's health, about once a second
    optrack/<site>/preview/<sensor>      low-rate down-sampled frames for the GUI
    optrack/<site>/clock                 the tracker's clock (a queryable)
    optrack/<site>/board_views/<sensor>  checkerboard views while a calibration capture runs
    optrack/<site>/person_clouds/<sensor> each person's decimated points (skeletons on)
    optrack/<site>/skeletons             SkeletonBatch from the skeleton node
"""

from __future__ import annotations

import dataclasses
import re

from optrack.errors import UserError

__all__ = ["NAME", "BusNameError", "SiteKeys", "check_name"]

ROOT = "optrack"
# One key chunk: no '/', and none of Zenoh's wildcard or reserved characters.
NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")


class BusNameError(UserError):
    """A site, sensor or node name that cannot be a key-expression chunk."""


def check_name(kind: str, name: str) -> str:
    """``name`` when it is one valid chunk (letters, digits, '_', '-', '.')."""
    if not isinstance(name, str) or not NAME.match(name):
        raise BusNameError(
            f"{kind} name '{name}' cannot be used on the bus; use 1 to 64 letters, digits, "
            "'_', '-' or '.', starting with a letter or digit."
        )
    return name


@dataclasses.dataclass(frozen=True)
class SiteKeys:
    """The key expressions of one site."""

    site: str

    def __post_init__(self) -> None:
        check_name("site", self.site)

    @property
    def prefix(self) -> str:
        return f"{ROOT}/{self.site}"

    def detections(self, sensor: str = "*") -> str:
        return (
            f"{self.prefix}/detections/{sensor if sensor == '*' else check_name('sensor', sensor)}"
        )

    @property
    def tracks(self) -> str:
        return f"{self.prefix}/tracks"

    @property
    def calibration(self) -> str:
        return f"{self.prefix}/calibration"

    def params(self, node: str = "*") -> str:
        return f"{self.prefix}/params/{node if node == '*' else check_name('node', node)}"

    def status(self, node: str = "*") -> str:
        return f"{self.prefix}/status/{node if node == '*' else check_name('node', node)}"

    def preview(self, sensor: str = "*") -> str:
        return f"{self.prefix}/preview/{sensor if sensor == '*' else check_name('sensor', sensor)}"

    def board_views(self, sensor: str = "*") -> str:
        """Where a detector node publishes its checkerboard views during a calibration
        capture (:class:`~optrack.net.messages.BoardViewMessage`)."""
        chunk = sensor if sensor == "*" else check_name("sensor", sensor)
        return f"{self.prefix}/board_views/{chunk}"

    def person_clouds(self, sensor: str = "*") -> str:
        """Where a detector node publishes each person's decimated points while the
        skeleton stage is on (:class:`~optrack.net.messages.PersonCloudsMessage`)."""
        chunk = sensor if sensor == "*" else check_name("sensor", sensor)
        return f"{self.prefix}/person_clouds/{chunk}"

    @property
    def skeletons(self) -> str:
        return f"{self.prefix}/skeletons"

    def command(self, node: str = "*") -> str:
        """Where a node answers commands (a queryable): start a recording, a calibration
        capture, a simulated operator's action."""
        return f"{self.prefix}/command/{node if node == '*' else check_name('node', node)}"

    @property
    def clock(self) -> str:
        return f"{self.prefix}/clock"

    @staticmethod
    def last_chunk(key: str) -> str:
        """The sensor or node a concrete key names (its last chunk)."""
        return key.rsplit("/", 1)[-1]
