"""The embedded venue's cache stays small: other versions' and formats' venues, venues
unused for weeks and the scratch folders of stopped renderings are removed."""

from __future__ import annotations

import os
import time
from pathlib import Path

from optrack.sim.venue_cache import STALE_AFTER_S, clean_stale_venues

SUFFIX = "-v9.9.9-png0"


def venue(root: Path, name: str, age_s: float, now: float, complete: bool = True) -> Path:
    path = root / name
    (path / "sensors").mkdir(parents=True)
    if complete:
        (path / ".complete").write_text("9.9.9\n")
        os.utime(path / ".complete", (now - age_s, now - age_s))
    os.utime(path, (now - age_s, now - age_s))
    return path


def test_stale_venues_go_and_current_ones_stay(tmp_path: Path) -> None:
    now = time.time()
    current = venue(tmp_path, f"mixed-seed0-6s{SUFFIX}", 3600.0, now)
    other_length = venue(tmp_path, f"mixed-seed0-4s{SUFFIX}", 86400.0, now)
    old_version = venue(tmp_path, "mixed-seed0-6s-v0.0.1-png0", 60.0, now)
    old_format = venue(tmp_path, "mixed-seed0-6s-v9.9.9-png1", 60.0, now)
    unused = venue(tmp_path, f"crowd-seed3-6s{SUFFIX}", STALE_AFTER_S["venue"] + 60.0, now)
    stopped = venue(
        tmp_path, f".mixed-seed0-6s{SUFFIX}.abc", STALE_AFTER_S["scratch"] + 60.0, now, False
    )
    rendering = venue(tmp_path, f".mixed-seed0-6s{SUFFIX}.def", 5.0, now, complete=False)
    (tmp_path / "notes.txt").write_text("not a venue")

    removed = clean_stale_venues(tmp_path, SUFFIX, now=now)

    assert sorted(removed) == sorted([old_version, old_format, unused, stopped])
    for path in (current, other_length, rendering, tmp_path / "notes.txt"):
        assert path.exists()
    for path in removed:
        assert not path.exists()
