"""Detection parameters: one registered schema, OpenPTrack's defaults per sensor model."""

from __future__ import annotations

import pytest

from optrack.detection import DETECTION_PARAMS, detection_params
from optrack.params import REGISTRY, ParamError


def test_schema_is_registered_with_openptracks_generic_defaults():
    assert REGISTRY["detection"] is DETECTION_PARAMS
    p = detection_params()
    assert (p.voxel_size, p.min_height, p.max_height, p.heads_minimum_distance) == (
        0.06,
        1.0,
        2.3,
        0.3,
    )
    assert (p.minimum_luminance, p.max_distance) == (120, 15.0)
    # OpenPTrack's -1.75 / -2.0 were for PCL's SVM; OpenCV's scores run lower (params.py).
    assert p.min_confidence == -3.0
    assert (p.background_resolution, p.background_seconds) == (0.3, 3.0)


@pytest.mark.parametrize(
    ("model", "sampling", "max_distance", "min_confidence"),
    [("kinect1", 4, 8.0, -3.0), ("kinect2", 2, 10.0, -3.0), ("sr4500", 1, 10.0, -3.25)],
)
def test_sensor_models_get_openptracks_values(model, sampling, max_distance, min_confidence):
    p = detection_params(model)
    assert (p.sampling_factor, p.max_distance, p.min_confidence) == (
        sampling,
        max_distance,
        min_confidence,
    )


def test_time_of_flight_uses_infrared_and_confidence():
    p = detection_params("sr4500")
    assert p.hog_image == "infrared" and p.confidence_threshold == 200


def test_children_preset_lowers_the_shortest_person_and_overrides_win():
    assert detection_params("kinect2", "children").min_height < 1.0
    assert detection_params("kinect2", "children", {"min_height": 0.7}).min_height == 0.7


def test_bad_preset_and_bad_value_are_refused():
    with pytest.raises(ParamError, match="no preset 'toddlers'"):
        detection_params(preset="toddlers")
    with pytest.raises(ParamError, match="voxel_size"):
        detection_params(overrides={"voxel_size": 0.0})


def test_a_config_section_sets_values_for_every_sensor_and_per_sensor_model():
    from optrack.detection.params import check_config_section

    section = {"max_distance": 7.0, "kinect1": {"max_distance": 9.0, "min_confidence": -2.5}}
    check_config_section(section)
    kinect1 = detection_params("kinect1", overrides=section)
    assert (kinect1.max_distance, kinect1.min_confidence) == (9.0, -2.5)
    kinect2 = detection_params("kinect2", overrides=section)
    assert (kinect2.max_distance, kinect2.min_confidence) == (7.0, -3.0)
    assert kinect2.sampling_factor == 2  # the model's own values stay
    # A camera optrack has no figures for takes the section's "default" values.
    unknown = detection_params(None, overrides={"default": {"max_distance": 3.0}})
    assert unknown.max_distance == 3.0


def test_a_bad_config_section_is_refused_naming_the_sensor_model():
    from optrack.detection.params import check_config_section

    with pytest.raises(ParamError, match="max_distanse"):
        check_config_section({"max_distanse": 7.0})
    with pytest.raises(ParamError, match="under kinect1"):
        check_config_section({"kinect1": {"max_distance": -1.0}})
    with pytest.raises(ParamError, match="'stereo' is a sensor model"):
        check_config_section({"stereo": 8.0})
