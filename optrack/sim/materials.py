"""Surface materials of the simulated world: colour, infrared reflectance, texture.

A mesh carries one material index per triangle; a :class:`MaterialTable` maps
it to an RGB albedo (0-1, linear), an infrared albedo at the time-of-flight
wavelength (~850 nm), a texture amplitude (the relative albedo variation a
stereo matcher can lock on to) and a texture cell size. ``checker`` marks the
printed face of a calibration board, whose albedo comes from the board's
pattern instead.
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["Material", "MaterialTable", "cell_noise"]


@dataclasses.dataclass(frozen=True)
class Material:
    name: str
    albedo: tuple[float, float, float]
    infrared: float = 0.6
    texture: float = 0.0
    texture_cell: float = 0.05
    checker: bool = False


class MaterialTable:
    """Materials as parallel arrays, indexed by a triangle's material index."""

    def __init__(self, materials: list[Material]) -> None:
        self.materials = list(materials)
        self.albedo = np.array([m.albedo for m in materials], dtype=np.float32).reshape(-1, 3)
        self.infrared = np.array([m.infrared for m in materials], dtype=np.float32)
        self.texture = np.array([m.texture for m in materials], dtype=np.float32)
        self.texture_cell = np.array([m.texture_cell for m in materials], dtype=np.float32)
        self.checker = np.array([m.checker for m in materials], dtype=bool)

    def __len__(self) -> int:
        return len(self.materials)


def cell_noise(points: np.ndarray, cell: np.ndarray) -> np.ndarray:
    """Deterministic value noise in [-1, 1] for Nx3 world points on a grid of ``cell`` metres.

    Each grid cell gets one pseudo-random value from an integer hash of its
    indices (the "PCG hash" of Jarzynski and Olano, JCGT 2020), so a textured
    surface looks the same from every sensor and in every frame.
    """
    cells = np.floor(points / np.asarray(cell, dtype=np.float32)[..., None]).astype(np.int64)
    h = (
        (cells[:, 0] * 73856093) ^ (cells[:, 1] * 19349663) ^ (cells[:, 2] * 83492791)
    ) & 0xFFFFFFFF
    h = h.astype(np.uint64)
    state = (h * np.uint64(747796405) + np.uint64(2891336453)) & np.uint64(0xFFFFFFFF)
    shift = (state >> np.uint64(28)) + np.uint64(4)
    word = (((state >> shift) ^ state) * np.uint64(277803737)) & np.uint64(0xFFFFFFFF)
    word = ((word >> np.uint64(22)) ^ word) & np.uint64(0xFFFFFFFF)
    return (word.astype(np.float64) / 2.0**31 - 1.0).astype(np.float32)
