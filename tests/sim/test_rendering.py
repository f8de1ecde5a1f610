"""Ray-cast rendering: depth on the people where ground truth says they are, visible
fractions, shading and lighting."""

from __future__ import annotations

import msgspec
import numpy as np
import pytest
from conftest import person_scenario

from optrack.geometry import invert, project, transform_points
from optrack.sim import MODELS, Simulation, load_scenario
from optrack.sim.body import JOINTS


@pytest.mark.parametrize("model", sorted(MODELS))
def test_person_centroid_projects_onto_pixels_at_the_person_depth(tmp_path, model):
    sim = Simulation(person_scenario(tmp_path), sensor_model=model)
    state = sim.snapshot(0.7)
    truth = sim.truth(state)
    person = truth.people[0]
    centroid = np.array(person.joints["spine"])
    assert np.hypot(centroid[0] - person.x, centroid[1] - person.y) < 0.1
    sensor = sim.sensors[0]
    camera = transform_points(invert(sensor.world_T_camera), centroid[None])[0]
    uv, _ = project(camera[None], sensor.model.intrinsics)
    u, v = uv[0]
    row, col = int(round(v)), int(round(u))
    ideal = sim.renderer(0).render(state.geometry)
    frame = sim.frame(0, 0, state)
    window = (slice(row - 1, row + 2), slice(col - 1, col + 2))
    assert np.all(ideal.labels[window] == 0), "the centroid's pixels show the person"
    surface = ideal.depth[window]
    # The body's front surface lies between the centroid and one torso depth before it.
    assert np.all(surface <= camera[2] + 0.01) and np.all(surface >= camera[2] - 0.3)
    measured = frame.depth[window] / 1000.0
    valid = measured > 0
    assert valid.sum() >= 5
    sigma = np.asarray(sensor.model.depth_sigma(surface, ideal.cos_incidence[window]))
    if model == "sr4500":
        sigma = sensor.model.depth_sigma(
            surface * ideal.ray_scale[window],
            ideal.cos_incidence[window],
            ideal.infrared_albedo[window],
        )
    assert np.all(
        np.abs(measured - surface)[valid]
        <= 4 * np.broadcast_to(sigma, surface.shape)[valid] + 0.0015
    )


def test_a_person_behind_the_partition_is_partly_hidden():
    sim = Simulation("occlusions", seed=0, seconds=20.0)
    sensor = sim.sensors[0].id
    fractions = []
    for t in np.arange(0.0, 20.0, 0.5):
        truth = sim.truth(sim.snapshot(t))
        fractions += [p.visible[sensor] for p in truth.people]
    fractions = np.array(fractions)
    assert fractions.max() > 0.9  # seen whole at times
    assert np.any((fractions > 0.05) & (fractions < 0.7))  # and partly hidden at others


def test_visible_fraction_is_zero_outside_the_view_and_matches_rendered_pixels(tmp_path):
    sim = Simulation(person_scenario(tmp_path), seed=0, sensors=1)
    state = sim.snapshot(1.0)
    fraction = sim.visible_fractions(state)[0, 0]
    assert fraction > 0.4  # the front half and more; the back is hidden by the body itself
    render = sim.renderer(0).render(state.geometry)
    assert (render.labels == 0).sum() > 500

    # Turn the sensor away: nothing of the person is visible.
    sim.sensors[0].world_T_camera = sim.sensors[0].world_T_camera @ np.diag([-1.0, 1.0, -1.0, 1.0])
    assert sim.visible_fractions(state)[0, 0] == 0.0


def test_depth_of_the_empty_venue_matches_the_floor_plane(tmp_path):
    sim = Simulation(person_scenario(tmp_path), seed=0)
    render = sim.renderer(0).render(None)
    sensor = sim.sensors[0]
    rows, cols = np.mgrid[300:420:10, 100:400:10]
    z = render.depth[rows, cols]
    k = sensor.model.intrinsics
    camera = np.stack([(cols - k.cx) / k.fx * z, (rows - k.cy) / k.fy * z, z], -1).reshape(-1, 3)
    world = transform_points(sensor.world_T_camera, camera)
    assert np.allclose(world[:, 2], 0.0, atol=1e-4)


def test_near_dark_lighting_gives_dark_noisy_colour_but_the_same_infrared(tmp_path):
    scenario = person_scenario(tmp_path)
    dark_venue = msgspec.structs.replace(
        scenario.venue, lighting=msgspec.structs.replace(scenario.venue.lighting, level=0.03)
    )
    dark = msgspec.structs.replace(scenario, venue=dark_venue)
    lit_frame = Simulation(scenario, seed=0).frame(0, 0, Simulation(scenario, seed=0).snapshot(0.0))
    sim = Simulation(dark, seed=0)
    dark_frame = sim.frame(0, 0, sim.snapshot(0.0))
    assert dark_frame.color.mean() < 0.35 * lit_frame.color.mean()
    assert (
        np.mean(np.abs(dark_frame.infrared.astype(float) - lit_frame.infrared.astype(float)))
        < 0.05 * lit_frame.infrared.mean()
    )


def test_people_wear_their_own_clothes(tmp_path):
    sim = Simulation("crowd", seed=3)
    shirts = {p.materials[2].albedo for p in sim.crowd.people}
    assert len(shirts) == len(sim.crowd.people)
    state = sim.snapshot(0.0)
    frame = sim.frame(0, 0, state)
    labels = sim.renderer(0).render(state.geometry).labels
    torso_colours = [frame.color[labels == k].mean(axis=0) for k in np.unique(labels[labels >= 0])]
    assert len(torso_colours) >= 3
    spread = np.ptp(np.array(torso_colours), axis=0).max()
    assert spread > 20


def test_joints_of_the_body_are_inside_its_rendered_silhouette(tmp_path):
    sim = Simulation(person_scenario(tmp_path), seed=0)
    state = sim.snapshot(0.5)
    sensor = sim.sensors[0]
    render = sim.renderer(0).render(state.geometry)
    camera = transform_points(invert(sensor.world_T_camera), state.joints[0])
    uv, _ = project(camera, sensor.model.intrinsics)
    inside = 0
    for name in ("head", "spine", "pelvis", "left_knee", "right_knee"):
        u, v = np.rint(uv[JOINTS.index(name)]).astype(int)
        inside += render.labels[v - 2 : v + 3, u - 2 : u + 3].max() == 0
    assert inside == 5


def test_scenario_lighting_is_read_from_the_file():
    scenario = load_scenario("mixed")
    assert scenario.venue.lighting.level == 1.0


def test_casting_only_near_moving_parts_gives_the_same_depth_as_casting_everything():
    import open3d as o3d

    sim = Simulation("mixed", seed=3, people=6)
    state = sim.snapshot(2.0)
    renderer = sim.renderer(0)
    fast = renderer.render(state.geometry)
    full = o3d.t.geometry.RaycastingScene()
    full.add_triangles(o3d.core.Tensor(sim.venue.vertices), o3d.core.Tensor(sim.venue.triangles))
    full.add_triangles(
        o3d.core.Tensor(state.geometry.vertices), o3d.core.Tensor(state.geometry.triangles)
    )
    depth = (
        full.cast_rays(o3d.core.Tensor(renderer.rays))["t_hit"].numpy().reshape(fast.depth.shape)
    )
    assert (fast.labels >= 0).sum() > 1000
    assert np.allclose(fast.depth, depth, rtol=0, atol=1e-5)
