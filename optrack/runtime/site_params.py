"""Parameters of the local site launcher (``optrack run``)."""

from __future__ import annotations

from optrack.params import Param, Schema, register
from optrack.sim.venue_cache import RECORDED_VENUE

__all__ = ["SITE_PARAMS"]

SITE_PARAMS = register(
    Schema(
        "site",
        [
            Param("name", "local", help="Site name (the bus keys are optrack/<name>/...)."),
            Param(
                "sensors",
                "",
                help="Comma-separated sensor URIs, one detector node each; empty: the embedded "
                "simulated venue.",
            ),
            Param(
                "scenario",
                "mixed",
                help="Embedded venue: the simulated scenario, each sensor rendered live by its detector.",
            ),
            Param("seed", 0, min=0, max=2**31 - 1, step=1, help="Embedded venue: random seed."),
            Param(
                "venue_seconds",
                RECORDED_VENUE["seconds"],
                min=1.0,
                max=600.0,
                step=1.0,
                unit="s",
                help="Recorded venue (optrack bench e2e): length of the rendered recording (rendered "
                "once, then cached).",
            ),
            Param(
                "venue_max_age_s",
                RECORDED_VENUE["max_age_s"],
                min=-1.0,
                max=1.0,
                step=0.005,
                unit="s",
                help="Embedded venue: each detector's node.replay_max_age_s (a frame already "
                "older than this when the detector is free is skipped for the next one: lower "
                "latency, fewer frames; negative: always the newest frame).",
            ),
            Param(
                "restart_delay_s",
                1.0,
                min=0.0,
                max=60.0,
                step=0.1,
                unit="s",
                help="Wait this long before restarting a node that stopped unexpectedly.",
            ),
            Param(
                "max_restart_delay_s",
                30.0,
                min=0.0,
                max=600.0,
                step=1.0,
                unit="s",
                help="A node that keeps failing right after starting is restarted ever more "
                "slowly, up to this delay.",
            ),
            Param(
                "stop_timeout_s",
                5.0,
                min=0.1,
                max=60.0,
                step=0.1,
                unit="s",
                help="On stop, a node that has not ended after this long is killed.",
            ),
            Param(
                "report_s",
                5.0,
                min=0.0,
                max=600.0,
                step=0.5,
                unit="s",
                help="Print a one-line summary of the site this often (0: never).",
            ),
            Param(
                "detector_nice",
                0,
                min=0,
                max=19,
                step=1,
                help="CPU niceness of the detector nodes, so that the tracker and the outputs "
                "keep their pace when detection saturates the computer.",
            ),
        ],
        help="The local site: which nodes 'optrack run' starts and how it keeps them alive.",
    )
)
