import pytest

from optrack.params import REGISTRY, Param, ParamError, Schema, load_config, save_config

SCHEMA = Schema(
    "detection",
    [
        Param("voxel_size", 0.06, min=0.01, max=0.5, step=0.01, unit="m", help="Voxel grid size."),
        Param("sampling_factor", 4, min=1, max=16, step=1, help="Take every n-th pixel."),
        Param("use_hog", True, help="Classify candidates with HOG."),
        Param("ground", "auto", choices=("auto", "manual", "calibration")),
    ],
)
REG = {"detection": SCHEMA}


def test_defaults_come_from_the_declaration():
    params = SCHEMA.create()
    assert params.voxel_size == 0.06 and params.sampling_factor == 4 and params.use_hog is True


def test_out_of_range_value_names_the_parameter_and_its_range():
    with pytest.raises(
        ParamError, match=r"^detection\.voxel_size must be between 0\.01 and 0\.5 m; got 2\.0\.$"
    ):
        SCHEMA.create().update({"voxel_size": 2.0})


@pytest.mark.parametrize(
    ("name", "value", "message"),
    [
        ("voxel_size", "big", "must be between"),
        ("sampling_factor", 2.5, "whole number"),
        ("sampling_factor", True, "must be between 1 and 16"),
        ("use_hog", 1, "true or false"),
        ("ground", "magic", "one of auto, manual, calibration"),
        ("voxel_size", float("nan"), "must be between"),
    ],
)
def test_wrong_type_is_refused_with_a_sentence(name, value, message):
    with pytest.raises(ParamError, match=message):
        SCHEMA.create().update({name: value})


def test_unknown_parameter_suggests_the_closest_name():
    with pytest.raises(ParamError, match="no parameter 'voxel'.*Did you mean 'voxel_size'"):
        SCHEMA.create().update({"voxel": 0.1})


def test_update_is_all_or_nothing_and_reports_changes():
    params = SCHEMA.create()
    with pytest.raises(ParamError):
        params.update({"voxel_size": 0.1, "sampling_factor": 0})
    assert params.voxel_size == 0.06
    assert params.update({"voxel_size": 0.1, "sampling_factor": 4}) == {"voxel_size": 0.1}
    params.sampling_factor = 2.0  # integral floats are accepted for whole numbers
    assert params.sampling_factor == 2 and isinstance(params.sampling_factor, int)


def test_declaring_a_bad_default_or_range_fails_at_import_time():
    with pytest.raises(ParamError):
        Param("x", 5.0, min=0, max=1)
    with pytest.raises(ValueError, match="above max"):
        Param("x", 0.5, min=1, max=0)


def test_config_round_trips_through_yaml(tmp_path):
    path = tmp_path / "site.yaml"
    params = SCHEMA.create({"voxel_size": 0.08, "ground": "manual"})
    save_config(path, {"detection": params}, registry=REG)
    loaded = load_config(path, registry=REG)
    assert loaded["detection"] == params


def test_config_errors_name_the_file_and_the_problem(tmp_path):
    with pytest.raises(ParamError, match="does not exist"):
        load_config(tmp_path / "missing.yaml", registry=REG)
    bad = tmp_path / "bad.yaml"
    bad.write_text("detection: [unclosed\n")
    with pytest.raises(ParamError, match="not valid YAML at line"):
        load_config(bad, registry=REG)
    bad.write_text("detecton:\n  voxel_size: 0.1\n")
    with pytest.raises(ParamError, match="unknown stage 'detecton'.*Did you mean 'detection'"):
        load_config(bad, registry=REG)
    bad.write_text("detection:\n  voxel_size: 9\n")
    with pytest.raises(ParamError, match=r"bad\.yaml: detection\.voxel_size must be between"):
        load_config(bad, registry=REG)


def test_save_never_leaves_a_half_written_file(tmp_path):
    path = tmp_path / "site.yaml"
    save_config(path, {"detection": SCHEMA.create()}, registry=REG)
    before = path.read_text()
    with pytest.raises(ParamError):
        save_config(path, {"detection": {"voxel_size": -1}}, registry=REG)
    assert path.read_text() == before
    assert [p.name for p in tmp_path.iterdir()] == ["site.yaml"]


def test_stages_of_optrack_register_their_schemas():
    import optrack.recording  # noqa: F401 - registers "recording"

    assert "recording" in REGISTRY
    assert REGISTRY["recording"]["color_format"].choices == ("jpg", "png")
