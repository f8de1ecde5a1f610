"""The embedded venue: a simulated site for ``optrack run`` without ``site.sensors``.

:func:`venue_uris` is what ``optrack run`` plays: each detector node renders its own
sensor of the simulated scenario live (``sim://``), every one on the same clock, so the
first tracks come as soon as the nodes are up, with nothing to render first and nothing
cached; people walk forwards only, and the venue starts again from its beginning every
``LIVE_LOOP_S``. A node renders at the rate its CPU share allows (a camera that drops
frames), about 80 % of what a cached replay reached on 2 cores.

The same venue rendered once into a cached recording, for what needs the exact same
frames every time (``optrack bench e2e``, tests), is
:func:`optrack.sim.venue_cache.venue_recording` (simulation only; re-exported here for
the callers that know it from this module).
"""

from __future__ import annotations

import time
from pathlib import Path
from urllib.parse import quote

from optrack.sim.venue_cache import (
    VENUE_FORMAT,
    VenueProgress,
    clean_stale_venues,
    venue_cache_root,
    venue_recording,
    venue_suffix,
)

__all__ = [
    "LIVE_LOOP_S",
    "VENUE_FORMAT",
    "VenueProgress",
    "clean_stale_venues",
    "venue_recording",
    "venue_uris",
]


#: The live venue's loop: its people walk forwards for this long, then it starts again. A
#: node that starts late (a restart) steps the crowd up to now first, which costs about
#: 2 % of the time it catches up; a loop this long keeps that to seconds.
LIVE_LOOP_S = 300.0


def venue_uris(scenario: str, seed: int, start: float | None = None) -> list[str]:
    """The embedded venue's sensors, live: one ``sim://`` URI per sensor of ``scenario``,
    all on the clock that starts at ``start`` (now by default), looping forwards. Stale
    cached venues go (:func:`clean_stale_venues`)."""
    from optrack.sim.scenario import load_scenario

    root = venue_cache_root()
    if root.is_dir():
        clean_stale_venues(root, suffix=venue_suffix())
    ids = load_scenario(scenario).sensors.sensor_ids()  # without importing the renderer
    path = Path(scenario)
    if path.suffix.lower() in (".yaml", ".yml"):  # a file: sim:///abs/path.yaml/N
        scenario = str(path.resolve())
    begin = time.time() if start is None else start
    query = f"seed={seed}&seconds={LIVE_LOOP_S:g}&start={begin!r}&loop=true"
    return [f"sim://{quote(scenario)}/{k}?{query}&id={quote(sid)}" for k, sid in enumerate(ids)]
