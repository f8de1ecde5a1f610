"""The static venue: floor, walls with doors, ceiling and furniture, as one triangle mesh.

The room spans ``x`` in [-length/2, length/2] and ``y`` in [-width/2,
width/2] around the world origin on the floor (z up). Besides the mesh that
sensors see, the venue gives walkers its floor plan: obstacle footprints
(circles and oriented rectangles) and the walls, as signed distances.
"""

from __future__ import annotations

import math

import numpy as np
import open3d as o3d

from optrack.sim.materials import Material, MaterialTable
from optrack.sim.scenario import Box, Partition, Pillar, Table, VenueSpec

__all__ = ["Venue"]

FLOOR_APRON = 3.0  # the floor goes on this far past the walls (seen through doors), m
WALL_THICKNESS = 0.1  # m
DOOR_HEIGHT = 2.1  # m
DOOR_INSET = 0.4  # where people appear and vanish, inside the door, m
TABLE_TOP = 0.04  # m
TABLE_LEG = 0.05  # m
PILLAR_SEGMENTS = 16
# Near-infrared (~850 nm) albedos: painted walls and ceilings reflect strongly, floors and
# furniture less.
FLOOR_INFRARED, WALL_INFRARED, FURNITURE_INFRARED = 0.5, 0.75, 0.6


def _box(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of an axis-aligned box from corner ``lo`` to ``hi``."""
    size = np.asarray(hi, dtype=np.float64) - np.asarray(lo, dtype=np.float64)
    mesh = o3d.geometry.TriangleMesh.create_box(*size)
    return np.asarray(mesh.vertices) + lo, np.asarray(mesh.triangles)


def _yawed(vertices: np.ndarray, center: tuple[float, float], yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    out = vertices.copy()
    x, y = vertices[:, 0] - center[0], vertices[:, 1] - center[1]
    out[:, 0] = center[0] + c * x - s * y
    out[:, 1] = center[1] + s * x + c * y
    return out


class Venue:
    """Mesh and floor plan of a :class:`~optrack.sim.scenario.VenueSpec`."""

    def __init__(self, spec: VenueSpec) -> None:
        self.spec = spec
        self.length, self.width = float(spec.size[0]), float(spec.size[1])
        self.half = np.array([self.length / 2, self.width / 2])
        self.lighting = spec.lighting
        self._vertices: list[np.ndarray] = []
        self._triangles: list[np.ndarray] = []
        self._material: list[np.ndarray] = []
        self._count = 0
        materials = [
            Material(
                "floor", spec.floor_color, FLOOR_INFRARED, spec.floor_texture, spec.texture_cell
            ),
            Material("wall", spec.wall_color, WALL_INFRARED, spec.wall_texture, spec.texture_cell),
        ]
        circles: list[tuple[float, float, float]] = []
        rects: list[tuple[float, float, float, float, float]] = []
        self._build_room()
        for obstacle in spec.obstacles:
            index = len(materials)
            name = type(obstacle).__name__.lower()
            materials.append(
                Material(
                    name, obstacle.color, FURNITURE_INFRARED, obstacle.texture, spec.texture_cell
                )
            )
            if isinstance(obstacle, Pillar):
                self._pillar(obstacle, index)
                circles.append((*obstacle.at, obstacle.radius))
            elif isinstance(obstacle, Table):
                self._table(obstacle, index)
                yaw = math.radians(obstacle.yaw_deg)
                rects.append((*obstacle.at, obstacle.size[0] / 2, obstacle.size[1] / 2, yaw))
            elif isinstance(obstacle, Box):
                yaw = math.radians(obstacle.yaw_deg)
                lo = np.array([-obstacle.size[0] / 2, -obstacle.size[1] / 2, 0.0])
                v, t = _box(lo, -lo + [0, 0, obstacle.size[2]])
                v[:, :2] += obstacle.at
                self._add(_yawed(v, obstacle.at, yaw), t, index)
                rects.append((*obstacle.at, obstacle.size[0] / 2, obstacle.size[1] / 2, yaw))
            elif isinstance(obstacle, Partition):
                a, b = np.array(obstacle.start), np.array(obstacle.to)
                center = (a + b) / 2
                yaw = math.atan2(*(b - a)[::-1])
                half = np.array([np.linalg.norm(b - a) / 2, obstacle.thickness / 2])
                v, t = _box(
                    np.array([-half[0], -half[1], 0.0]), [half[0], half[1], obstacle.height]
                )
                v[:, :2] += center
                self._add(_yawed(v, tuple(center), yaw), t, index)
                rects.append((*center, *half, yaw))
        self.materials = MaterialTable(materials)
        self.vertices = np.concatenate(self._vertices).astype(np.float32)
        self.triangles = np.concatenate(self._triangles).astype(np.uint32)
        self.triangle_material = np.concatenate(self._material).astype(np.int32)
        self.circles = np.array(circles, dtype=np.float64).reshape(-1, 3)
        self.rects = np.array(rects, dtype=np.float64).reshape(-1, 5)
        self.doors = self._door_points()

    # ---------------------------------------------------------------- mesh
    def _add(self, vertices: np.ndarray, triangles: np.ndarray, material: int) -> None:
        self._vertices.append(np.asarray(vertices, dtype=np.float64))
        self._triangles.append(np.asarray(triangles) + self._count)
        self._material.append(np.full(len(triangles), material))
        self._count += len(vertices)

    def _build_room(self) -> None:
        spec, hx, hy, h, t = (
            self.spec,
            self.length / 2,
            self.width / 2,
            self.spec.wall_height,
            WALL_THICKNESS,
        )
        apron = FLOOR_APRON
        v, tri = _box(np.array([-hx - apron, -hy - apron, -0.05]), [hx + apron, hy + apron, 0.0])
        self._add(v, tri, 0)
        if spec.ceiling:
            v, tri = _box(np.array([-hx - t, -hy - t, h]), [hx + t, hy + t, h + 0.05])
            self._add(v, tri, 1)
        # Each wall runs along an axis; doors cut gaps (with a lintel above).
        walls = {
            "north": (0, hy, +1),
            "south": (0, -hy, -1),
            "east": (1, hx, +1),
            "west": (1, -hx, -1),
        }
        for name, (axis, position, side) in walls.items():
            span = hx if axis == 0 else hy
            gaps = sorted(
                (d.at - d.width / 2, d.at + d.width / 2) for d in spec.doors if d.wall == name
            )
            cuts = [-span - t]
            for lo, hi in gaps:
                cuts += [lo, hi]
            cuts.append(span + t)
            for start, end in zip(cuts[::2], cuts[1::2], strict=True):
                if end - start > 1e-6:
                    self._wall_piece(axis, position, side, start, end, 0.0, h)
            for lo, hi in gaps:
                self._wall_piece(axis, position, side, lo, hi, DOOR_HEIGHT, h)

    def _wall_piece(
        self, axis: int, position: float, side: int, a: float, b: float, z0: float, z1: float
    ) -> None:
        inner, outer = position, position + side * WALL_THICKNESS
        lo_n, hi_n = min(inner, outer), max(inner, outer)
        if axis == 0:  # along x, at y = position
            v, tri = _box(np.array([a, lo_n, z0]), [b, hi_n, z1])
        else:
            v, tri = _box(np.array([lo_n, a, z0]), [hi_n, b, z1])
        self._add(v, tri, 1)

    def _pillar(self, pillar: Pillar, material: int) -> None:
        height = self.spec.wall_height
        mesh = o3d.geometry.TriangleMesh.create_cylinder(
            pillar.radius, height, resolution=PILLAR_SEGMENTS, split=1
        )
        v = np.asarray(mesh.vertices) + [pillar.at[0], pillar.at[1], height / 2]
        self._add(v, np.asarray(mesh.triangles), material)

    def _table(self, table: Table, material: int) -> None:
        hx, hy, h, yaw = (
            table.size[0] / 2,
            table.size[1] / 2,
            table.height,
            math.radians(table.yaw_deg),
        )
        parts = [_box(np.array([-hx, -hy, h - TABLE_TOP]), [hx, hy, h])]
        leg = TABLE_LEG
        for sx in (-1, 1):
            for sy in (-1, 1):
                cx, cy = sx * (hx - leg), sy * (hy - leg)
                parts.append(
                    _box(
                        np.array([cx - leg / 2, cy - leg / 2, 0.0]),
                        [cx + leg / 2, cy + leg / 2, h - TABLE_TOP],
                    )
                )
        for v, tri in parts:
            v = v.copy()
            v[:, :2] += table.at
            self._add(_yawed(v, table.at, yaw), tri, material)

    # ----------------------------------------------------------- floor plan
    def _door_points(self) -> np.ndarray:
        points = []
        for door in self.spec.doors:
            if door.wall == "north":
                points.append((door.at, self.width / 2 - DOOR_INSET))
            elif door.wall == "south":
                points.append((door.at, -self.width / 2 + DOOR_INSET))
            elif door.wall == "east":
                points.append((self.length / 2 - DOOR_INSET, door.at))
            else:
                points.append((-self.length / 2 + DOOR_INSET, door.at))
        return np.array(points, dtype=np.float64).reshape(-1, 2)

    def distances(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distances (N, K) from N floor points to the K obstacles and walls, and the unit
        normals (N, K, 2) pointing from each obstacle towards the point. Negative
        distances are inside an obstacle."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        dists, normals = [], []
        if len(self.circles):
            delta = p[:, None, :] - self.circles[None, :, :2]
            norm = np.linalg.norm(delta, axis=2)
            dists.append(norm - self.circles[None, :, 2])
            normals.append(delta / np.maximum(norm, 1e-9)[..., None])
        if len(self.rects):
            c, s = np.cos(self.rects[:, 4]), np.sin(self.rects[:, 4])
            delta = p[:, None, :] - self.rects[None, :, :2]
            local = np.stack(
                [c * delta[..., 0] + s * delta[..., 1], -s * delta[..., 0] + c * delta[..., 1]],
                axis=2,
            )
            q = np.abs(local) - self.rects[None, :, 2:4]
            outside = np.maximum(q, 0.0)
            out_norm = np.linalg.norm(outside, axis=2)
            inside = np.minimum(np.max(q, axis=2), 0.0)
            dists.append(out_norm + inside)
            # Gradient of the box distance, in the box frame, then rotated back.
            grad = np.where(
                (out_norm > 0)[..., None],
                outside / np.maximum(out_norm, 1e-9)[..., None],
                np.stack([q[..., 0] >= q[..., 1], q[..., 0] < q[..., 1]], axis=2).astype(float),
            ) * np.sign(local + (local == 0))
            normals.append(
                np.stack(
                    [c * grad[..., 0] - s * grad[..., 1], s * grad[..., 0] + c * grad[..., 1]],
                    axis=2,
                )
            )
        hx, hy = self.half
        walls = np.stack([hx - p[:, 0], p[:, 0] + hx, hy - p[:, 1], p[:, 1] + hy], axis=1)
        dists.append(walls)
        wall_normals = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]])
        normals.append(np.broadcast_to(wall_normals, (len(p), 4, 2)))
        return np.concatenate(dists, axis=1), np.concatenate(normals, axis=1)

    def clearance(self, points: np.ndarray) -> np.ndarray:
        """Distance from each floor point to the nearest obstacle or wall, m."""
        distances, _ = self.distances(points)
        return distances.min(axis=1)

    def is_free(self, points: np.ndarray, margin: float) -> np.ndarray:
        return self.clearance(points) >= margin
