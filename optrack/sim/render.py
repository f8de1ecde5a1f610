"""Ray-cast rendering with Open3D's ``RaycastingScene`` (Embree).

A sensor's rays never change (its pose is fixed), and neither does the
venue, so each :class:`SensorRenderer` casts the static venue once and keeps
the result. Each frame then casts only the rays that can hit something that
moves: those inside the image rectangles of the people's (and the board's)
bounding boxes, against a small scene of just the moving meshes, and keeps
the nearer hit. The output is the same as casting everything every frame.

Ray directions are ``R (x/z, y/z, 1)`` per pixel, so a hit distance is the
pixel's depth (z in the camera frame) directly. Shading is Lambertian: one
directional light plus an ambient share, scaled by the lighting level;
infrared albedo is kept separately for time-of-flight amplitude.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import open3d as o3d

from optrack.geometry import invert, transform_points
from optrack.params import Param, Params, Schema, register
from optrack.sim.board import PhysicalBoard
from optrack.sim.materials import MaterialTable, cell_noise
from optrack.sim.scenario import Lighting
from optrack.sim.venue import Venue
from optrack.types import Intrinsics

__all__ = [
    "RENDER_PARAMS",
    "DynamicGeometry",
    "RenderResult",
    "SensorRenderer",
    "StaticScene",
]

RENDER_PARAMS = register(
    Schema(
        "sim_render",
        [
            Param("threads", 0, 0, 256, 1, "", "Ray casting threads (0: all cores)."),
            Param(
                "shadow_epsilon",
                0.003,
                0.0001,
                0.1,
                0.0001,
                "m",
                "Second-view rays stop this short of the surface.",
            ),
            Param(
                "near_clip",
                0.05,
                0.001,
                1.0,
                0.01,
                "m",
                "Boxes closer than this to the camera plane cover the whole image.",
            ),
        ],
        help="Ray-cast rendering of the simulated sensors.",
    )
)

_NO_OWNER = -1


def _tensor(array: np.ndarray) -> o3d.core.Tensor:
    return o3d.core.Tensor.from_numpy(np.ascontiguousarray(array))


def light_direction(lighting: Lighting) -> np.ndarray:
    az, el = math.radians(lighting.azimuth_deg), math.radians(lighting.elevation_deg)
    return np.array(
        [math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)], dtype=np.float32
    )


def shade(normals: np.ndarray, directions: np.ndarray, lighting: Lighting) -> np.ndarray:
    """Irradiance factor (N,) of surfaces with world ``normals`` seen along ``directions``."""
    facing = np.einsum("ij,ij->i", normals, directions)
    oriented = normals * np.where(facing > 0, -1.0, 1.0).astype(np.float32)[:, None]
    lambert = np.maximum(oriented @ light_direction(lighting), 0.0)
    return (lighting.level * (lighting.ambient + (1.0 - lighting.ambient) * lambert)).astype(
        np.float32
    )


class StaticScene:
    """The venue's mesh in a RaycastingScene, with its materials."""

    def __init__(self, venue: Venue) -> None:
        self.venue = venue
        self.materials: MaterialTable = venue.materials
        self.triangle_material = venue.triangle_material
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(_tensor(venue.vertices), _tensor(venue.triangles))


@dataclasses.dataclass
class DynamicGeometry:
    """Everything that moves at one instant, as one mesh.

    ``boxes[k]`` is the axis-aligned (min, max) box of owner k (a person, or
    the board, last). ``hulls`` are groups of points (arrays (G, K, 3)) whose
    convex hulls together cover the meshes: their image rectangles decide the
    rays a frame casts.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    triangle_material: np.ndarray
    triangle_owner: np.ndarray
    triangle_texture: np.ndarray
    materials: MaterialTable
    boxes: np.ndarray
    hulls: list[np.ndarray]
    board: PhysicalBoard | None = None
    world_T_board: np.ndarray | None = None
    triangle_part: np.ndarray | None = None  # body part of each triangle (-1: none)
    _scene: o3d.t.geometry.RaycastingScene | None = None

    @property
    def empty(self) -> bool:
        return len(self.triangles) == 0

    @property
    def scene(self) -> o3d.t.geometry.RaycastingScene:
        """The moving meshes' ray-casting scene (built once, shared by every sensor)."""
        if self._scene is None:
            self._scene = o3d.t.geometry.RaycastingScene()
            self._scene.add_triangles(
                _tensor(self.vertices.astype(np.float32)), _tensor(self.triangles.astype(np.uint32))
            )
        return self._scene


@dataclasses.dataclass(eq=False)
class RenderResult:
    """Ideal images of one sensor at one instant (before the sensor model).

    ``depth`` is z in the camera frame (metres, inf where no surface);
    ``ray_scale`` turns depth into range along the ray; ``labels`` is the owner
    index of a moving object per pixel (-1 for the venue or nothing), ``parts`` the
    body part there (an index into :data:`optrack.sim.body.PART_NAMES`; -1 elsewhere);
    ``radiance`` is linear RGB (1 = white, fully lit); ``second_view_blocked``
    marks points the model's second viewpoint cannot see. ``static`` is the
    venue-only render of the same sensor (never changes) and ``changed`` the
    flat indices of the pixels where this frame differs from it, so that
    models can cache what depends only on the venue.
    """

    depth: np.ndarray
    cos_incidence: np.ndarray
    ray_scale: np.ndarray
    labels: np.ndarray
    radiance: np.ndarray | None = None
    infrared_albedo: np.ndarray | None = None
    second_view_blocked: np.ndarray | None = None
    static: RenderResult | None = None
    parts: np.ndarray | None = None
    changed: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    @property
    def venue(self) -> RenderResult:
        """The venue-only render (this one, when it is that)."""
        return self if self.static is None else self.static


class SensorRenderer:
    """Renders one sensor (fixed pose and intrinsics) of one venue."""

    def __init__(
        self,
        static: StaticScene,
        intrinsics: Intrinsics,
        world_T_camera: np.ndarray,
        lighting: Lighting,
        *,
        radiance: bool = True,
        infrared: bool = True,
        second_view: float | None = None,
        params: Params | None = None,
    ) -> None:
        self.static = static
        self.intrinsics = intrinsics
        self.world_T_camera = np.asarray(world_T_camera, dtype=np.float64)
        self.camera_T_world = invert(self.world_T_camera)
        self.lighting = lighting
        self.want_radiance = radiance
        self.want_infrared = infrared
        self.second_view = second_view
        self.params = params if params is not None else RENDER_PARAMS.create()
        self.threads = int(self.params.threads)
        k = intrinsics
        self.height, self.width = k.height, k.width
        x = (np.arange(k.width, dtype=np.float64) - k.cx) / k.fx
        y = (np.arange(k.height, dtype=np.float64) - k.cy) / k.fy
        camera_dirs = np.stack(np.broadcast_arrays(x[None, :], y[:, None], 1.0), axis=-1)
        rotation = self.world_T_camera[:3, :3]
        world_dirs = camera_dirs @ rotation.T
        origin = np.broadcast_to(self.world_T_camera[:3, 3], world_dirs.shape)
        rays = np.concatenate([origin, world_dirs], axis=-1)
        self.rays = np.ascontiguousarray(rays.reshape(-1, 6), dtype=np.float32)  # flat, row-major
        self.ray_scale = np.linalg.norm(camera_dirs, axis=-1).astype(np.float32)
        self._ray_norm = self.ray_scale.ravel()  # |direction| per flat pixel (rotation keeps it)
        self.second_origin = (
            None
            if second_view is None
            else (self.world_T_camera @ np.array([second_view, 0.0, 0.0, 1.0]))[:3].astype(
                np.float32
            )
        )
        self.venue = self._render_static()

    @property
    def shape(self) -> tuple[int, int]:
        return self.height, self.width

    # ------------------------------------------------------------- static
    def _render_static(self) -> RenderResult:
        hit = self.static.scene.cast_rays(_tensor(self.rays), nthreads=self.threads)
        t = hit["t_hit"].numpy().astype(np.float32)
        index = np.flatnonzero(np.isfinite(t))
        normals = hit["primitive_normals"].numpy()[index]
        directions = self.rays[index, 3:]
        cos = np.zeros(t.shape, dtype=np.float32)
        cos[index] = self._cos(normals, directions, index)
        radiance = infrared = blocked = None
        if self.want_radiance or self.want_infrared:
            material = self.static.triangle_material[hit["primitive_ids"].numpy()[index]]
            table = self.static.materials
            points = self.rays[index, :3] + t[index, None] * directions
            factor = 1.0 + table.texture[material] * cell_noise(
                points, table.texture_cell[material]
            )
            if self.want_radiance:
                radiance = np.zeros((t.size, 3), dtype=np.float32)
                light = shade(normals, directions, self.lighting)
                radiance[index] = table.albedo[material] * (factor * light)[:, None]
                radiance = radiance.reshape(*self.shape, 3)
            if self.want_infrared:
                infrared = np.zeros(t.size, dtype=np.float32)
                infrared[index] = table.infrared[material] * factor
                infrared = infrared.reshape(self.shape)
        if self.second_origin is not None:
            blocked = np.zeros(t.size, dtype=bool)
            blocked[index] = self._blocked(self.static.scene, index, t)
            blocked = blocked.reshape(self.shape)
        return RenderResult(
            depth=t.reshape(self.shape),
            cos_incidence=cos.reshape(self.shape),
            ray_scale=self.ray_scale,
            labels=np.full(self.shape, _NO_OWNER, dtype=np.int16),
            radiance=radiance,
            infrared_albedo=infrared,
            second_view_blocked=blocked,
        )

    def _cos(self, normals: np.ndarray, directions: np.ndarray, index: np.ndarray) -> np.ndarray:
        """|cos| of the angle between surface normals and the rays of pixels ``index``."""
        dot = np.abs(np.einsum("ij,ij->i", normals, directions))
        return (dot / self._ray_norm[index]).astype(np.float32)

    def _blocked(
        self, scene: o3d.t.geometry.RaycastingScene, index: np.ndarray, depth: np.ndarray
    ) -> np.ndarray:
        """Whether the second viewpoint's rays to the surface points of the pixels at flat
        ``index`` (with flat ``depth``) are blocked by ``scene``."""
        if len(index) == 0:
            return np.zeros(0, dtype=bool)
        points = self.rays[index, :3] + depth[index, None] * self.rays[index, 3:]
        delta = points - self.second_origin
        length = float(max(np.linalg.norm(delta, axis=1).min(), 1e-6))
        rays = np.concatenate([np.broadcast_to(self.second_origin, delta.shape), delta], axis=1)
        tfar = 1.0 - float(self.params.shadow_epsilon) / length
        blocked = scene.test_occlusions(
            _tensor(rays.astype(np.float32)), tnear=0.0, tfar=tfar, nthreads=self.threads
        )
        return blocked.numpy().astype(bool)

    # -------------------------------------------------------------- frames
    def pixels(self, dynamic: DynamicGeometry, widen: bool = False) -> np.ndarray:
        """Flat indices of the pixels whose rays can meet the moving meshes: the union of
        the image rectangles bounding each hull's projected points (a convex hull projects
        inside the rectangle of its projected points; pixel centres sit at integer
        coordinates, and the rectangle is rounded outwards). ``widen`` adds the second view's
        disparity sideways (pixels whose second-view ray can pass a hull)."""
        k, near = self.intrinsics, float(self.params.near_clip)
        rotation = self.camera_T_world[:3, :3].T.astype(np.float32)
        translation = self.camera_T_world[:3, 3].astype(np.float32)
        rects = []
        for group in dynamic.hulls:
            if len(group) == 0:
                continue
            camera = group @ rotation + translation
            z = camera[..., 2]
            z_min = z.min(axis=1)
            if np.any((z_min <= near) & (z.max(axis=1) > near)):
                return np.arange(self.width * self.height)  # a hull straddles the camera plane
            with np.errstate(divide="ignore", invalid="ignore"):
                u = k.fx * camera[..., 0] / z + k.cx
                v = k.fy * camera[..., 1] / z + k.cy
            pad = 0.0
            if widen and self.second_view is not None:
                pad = np.ceil(k.fx * abs(self.second_view) / np.maximum(z_min, near))
            rects.append(
                np.stack(
                    [
                        np.floor(v.min(axis=1)),
                        np.ceil(v.max(axis=1)) + 1,
                        np.floor(u.min(axis=1)) - pad,
                        np.ceil(u.max(axis=1)) + 1 + pad,
                        z_min,
                    ],
                    axis=1,
                )
            )
        if not rects:
            return np.zeros(0, dtype=np.int64)
        rects = np.concatenate(rects)
        rects = rects[rects[:, 4] > near]
        v0, v1 = (np.clip(rects[:, i], 0, self.height).astype(int) for i in (0, 1))
        u0, u1 = (np.clip(rects[:, i], 0, self.width).astype(int) for i in (2, 3))
        mask = np.zeros(self.shape, dtype=bool)
        for b in np.flatnonzero((u0 < u1) & (v0 < v1)):
            mask[v0[b] : v1[b], u0[b] : u1[b]] = True
        return np.flatnonzero(mask)

    def render(self, dynamic: DynamicGeometry | None) -> RenderResult:
        """The ideal images of this sensor with ``dynamic`` (or just the venue)."""
        venue = self.venue
        depth = venue.depth.ravel().copy()
        cos = venue.cos_incidence.ravel().copy()
        labels = venue.labels.ravel().copy()
        parts = np.full(labels.shape, _NO_OWNER, dtype=np.int16)
        radiance = None if venue.radiance is None else venue.radiance.reshape(-1, 3).copy()
        infrared = None if venue.infrared_albedo is None else venue.infrared_albedo.ravel().copy()
        blocked = (
            None if venue.second_view_blocked is None else venue.second_view_blocked.ravel().copy()
        )
        changed = np.zeros(0, dtype=np.int64)
        if dynamic is not None and not dynamic.empty:
            changed = self._cast(dynamic, depth, cos, labels, radiance, infrared, parts)
            if blocked is not None:
                self._second_view(dynamic, depth, changed, blocked)
        shape = self.shape
        return RenderResult(
            depth=depth.reshape(shape),
            cos_incidence=cos.reshape(shape),
            ray_scale=self.ray_scale,
            labels=labels.reshape(shape),
            parts=parts.reshape(shape),
            radiance=None if radiance is None else radiance.reshape(*shape, 3),
            infrared_albedo=None if infrared is None else infrared.reshape(shape),
            second_view_blocked=None if blocked is None else blocked.reshape(shape),
            static=venue,
            changed=changed,
        )

    def _cast(
        self,
        dynamic: DynamicGeometry,
        depth: np.ndarray,
        cos: np.ndarray,
        labels: np.ndarray,
        radiance: np.ndarray | None,
        infrared: np.ndarray | None,
        parts: np.ndarray | None = None,
    ) -> np.ndarray:
        """Cast the rays that can meet moving things; update the flat images where they
        hit something nearer than the venue. Returns the flat indices updated."""
        candidates = self.pixels(dynamic)
        if len(candidates) == 0:
            return candidates
        rays = self.rays[candidates]
        hit = dynamic.scene.cast_rays(_tensor(rays), nthreads=self.threads)
        t = hit["t_hit"].numpy()
        nearer = np.flatnonzero(t < depth[candidates])
        index = candidates[nearer]
        if len(index) == 0:
            return index
        tt = t[nearer]
        prim = hit["primitive_ids"].numpy()[nearer]
        normals = hit["primitive_normals"].numpy()[nearer]
        directions = rays[nearer, 3:]
        depth[index] = tt
        cos[index] = self._cos(normals, directions, index)
        labels[index] = dynamic.triangle_owner[prim]
        if parts is not None and dynamic.triangle_part is not None:
            parts[index] = dynamic.triangle_part[prim]
        if radiance is None and infrared is None:
            return index
        table = dynamic.materials
        material = dynamic.triangle_material[prim]
        factor = 1.0 + table.texture[material] * dynamic.triangle_texture[prim]
        albedo = table.albedo[material] * factor[:, None]
        ir = table.infrared[material] * factor
        checker = np.flatnonzero(table.checker[material])
        if len(checker) and dynamic.board is not None and dynamic.world_T_board is not None:
            board = dynamic.board
            points = rays[nearer[checker], :3] + tt[checker, None] * directions[checker]
            local = transform_points(invert(dynamic.world_T_board), points)
            ranges = tt[checker] * self._ray_norm[index[checker]]
            footprint = ranges / self.intrinsics.fx / np.maximum(cos[index[checker]], 0.2)
            white = board.reflectance(local[:, :2], footprint)
            p = board.params
            albedo[checker] = (p.black + (p.white - p.black) * white)[:, None]
            ir[checker] = p.black_infrared + (p.white_infrared - p.black_infrared) * white
        if radiance is not None:
            radiance[index] = albedo * shade(normals, directions, self.lighting)[:, None]
        if infrared is not None:
            infrared[index] = ir
        return index

    def _second_view(
        self, dynamic: DynamicGeometry, depth: np.ndarray, moving: np.ndarray, blocked: np.ndarray
    ) -> None:
        """Recompute second-view blocking where the moving meshes can matter: their
        own pixels (against the venue) and every pixel near them (against them)."""
        blocked[moving] = self._blocked(self.static.scene, moving, depth)
        near = self.pixels(dynamic, widen=True)
        near = near[np.isfinite(depth[near])]
        blocked[near] |= self._blocked(dynamic.scene, near, depth)
