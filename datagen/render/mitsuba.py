"""Mitsuba 3 plumbing shared by the renderer and the asset contact sheets.

- :func:`mitsuba_mesh` turns triangle arrays into a ``mi.Mesh`` (any file format
  trimesh reads can thus be rendered, parts kept apart).
- :func:`sensor_dict` places a perspective sensor whose intrinsics are exactly
  :class:`datagen.core.camera.Intrinsics` (``fov_axis='x'``, principal point at the
  image centre) at an OpenCV-convention ``world_from_cam``.
- :func:`visible` casts rays to test which 3D points the camera sees.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from datagen.core.camera import Intrinsics
from datagen.core.conventions import CVCAM_FROM_MICAM

__all__ = [
    "aligned",
    "jit_array",
    "jit_vectors",
    "mitsuba_mesh",
    "sensor_dict",
    "visible",
    "world_from_micam",
]


def mitsuba_mesh(name: str, vertices: ArrayLike, faces: ArrayLike, bsdf=None, texcoords: ArrayLike | None = None,
                 emitter=None, normals: ArrayLike | None = None):
    """A ``mi.Mesh`` from ``(V, 3)`` vertices and ``(F, 3)`` faces (current variant), with
    ``(V, 2)`` texture coordinates, ``(V, 3)`` vertex normals and an area ``emitter`` when
    given."""
    import mitsuba as mi

    v = np.ascontiguousarray(vertices, dtype=np.float32)
    f = np.ascontiguousarray(faces, dtype=np.uint32)
    props = mi.Properties()
    props.set_id(name)
    if bsdf is not None:
        props["bsdf"] = bsdf
    if emitter is not None:
        props["emitter"] = emitter
    mesh = mi.Mesh(name, len(v), len(f), props=props, has_vertex_normals=normals is not None,
                   has_vertex_texcoords=texcoords is not None)
    params = mi.traverse(mesh)
    set_buffer(params, "vertex_positions", v)
    set_buffer(params, "faces", f)
    if texcoords is not None:
        set_buffer(params, "vertex_texcoords", np.asarray(texcoords, dtype=np.float32))
    if normals is not None:
        set_buffer(params, "vertex_normals", np.asarray(normals, dtype=np.float32))
    params.update()
    return mesh


def set_buffer(params, key: str, array: ArrayLike) -> None:
    """Assign a flat numpy buffer to a mesh parameter in any variant (scalar
    variants take their own dynamic array type, vectorized ones mi.Float/UInt32)."""
    params[key] = scene_array(type(params[key]), np.ravel(array))


def jit_array(cls, values: ArrayLike):
    """``values`` as the Dr.Jit array type ``cls`` (``mi.Float``, ``mi.UInt32``,
    ``mi.TensorXf``, a scalar variant's dynamic arrays), made from :func:`aligned` memory
    of its own element type (memory of another type would be converted by a copy wherever
    numpy put it): how every numpy array reaches Dr.Jit. An array the scene holds, read
    inside the render, goes through :func:`scene_array` instead."""
    import drjit as dr

    return cls(aligned(values, np.uint32 if dr.type_v(cls) == dr.VarType.UInt32 else np.float32))


def scene_array(cls, values: ArrayLike):
    """:func:`jit_array` for an array the scene holds (a mesh's buffer, a texture's data or
    table, the air's): under a JIT variant copied into memory Dr.Jit allocated. Dr.Jit maps
    numpy memory into an array without copying, and a recording of the render
    (``dr.freeze``, :mod:`datagen.render.frozen`) replays with the memory a mapped array had
    when it recorded, not the array it is given (measured, Dr.Jit 1.5: stale values, and a
    loop bound read from freed memory that never ended); an array in Dr.Jit's own memory it
    takes as the input it is. Arrays used outside the render (rays, images, a field's
    samples) stay mapped: no copy."""
    import drjit as dr

    out = jit_array(cls, values)
    if not dr.is_jit_v(cls):
        return out
    if dr.is_tensor_v(cls):
        return cls(_owned(out.array), out.shape)
    return _owned(out)


def _owned(mapped):
    """A flat JIT array's values in memory Dr.Jit allocated (a scatter: Dr.Jit folds a copy
    it can see through, such as ``zeros + a`` or a gather of every index, back to ``a``)."""
    import drjit as dr

    n = dr.width(mapped)
    out = dr.zeros(type(mapped), n)
    dr.scatter(out, mapped, dr.arange(dr.uint32_array_t(type(mapped)), n))
    dr.eval(out)
    return out


def aligned(values: ArrayLike, dtype=np.float32) -> NDArray:
    """A contiguous copy of ``values`` as ``dtype`` (the element type of the Dr.Jit array
    it becomes), in their shape, that starts on a 64-byte boundary: what every numpy array
    handed to Dr.Jit goes through.

    Dr.Jit maps numpy memory into a kernel without copying, and a kernel that loads a
    buffer whole or in packets (a mesh's texture coordinates, a texture) is compiled for
    the buffer's alignment, without packet gathers where it is unaligned: with numpy's
    arbitrary alignment a render kernel would exist in aligned and unaligned variants,
    compiled anew by chance in each process (seconds each)."""
    src = np.asarray(values, dtype=dtype)
    buffer = np.empty(src.size + 64 // src.dtype.itemsize, dtype=src.dtype)
    start = (-buffer.ctypes.data % 64) // src.dtype.itemsize
    out = buffer[start:start + src.size].reshape(src.shape)
    out[...] = src
    return out


def jit_vectors(cls, xyz: ArrayLike):
    """``cls`` (``mi.Point3f``, ``mi.Vector3f``) of the rows of an ``(N, 3)`` array."""
    import mitsuba as mi

    xyz = np.asarray(xyz).reshape(-1, 3)
    return cls(*(jit_array(mi.Float, xyz[:, i]) for i in range(3)))


def world_from_micam(world_from_cam: ArrayLike) -> NDArray[np.float64]:
    """A sensor's Mitsuba ``to_world`` for an OpenCV-convention ``world_from_cam``."""
    return np.asarray(world_from_cam, dtype=np.float64) @ CVCAM_FROM_MICAM


def sensor_dict(intrinsics: Intrinsics, world_from_cam: ArrayLike, spp: int, *,
                rfilter: str = "box", pixel_format: str = "rgb", size: tuple[int, int] | None = None) -> dict:
    """A perspective sensor matching ``intrinsics`` at the OpenCV ``world_from_cam``; with
    ``size`` (width, height), a film of that size at the same focal length, centred until
    its principal point is moved (:class:`datagen.render.target.TargetWindow`)."""
    import mitsuba as mi

    width, height = size or (intrinsics.width, intrinsics.height)
    hfov_rad = intrinsics.hfov_rad if size is None else 2.0 * np.arctan(width / (2.0 * intrinsics.fx))
    return {
        "type": "perspective",
        "fov": float(np.degrees(hfov_rad)),
        "fov_axis": "x",
        "near_clip": 0.01,
        "far_clip": 1.0e8,  # beyond the sea's edge (datagen.render.world.EARTH_CAP_M)
        "to_world": mi.ScalarTransform4f(world_from_micam(world_from_cam).tolist()),
        "sampler": {"type": "independent", "sample_count": int(spp)},
        "film": {
            "type": "hdrfilm",
            "width": int(width),
            "height": int(height),
            "rfilter": {"type": rfilter},
            "pixel_format": pixel_format,
        },
    }


def place_sensor(sensor, to_world: ArrayLike) -> None:
    """Pose a :func:`sensor_dict` sensor at ``to_world`` (4 x 4, its Mitsuba to_world), its
    values device arrays (opaque) under a JIT variant, without reading anything back.

    Through ``mi.traverse`` the sensor's ``parameters_changed`` makes the matrix and its
    inverse opaque and then copies them to its host-side twin value by value: 32 reads,
    each a wait for a GPU, every frame. Assigned as literals, the twin reads them for free;
    made opaque then (the sensor's own, in place), they become arrays by fills, which do not
    wait. Nothing else of a perspective sensor follows its pose."""
    import drjit as dr

    sensor.m_to_world = type(sensor.m_to_world)(np.asarray(to_world, dtype=np.float64).tolist())
    dr.make_opaque(sensor.m_to_world)  # (a no-op under a scalar variant)


def visible(scene, origin: ArrayLike, points: ArrayLike, tolerance_m: float | ArrayLike = 0.01) -> NDArray[np.bool_]:
    """Which ``points`` ``(N, 3)`` are seen from ``origin``: nothing is hit on the way
    to them, up to ``tolerance_m`` (one value, or one per point) before them (the
    point's own surface)."""
    import mitsuba as mi

    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    o = np.asarray(origin, dtype=np.float64)
    d = p - o
    dist = np.linalg.norm(d, axis=1)
    d /= np.maximum(dist, 1e-12)[:, None]
    max_t = np.maximum(dist - np.broadcast_to(np.asarray(tolerance_m, dtype=np.float64), dist.shape), 0.0)
    n = len(p)
    if str(mi.variant()).startswith("scalar"):
        seen = np.empty(n, dtype=bool)
        for i, (di, t) in enumerate(zip(d, max_t, strict=True)):
            ray: Any = mi.Ray3f(mi.Point3f(*map(float, o)), mi.Vector3f(*map(float, di)))
            ray.maxt = float(t)  # (Ray3f's third positional argument is the time, not maxt)
            seen[i] = not scene.ray_test(ray)
        return seen
    ray = mi.Ray3f(jit_vectors(mi.Point3f, np.broadcast_to(o, (n, 3))), jit_vectors(mi.Vector3f, d))
    ray.maxt = jit_array(mi.Float, max_t)
    hit = np.asarray(scene.ray_test(ray), dtype=bool).reshape(n)
    return ~hit
