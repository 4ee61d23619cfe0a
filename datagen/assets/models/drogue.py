"""Drogue basket and hose.

The drogue frame: x forward (towards the tanker, along the hose), y left, z up,
origin at the drogue centre on the basket axis, where the probe tip is at
contact. The coupling (where the hose attaches, at
:data:`datagen.assets.rig.HOSE_ATTACH_DROGUE_M`) is ahead of the centre and the
canopy opens aft towards the receiver: 16 struts carry a canopy of 16 fabric gores
about 0.7 m across at the rim (a high-speed drogue's 27 inches), whose parts
(alternate gores, the rim band, two marked gores, the rim's tape, the struts, the
coupling) a canopy scheme colours (:mod:`datagen.assets.drogues`).

The hose is not a rigid object: :func:`hose_mesh` makes a tube of fixed
topology along the hose curve of each frame, so the renderer only updates its
vertex positions.
"""

from __future__ import annotations

from typing import Final

import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray

from datagen.assets.models import FeatureAnchor, InternalFeature, Model
from datagen.assets.models.loft import Parts, box, loft, tube, tube_rings
from datagen.assets.rig import HOSE_ATTACH_DROGUE_M
from datagen.core.transforms import vec3

__all__ = [
    "HOSE_RADIUS_M", "HOSE_SIDES", "build_drogue", "hose_faces", "hose_mesh", "hose_placeholder", "hose_texcoords",
    "hose_vertices",
]

N_RIBS: Final = 16
RIM_X: Final = -0.35  # canopy rim plane, aft of the centre
RIM_RADIUS: Final = 0.35  # 0.70 m across
THROAT_X: Final = 0.12  # where the ribs meet the coupling
THROAT_RADIUS: Final = 0.115
#: The rim band's share of the canopy's length (from the rim forwards).
BAND_SHARE: Final = 0.3

#: Hose outer radius (about 7 cm across) and sides of its tube mesh.
HOSE_RADIUS_M: Final = 0.035
HOSE_SIDES: Final = 12


def _rib_angles() -> NDArray[np.float64]:
    return np.linspace(0.0, 2 * np.pi, N_RIBS, endpoint=False)


def _on_axis(x: float, radius: float | NDArray[np.float64], angle: ArrayLike) -> NDArray[np.float64]:
    a = np.asarray(angle, dtype=np.float64)
    return np.stack([np.full_like(a, x), radius * np.cos(a), radius * np.sin(a)], axis=-1)


def build_drogue() -> Model:
    parts = Parts()
    attach = np.asarray(HOSE_ATTACH_DROGUE_M, dtype=np.float64)

    # Coupling: a metal body from the throat forward to the hose attachment, a
    # reception ring at the throat, and a collar.
    coupling = np.array([[attach[0] + 0.02, 0, 0], [attach[0] - 0.02, 0, 0], [0.30, 0, 0],
                         [0.20, 0, 0], [THROAT_X + 0.02, 0, 0], [THROAT_X, 0, 0]])
    parts.add("metal", tube(coupling, [0.045, 0.06, 0.09, 0.10, THROAT_RADIUS, THROAT_RADIUS], n=32))
    ring = trimesh.creation.torus(major_radius=THROAT_RADIUS, minor_radius=0.018, major_sections=48,
                                  minor_sections=12)
    ring.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    ring.apply_translation((THROAT_X, 0.0, 0.0))
    parts.add("metal", ring)

    # Canopy: a thin fabric shell scalloped between the ribs (a ring of 2 x 16
    # points: ribs at full radius, mid-panels sagging inwards).
    m = 2 * N_RIBS
    angles = np.linspace(0.0, 2 * np.pi, m, endpoint=False)
    sag = np.where(np.arange(m) % 2 == 0, 1.0, 0.93)

    def shell_ring(x: float, radius: float) -> NDArray[np.float64]:
        return _on_axis(x, radius * sag, angles)

    t = 0.006
    front_x, rear_x = THROAT_X - 0.02, RIM_X
    front_r, rear_r = THROAT_RADIUS + 0.005, RIM_RADIUS
    band_x = rear_x + BAND_SHARE * (front_x - rear_x)  # where the rim band begins
    band_r = rear_r + BAND_SHARE * (front_r - rear_r)
    shell = [shell_ring(front_x, front_r + t), shell_ring(band_x, band_r + t), shell_ring(rear_x, rear_r + t),
             shell_ring(rear_x, rear_r - t), shell_ring(band_x, band_r - t), shell_ring(front_x, front_r - t)]
    canopy = loft(shell, closed=True)
    # The gores (the 16 panels between ribs) in two alternating sets, the band at the rim,
    # and two marked gores that break the basket's rotational symmetry: a canopy's scheme
    # (datagen.assets.drogues) colours each set.
    panels = np.arange(len(canopy.faces))
    centroids = canopy.triangles_center
    polar = np.arctan2(centroids[:, 2], centroids[:, 1]) % (2 * np.pi)
    gore = np.floor(polar / (2 * np.pi / N_RIBS)).astype(int) % N_RIBS
    in_band = centroids[:, 0] < band_x
    marked = (polar > np.pi / 2 - 2 * np.pi / N_RIBS) & (polar < np.pi / 2)  # the panel left of top
    marked |= (polar > 0) & (polar < 2 * np.pi / N_RIBS)  # and the panel above the left rib
    marked &= ~in_band
    body = ~marked & ~in_band
    for part, faces in (("fabric", body & (gore % 2 == 0)), ("fabric_alt", body & (gore % 2 == 1)),
                        ("fabric_band", in_band), ("markings", marked)):
        piece = canopy.submesh([panels[faces]], append=True)
        assert isinstance(piece, trimesh.Trimesh)  # (appended: one mesh)
        parts.add(part, piece)

    # Ribs (struts) from the throat to the rim, and the rim's band (reflective tape on many drogues).
    rib_angles = _rib_angles()
    for a in rib_angles:
        path = np.stack([_on_axis(THROAT_X, THROAT_RADIUS + 0.012, a), _on_axis(RIM_X, RIM_RADIUS + 0.012, a)])
        parts.add("struts", tube(path, 0.008, n=8))
    rim = trimesh.creation.torus(major_radius=RIM_RADIUS + 0.004, minor_radius=0.014, major_sections=64,
                                 minor_sections=10)
    rim.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    rim.apply_translation((RIM_X, 0.0, 0.0))
    parts.add("tape", rim)
    parts.add("metal", box((0.38, 0.0, 0.085), (0.06, 0.02, 0.04)))  # latch housing on top of the coupling
    meshes = parts.build()

    tip = _on_axis(RIM_X - 0.014, RIM_RADIUS + 0.004, rib_angles)
    anchors = [FeatureAnchor.at(f"rib_{i:02d}_tip", p) for i, p in enumerate(tip)]
    for label, a in (("top", np.pi / 2), ("right", np.pi), ("bottom", 3 * np.pi / 2), ("left", 0.0)):
        anchors.append(FeatureAnchor.at(f"coupling_{label}", _on_axis(0.25, 0.1, a)))
    anchors.append(FeatureAnchor.at("coupling_latch", (0.38, 0.0, 0.105)))
    rim_points = _on_axis(RIM_X, RIM_RADIUS + 0.018, rib_angles[::2])
    throat_points = _on_axis(THROAT_X, THROAT_RADIUS + 0.018, rib_angles[::4])
    basket = InternalFeature(
        "basket_centre",
        tuple(vec3(p) for p in np.concatenate([rim_points, throat_points])),
        (0.0, 0.0, 0.0),
        "large",
    )
    return Model("drogue", meshes, tuple(anchors), (basket,), small_radius_m=0.02)


def hose_faces(n_points: int, sides: int = HOSE_SIDES) -> NDArray[np.uint32]:
    """Faces of the hose tube along ``n_points`` curve points: the same for every
    frame, so that only vertex positions change."""
    path = np.column_stack([np.linspace(0.0, -1.0, n_points), np.zeros(n_points), np.zeros(n_points)])
    return np.asarray(_hose_loft(tube_rings(path, HOSE_RADIUS_M, sides)).faces, dtype=np.uint32)


def hose_vertices(points: ArrayLike, sides: int = HOSE_SIDES) -> NDArray[np.float64]:
    """Vertices of the hose tube around the curve ``points`` (``(N, 3)``), in the order
    of :func:`hose_faces`: the rings, then the two cap centres."""
    rings = tube_rings(points, HOSE_RADIUS_M, sides)
    flat = rings.reshape(-1, 3)
    return np.concatenate([flat, rings[0].mean(axis=0)[None], rings[-1].mean(axis=0)[None]])


def hose_texcoords(points: ArrayLike, span_m: float, sides: int = HOSE_SIDES) -> NDArray[np.float32]:
    """Texture coordinates of :func:`hose_vertices` (same order): u is the distance along the
    hose from its drogue end (the last point), over ``span_m``; v is 0.5."""
    p = np.asarray(points, dtype=np.float64)
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    from_drogue = np.concatenate([np.cumsum(step[::-1])[::-1], [0.0]]) / span_m
    u = np.concatenate([np.repeat(from_drogue, sides), from_drogue[[0, -1]]])
    return np.column_stack([u, np.full_like(u, 0.5)]).astype(np.float32)


def hose_placeholder(n_points: int, sides: int = HOSE_SIDES) -> NDArray[np.float64]:
    """Vertices for a hose mesh before it is posed: as many as :func:`hose_vertices` gives
    (the rings, then the two cap centres), spread along x so that no triangle is degenerate."""
    placeholder = np.zeros((n_points * sides + 2, 3))
    placeholder[:, 0] = np.arange(len(placeholder)) * 1e-3
    return placeholder


def _hose_loft(rings: NDArray[np.float64]) -> trimesh.Trimesh:
    """Side and cap faces of a tube over ``rings``, without merging or reordering vertices."""
    s, n, _ = rings.shape
    idx = np.arange(s * n).reshape(s, n)
    faces = []
    for a in range(s - 1):
        a0, a1, b0, b1 = idx[a], np.roll(idx[a], -1), idx[a + 1], np.roll(idx[a + 1], -1)
        faces += [np.column_stack([a0, b0, b1]), np.column_stack([a0, b1, a1])]
    start, end = s * n, s * n + 1
    faces.append(np.column_stack([np.full(n, start), idx[0], np.roll(idx[0], -1)]))
    faces.append(np.column_stack([np.full(n, end), np.roll(idx[-1], -1), idx[-1]]))
    vertices = np.concatenate([rings.reshape(-1, 3), rings[0].mean(axis=0)[None], rings[-1].mean(axis=0)[None]])
    return trimesh.Trimesh(vertices, np.concatenate(faces), process=False)


def hose_mesh(points: ArrayLike, sides: int = HOSE_SIDES) -> trimesh.Trimesh:
    """The hose as a closed tube around the curve ``points``."""
    return trimesh.Trimesh(hose_vertices(points, sides), hose_faces(len(np.asarray(points)), sides),
                           process=False)
