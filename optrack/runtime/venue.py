"""The embedded venue: a simulated site for ``optrack run`` without ``site.sensors``.

:func:`venue_uris` is what ``optrack run`` plays: each detector node renders its own
sensor of the simulated scenario live (``sim://``), every one on the same clock, so the
first tracks come as soon as the nodes are up, with nothing to render first and nothing
cached; people walk forwards only, and the venue starts again from its beginning every
``LIVE_LOOP_S``. A node renders at the rate its CPU share allows (a camera that drops
frames), about 80 % of what a cached replay reached on 2 cores.

:func:`venue_recording` renders the same venue once into a recording and caches it (per
scenario, seed, length, optrack version and format) for what needs the exact same
frames every time (``optrack bench e2e``, tests); :func:`clean_stale_venues` keeps that
cache small.
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from urllib.parse import quote

__all__ = [
    "LIVE_LOOP_S",
    "VENUE_FORMAT",
    "VenueProgress",
    "clean_stale_venues",
    "venue_recording",
    "venue_uris",
]

log = logging.getLogger("optrack.runtime.site")


def _cache_root() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "optrack" / "venues"


#: The live venue's loop: its people walk forwards for this long, then it starts again. A
#: node that starts late (a restart) steps the crowd up to now first, which costs about
#: 2 % of the time it catches up; a loop this long keeps that to seconds.
LIVE_LOOP_S = 300.0


def venue_uris(scenario: str, seed: int, start: float | None = None) -> list[str]:
    """The embedded venue's sensors, live: one ``sim://`` URI per sensor of ``scenario``,
    all on the clock that starts at ``start`` (now by default), looping forwards. Stale
    cached venues go (:func:`clean_stale_venues`)."""
    from optrack import __version__
    from optrack.sim.scenario import load_scenario

    root = _cache_root()
    if root.is_dir():
        clean_stale_venues(root, suffix=f"-v{__version__}-png{VENUE_FORMAT['png_compression']}")
    ids = load_scenario(scenario).sensors.sensor_ids()  # without importing the renderer
    path = Path(scenario)
    if path.suffix.lower() in (".yaml", ".yml"):  # a file: sim:///abs/path.yaml/N
        scenario = str(path.resolve())
    begin = time.time() if start is None else start
    query = f"seed={seed}&seconds={LIVE_LOOP_S:g}&start={begin!r}&loop=true"
    return [f"sim://{quote(scenario)}/{k}?{query}&id={quote(sid)}" for k, sid in enumerate(ids)]


#: How the embedded venue is cached: depth (and infrared) as PNG without deflate, colour as
#: JPEG. Encoding is several times faster than deflated PNG (the rendering's biggest cost
#: after ray casting), and so is decoding in the detector nodes, where it counts in every
#: frame's latency; the files are larger (see docs/runtime.md for the measured figures).
VENUE_FORMAT = {"color_format": "jpg", "jpeg_quality": 95, "png_compression": 0}

#: A cached venue not used for this long is removed (the next start that needs it renders it
#: again); so is a rendering's scratch folder this old (its process is gone).
STALE_AFTER_S = {"venue": 14 * 86400.0, "scratch": 3600.0}

#: ``progress(done, total, frames_per_s)`` while a venue renders.
VenueProgress = Callable[[int, int, float], None]


def venue_recording(
    scenario: str,
    seed: int,
    seconds: float,
    cache: Path | None = None,
    progress: VenueProgress | None = None,
) -> Path:
    """The embedded venue's recording, rendered once (a progress bar on stderr, and
    ``progress`` called as it goes) and then reused."""
    from optrack import __version__
    from optrack.recording import is_recording
    from optrack.recording.format import RECORDING_PARAMS
    from optrack.sim.recorder import ProgressBar, write_recording
    from optrack.sim.world import Simulation

    level = VENUE_FORMAT["png_compression"]
    name = f"{Path(scenario).stem}-seed{seed}-{seconds:g}s-v{__version__}-png{level}"
    path = (cache or _cache_root()) / name
    done = path / ".complete"
    if path.parent.is_dir():
        clean_stale_venues(path.parent, suffix=f"-v{__version__}-png{level}")
    if done.is_file() and is_recording(path):
        os.utime(done)  # last use: what clean_stale_venues keeps
        return path
    sim = Simulation(scenario, seed=seed, seconds=seconds)
    total = sum(sim.frame_count(k) for k in range(len(sim.sensors)))
    log.info(
        "rendering the venue '%s' once: %d frames, a few minutes on 2 cores (later runs reuse %s)",
        scenario,
        total,
        path,
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    scratch = Path(tempfile.mkdtemp(prefix=f".{name}.", dir=path.parent))
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
    return path


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
