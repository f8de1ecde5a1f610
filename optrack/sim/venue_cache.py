"""The recorded venue: a simulated scenario rendered once into a recording, then cached.

:func:`venue_recording` renders a scenario's sensors into a recording (per scenario,
seed, length, optrack version and format) for what needs the exact same frames every
time (``optrack bench e2e``, tests); :func:`clean_stale_venues` keeps that cache small.
``optrack run``'s embedded venue renders live instead
(:func:`optrack.runtime.venue.venue_uris`), and only keeps the cache clean.
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

__all__ = [
    "RECORDED_VENUE",
    "STALE_AFTER_S",
    "VENUE_FORMAT",
    "VenueProgress",
    "clean_stale_venues",
    "venue_cache_root",
    "venue_recording",
    "venue_suffix",
]

log = logging.getLogger("optrack.sim.venue_cache")

#: How the venue is cached: depth (and infrared) as PNG without deflate, colour as JPEG.
#: Encoding is several times faster than deflated PNG (the rendering's biggest cost after
#: ray casting), and so is decoding in the detector nodes, where it counts in every
#: frame's latency; the files are larger (see docs/runtime.md for the measured figures).
VENUE_FORMAT = {"color_format": "jpg", "jpeg_quality": 95, "png_compression": 0}

#: The recorded venue as a site plays it: its length (``site.venue_seconds``), and each
#: detector's ``node.replay_max_age_s`` when it plays the venue (``site.venue_max_age_s``:
#: a frame already older than this when the detector is free is skipped for the next one).
RECORDED_VENUE = {"seconds": 6.0, "max_age_s": 0.01}

#: A cached venue not used for this long is removed (the next start that needs it renders it
#: again); so is a rendering's scratch folder this old (its process is gone).
STALE_AFTER_S = {"venue": 14 * 86400.0, "scratch": 3600.0}

#: ``progress(done, total, frames_per_s)`` while a venue renders.
VenueProgress = Callable[[int, int, float], None]


def venue_cache_root() -> Path:
    """Where rendered venues are kept: $XDG_CACHE_HOME/optrack/venues."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "optrack" / "venues"


def venue_suffix() -> str:
    """How the names of this optrack version's and format's venues end."""
    from optrack import __version__

    return f"-v{__version__}-png{VENUE_FORMAT['png_compression']}"


def venue_recording(
    scenario: str,
    seed: int,
    seconds: float,
    cache: Path | None = None,
    progress: VenueProgress | None = None,
) -> Path:
    """The venue's recording, rendered once (a progress bar on stderr, and ``progress``
    called as it goes) and then reused."""
    from optrack.recording import is_recording

    suffix = venue_suffix()
    name = f"{Path(scenario).stem}-seed{seed}-{seconds:g}s{suffix}"
    path = (cache or venue_cache_root()) / name
    done = path / ".complete"
    if path.parent.is_dir():
        clean_stale_venues(path.parent, suffix=suffix)
    if done.is_file() and is_recording(path):
        os.utime(done)  # last use: what clean_stale_venues keeps
        return path
    _render(scenario, seed, seconds, path, progress)
    return path


def _render(
    scenario: str, seed: int, seconds: float, path: Path, progress: VenueProgress | None
) -> None:
    """Render the venue into a scratch folder beside ``path``, then move it there."""
    from optrack import __version__
    from optrack.recording.format import RECORDING_PARAMS
    from optrack.sim.recorder import ProgressBar, write_recording
    from optrack.sim.world import Simulation

    sim = Simulation(scenario, seed=seed, seconds=seconds)
    total = sum(sim.frame_count(k) for k in range(len(sim.sensors)))
    log.info(
        "rendering the venue '%s' once: %d frames, a few minutes on 2 cores (later runs reuse %s)",
        scenario,
        total,
        path,
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    scratch = Path(tempfile.mkdtemp(prefix=f".{path.name}.", dir=path.parent))
    bar = ProgressBar(f"venue {sim.scenario.name}", total)
    started = time.perf_counter()

    def advance(n: int, _total: int) -> None:
        bar.update(n)
        if progress is not None:
            progress(n, total, n / max(time.perf_counter() - started, 1e-9))

    try:
        write_recording(
            sim,
            scratch / "recording",
            progress=advance,
            params=RECORDING_PARAMS.create(VENUE_FORMAT),
        )
        bar.close()
        (scratch / "recording" / ".complete").write_text(__version__ + "\n", encoding="utf-8")
        if path.exists():
            shutil.rmtree(path)
        os.replace(scratch / "recording", path)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    log.info(
        "venue rendered in %.0f s (%.1f frames/s)",
        time.perf_counter() - started,
        total / max(time.perf_counter() - started, 1e-9),
    )


def clean_stale_venues(root: Path, suffix: str, now: float | None = None) -> list[Path]:
    """Remove from ``root`` the venues another optrack version or format rendered (their
    name does not end in ``suffix``), those unused for ``STALE_AFTER_S["venue"]``, and
    the scratch folders of renderings that stopped; returns what was removed."""
    now = time.time() if now is None else now
    removed = []
    for entry in root.iterdir():
        if not entry.is_dir():
            continue
        if entry.name.startswith("."):
            stale = now - entry.stat().st_mtime > STALE_AFTER_S["scratch"]
        else:
            done = entry / ".complete"
            used = done.stat().st_mtime if done.is_file() else entry.stat().st_mtime
            stale = not entry.name.endswith(suffix) or now - used > STALE_AFTER_S["venue"]
        if stale:
            shutil.rmtree(entry, ignore_errors=True)
            removed.append(entry)
    if removed:
        log.info("removed %d stale venue(s) from %s", len(removed), root)
    return removed
