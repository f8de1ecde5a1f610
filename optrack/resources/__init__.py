"""The files optrack ships inside its package, read through ``importlib.resources``.

Scenarios, the desktop entry and icon, the default site configuration (and the
detector's models) live in this package's folder, so a wheel, the Debian
package and a source checkout all read them the same way: never through a path
relative to the checkout.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

__all__ = ["resource_path", "scenario_dir"]


def resource_path(*parts: str) -> Path:
    """The file or folder ``parts`` inside the package's resources, as a real path
    (optrack is installed as files, never imported from a zip archive)."""
    found = files(__name__).joinpath(*parts)
    if not isinstance(found, Path):
        raise RuntimeError(f"optrack's resources are not on the file system ({found!r}).")
    return found


def scenario_dir() -> Path:
    """The folder of the built-in scenarios (``<name>.yaml``)."""
    return resource_path("scenarios")
