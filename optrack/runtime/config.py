"""A node's configuration: one YAML file for every stage it runs (docs/runtime.md).

The same file format as :func:`optrack.params.load_config` (one mapping per
stage), read with every stage a node may run registered: ``bus``, ``clock``,
``node``, ``site``, ``outputs``, ``detection``, ``tracking``, ``appearance``,
``smoothing``, ``playback``, ``openni``, ``realsense``, ``usb``, ``recording``, ``skeleton_live``,
``skeleton``, ``skeleton_fusion``. :class:`NodeConfig` also keeps
which values the file set explicitly, so that a detector node lays them
over its sensor model's defaults.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from optrack.params import REGISTRY, Param, Params, Schema, load_config, register, save_config

__all__ = ["NODE_PARAMS", "NodeConfig", "load_node_config", "state_dir"]

NODE_PARAMS = register(
    Schema(
        "node",
        [
            Param(
                "status_period_s",
                1.0,
                min=0.05,
                max=60.0,
                step=0.05,
                unit="s",
                help="How often a node publishes its status.",
            ),
            Param(
                "preview_hz",
                2.0,
                min=0.0,
                max=30.0,
                step=0.5,
                unit="Hz",
                help="Rate of a detector's down-sampled previews for the GUI (0: none).",
            ),
            Param(
                "preview_width",
                160,
                min=32,
                max=1920,
                step=16,
                unit="px",
                help="Width of the preview images (height follows the aspect ratio).",
            ),
            Param(
                "preview_points",
                2000,
                min=0,
                max=100000,
                step=100,
                help="Points of the decimated preview cloud (0: none).",
            ),
            Param(
                "state_dir",
                "",
                help="Folder where a node keeps the calibration it received; empty: "
                "$XDG_STATE_HOME/optrack/<site> (~/.local/state/optrack/<site>).",
            ),
            Param(
                "data_folder",
                "~/optrack-recordings",
                help="The site's data folder: a node writes recordings (record_start) only "
                "inside it and refuses any other folder.",
            ),
            Param(
                "outputs",
                True,
                help="The tracker node sends the outputs itself, straight from its loop (off "
                "only when a separate outputs process takes the tracks from the bus).",
            ),
            Param(
                "replay_max_age_s",
                -1.0,
                min=-1.0,
                max=1.0,
                step=0.005,
                unit="s",
                help="A detector replaying a recording skips a frame already older than this "
                "when it is free, and waits for the next one (decoded while waiting): lower "
                "latency, fewer frames. Negative: always the newest frame due.",
            ),
            Param(
                "max_future_s",
                0.1,
                min=0.0,
                max=10.0,
                step=0.01,
                unit="s",
                help="The tracker node refuses (and counts) detections stamped further ahead "
                "of its clock than this: a node whose clock is not synchronised yet, or jumped.",
            ),
            Param(
                "tracks_publish",
                "update",
                choices=("update", "rate"),
                help="When the tracker node sends tracks: 'update' after every detection batch "
                "and, between updates, at least at smoothing.rate (lowest latency); 'rate' only "
                "at smoothing.rate, the newest state each time.",
            ),
            Param(
                "nice",
                0,
                min=0,
                max=19,
                step=1,
                help="Lower this node's CPU priority by this much (Unix niceness).",
            ),
        ],
        help="Every node: status, previews, where it keeps state.",
    )
)


def register_node_stages() -> None:
    """Import every module whose stages a node may take (they register their schemas)."""
    import optrack.detection.params  # noqa: F401
    import optrack.net.clock  # noqa: F401
    import optrack.net.config  # noqa: F401
    import optrack.outputs.streams  # noqa: F401
    import optrack.recording.format  # noqa: F401
    import optrack.runtime.site_params  # noqa: F401
    import optrack.runtime.skeleton_params  # noqa: F401
    import optrack.sensors.openni  # noqa: F401
    import optrack.sensors.playback  # noqa: F401
    import optrack.sensors.realsense  # noqa: F401
    import optrack.sensors.usb  # noqa: F401
    import optrack.skeleton.fusion  # noqa: F401
    import optrack.skeleton.params  # noqa: F401
    import optrack.tracking.params  # noqa: F401


@dataclasses.dataclass
class NodeConfig:
    """Parameters of every stage, and the values the file set explicitly."""

    params: dict[str, Params]
    explicit: dict[str, dict[str, Any]]
    path: Path | None = None

    def __getitem__(self, stage: str) -> Params:
        return self.params[stage]

    def save(
        self, path: str | os.PathLike[str], stages: Mapping[str, Params] | None = None
    ) -> None:
        """Write a complete config file (every stage's current values)."""
        save_config(path, dict(stages if stages is not None else self.params))


def load_node_config(
    path: str | os.PathLike[str] | None, overrides: Mapping[str, Mapping[str, Any]] | None = None
) -> NodeConfig:
    """Every stage's parameters from a YAML file (defaults without one), then ``overrides``."""
    register_node_stages()
    explicit: dict[str, dict[str, Any]] = {}
    if path:
        params = load_config(path)  # validates everything, one sentence on error
        data = yaml.safe_load(Path(path).read_text(encoding="utf-8")) or {}
        explicit = {stage: dict(values or {}) for stage, values in data.items()}
    else:
        params = {stage: schema.create() for stage, schema in REGISTRY.items()}
    for stage, values in (overrides or {}).items():
        params[stage].update(values)
        explicit.setdefault(stage, {}).update(values)
    return NodeConfig(params, explicit, Path(path) if path else None)


def state_dir(config: NodeConfig, site: str) -> Path:
    """Where nodes of ``site`` on this computer keep their state."""
    chosen = str(config["node"].state_dir)
    if chosen:
        return Path(chosen).expanduser()
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "optrack" / site
