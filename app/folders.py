"""The operator's own optrack folders: where the window saves and first looks for
calibrations and recordings, and where the nodes of this computer keep theirs."""

from __future__ import annotations

from pathlib import Path

__all__ = ["calibrations_folder", "node_state_folder", "recordings_folder", "start_in"]


def calibrations_folder() -> Path:
    """``~/optrack-calibrations``: the wizard's Save… and File → Open calibration… start here."""
    return Path.home() / "optrack-calibrations"


def recordings_folder() -> Path:
    """``~/optrack-recordings``: new takes go here; File → Open recording… starts here."""
    return Path.home() / "optrack-recordings"


def node_state_folder() -> str:
    """Where a node of this computer keeps the calibration it received (``node.state_dir``
    empty: the XDG state folder)."""
    return "$XDG_STATE_HOME/optrack/<site> (~/.local/state/optrack/<site>)"


def start_in(folder: Path, name: str = "") -> str:
    """A file dialog's starting path: ``folder`` (made if it is missing and can be),
    with ``name`` in it; the current folder when ``folder`` cannot be made."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        folder = Path.cwd()
    return str(folder / name) if name else str(folder)
