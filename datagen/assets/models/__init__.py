"""The built-in procedural models: tanker, receiver with probe, drogue, hose.

Each builder returns a :class:`Model`: meshes by part name in the object's body
frame (:mod:`datagen.core.conventions`), and the feature anchors from which
:mod:`datagen.assets.loader` derives the feature point sets. The models are built
around the mounts and hose port of :mod:`datagen.assets.rig`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Final, Literal

from datagen.core.transforms import vec3

if TYPE_CHECKING:  # trimesh takes most of a second to import: only where meshes are made
    import trimesh
    from numpy.typing import ArrayLike

__all__ = [
    "MATERIAL_CLASSES",
    "FeatureAnchor",
    "InternalFeature",
    "Model",
    "material_class",
]

Size = Literal["small", "medium", "large"]

#: Material class of each built-in part name; the renderer randomizes a material
#: per class. Unknown part names (a user's mesh) fall back on keywords, then paint.
MATERIAL_CLASSES: Final[dict[str, str]] = {
    "paint": "paint",
    "radome": "paint",
    "stores": "paint",
    "pod": "paint",
    "glass": "glass",
    "metal": "metal",
    "probe": "metal",
    "markings": "markings",
    "engine_inlets": "dark",
    "engine_exhausts": "dark",
    "fabric": "fabric",
    "fabric_alt": "fabric_alt",
    "fabric_band": "fabric_band",
    "tape": "tape",
    "struts": "strut",
    "hose": "rubber",
}

_KEYWORDS: Final = (("glass", "glass"), ("canopy", "glass"), ("window", "glass"), ("metal", "metal"),
                    ("chrome", "metal"), ("marking", "markings"), ("decal", "markings"),
                    ("inlet", "dark"), ("intake", "dark"), ("exhaust", "dark"), ("nozzle", "metal"),
                    ("fabric", "fabric"), ("hose", "rubber"))


def material_class(part: str) -> str:
    """Material class of a part name: exact built-in name, else a keyword in it, else paint."""
    if part in MATERIAL_CLASSES:
        return MATERIAL_CLASSES[part]
    lowered = part.lower()
    return next((cls for key, cls in _KEYWORDS if key in lowered), "paint")


@dataclass(frozen=True)
class FeatureAnchor:
    """A feature defined by a point on (or near) the surface.

    Its point set is the anchor snapped to the surface plus a ring of surface
    points around it, of radius ``model.small_radius_m * SIZE_SCALE[size]`` (:data:`datagen.core.features.SIZE_SCALE`);
    its true centre is the snapped anchor.
    """

    name: str
    anchor_m: tuple[float, float, float]
    size: Size = "small"

    @staticmethod
    def at(name: str, point, size: Size = "small") -> FeatureAnchor:
        return FeatureAnchor(name, vec3(point), size)

    @staticmethod
    def on_both_sides(right: dict[str, ArrayLike], y0: float = 0.0,
                      sizes: dict[str, Size] | None = None) -> list[FeatureAnchor]:
        """Anchors given by their points on the right of the centre plane y = ``y0``, and the
        same mirrored to the left (:func:`datagen.assets.models.loft.on_side`): every right
        one in the order given, then every left one; ``{side}`` in a name becomes ``right``
        or ``left``, and ``sizes`` gives the size of those not small."""
        from datagen.assets.models.loft import on_side

        sizes = sizes or {}
        return [FeatureAnchor.at(name.format(side=label), on_side(point, side, y0), sizes.get(name, "small"))
                for side, label in ((-1, "right"), (1, "left")) for name, point in right.items()]


@dataclass(frozen=True)
class InternalFeature:
    """A feature whose centre is not on the surface (a ring centre): explicit
    surface points around it and an explicit centre inside their convex hull."""

    name: str
    points_m: tuple[tuple[float, float, float], ...]
    center_m: tuple[float, float, float]
    size: Size = "medium"


@dataclass(frozen=True)
class Model:
    """A built-in object: meshes by part and the features that define its classes."""

    name: str
    parts: dict[str, trimesh.Trimesh]
    anchors: tuple[FeatureAnchor, ...]
    internal: tuple[InternalFeature, ...] = ()
    small_radius_m: float = 0.1

    def combined(self) -> trimesh.Trimesh:
        """All parts as one mesh."""
        from datagen.assets.loader import concatenated

        return concatenated(list(self.parts.values()))
