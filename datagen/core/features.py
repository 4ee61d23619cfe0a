"""Feature point sets: the 3D features whose image centres a detector learns.

A *feature* is a set of 3D points in its object's model frame (metres, body
axes of :mod:`datagen.core.conventions`) that surround something distinct on the
airframe, plus a *true centre* (explicit, or by default the centroid of its
points). Its class id is what YOLO predicts; its centre is what PnP uses.

:class:`FeatureTable` holds every feature of a dataset in arrays, so labels for
all features of many frames are computed in one vectorized pass. Point sets of
different sizes are padded to a common length by repeating their first point,
which changes neither a box nor an in-front test.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["FEATURE_VARIANTS", "MAX_NAME_CHARS", "SIZE_SCALE", "STORED_VARIANTS", "FeatureTable", "valid_name"]

#: Feature sizes: the ring radius of a feature relative to its object's small radius,
#: so that each size has four times the area of the one before (paper models J, K, L).
#: Longest feature name, characters.
MAX_NAME_CHARS: Final = 100


def valid_name(name: object) -> bool:
    """Whether ``name`` may name a feature: a non-empty printable string of at most
    :data:`MAX_NAME_CHARS` characters (it is printed, drawn and written to data.yaml)."""
    return isinstance(name, str) and 0 < len(name) <= MAX_NAME_CHARS and name.isprintable()


SIZE_SCALE: Final[dict[str, float]] = {"small": 1.0, "medium": 2.0, "large": 4.0}
#: Variants a feature file stores: the paper's baseline and the co-located size variants.
STORED_VARIANTS: Final[tuple[str, ...]] = ("baseline", *SIZE_SCALE)
#: Every feature variant a config may ask for: the stored ones and seeded random surface
#: features generated from the mesh (paper model I).
FEATURE_VARIANTS: Final[tuple[str, ...]] = (*STORED_VARIANTS, "random")


@dataclass(frozen=True, eq=False)
class FeatureTable:
    """All features of a dataset, one row per class, ordered by class id.

    Attributes:
        class_id: ``(F,)`` int64, the YOLO class of each feature.
        name: ``F`` feature names.
        objects: the distinct objects the features belong to; the columns of
            the ``cam_from_objects`` argument of :func:`datagen.core.label_boxes.compute_labels`.
        object_index: ``(F,)`` index into ``objects`` of each feature's object.
        points_model: ``(F, P, 3)`` point sets in their object's frame, padded
            to ``P = max(n_points)`` by repeating each set's first point.
        n_points: ``(F,)`` true number of points per feature.
        center_model: ``(F, 3)`` true 3D centre of each feature.
        size: ``F`` size tags (for example ``"small"``, ``"medium"``, ``"large"``).
    """

    class_id: NDArray[np.int64]
    name: tuple[str, ...]
    objects: tuple[str, ...]
    object_index: NDArray[np.int64]
    points_model: NDArray[np.float64]
    n_points: NDArray[np.int64]
    center_model: NDArray[np.float64]
    size: tuple[str, ...]

    def __post_init__(self) -> None:
        f = len(self.name)
        checks = {
            "class_id": self.class_id.shape == (f,),
            "object_index": self.object_index.shape == (f,),
            "points_model": self.points_model.ndim == 3 and self.points_model.shape[::2] == (f, 3),
            "n_points": self.n_points.shape == (f,),
            "center_model": self.center_model.shape == (f, 3),
            "size": len(self.size) == f,
        }
        bad = [k for k, ok in checks.items() if not ok]
        if bad:
            raise ValueError(f"FeatureTable: inconsistent shapes for {', '.join(bad)} ({f} features)")
        for arr in (self.class_id, self.object_index, self.points_model, self.n_points, self.center_model):
            arr.setflags(write=False)

    @classmethod
    def from_point_sets(
        cls,
        point_sets: Sequence[ArrayLike],
        *,
        objects: Sequence[str],
        class_ids: Sequence[int] | None = None,
        names: Sequence[str] | None = None,
        centers: Sequence[ArrayLike | None] | None = None,
        sizes: Sequence[str] | None = None,
    ) -> FeatureTable:
        """Build a table from ragged point sets ``[(n_i, 3), ...]``.

        ``objects[i]`` names feature i's object; ``centers[i]`` of ``None`` (or
        ``centers`` omitted) means the centroid of the points.
        """
        n = len(point_sets)
        if len(objects) != n:
            raise ValueError(f"{n} point sets but {len(objects)} object names")
        sets = [np.asarray(p, dtype=np.float64).reshape(-1, 3) for p in point_sets]
        for i, p in enumerate(sets):
            if len(p) == 0:
                raise ValueError(f"feature {i}: empty point set")
        counts = np.array([len(p) for p in sets], dtype=np.int64)
        width = int(counts.max()) if n else 1
        padded = np.empty((n, width, 3))
        for i, p in enumerate(sets):
            padded[i, : len(p)] = p
            padded[i, len(p) :] = p[0]
        center = np.empty((n, 3))
        for i, p in enumerate(sets):
            c = None if centers is None else centers[i]
            center[i] = p.mean(axis=0) if c is None else np.asarray(c, dtype=np.float64)
        distinct = tuple(dict.fromkeys(objects))
        return cls(
            class_id=np.asarray(range(n) if class_ids is None else class_ids, dtype=np.int64),
            name=tuple(names) if names is not None else tuple(f"feature_{i}" for i in range(n)),
            objects=distinct,
            object_index=np.array([distinct.index(o) for o in objects], dtype=np.int64),
            points_model=padded,
            n_points=counts,
            center_model=center,
            size=tuple(sizes) if sizes is not None else ("",) * n,
        )

    @functools.cached_property
    def points_and_center_by_axis(self) -> tuple[NDArray[np.float64], ...]:
        """x, y, z arrays ``(F, P + 1)``: each feature's points, then its centre.

        The layout :func:`datagen.core.label_boxes.compute_labels` transforms in one pass.
        """
        both = np.concatenate([self.points_model, self.center_model[:, None, :]], axis=1)
        axes = tuple(np.ascontiguousarray(both[..., i]) for i in range(3))
        for a in axes:
            a.setflags(write=False)
        return axes

    def __len__(self) -> int:
        return len(self.name)

    def point_set(self, i: int) -> NDArray[np.float64]:
        """Feature i's own points ``(n_i, 3)``, without padding."""
        return self.points_model[i, : self.n_points[i]]
