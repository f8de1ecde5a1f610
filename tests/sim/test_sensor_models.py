"""Sensor models: noise that follows each model's formula, and each device's quirks."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import person_scenario, wall_scenario

from optrack.sim import Simulation
from optrack.sim.models import MODELS, Kinect1, make_model
from optrack.sim.scenario import ScenarioError


def _central_errors(sim: Simulation) -> tuple[np.ndarray, np.ndarray]:
    """Depth errors (m) of one noisy frame against the ideal one in the image's centre,
    and each pixel's noise by the model's formula."""
    model = sim.sensors[0].model
    render = sim.renderer(0).render(None)
    rng = np.random.default_rng(7)
    ideal = model.measure(render, rng, noise=False).depth / 1000.0
    noisy = model.measure(render, rng, noise=True).depth / 1000.0
    h, w = ideal.shape
    c = min(h, w) // 8
    window = (slice(h // 2 - c, h // 2 + c), slice(w // 2 - c, w // 2 + c))
    ok = (ideal[window] > 0) & (noisy[window] > 0)
    z = render.depth[window][ok]
    cos = render.cos_incidence[window][ok]
    if model.name == "sr4500":  # amplitude based: range and albedo of each pixel
        sigma = model.depth_sigma(
            z * render.ray_scale[window][ok], cos, render.infrared_albedo[window][ok]
        )
    else:
        sigma = model.depth_sigma(z, cos)
    return (noisy[window] - ideal[window])[ok], np.broadcast_to(sigma, z.shape)


@pytest.mark.parametrize("model", sorted(MODELS))
@pytest.mark.parametrize("distance", [2.0, 6.0])
def test_depth_noise_std_matches_the_model_formula(tmp_path, model, distance):
    sim = Simulation(wall_scenario(tmp_path, distance), sensor_model=model)
    errors, sigma = _central_errors(sim)
    assert len(errors) > 500
    expected = float(np.sqrt(np.mean(np.square(sigma))))
    assert np.std(errors) == pytest.approx(expected, rel=0.2)


def test_kinect1_error_grows_with_distance_squared_and_kinect2_stays_nearly_flat():
    k1, k2 = make_model("kinect1"), make_model("kinect2")
    assert float(k1.depth_sigma(6.0) / k1.depth_sigma(2.0)) == pytest.approx(9.0)
    assert float(k2.depth_sigma(6.0)) < 0.2 * float(k1.depth_sigma(6.0))
    assert float(k2.depth_sigma(2.0)) < 0.005


def test_kinect1_depth_is_quantised_in_disparity_steps(tmp_path):
    sim = Simulation(wall_scenario(tmp_path, 4.0), sensor_model="kinect1")
    model = sim.sensors[0].model
    depth = model.measure(sim.renderer(0).render(None), np.random.default_rng(1)).depth
    wall = depth[180:300, 260:380]
    values = np.unique(wall[wall > 0])
    # Few distinct depths on a flat wall: 1/8-px disparity steps are ~5 cm apart at 4 m.
    assert len(values) < 40
    step = 4.0**2 / (model.intrinsics.fx * model.params.baseline) * model.params.disparity_step
    gaps = np.diff(values) / 1000.0
    assert np.median(gaps[gaps > 0.01]) == pytest.approx(step, rel=0.1)


def test_models_have_their_device_resolutions_rates_and_ranges():
    expected = {
        "kinect1": ((640, 480), 30.0, (0.8, 8.0)),
        "kinect2": ((512, 424), 30.0, (0.4, 10.0)),
        "sr4500": ((176, 144), 13.0, (0.4, 9.0)),
    }
    for name, (size, fps, span) in expected.items():
        model = make_model(name)
        assert (model.intrinsics.width, model.intrinsics.height) == size
        assert model.fps == fps
        assert (model.min_range, model.max_range) == span
    low = Kinect1(Kinect1.schema.create({"resolution": "320x240"}))
    assert (low.intrinsics.width, low.intrinsics.height) == (320, 240)
    assert low.intrinsics.fx == pytest.approx(262.5)


def test_unknown_model_is_refused_with_the_known_names():
    with pytest.raises(ScenarioError, match="kinect2"):
        make_model("kinect3")


def test_streams_per_model(tmp_path):
    scenario = person_scenario(tmp_path)
    frames = {}
    for name in MODELS:
        sim = Simulation(scenario, sensor_model=name)
        frames[name] = sim.frame(0, 0, sim.snapshot(0.0))
    assert frames["kinect2"].infrared.dtype == np.uint16 and frames["kinect2"].color is not None
    assert frames["sr4500"].color is None
    assert frames["sr4500"].confidence.dtype == np.uint16
    assert frames["sr4500"].infrared is not None
    assert frames["kinect1"].infrared is None and frames["kinect1"].color.shape == (480, 640, 3)
    assert frames["stereo"].color.shape == (480, 640, 3)


def test_sr4500_confidence_falls_with_distance(tmp_path):
    near = Simulation(wall_scenario(tmp_path, 2.0), sensor_model="sr4500")
    far = Simulation(wall_scenario(tmp_path, 7.0), sensor_model="sr4500")
    rng = np.random.default_rng(0)
    c_near = near.sensors[0].model.measure(near.renderer(0).render(None), rng).confidence
    c_far = far.sensors[0].model.measure(far.renderer(0).render(None), rng).confidence
    assert np.median(c_near[60:80, 80:100]) > 2 * np.median(c_far[60:80, 80:100])


def test_stereo_has_holes_on_textureless_walls_but_not_on_textured_ones(tmp_path):
    textured = Simulation(wall_scenario(tmp_path, 3.0), sensor_model="stereo")
    plain = Simulation(wall_scenario(tmp_path, 3.0, texture=0.0), sensor_model="stereo")
    rng = np.random.default_rng(0)
    with_texture = textured.sensors[0].model.measure(textured.renderer(0).render(None), rng).depth
    without = plain.sensors[0].model.measure(plain.renderer(0).render(None), rng).depth
    centre = (slice(200, 280), slice(280, 360))
    assert np.mean(with_texture[centre] > 0) > 0.3
    assert np.mean(without[centre] > 0) < 0.02


def test_kinect1_projector_shadow_leaves_a_band_without_depth_beside_a_person(tmp_path):
    sim = Simulation(person_scenario(tmp_path), sensor_model="kinect1")
    state = sim.snapshot(0.5)
    render = sim.renderer(0).render(state.geometry)
    assert render.second_view_blocked is not None
    person = render.labels == 0
    # Shadowed pixels are not on the person and have a surface behind: the wall or floor.
    shadow = render.second_view_blocked & ~person & np.isfinite(render.depth)
    assert shadow.sum() > 50
    rows, cols = np.nonzero(shadow)
    person_cols = np.nonzero(person)[1]
    assert abs(np.median(cols) - np.median(person_cols)) < 60
    frame = sim.frame(0, 0, state)
    assert np.all(frame.depth[shadow] == 0)


def test_kinect2_flying_pixels_sit_between_foreground_and_background(tmp_path):
    sim = Simulation(person_scenario(tmp_path), sensor_model="kinect2")
    state = sim.snapshot(0.5)
    render = sim.renderer(0).render(state.geometry)
    ideal = render.depth
    model = sim.sensors[0].model
    depth = model.measure(render, np.random.default_rng(3)).depth / 1000.0
    person = render.labels == 0
    person_depth = np.median(ideal[person])
    # Pixels measured well away from both the person and what is behind them.
    off = (depth > person_depth + 0.3) & (depth < ideal - 0.3) & (depth > 0)
    assert off.sum() > 10
    assert off.sum() < 0.5 * person.sum()


def test_timestamps_carry_clock_offset_and_jitter(tmp_path):
    data = {
        "venue": {"size": [8.0, 6.0]},
        "sensors": {"count": 2, "clock_offset_max_s": 0.5},
        "people": {"count": 0},
    }
    from conftest import write_scenario

    from optrack.sim import load_scenario

    sim = Simulation(load_scenario(write_scenario(tmp_path / "clock.yaml", data)), seed=3)
    for k, sensor in enumerate(sim.sensors):
        stamps = np.array([sim.stamp(k, n) for n in range(300)])
        truth = np.array([sensor.frame_time(n) for n in range(300)])
        offset = stamps - truth
        assert abs(np.mean(offset) - sensor.clock_offset) < 1e-3
        assert np.std(offset) == pytest.approx(sensor.model.jitter, rel=0.25)
        assert np.all(np.diff(stamps) > 0)
    assert sim.sensors[0].clock_offset != sim.sensors[1].clock_offset
    assert all(abs(s.clock_offset) <= 0.5 for s in sim.sensors)
