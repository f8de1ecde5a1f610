"""Where a node keeps the calibration published on the bus.

A calibration received from ``optrack/<site>/calibration`` is written to
``<state dir>/calibration.yaml`` in the calibration file format
(:mod:`optrack.calibration.files`): atomically, after the previous file is
copied to ``calibration.yaml.bak``. A node that restarts uses the stored one
until a newer calibration arrives.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

from optrack.calibration.files import (
    CalibrationFile,
    CalibrationFileError,
    load_network,
    save_calibration,
)
from optrack.types import NetworkCalibration

__all__ = ["CalibrationStore"]

log = logging.getLogger("optrack.runtime")

FILE_NAME = "calibration.yaml"


class CalibrationStore:
    """The calibration file of one node's state folder."""

    def __init__(self, directory: str | os.PathLike[str]) -> None:
        self.directory = Path(directory)
        self.path = self.directory / FILE_NAME

    @property
    def previous_path(self) -> Path:
        return self.path.with_name(self.path.name + ".bak")

    def save(self, calibration: NetworkCalibration) -> Path:
        """Store atomically, keeping the previous file as ``.bak``; returns the file."""
        self.directory.mkdir(parents=True, exist_ok=True)
        save_calibration(self.path, CalibrationFile.from_network(calibration))
        return self.path

    def load(self) -> NetworkCalibration | None:
        """The stored calibration; None when there is none or it cannot be read (logged)."""
        if not self.path.exists():
            return None
        try:
            return load_network(self.path)
        except CalibrationFileError as error:
            log.warning("ignoring the stored calibration: %s", error)
            return None
