"""docs/tracking.md's settings tables name every parameter with its default."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from optrack.tracking.params import APPEARANCE_PARAMS, SMOOTHING_PARAMS, TRACKING_PARAMS

GUIDE = Path(__file__).parents[2] / "docs" / "tracking.md"


def _documented(stage: str) -> dict[str, str]:
    """name -> default as the guide's table for the stage writes it."""
    text = GUIDE.read_text(encoding="utf-8")
    section = text.split(f"### `{stage}`", 1)[1].split("\n#", 1)[0]
    out = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        names = re.findall(r"`(\w+)`", cells[0]) if len(cells) >= 3 else []
        defaults = cells[1].split(", ") if names else []
        if len(names) > 1 and len(defaults) != len(names):
            raise AssertionError(f"row {line!r} gives {len(defaults)} defaults")
        for name, default in zip(names, defaults, strict=False):
            out[name] = default
    return out


@pytest.mark.parametrize("schema", [TRACKING_PARAMS, APPEARANCE_PARAMS, SMOOTHING_PARAMS])
def test_every_parameter_is_in_the_guide_with_its_default(schema) -> None:
    documented = _documented(schema.stage)
    defaults = schema.defaults()
    assert sorted(documented) == sorted(defaults)
    for name, value in defaults.items():
        written = documented[name].split(" ")[0]
        expected = f"`{value}`" if isinstance(value, str) else str(value)
        assert written == expected, f"{name}: the guide says {written}, the schema {expected}"
