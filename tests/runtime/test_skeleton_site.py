"""`optrack run` with skeletons as a user runs it, on the simulated venue: with
`--skeleton`, skeletons of the tracked people arrive over UDP (OpenPTrack v2's pose
message) and OSC on loopback; without it nothing about skeletons is sent until the stage
is switched on live, and then the site starts its skeleton node and they arrive."""

from __future__ import annotations

import time

from optrack.net.messages import ParamsMessage

from .sites import RunningSite, venue_sensors

SENSORS = ("kinect2_0", "kinect2_1")


class SkeletonSite(RunningSite):
    """A running `optrack run` on two sensors of the venue, and its UDP and OSC receivers."""

    def __init__(self, venue, tmp_path, skeleton: bool) -> None:
        values = {
            "site": {
                "name": "skeletonsite",
                "sensors": venue_sensors(venue, SENSORS),
                "report_s": 2.0,
            },
            "node": {"state_dir": str(tmp_path / "state"), "status_period_s": 0.5},
            "skeleton": {"particles": 200, "init_layers": 6},
        }
        super().__init__(tmp_path, values, ("--skeleton",) if skeleton else ())

    def skeletons(self) -> list[dict]:
        """Every skeleton with joints received over UDP."""
        return [s for _, d in self.documents() for s in d.get("pose_tracks", []) if s["joints"]]

    def osc_joints(self) -> list[tuple[str, tuple]]:
        with self.lock:
            messages = list(self.osc)
        return [(a, args) for _, a, args in messages if a.startswith("/optrack/skeleton/")]

    def check_skeletons(self) -> None:
        """Skeletons over UDP and OSC, each a track's, with v2's joint names."""
        self.wait(lambda: self.skeletons() and self.osc_joints(), 200, "no skeletons")
        tracked = {t["id"] for _, d in self.documents() for t in d.get("tracks", [])}
        found = self.skeletons()
        assert {s["id"] for s in found} <= tracked  # a skeleton is a track's
        assert {"HEAD", "NECK", "LEFT_WRIST", "RIGHT_ANKLE"} <= set(found[0]["joints"])
        assert 0.5 < found[0]["joints"]["HEAD"]["z"] < 2.3
        assert len(self.osc_joints()[0][1]) == 3  # x y z
        # statuses come once a second: the one seen may predate the first skeleton
        self.wait(lambda: self.counted("skeleton", "updates"), 30, "no skeleton updates counted")
        for sensor in SENSORS:  # the detectors keep detecting
            self.wait(lambda s=sensor: self.counted(s, "frames"), 30, f"no frames from {sensor}")


def test_a_site_run_with_skeleton_sends_them_over_udp_and_osc(venue, tmp_path):
    site = SkeletonSite(venue, tmp_path, skeleton=True)
    try:
        site.check_skeletons()
    finally:
        site.close()


def test_skeletons_switched_on_live_start_the_skeleton_node(venue, tmp_path):
    site = SkeletonSite(venue, tmp_path, skeleton=False)
    try:
        site.wait(
            lambda: any(d.get("tracks") for _, d in site.documents()), 200, "no tracks on UDP"
        )
        time.sleep(2.0)
        assert site.skeletons() == [] and site.osc_joints() == []  # off: nothing about them
        assert "skeleton" not in site.statuses
        for sensor in SENSORS:
            site.bus.publish(
                site.bus.keys.params(sensor),
                ParamsMessage(updates={"skeleton_live": {"enabled": True}}),
            )
        site.check_skeletons()
    finally:
        site.close()
