"""The calibration wizard without a window (``optrack calibrate live``): extrinsics,
floor, the solve, optionally a walk's refinement, then save and publish, against a
running site through :class:`~optrack.runtime.calibration_live.LiveCalibration`.

Progress goes to ``say`` (stderr for the command); the result is one payload
(the command's JSON).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from optrack.calibration.live import LiveState
from optrack.runtime.calibration_live import LiveCalibration

__all__ = ["HeadlessPlan", "calibrate_headless", "describe_state"]


@dataclasses.dataclass
class HeadlessPlan:
    """How long each phase may take, when it is done, and what to do with the result."""

    out: str  # calibration file to write
    extrinsics_s: float = 120.0  # longest extrinsics phase
    min_views: int = 3  # the extrinsics end when every sensor is calibrated with this many
    floor_s: float = 60.0  # longest floor phase
    floor_views: int = 3  # the floor phase ends at this many floor views
    refine_s: float = 0.0  # seconds of one person walking (0: no refinement)
    publish: bool = True  # send the calibration to the nodes


def describe_state(state: LiveState) -> str:
    """One progress line: the phase, each sensor's views and search rate, the advice."""
    sensors = ", ".join(
        f"{s} {v.views} view{'' if v.views == 1 else 's'}{' calibrated' if v.settled else ''} "
        f"({v.capture_hz:.1f} Hz)"
        for s, v in sorted(state.sensors.items())
    )
    extra = f", {state.floor_views} floor views" if state.phase == "floor" else ""
    if state.phase == "refinement":
        extra = ", detections " + ", ".join(
            f"{s} {n}" for s, n in sorted(state.refinement_samples.items())
        )
    return f"{state.phase} {state.elapsed_s:5.1f} s: {sensors}{extra}. {state.message}"


def _run_phase(
    live: LiveCalibration,
    phase: str,
    seconds: float,
    done: Callable[[LiveState], bool],
    say: Callable[[str], None],
) -> float:
    """Capture ``phase`` until ``done`` or ``seconds``; returns the seconds it took."""
    started = time.monotonic()
    live.start(phase)
    say(f"{phase}: started in {time.monotonic() - started:.1f} s. {live.state().message}")
    next_report = 0.0
    while True:
        state = live.state()
        now = time.monotonic()
        if now >= next_report:
            say(describe_state(state))
            next_report = now + 2.0
        if done(state) or now - started >= seconds:
            break
        time.sleep(0.2)
    live.stop()
    return time.monotonic() - started


def _capture(
    live: LiveCalibration, plan: HeadlessPlan, say: Callable[[str], None]
) -> dict[str, float]:
    """Extrinsics, then the floor (a real site's people are told what to do); the seconds
    each took."""
    if not live.simulated:
        say(
            "Move the board through the space, holding it still for a second wherever two "
            "cameras see it; then lay it on the floor when asked."
        )

    def extrinsics_done(state: LiveState) -> bool:
        # calibrated on enough shared board poses (calibration_live.min_shared_poses)
        return all(v.settled and v.views >= plan.min_views for v in state.sensors.values())

    timings = {
        "extrinsics_s": _run_phase(live, "extrinsics", plan.extrinsics_s, extrinsics_done, say)
    }
    if not live.simulated:
        say("Now lay the board flat on the floor where cameras see it.")
    timings["floor_s"] = _run_phase(
        live, "floor", plan.floor_s, lambda state: state.floor_views >= plan.floor_views, say
    )
    return timings


def calibrate_headless(
    live: LiveCalibration, plan: HeadlessPlan, say: Callable[[str], None], connect_s: float = 0.0
) -> dict[str, Any]:
    """Run the phases, solve, refine (``plan.refine_s``), save to ``plan.out`` and publish;
    the payload of ``optrack calibrate live --json`` (``connect_s``: the seconds it took to
    find the site's sensors, the first of its ``seconds``)."""
    timings = {"connect_s": connect_s, **_capture(live, plan, say)}
    started = time.monotonic()
    calibration = live.solve(lambda f, m: say(m))
    timings["solve_s"] = time.monotonic() - started
    report = None
    if plan.refine_s > 0:
        if not live.simulated:
            say("Now one person walks alone through every camera's view.")
        timings["refinement_s"] = _run_phase(
            live, "refinement", plan.refine_s, lambda state: False, say
        )
        started = time.monotonic()
        report = live.refine(lambda f, m: say(m))
        timings["refine_s"] = time.monotonic() - started
        calibration = report.calibration
    path = live.save(plan.out)
    if plan.publish:
        live.publish()
    result = live.result
    assert result is not None
    payload: dict[str, Any] = {
        "out": str(path),
        "id": calibration.notes,
        "site": live.bus.keys.site,
        "simulated": live.simulated,
        "world": result.world,
        "rms_px": result.rms_px,
        "floor_views": result.floor_views,
        "uncalibrated": result.uncalibrated,
        "published": plan.publish,
        "sensors": {
            sid: {
                "views": result.sensors[sid].used_views,
                "rms_px": result.sensors[sid].rms_px,
                "world_T_camera": np.asarray(entry.world_T_camera).round(6).tolist(),
            }
            for sid, entry in sorted(calibration.sensors.items())
        },
        "seconds": {k: round(v, 2) for k, v in timings.items()},
    }
    if report is not None:
        payload["refinement"] = {
            "error_before_m": report.error_before_m,
            "error_after_m": report.error_after_m,
            "skipped": report.skipped,
            "refused": report.refused,
        }
    return payload
