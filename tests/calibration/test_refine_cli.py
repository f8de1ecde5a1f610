"""``optrack calibrate refine`` end to end: the simulator's walking person, the detector,
Algorithm 1, the refined file. A short, 5 fps version of the ``refinement`` scenario keeps
it quick; the full scenario's figures are in docs/calibration.md."""

from __future__ import annotations

import json

import numpy as np
import pytest

from optrack.calibration.files import load_calibration
from optrack.cli import main
from optrack.geometry import invert


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    from optrack.sim.models import KINECT2_PARAMS
    from optrack.sim.recorder import write_recording
    from optrack.sim.world import Simulation

    out = tmp_path_factory.mktemp("refine") / "walk"
    params = {"sim_kinect2": KINECT2_PARAMS.create({"fps": 5})}
    write_recording(Simulation("refinement", seed=0, seconds=14, params=params), out)
    return out


def test_refine_cli_undoes_most_of_a_10_cm_2_degree_perturbation(walk, tmp_path, capsys):
    perturbed = tmp_path / "perturbed.yaml"
    refined = tmp_path / "refined.yaml"
    assert (
        main(["calibrate", "truth", str(walk), "--out", str(perturbed), "--perturb", "0.1,2"]) == 0
    )
    capsys.readouterr()
    code = main(
        ["calibrate", "refine", str(walk), "--calibration", str(perturbed), "--out", str(refined)]
        + ["--rate", "5", "--json"]
    )
    assert code == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["error_before_m"] > 0.1
    assert payload["error_after_m"] < payload["error_before_m"] / 3
    assert payload["truth_before"]["max_position_error_m"] > 0.1
    assert payload["truth_after"]["max_position_error_m"] < 0.03
    # The file keeps each correction, and world_T_camera includes it.
    before, after = load_calibration(perturbed), load_calibration(refined)
    for sid, entry in after.sensors.items():
        correction = np.asarray(entry.refinement)
        np.testing.assert_allclose(entry.pose, correction @ before.pose(sid), atol=1e-9)
        assert np.linalg.norm(invert(correction)[:3, 3]) > 0.0
    assert after.quality["refinement_error_after_m"] == pytest.approx(payload["error_after_m"])
