"""The Parameters panel is built from Schemas, validates every edit and reads/writes presets."""

import pytest
import yaml

from app.widgets.parameters_panel import ParametersPanel, decimals_for
from optrack.params import Param, Schema

DETECTOR = Schema(
    "detector_gui_test",
    [
        Param("voxel_size", 0.06, min=0.01, max=0.2, step=0.01, unit="m", help="Leaf size."),
        Param("sampling_factor", 4, min=1, max=8, step=1, help="Keep every n-th pixel."),
        Param("use_hog", True, help="Judge clusters with HOG."),
        Param("classifier", "hog", choices=("hog", "none"), help="Which classifier."),
        Param("max_missing", 1.5, min=0.0, unit="s", help="No upper bound."),
    ],
    help="A detector-like stage for the panel's tests.",
)
VIEW = Schema("view_gui_test", [Param("trail_seconds", 8.0, min=0.0, max=120.0, step=0.5)])


@pytest.fixture
def panel(qtbot):
    panel = ParametersPanel()
    qtbot.addWidget(panel)
    panel.set_schemas({DETECTOR.stage: DETECTOR})
    panel.set_schemas({VIEW.stage: VIEW}, local=True)
    return panel


def editor(panel, name):
    return panel.editors[DETECTOR.stage][name]


def test_controls_carry_units_ranges_and_help(panel):
    voxel = editor(panel, "voxel_size")
    assert voxel.spin.suffix() == " m" and voxel.spin.decimals() == 2
    assert (voxel.spin.minimum(), voxel.spin.maximum()) == (0.01, 0.2)
    assert (voxel.slider.minimum(), voxel.slider.maximum()) == (0, 19)
    assert "Leaf size." in voxel.toolTip() and "between 0.01 and 0.2 m" in voxel.toolTip()
    assert editor(panel, "use_hog").check.isChecked()
    assert editor(panel, "classifier").combo.currentText() == "hog"
    assert editor(panel, "max_missing").slider is None  # no upper bound: a spin box only
    assert [panel.pages.itemText(i) for i in range(panel.pages.count())] == [
        "Detector GUI test",
        "View GUI test (this window)",
    ]
    assert panel.pages.itemToolTip(0) == "Section 'detector_gui_test' of a config file or preset."


def test_moving_a_slider_emits_the_validated_value(qtbot, panel):
    voxel = editor(panel, "voxel_size")
    with qtbot.waitSignal(panel.changed) as changed:
        voxel.slider.setValue(7)  # 0.01 + 7 * 0.01
    assert changed.args == [DETECTOR.stage, {"voxel_size": 0.08}]
    assert voxel.spin.value() == 0.08
    assert panel.values[DETECTOR.stage].voxel_size == 0.08
    with qtbot.waitSignal(panel.changed) as changed:
        editor(panel, "sampling_factor").spin.setValue(6)
    assert changed.args == [DETECTOR.stage, {"sampling_factor": 6}]
    assert isinstance(changed.args[1]["sampling_factor"], int)
    with qtbot.waitSignal(panel.changed) as changed:
        editor(panel, "use_hog").check.setChecked(False)
    assert changed.args == [DETECTOR.stage, {"use_hog": False}]


def test_a_value_the_schema_refuses_is_not_sent_and_is_explained(qtbot, panel):
    with qtbot.assertNotEmitted(panel.changed), qtbot.waitSignal(panel.problem) as problem:
        assert not panel.edit(DETECTOR.stage, "max_missing", -1.0)
    assert problem.args == ["detector_gui_test.max_missing must be at least 0 s; got -1.0."]
    assert panel.message.text() == problem.args[0]
    assert editor(panel, "max_missing").value() == 1.5  # back to the accepted value


def test_values_reported_by_the_nodes_are_shown_but_not_sent_back(qtbot, panel):
    with qtbot.assertNotEmitted(panel.changed):
        panel.set_values(DETECTOR.stage, {"voxel_size": 0.1, "classifier": "none"})
    assert editor(panel, "voxel_size").spin.value() == 0.1
    assert editor(panel, "voxel_size").slider.value() == 9
    assert editor(panel, "classifier").combo.currentText() == "none"


def test_presets_round_trip_through_config_files(qtbot, panel, tmp_path):
    editor(panel, "voxel_size").slider.setValue(4)
    editor(panel, "use_hog").check.setChecked(False)
    preset = tmp_path / "crowded.yaml"
    assert panel.save_preset(preset)
    saved = yaml.safe_load(preset.read_text())
    assert set(saved) == {DETECTOR.stage}  # the window's own view settings stay out
    assert saved[DETECTOR.stage]["voxel_size"] == 0.05 and saved[DETECTOR.stage]["use_hog"] is False
    panel.defaults_button.click()  # the open page is the first: back to defaults
    assert panel.values[DETECTOR.stage].voxel_size == 0.06
    with qtbot.waitSignal(panel.changed) as changed:
        assert panel.load_preset(preset)
    assert changed.args == [DETECTOR.stage, {"voxel_size": 0.05, "use_hog": False}]
    assert editor(panel, "voxel_size").spin.value() == 0.05


def test_a_broken_preset_is_refused_with_the_loaders_sentence(qtbot, panel, tmp_path):
    preset = tmp_path / "bad.yaml"
    preset.write_text(f"{DETECTOR.stage}:\n  voxel_size: 3.0\n")
    with qtbot.assertNotEmitted(panel.changed):
        assert not panel.load_preset(preset)
    assert "voxel_size must be between 0.01 and 0.2 m; got 3.0" in panel.message.text()
    assert not panel.load_preset(tmp_path / "missing.yaml")
    assert "does not exist" in panel.message.text()


def test_decimals_show_step_bounds_and_default_exactly():
    assert decimals_for(Param("a", 0.0015, min=0.0, max=0.05, step=0.0005)) == 4
    assert decimals_for(Param("b", 100.0, min=0.01, max=10000.0, step=1.0)) == 2
    assert decimals_for(Param("c", 30.0, min=1.0, max=300.0, step=1.0)) == 0


def test_every_node_stage_of_optrack_builds_a_page(qtbot):
    from app.source import node_schemas

    schemas = node_schemas()
    assert {"detection", "tracking"} <= set(schemas)
    panel = ParametersPanel()
    qtbot.addWidget(panel)
    panel.set_schemas(schemas)
    for stage, schema in schemas.items():
        for param in schema:
            assert panel.editors[stage][param.name].value() == param.default, (
                f"{stage}.{param.name}"
            )


def test_names_units_and_fields_read_as_words_and_are_never_cut_off(qtbot):
    """Page and parameter names in words (acronyms in capitals), exponents written as
    superscripts, and a value field wide enough for its longest value and unit even in a
    narrow dock."""
    from PySide6.QtGui import QFontMetrics

    from app.widgets.parameters_panel import title_for

    schema = Schema(
        "calibration_capture",
        [
            Param("ukf_alpha", 0.001, min=0.0001, max=1.0, help="Spread of the sigma points."),
            Param(
                "acceleration_noise",
                12.5,
                min=0.0,
                max=100000.0,
                step=0.001,
                unit="m^2/s^4",
                help="Process noise.",
            ),
        ],
    )
    panel = ParametersPanel()
    qtbot.addWidget(panel)
    panel.set_schemas({schema.stage: schema})
    panel.resize(200, 400)
    panel.show()
    assert panel.pages.itemText(0) == "Calibration capture"
    assert title_for("ukf_alpha") == "UKF alpha" and title_for("use_hog") == "Use HOG"
    noise = panel.editors["calibration_capture"]["acceleration_noise"]
    assert noise.label.text() == "<b>Acceleration noise</b> (m²/s⁴)"
    assert noise.spin.suffix() == " m²/s⁴" and "m^2" not in noise.toolTip()
    longest = noise.spin.textFromValue(noise.spin.maximum()) + noise.spin.suffix()
    assert noise.spin.width() >= QFontMetrics(noise.spin.font()).horizontalAdvance(longest)


def test_the_tooltip_says_the_value_in_use_when_it_is_not_the_default(panel):
    """A site may start a stage with other values than the schema's defaults: the
    tooltip beside the field names both, never a default that disagrees unexplained."""
    voxel = editor(panel, "voxel_size")
    assert "default 0.06." in voxel.toolTip()
    panel.set_values(DETECTOR.stage, {"voxel_size": 0.1})
    assert voxel.spin.value() == 0.1
    assert "default 0.06; in use now: 0.1." in voxel.toolTip()
    assert voxel.label.toolTip() == voxel.toolTip()
