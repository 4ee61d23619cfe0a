"""Small procedural-modelling toolkit on top of trimesh.

Everything here builds closed triangle meshes from cross-sections: a fuselage
is a loft of superellipse rings, a wing or fin a loft of symmetric NACA
sections, a nacelle or hose a loft of circles. :class:`Parts` collects meshes
under part names (``paint``, ``glass``, ``metal``...) so that each part can get
its own material when rendered.

Coordinates are body axes (x forward, y left, z up), metres.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence

import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray

from datagen.assets.loader import concatenated

__all__ = [
    "Parts",
    "airfoil_ring",
    "box",
    "ellipsoid",
    "loft",
    "mirror_y",
    "on_side",
    "superellipse_ring",
    "tube",
    "wing",
]

#: Vertices are rounded to this many decimals (10 micrometres) before export, so
#: that last-bit differences in libm between machines cannot change the files.
VERTEX_DECIMALS = 5


def _mesh(vertices: ArrayLike, faces: ArrayLike) -> trimesh.Trimesh:
    mesh = trimesh.Trimesh(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64),
                           process=True)
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.remove_unreferenced_vertices()
    return mesh


def loft(rings: Sequence[ArrayLike] | NDArray[np.float64], *, cap_start: bool = True, cap_end: bool = True,
         closed: bool = False) -> trimesh.Trimesh:
    """Skin consecutive rings of ``N`` points each (``(S, N, 3)``) into a surface.

    Rings run counter-clockwise seen from ahead of the first ring looking back
    along the sweep, so that normals point outwards. A ring whose points
    coincide closes the surface to a point. ``closed`` joins the last ring back
    to the first (a swept loop, such as a thin shell); otherwise the open ends
    are capped with a fan around their centroid when asked.
    """
    r = np.asarray(rings, dtype=np.float64)
    s, n, _ = r.shape
    vertices = [r.reshape(-1, 3)]
    idx = np.arange(s * n).reshape(s, n)
    faces = []
    pairs = [(i, i + 1) for i in range(s - 1)] + ([(s - 1, 0)] if closed else [])
    for a, b in pairs:
        a0, a1 = idx[a], np.roll(idx[a], -1)
        b0, b1 = idx[b], np.roll(idx[b], -1)
        faces.append(np.column_stack([a0, b0, b1]))
        faces.append(np.column_stack([a0, b1, a1]))
    count = s * n
    if not closed:
        for ring_index, flip, wanted in ((0, True, cap_start), (s - 1, False, cap_end)):
            if not wanted:
                continue
            vertices.append(r[ring_index].mean(axis=0)[None])
            ring = idx[ring_index]
            fan = np.column_stack([np.full(n, count), np.roll(ring, -1), ring])
            faces.append(fan if not flip else fan[:, ::-1])
            count += 1
    mesh = _mesh(np.concatenate(vertices), np.concatenate(faces))
    if mesh.is_watertight:
        _outward(mesh)
    return mesh


def superellipse_ring(x: float, y: float, z: float, half_width: float, half_height: float, n: int,
                      exponent: float = 2.0, angles: ArrayLike | None = None) -> NDArray[np.float64]:
    """Ring of ``n`` points in the plane x = const, centred at (y, z), counter-clockwise
    seen from +x looking aft. ``exponent`` 2 is an ellipse, larger is boxier."""
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False) if angles is None else np.asarray(angles)
    c, s = np.cos(t), np.sin(t)
    p = 2.0 / exponent
    yy = y - half_width * np.sign(c) * np.abs(c) ** p
    zz = z + half_height * np.sign(s) * np.abs(s) ** p
    return np.column_stack([np.full_like(t, x), yy, zz])


def _basis(axis: ArrayLike) -> tuple[NDArray, NDArray, NDArray]:
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    helper = np.array([0.0, 0.0, 1.0]) if abs(a[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(helper, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    return e1, e2, a


def tube(path: ArrayLike, radius: float | ArrayLike, n: int = 16, *, cap_start: bool = True,
         cap_end: bool = True) -> trimesh.Trimesh:
    """A tube of circular section along a polyline, with frames transported along
    the path (no twist), so that the same path always gives the same mesh."""
    return loft(tube_rings(path, radius, n), cap_start=cap_start, cap_end=cap_end)


def tube_rings(path: ArrayLike, radius: float | ArrayLike, n: int) -> NDArray[np.float64]:
    """The rings of :func:`tube`: ``(len(path), n, 3)``."""
    p = np.asarray(path, dtype=np.float64)
    radii = np.broadcast_to(np.asarray(radius, dtype=np.float64), (len(p),))
    tangents = np.gradient(p, axis=0)
    tangents /= np.linalg.norm(tangents, axis=1, keepdims=True)
    e1, _, _ = _basis(tangents[0])
    first = np.empty((len(p), 3))  # each ring's basis: the first vector transported along the path
    for i, tangent in enumerate(tangents):
        e1 = e1 - tangent * (e1 @ tangent)
        e1 /= np.linalg.norm(e1)
        first[i] = e1
    second = _cross(tangents, first)
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    return p[:, None, :] + radii[:, None, None] * (np.cos(t)[None, :, None] * first[:, None, :]
                                                   - np.sin(t)[None, :, None] * second[:, None, :])


def _cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Row-wise cross products of ``(N, 3)`` arrays, as ``np.cross`` computes them (each
    component a product less a product), without its per-call cost."""
    return np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1], a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                     a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=1)


def airfoil_ring(n: int, thickness: float) -> NDArray[np.float64]:
    """Closed symmetric NACA 00xx section, ``n`` points (even), chord 0..1 from the
    leading edge, as (u, v): u along the chord, v across, counter-clockwise seen
    with u to the right and v up."""
    half = n // 2
    beta = np.linspace(0.0, np.pi, half + 1)
    u = 0.5 * (1 - np.cos(beta))  # cosine spacing, dense at both edges
    v = 5 * thickness * (0.2969 * np.sqrt(u) - 0.1260 * u - 0.3516 * u**2 + 0.2843 * u**3 - 0.1036 * u**4)
    v[-1] = 0.0  # sharp, closed trailing edge
    upper = np.column_stack([u, v])[::-1]  # trailing edge to leading edge over the top
    lower = np.column_stack([u[1:-1], -v[1:-1]])  # leading edge back to the trailing edge underneath
    return np.concatenate([upper, lower])


def wing(root_le: ArrayLike, root_chord: float, tip_le: ArrayLike, tip_chord: float, *,
         thickness: float | tuple[float, float] = 0.1, vertical: bool = False,
         n: int = 32) -> trimesh.Trimesh:
    """A straight-tapered wing, fin or pylon panel between two airfoil sections.

    Chords run aft (-x) from the leading-edge points. Horizontal panels are thick
    along z; ``vertical`` panels (fins, pylons) along y.
    """
    t_root, t_tip = (thickness, thickness) if isinstance(thickness, (int, float)) else thickness
    rings = []
    for le, chord, t in ((root_le, root_chord, t_root), (tip_le, tip_chord, t_tip)):
        uv = airfoil_ring(n, t) * chord
        le = np.asarray(le, dtype=np.float64)
        offset = np.zeros((len(uv), 3))
        offset[:, 0] = -uv[:, 0]
        offset[:, 2 if not vertical else 1] = uv[:, 1]
        rings.append(le + offset)
    return loft(rings)


def _outward(mesh: trimesh.Trimesh) -> None:
    """Flip a closed mesh inside out if its volume came out negative."""
    if mesh.volume < 0:
        mesh.invert()


def box(center: ArrayLike, extents: ArrayLike, rotation: ArrayLike | None = None) -> trimesh.Trimesh:
    """An axis-aligned (or rotated) box."""
    transform = np.eye(4)
    if rotation is not None:
        transform[:3, :3] = rotation
    transform[:3, 3] = center
    return trimesh.creation.box(extents=extents, transform=transform)


def ellipsoid(center: ArrayLike, radii: ArrayLike, subdivisions: int = 3) -> trimesh.Trimesh:
    """An ellipsoid with semi-axes ``radii`` along x, y, z."""
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    sphere.apply_scale(np.asarray(radii, dtype=np.float64))
    sphere.apply_translation(np.asarray(center, dtype=np.float64))
    return sphere


def mirror_y(mesh: trimesh.Trimesh, y0: float) -> trimesh.Trimesh:
    """The mirror image of ``mesh`` across the plane y = ``y0``, with outward normals."""
    out = mesh.copy()
    v = out.vertices.copy()
    v[:, 1] = 2 * y0 - v[:, 1]
    out.vertices = v
    out.invert()
    return out


def on_side(point: ArrayLike, side: int, y0: float = 0.0) -> NDArray[np.float64]:
    """A point given on the right (-y) of the plane y = ``y0``, on ``side``: -1
    keeps it, +1 mirrors it to the left."""
    p = np.asarray(point, dtype=np.float64)
    return p if side < 0 else np.array([p[0], 2 * y0 - p[1], p[2]])


class Parts:
    """Meshes collected under part names; each part becomes one mesh (one material)."""

    def __init__(self) -> None:
        self._meshes: dict[str, list[trimesh.Trimesh]] = defaultdict(list)

    def add(self, part: str, *meshes: trimesh.Trimesh) -> None:
        self._meshes[part].extend(meshes)

    def add_mirrored(self, part: str, y0: float, *meshes: trimesh.Trimesh) -> None:
        """Add ``meshes`` and their mirror images across the plane y = ``y0``."""
        self.add(part, *meshes, *(mirror_y(m, y0) for m in meshes))

    def build(self) -> dict[str, trimesh.Trimesh]:
        """One concatenated mesh per part, vertices rounded to :data:`VERTEX_DECIMALS`,
        parts in name order."""
        out = {}
        for name in sorted(self._meshes):
            mesh = concatenated(self._meshes[name])
            mesh = trimesh.Trimesh(np.round(mesh.vertices, VERTEX_DECIMALS), mesh.faces, process=False)
            out[name] = mesh
        return out


def transformed(mesh: trimesh.Trimesh, rotation: ArrayLike | None = None,
                translation: ArrayLike = (0.0, 0.0, 0.0)) -> trimesh.Trimesh:
    """A copy of ``mesh`` rotated about the origin, then translated."""
    transform = np.eye(4)
    if rotation is not None:
        transform[:3, :3] = rotation
    transform[:3, 3] = translation
    out = mesh.copy()
    out.apply_transform(transform)
    return out


class Panel:
    """A straight-tapered lifting surface: root and tip leading edges and chords.

    Gives points on its edges for feature anchors and the mesh of :func:`wing`.
    """

    def __init__(self, root_le: ArrayLike, root_chord: float, tip_le: ArrayLike, tip_chord: float,
                 *, thickness: float | tuple[float, float] = 0.1, vertical: bool = False) -> None:
        self.root_le = np.asarray(root_le, dtype=np.float64)
        self.tip_le = np.asarray(tip_le, dtype=np.float64)
        self.root_chord = root_chord
        self.tip_chord = tip_chord
        self.thickness = thickness
        self.vertical = vertical

    def le(self, f: float) -> NDArray[np.float64]:
        """Leading-edge point at span fraction ``f`` (0 root, 1 tip)."""
        return (1 - f) * self.root_le + f * self.tip_le

    def chord(self, f: float) -> float:
        return (1 - f) * self.root_chord + f * self.tip_chord

    def te(self, f: float) -> NDArray[np.float64]:
        """Trailing-edge point at span fraction ``f``."""
        return self.le(f) - np.array([self.chord(f), 0.0, 0.0])

    def at(self, f: float, u: float) -> NDArray[np.float64]:
        """Point on the chord line at span fraction ``f``, chord fraction ``u``."""
        return self.le(f) - np.array([u * self.chord(f), 0.0, 0.0])

    def mesh(self, n: int = 32) -> trimesh.Trimesh:
        return wing(self.root_le, self.root_chord, self.tip_le, self.tip_chord,
                    thickness=self.thickness, vertical=self.vertical, n=n)

    def mirrored(self, y0: float) -> Panel:
        flip = np.array([1.0, -1.0, 1.0])
        shift = np.array([0.0, 2 * y0, 0.0])
        return Panel(self.root_le * flip + shift, self.root_chord, self.tip_le * flip + shift,
                     self.tip_chord, thickness=self.thickness, vertical=self.vertical)


def decal(surface: trimesh.Trimesh, near: ArrayLike, extents: tuple[float, float],
          *, round_: bool = False, along: ArrayLike = (1.0, 0.0, 0.0),
          thickness: float = 0.004, lift: float = 0.002) -> trimesh.Trimesh:
    """A thin flat plate (``extents`` long x wide, or a disc of diameter
    ``extents[0]``) lying on ``surface`` at the point closest to ``near``: its
    bottom face ``lift`` above the surface, its long side along ``along``
    projected onto the surface."""
    closest, _, tri = trimesh.proximity.closest_point(surface, np.asarray(near, dtype=np.float64)[None])
    point, normal = closest[0], surface.face_normals[tri[0]]
    u = np.asarray(along, dtype=np.float64) - normal * (normal @ np.asarray(along, dtype=np.float64))
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    rotation = np.column_stack([u, v, normal])
    centre = point + normal * (lift + thickness / 2)
    if round_:
        plate = trimesh.creation.cylinder(radius=extents[0] / 2, height=thickness, sections=24)
    else:
        plate = trimesh.creation.box(extents=(extents[0], extents[1], thickness))
    return transformed(plate, rotation, centre)
