"""Background subtraction: an occupancy voxel map of the empty scene.

OpenPTrack learns the background for ``background_seconds`` as the union
of the voxelised clouds and stores it in an octree of
``background_resolution``; afterwards points in occupied voxels are
dropped before clustering (Munaro et al. 2016, section 4.2). Here the
occupied voxels are a sorted array of packed integer keys, looked up with
``np.isin``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["BackgroundModel"]

#: Bits per axis of a packed voxel key; voxel indices are offset to be non-negative.
KEY_BITS = 21
KEY_OFFSET = 1 << (KEY_BITS - 1)


class BackgroundModel:
    """Occupied voxels (camera frame) of the empty scene, learnt over a time span.

    Call :meth:`learn` with each frame's voxelised cloud while
    :attr:`learning`; afterwards :meth:`foreground` tells which points are
    not background. :meth:`relearn` starts over (OpenPTrack's
    ``background_update`` command).
    """

    def __init__(self, resolution: float, seconds: float) -> None:
        if resolution <= 0:
            raise ValueError(f"background resolution must be > 0 m; got {resolution}.")
        self.resolution = float(resolution)
        self.seconds = float(seconds)
        self._occupied = np.empty(0, dtype=np.int64)
        self._started: float | None = None
        self.learning = True
        self.frames = 0

    def relearn(self) -> None:
        """Forget the background and learn it again from the next frames."""
        self._occupied = np.empty(0, dtype=np.int64)
        self._started = None
        self.learning = True
        self.frames = 0

    def _keys(self, points: np.ndarray) -> np.ndarray:
        index = np.floor(np.asarray(points) / self.resolution).astype(np.int64) + KEY_OFFSET
        np.clip(index, 0, (1 << KEY_BITS) - 1, out=index)
        return (index[:, 0] << (2 * KEY_BITS)) | (index[:, 1] << KEY_BITS) | index[:, 2]

    def learn(self, points: np.ndarray, stamp: float) -> bool:
        """Add a frame's points to the background; True while still learning.

        Learning ends with the first frame at least ``seconds`` after the first one.
        """
        if not self.learning:
            return False
        if self._started is None:
            self._started = stamp
        elif stamp - self._started >= self.seconds:
            self.learning = False
            return False
        self._occupied = np.union1d(self._occupied, self._keys(points))
        self.frames += 1
        return True

    @property
    def voxels(self) -> int:
        """Number of occupied background voxels."""
        return len(self._occupied)

    def foreground(self, points: np.ndarray) -> np.ndarray:
        """Boolean mask of the points outside every background voxel."""
        if len(points) == 0 or len(self._occupied) == 0:
            return np.ones(len(points), dtype=bool)
        return ~np.isin(self._keys(points), self._occupied, assume_unique=False)
