"""Scenario files: the built-in ones load; a broken one gives one clear sentence."""

from __future__ import annotations

import pytest
from conftest import write_scenario

from optrack.cli import main
from optrack.sim import ScenarioError, Simulation, builtin_scenarios, load_scenario

BUILT_IN = {"crowd", "distance", "occlusions", "calibration", "refinement", "mixed"}


def _one_sentence(message: str) -> None:
    assert message.endswith(".")
    assert "\n" not in message
    assert "Traceback" not in message


def test_built_in_scenarios_are_all_there_and_load():
    assert BUILT_IN <= set(builtin_scenarios())
    for name in BUILT_IN:
        scenario = load_scenario(name)
        assert scenario.name == name and scenario.description


def test_default_mixed_venue_has_three_sensors_four_to_six_people_and_furniture():
    scenario = load_scenario("mixed")
    assert scenario.sensors.count == 3
    assert scenario.people_count_range() == (4, 6)
    kinds = {type(o).__name__ for o in scenario.venue.obstacles}
    assert kinds == {"Pillar", "Table", "Box", "Partition"}
    counts = {len(Simulation("mixed", seed=s).crowd.people) for s in range(12)}
    assert counts <= {4, 5, 6} and len(counts) > 1


def test_sensors_can_be_of_mixed_models_repeated_in_order_unless_one_is_forced(tmp_path):
    path = tmp_path / "mixed_models.yaml"
    path.write_text(
        "sensors: {count: 5, models: [kinect2, sr4500]}\npeople: {count: 0}\n", encoding="utf-8"
    )
    sim = Simulation(str(path), seed=0)
    assert [s.model.name for s in sim.sensors] == ["kinect2", "sr4500"] * 2 + ["kinect2"]
    assert [s.id for s in sim.sensors][:2] == ["kinect2_0", "sr4500_1"]
    assert {s.model.name for s in Simulation(str(path), sensor_model="kinect1").sensors} == {
        "kinect1"
    }


def test_crowd_scenario_has_seven_people_one_to_nine_metres_from_the_sensor():
    sim = Simulation("crowd", seed=0)
    assert len(sim.crowd.people) == 7
    sensor = sim.sensors[0].world_T_camera[:2, 3]
    x0, y0, x1, y1 = sim.crowd.area
    assert x0 - sensor[0] == pytest.approx(1.0, abs=0.05)
    assert x1 - sensor[0] == pytest.approx(9.0, abs=0.05)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("venue: [1, 2\n", "not valid YAML at line"),
        ("- just\n- a list\n", "must be a mapping"),
        ("venue:\n  size: [8, 6]\n  colour: red\n", "venue"),
        ("people:\n  count: many\n", "people.count"),
        ("venue:\n  obstacles:\n    - {kind: sofa, at: [0, 0]}\n", "venue.obstacles"),
        ("venue:\n  obstacles:\n    - {kind: pillar, at: [40, 0]}\n", "outside the"),
        ("sensors:\n  count: 0\n", "sensors.count"),
        ("people:\n  enter_leave: 1\n", "door"),
        ("board: {cols: 5, rows: 5}\n", "board.cols"),
        ("seconds: .nan\n", "finite"),
    ],
)
def test_broken_scenario_file_gives_one_clear_sentence(tmp_path, text, expected):
    path = tmp_path / "broken.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ScenarioError) as error:
        load_scenario(path)
    message = str(error.value)
    assert str(path) in message
    assert expected in message
    _one_sentence(message)


def test_missing_file_and_unknown_name_say_what_to_do(tmp_path):
    with pytest.raises(ScenarioError, match="does not exist"):
        load_scenario(tmp_path / "nowhere.yaml")
    with pytest.raises(ScenarioError, match="built in: .*mixed") as error:
        load_scenario("banquet")
    _one_sentence(str(error.value))


def test_cli_reports_a_broken_scenario_in_one_line_and_exits_1(tmp_path, capsys):
    path = write_scenario(tmp_path / "bad.yaml", {"people": {"count": -3}})
    code = main(["sim", str(path), "--out", str(tmp_path / "out"), "--json"])
    captured = capsys.readouterr()
    assert code == 1
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "people.count" in lines[0]
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("option", [["--people", "-1"], ["--sensors", "0"], ["--seconds", "0"]])
def test_cli_refuses_impossible_overrides(tmp_path, capsys, option):
    code = main(["sim", "mixed", "--out", str(tmp_path / "out"), *option])
    assert code == 1
    assert option[0] in capsys.readouterr().err


def test_a_venue_with_nobody_in_it_renders(tmp_path, capsys):
    """`--people 0` is an empty room (a background recording), not a traceback."""
    out = tmp_path / "empty"
    args = ["sim", "crowd", "--people", "0", "--seconds", "0.2", "--sensors", "1"]
    assert main([*args, "--out", str(out), "--json"]) == 0
    assert '"people": 0' in capsys.readouterr().out
