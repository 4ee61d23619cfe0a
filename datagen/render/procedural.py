"""Procedural textures inside Mitsuba's kernels: the fields of :mod:`datagen.assets.noise`
evaluated at each shading point, band-limited by the footprint of a pixel there.

A texture here is a Python :class:`mitsuba.Texture`: Dr.Jit traces its ``eval`` into the
render kernel like any other texture. What changes between frames (the field's offsets and
seeds, a layer's threshold, the camera's position, a colour) enters the kernel as opaque
values, so that a new frame reuses the compiled kernel.

The footprint of a pixel at a point is its distance from the camera times the angle a
pixel subtends (``1 / fx``): exact for what the camera sees directly, and a lower bound
for what it sees through a reflection. On a ``slant`` texture (the sea) it is the
ellipse a pixel covers on the horizontal plane (:class:`datagen.assets.noise.Slant`,
stretched at most :data:`SLANT_STRETCH_MAX` times along the view): a wave running
across the view fades where the view is edge-on to it, one running along it where the
pixel's width is.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, ClassVar, Final

import numpy as np

from datagen.assets.noise import FADE_LO, NUMPY, Ops, Slant, row_params
from datagen.core.transforms import vec3
from datagen.render.mitsuba import jit_array, scene_array

__all__ = ["body_texture_class", "drjit_ops", "evaluate", "mask_class", "only_where", "texture_class"]

#: The area a texture's field is evaluated on: its surface's render-frame x and y (metres).
PLANE_AXES: Final = (0, 1)
#: A series' first rows are summed in straight-line code (every lane needs them: a pixel
#: holds a field's longest waves almost everywhere), the rest in a loop lanes leave early.
UNROLLED: Final = 4
#: A slant footprint's length along the view: 1 / cos of the view's angle to the vertical, up to this.
SLANT_STRETCH_MAX: Final = 50.0
#: Where a cloud's opacity is at most this, every path passes it with the weight it lets
#: through (:func:`mask_class`); above it, a share of paths stops. Passing every path costs
#: the paths that go on behind: the whole range cost 25% more path tracing, this half 6%.
MASK_SPLIT: Final = 0.5


def drjit_ops() -> Ops:
    """:class:`datagen.assets.noise.Ops` for the current Mitsuba variant's Dr.Jit arrays
    (a scalar variant's are Python numbers: numpy's float32 and uint32 scalars then)."""
    import mitsuba as mi

    return _ops(mi.variant())


@functools.cache
def _ops(variant: str) -> Ops:
    import drjit as dr
    import mitsuba as mi

    if variant.startswith("scalar"):
        return NUMPY

    ops = Ops(
        floor=dr.floor,
        to_u32=lambda f: mi.UInt32(mi.Int32(f)),
        to_f32=mi.Float,
        clip=dr.clip,
        f32=float,
        u32=int,
        param_f32=lambda v: v if isinstance(v, mi.Float) else _param(mi.Float, float(v)),
        param_u32=lambda v: v if isinstance(v, mi.UInt32) else _param(mi.UInt32, int(v)),
        sin=dr.sin,
        sqrt=dr.sqrt,
        exp=dr.exp,
        log=dr.log,
        abs=dr.abs,
        select=dr.select,
    )
    return dataclasses.replace(ops, series_loop=functools.partial(_series_loop, ops), only_where=only_where)


class _Reading:
    """A texture's kernel being traced (:meth:`ShadedTexture._value`): where its values come from.

    ``collect``: a dry trace (:meth:`ShadedTexture.prepare`) that notes every value and table
    the texture's ``shade`` asks for, in the order asked (what it makes of them is never
    evaluated); otherwise the values come from the device values those notes made (an
    opaque scalar each, as each value was when made inside the render: the same kernel),
    and the tables from the device arrays, in the same order: the kernel reads them as
    data, so that a recording of it (``dr.freeze``) replays with the next approach's values."""

    def __init__(self, texture, collect: bool) -> None:
        self.texture, self.collect = texture, collect
        self.values: dict = {"f32": [], "u32": []}
        self.tables: list = []
        self.read = {"f32": 0, "u32": 0, "tables": 0}

    def __enter__(self) -> _Reading:
        _READING.append(self)
        return self

    def __exit__(self, *exc) -> None:
        _READING.pop()

    def param(self, cls, value):
        import drjit as dr

        kind = "u32" if dr.type_v(cls) == dr.VarType.UInt32 else "f32"
        i = self.read[kind]
        self.read[kind] += 1
        if self.collect:
            self.values[kind].append(value)
            # A read like the render's, from a stand-in: Dr.Jit then sees the same expressions.
            return dr.gather(cls, _stand_in(cls), i)
        held = self.texture._book[kind]
        if i >= len(held):
            self.check()
        return held[i]

    def table(self, cls, values: np.ndarray):
        i = self.read["tables"]
        self.read["tables"] += 1
        if self.collect:  # uploaded after the dry trace (not inside its loops)
            self.tables.append((cls, values))
            return _stand_in(cls)
        return self.texture._book["tables"][i]

    def check(self) -> None:
        """Every value the notes hold was read, and no more (a ``shade`` whose asks depend on
        anything but its own state would read another value's slot)."""
        book = self.texture._book
        held = {kind: len(book[kind]) for kind in self.read}
        if held != self.read:  # (asked mid-trace: it has read more than they hold)
            raise RuntimeError(f"{type(self.texture).__name__}: the kernel read {self.read} values, "
                               f"its notes hold {held}")


def _same_shade(a, b) -> bool:
    """Whether two ``shade`` callables compute the same: one function, bound to or partially
    applied with the same objects (numbers: equal ones). An owner sets a texture's shade
    every frame; its values are noted again only when it changed."""
    if a is b:
        return True
    if isinstance(a, functools.partial) and isinstance(b, functools.partial):
        return (_same_shade(a.func, b.func) and len(a.args) == len(b.args)
                and all(_same_argument(x, y) for x, y in zip(a.args, b.args, strict=True))
                and a.keywords.keys() == b.keywords.keys()
                and all(_same_argument(a.keywords[k], b.keywords[k]) for k in a.keywords))
    self_a, self_b = getattr(a, "__self__", None), getattr(b, "__self__", None)
    if self_a is not None and self_b is not None:  # bound methods
        return getattr(a, "__func__", None) is getattr(b, "__func__", None) and self_a is self_b
    return False


def _same_argument(x, y) -> bool:
    if x is y:
        return True
    if isinstance(x, (bool, int, float, str)) and type(x) is type(y):
        return x == y
    return False


def _loops_traced_once():
    """A scope in which Dr.Jit traces a loop's body once: with ``OptimizeLoops`` it traces
    it again where it finds a state variable the body leaves unchanged, which the dry trace
    and the render need not find alike (their points differ), and each trace reads values."""
    import drjit as dr

    return dr.scoped_set_flag(dr.JitFlag.OptimizeLoops, False)


@functools.cache
def _stand_in(cls):
    """What a dry trace reads its values from: zeros, more than any texture asks for."""
    import drjit as dr

    out = dr.zeros(cls, 1 << 16)
    dr.eval(out)
    return out


#: The textures whose kernels are being traced, innermost last (a texture's field may trace another's).
_READING: list[_Reading] = []


class _HostState:
    """A texture's attributes, where Dr.Jit's walk over a frozen function's inputs passes at
    once: a Dr.Jit struct of no fields (every other Python value it meets it probes for what
    it may hold, several failed lookups each)."""

    DRJIT_STRUCT: ClassVar[dict] = {}


def _param(cls, value):
    """``value`` as a kernel input: from the tracing texture's notes, or (outside any) an
    opaque value of its own."""
    import drjit as dr

    return _READING[-1].param(cls, value) if _READING else dr.opaque(cls, value)


def _table(cls, values: np.ndarray):
    """``values`` (a series' rows) as a device array: from the tracing texture's notes, or
    (outside any) uploaded now."""
    if _READING:
        return _READING[-1].table(cls, values)
    return jit_array(cls, values)


def only_where(active, initial: tuple, fn) -> tuple:
    """:meth:`datagen.assets.noise.Ops.where` in a kernel: ``fn`` inside a loop of at most one
    pass, which the lanes that are not ``active`` leave at once (a packet of lanes none of
    which is active skips the work)."""
    import drjit as dr
    import mitsuba as mi

    width = max(dr.width(active), *(dr.width(v) for v in initial))
    state = (dr.zeros(mi.UInt32, width), *(v + dr.zeros(type(v), width) for v in initial))

    def body(i, *values):
        return i + 1, *fn()

    return tuple(dr.while_loop(state=state, cond=lambda i, *v: (i < 1) & active, body=body)[1:])


def evaluate(fn, *arrays: np.ndarray) -> np.ndarray:
    """``fn(*arrays, ops)`` over numpy float32 arrays, evaluated by the current variant's
    Dr.Jit (by numpy under a scalar variant); the result as a numpy array of their shape."""
    import drjit as dr
    import mitsuba as mi

    ops = drjit_ops()
    flat = [np.ascontiguousarray(a, dtype=np.float32).reshape(-1) for a in arrays]
    if ops is NUMPY:
        out = fn(*flat, ops)
    else:
        out = fn(*(jit_array(mi.Float, a) for a in flat), ops)
        dr.eval(out)
    return np.asarray(out, dtype=np.float32).reshape(np.shape(arrays[0]))


def _series_loop(ops: Ops, rows: dict[str, np.ndarray], term, footprint_m, outputs: int, settled=None):
    """:func:`datagen.assets.noise.series` at a footprint: the first :data:`UNROLLED` rows in
    straight-line code, then a loop over the rest that each lane leaves at its first row a
    pixel cannot hold (every later one is shorter): far away, few terms cost anything. A
    lane that stops within the first rows adds none of the rest (both rules only ever stop
    a lane for good), so the sum is the same, term by term, as the Python loop's. The
    straight-line rows are opaque scalars, the loop's rows opaque arrays gathered per
    step: a new draw compiles no kernel."""
    import drjit as dr
    import mitsuba as mi

    n = len(rows["wavelength"])
    narrowest = footprint_m.across if isinstance(footprint_m, Slant) else footprint_m
    limit = narrowest * FADE_LO  # a term whose wavelength is at most this adds nothing
    width = dr.width(narrowest)

    def going(row, total):
        go = row["wavelength"] > limit
        if settled is not None:
            go &= ~settled(total, {"rest": row["rest"]}, ops)
        return go

    total = tuple(dr.zeros(mi.Float, width) for _ in range(outputs))
    active = dr.full(mi.Bool, True, width)
    for i in range(min(UNROLLED, n)):
        row = row_params(rows, i, ops)
        active &= going(row, total)
        total = tuple(dr.select(active, a + b, a) for a, b in zip(total, term(row, footprint_m, ops), strict=True))
    if n <= UNROLLED:
        return total

    # device arrays, not literals: a new draw compiles no kernel
    table = {name: _table(mi.UInt32 if values.dtype == np.uint32 else mi.Float, values)
             for name, values in rows.items()}

    def cond(*state):
        i, *total = state
        last = dr.minimum(i, n - 1)
        row = {"wavelength": dr.gather(mi.Float, table["wavelength"], last)}
        if settled is not None:
            row["rest"] = dr.gather(mi.Float, table["rest"], last)
        return (i < n) & going(row, total)

    def body(*state):
        i, *total = state
        row = {name: dr.gather(type(values), values, i) for name, values in table.items()}
        return i + 1, *(a + b for a, b in zip(total, term(row, footprint_m, ops), strict=True))

    state = (dr.select(active, mi.UInt32(UNROLLED), mi.UInt32(n)), *total)
    return dr.while_loop(state=state, cond=cond, body=body)[1:]


@functools.cache
def _shaded_texture(variant: str):
    """The base of this module's textures: ``eval`` and its kin from the subclass's
    ``_value(si)`` (a ``Color3f`` where ``colour``, else a ``Float``), and the camera's
    render-frame position ``camera`` (set per frame; held as opaque device values made when
    set, so that the render reads it as data: ``_camera_jit``)."""
    import mitsuba as mi

    class ShadedTexture(mi.Texture):
        # A frozen render walks a texture once for every object that holds it (each of an
        # aircraft's parts' BSDFs), at every call, and the noted values alone are hundreds: a
        # texture keeps its attributes, its device values among them, where that walk passes at
        # once (a _HostState), and its device values reach a frozen function once, as an
        # argument of their own (:meth:`inputs`; the performance page has the walk's time).
        def __setattr__(self, name: str, value) -> None:
            if hasattr(type(self), name):  # a property: its setter
                super().__setattr__(name, value)
                return
            host = self.__dict__.get("_host")
            if host is None:
                host = _HostState()
                super().__setattr__("_host", host)
            host.__dict__[name] = value

        def __getattr__(self, name: str):
            host = self.__dict__.get("_host")
            if host is None or name not in host.__dict__:
                raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
            return host.__dict__[name]

        def inputs(self) -> tuple:
            """Every Dr.Jit value the texture's kernel reads (the camera, the noted values and
            tables): what a frozen function that evaluates it takes as an argument."""
            return self._camera_jit, getattr(self, "_book", None)

        @property
        def camera(self) -> tuple[float, float, float]:
            return self._camera

        @camera.setter
        def camera(self, value) -> None:
            self._camera = vec3(value)
            self._camera_jit = _opaque_point(self._camera)

        @property
        def shade(self):
            return self._shade

        @shade.setter
        def shade(self, value) -> None:
            if not _same_shade(value, getattr(self, "_shade", None)):
                self._stale = True
            self._shade = value

        def prepare(self) -> None:
            """Note the values and tables the kernel of the current ``shade`` reads and hold
            them on the device (a dry trace of :meth:`_value`, only when ``shade`` computes
            something else since). The render reads them from there as data."""
            if not getattr(self, "_stale", True) or self._shade is None or drjit_ops() is NUMPY:
                return
            import drjit as dr

            # The stand-in point holds data, as the render's points do (literals would fold
            # away a branch Dr.Jit then never traces), two lanes wide as theirs are wide.
            si = dr.zeros(mi.SurfaceInteraction3f, 2)
            dr.make_opaque(si)
            with _Reading(self, collect=True) as notes, _loops_traced_once():
                self._value_of(si)
            f32 = np.asarray(notes.values["f32"], dtype=np.float32)
            u32 = np.asarray(notes.values["u32"], dtype=np.uint32)
            self._book = {"f32": tuple(dr.opaque(mi.Float, v) for v in f32.tolist()),
                          "u32": tuple(dr.opaque(mi.UInt32, v) for v in u32.tolist()),
                          "tables": tuple(scene_array(cls, values) for cls, values in notes.tables)}
            self._stale = False

        def _value_of(self, si):
            """The subclass's value at ``si`` (a ``Color3f`` where ``colour``, else a ``Float``)."""
            raise NotImplementedError

        def _value(self, si):
            if drjit_ops() is NUMPY:  # a scalar variant: numpy's numbers, no kernel
                return self._value_of(si)
            self.prepare()
            with _Reading(self, collect=False) as reading, _loops_traced_once():
                v = self._value_of(si)
            reading.check()
            return v

        def eval(self, si, active=True):
            v = self._value(si)
            return v if self.colour else mi.Color3f(v)

        def eval_1(self, si, active=True):
            v = self._value(si)
            return mi.luminance(v) if self.colour else v

        def eval_3(self, si, active=True):
            return self.eval(si, active)

        def mean(self):
            return 0.5

        def is_spatially_varying(self):
            return True

        def to_string(self):
            return f"{type(self).__name__}[]"

    assert mi.variant() == variant
    return ShadedTexture


def _opaque_point(xyz: tuple[float, float, float]):
    """``xyz`` as a ``mi.Point3f`` of opaque values (the current variant's; ``None`` under a
    scalar variant, which reads the host copy)."""
    import drjit as dr
    import mitsuba as mi

    if str(mi.variant()).startswith("scalar"):
        return None
    return mi.Point3f(*(dr.opaque(mi.Float, c) for c in xyz))


def _opaque_rows(matrix: np.ndarray) -> tuple | None:
    """The first three rows of a 4x4 as twelve opaque ``mi.Float`` values, row by row
    (``None`` under a scalar variant)."""
    import drjit as dr
    import mitsuba as mi

    if str(mi.variant()).startswith("scalar"):
        return None
    return tuple(dr.opaque(mi.Float, float(v)) for v in matrix[:3].reshape(-1))


@functools.cache
def texture_class(variant: str):
    """A :class:`mitsuba.Texture` whose value is ``shade(x, y, footprint_m, ops)``, a
    callable the owner sets (and replaces per frame) on the instance's ``shade``; the
    camera's render-frame position goes in ``camera`` and a pixel's angle in
    ``pixel_rad``. ``eval`` returns what ``shade`` does (a colour or a value); ``slant``: the
    texture lies on a horizontal plane, and ``shade`` gets its footprint there as a
    :class:`~datagen.assets.noise.Slant`; ``front_only``: the texture is the radiance of a
    one-sided ``area`` emitter, which shows nothing of it behind its surface (Mitsuba's
    ``area`` returns 0 there but evaluates its texture first): a lane that sees the back
    gets an infinite footprint, so that a series sums no term there. ``varying``: what
    :meth:`is_spatially_varying` says (see :class:`FieldTexture`'s)."""
    import drjit as dr
    import mitsuba as mi

    base: Any = _shaded_texture(variant)

    class FieldTexture(base):
        def __init__(self, props=None, *, pixel_rad: float = 1e-3, colour: bool = False, slant: bool = False,
                     front_only: bool = False, varying: bool = True):
            super().__init__(props if props is not None else mi.Properties())
            self.varying = varying
            self.pixel_rad = float(pixel_rad)
            self.colour = colour
            self.slant = slant
            self.front_only = front_only
            self.camera = (0.0, 0.0, 0.0)
            self.shade = None  # (x, y, footprint_m, ops) -> value (Float, or Color3f when colour)

        def is_spatially_varying(self):
            """Whether Mitsuba is told the texture varies over its surface: the radiance of
            an emitter that is never sampled (``sampling_weight`` 0: the cloud layers') says
            no. Told yes, the ``area`` emitter's ``pdf_direction`` of a path that met it maps
            the hit back onto the mesh through the mesh's UV parameterization, a scene of its
            own that Mitsuba rebuilds on first use after the mesh changes, inside the render:
            a frozen render's recording then met an object its inputs did not hold and was
            refused at every other approach, and a replay of an older recording read the
            freed scene and crashed (measured, Mitsuba 3.9). Told no, it asks the shape;
            Mitsuba multiplies either pdf by the emitter's sampling weight, 0, and the image
            is the same bit for bit (measured)."""
            return self.varying

        def _at(self, si):
            """``(x, y, footprint_m)`` of the point ``si``, for ``shade``."""
            ops = drjit_ops()
            if ops is NUMPY:  # a scalar variant: one point, numpy's wrapping uint32 arithmetic
                p = np.array([si.p.x, si.p.y, si.p.z], dtype=np.float64)
                view = p - np.asarray(self.camera)
                distance = np.linalg.norm(view)
                footprint = np.float32(distance * self.pixel_rad)
                if self.front_only and not si.wi[2] > 0.0:
                    footprint = np.float32(np.inf)
                if self.slant:
                    height = max(abs(view[2]), distance / SLANT_STRETCH_MAX)
                    footprint = Slant(footprint, np.float32(view[0] / height), np.float32(view[1] / height))
                return np.float32(p[0]), np.float32(p[1]), footprint
            view = si.p - self._camera_jit
            distance = dr.norm(view)
            footprint = distance * self.pixel_rad
            if self.front_only:
                footprint = dr.select(mi.Frame3f.cos_theta(si.wi) > 0.0, footprint, dr.inf)
            if self.slant:
                height = dr.maximum(dr.abs(view.z), distance * (1.0 / SLANT_STRETCH_MAX))
                footprint = Slant(footprint, view.x / height, view.y / height)
            return si.p.x, si.p.y, footprint

        def _value_of(self, si):
            with np.errstate(over="ignore"):
                return self.shade(*self._at(si), drjit_ops())

        def value_at(self, x, y, footprint_m):
            """``shade`` at render-frame points ``(x, y)`` seen with a pixel's footprint
            ``footprint_m`` there (the geometry pass's question to a cloud layer's opacity),
            reading the values :meth:`prepare` noted, as the render does: a recording of it
            reads them as data."""
            ops = drjit_ops()
            with np.errstate(over="ignore"):
                if ops is NUMPY:
                    return self.shade(x, y, footprint_m, ops)
                self.prepare()
                with _Reading(self, collect=False) as reading, _loops_traced_once():
                    value = self.shade(x, y, footprint_m, ops)
            reading.check()
            return value


    assert mi.variant() == variant
    return FieldTexture


@functools.cache
def body_texture_class(variant: str):
    """A :class:`mitsuba.Texture` on an object's surface whose value is ``shade(point, ops)``
    for a :class:`~datagen.assets.liveries.PaintPoint`: the mesh's texture coordinates as
    ``(s, t)``, the point and its normal in the object's body frame (the owner sets the
    frame's ``body_from_render``, a 4x4, and the camera's render-frame position ``camera``;
    both reach the kernel as opaque values), and a pixel's footprint there: its distance
    times ``pixel_rad`` across the view, and its extents along ``s`` and ``t``, stretched
    along the view's direction on the surface by 1 / cosine (at most 1 /
    :data:`~datagen.assets.liveries.MIN_COSINE`): the shading frame's first axis is ``s``
    (Mitsuba aligns it with the texture coordinates' ``dp/du``)."""
    import drjit as dr
    import mitsuba as mi

    from datagen.assets.liveries import MIN_COSINE, PaintPoint

    base: Any = _shaded_texture(variant)

    class BodyTexture(base):
        def inputs(self) -> tuple:
            return (*super().inputs(), self._body_jit, self._twin_jit, self._twin_id, self._frame_values)

        @property
        def frame_values(self) -> dict:
            """Numbers a ``shade`` reads that change from frame to frame (:meth:`set_value`):
            one dict for the texture's life, which a ``shade`` may hold."""
            return self._frame_values

        def set_value(self, name: str, value: float) -> None:
            """Set ``frame_values[name]``: an opaque device value (a scalar variant's: float32)."""
            scalar = str(mi.variant()).startswith("scalar")
            self._frame_values[name] = np.float32(value) if scalar else dr.opaque(mi.Float, float(value))

        # Each per-frame value is held as opaque device values made when it is set, so that
        # the render reads it as data (the host copy serves a scalar variant), as the camera is.
        @property
        def body_from_render(self) -> np.ndarray:
            return self._body_from_render

        @body_from_render.setter
        def body_from_render(self, value) -> None:
            self._body_from_render = np.asarray(value, dtype=np.float64)
            self._body_jit = _opaque_rows(self._body_from_render)

        @property
        def twin_body_from_render(self) -> np.ndarray:
            return self._twin_body_from_render

        @twin_body_from_render.setter
        def twin_body_from_render(self, value) -> None:
            self._twin_body_from_render = np.asarray(value, dtype=np.float64)
            self._twin_jit = _opaque_rows(self._twin_body_from_render)

        @property
        def twin(self) -> int | None:
            return self._twin

        @twin.setter
        def twin(self, value: int | None) -> None:
            self._twin = None if value is None else int(value)
            scalar = str(mi.variant()).startswith("scalar")
            self._twin_id = None if self._twin is None or scalar else dr.opaque(mi.UInt32, self._twin)

        def __init__(self, props=None, *, pixel_rad: float = 1e-3, colour: bool = False):
            super().__init__(props if props is not None else mi.Properties())
            self.pixel_rad = float(pixel_rad)
            self.colour = colour
            self.camera = (0.0, 0.0, 0.0)
            self.body_from_render = np.eye(4)
            # Another instance of the same shapes (datagen.scene.traffic): its registry id and
            # its own body frame, so that it wears the paint where it is.
            self.twin = None
            self.twin_body_from_render = np.eye(4)
            self.shade = None  # (PaintPoint, ops) -> value (a tuple of three when colour)
            self._frame_values: dict = {}

        def _point(self, si) -> PaintPoint:
            ops = drjit_ops()
            if ops is NUMPY:  # a scalar variant: one point
                m = self.body_from_render
                p = np.array([si.p.x, si.p.y, si.p.z], dtype=np.float64)
                body = m[:3, :3] @ p + m[:3, 3]
                nz = float(m[2, :3] @ np.array([si.n.x, si.n.y, si.n.z]))
                wi = np.array([si.wi[0], si.wi[1], si.wi[2]], dtype=np.float64)
                across = np.linalg.norm(p - np.asarray(self.camera)) * self.pixel_rad
                along = across * np.sqrt(1.0 + np.square(wi[:2] / max(abs(wi[2]), MIN_COSINE)))
                bx, by, bz = (np.float32(c) for c in body)
                return PaintPoint(np.float32(si.uv.x), np.float32(si.uv.y), bx, by, bz, np.float32(nz),
                                  np.float32(across), np.float32(along[0]), np.float32(along[1]))
            rows, twin_rows = self._body_jit, self._twin_jit
            assert rows is not None and twin_rows is not None  # (a device variant's)
            c = list(rows)
            if self._twin_id is not None:  # the twin's hits: its body frame (the instance a ray met)
                on_twin = dr.reinterpret_array(mi.UInt32, si.instance) == self._twin_id
                c = [dr.select(on_twin, t, a) for a, t in zip(c, twin_rows, strict=True)]
            p = si.p
            x, y, z = [c[4 * i] * p.x + c[4 * i + 1] * p.y + c[4 * i + 2] * p.z + c[4 * i + 3] for i in range(3)]
            nz = c[8] * si.n.x + c[9] * si.n.y + c[10] * si.n.z
            across = dr.norm(p - self._camera_jit) * self.pixel_rad
            inverse = 1.0 / dr.maximum(dr.abs(si.wi.z), MIN_COSINE)
            along_s = across * dr.sqrt(1.0 + dr.square(si.wi.x * inverse))
            along_t = across * dr.sqrt(1.0 + dr.square(si.wi.y * inverse))
            return PaintPoint(si.uv.x, si.uv.y, x, y, z, nz, across, along_s, along_t)

        def _value_of(self, si):
            with np.errstate(over="ignore"):
                v = self.shade(self._point(si), drjit_ops())
            return mi.Color3f(*v) if self.colour else v

    assert mi.variant() == variant
    return BodyTexture


@functools.cache
def mask_class(variant: str):
    """Mitsuba's ``mask`` BSDF over a black mirror, as a Python :class:`mitsuba.BSDF` whose
    opacity is a :func:`texture_class` texture; shadow rays' null transmission is ``1 -
    opacity``, as ``mask``'s.

    A path that meets the surface where its opacity is at most :data:`MASK_SPLIT` passes it
    with weight ``1 - opacity`` (a ``Null`` event, whose pdf the path tracers do not use:
    it reports 1); elsewhere, as with ``mask``, it stops there (the black mirror reflects
    nothing) with probability ``opacity`` or passes unchanged (weight 1). Both are
    unbiased; the first draws no noise where the camera sees through a cloud's thin parts
    (a path that stopped there with probability ``opacity`` drew grains over every soft
    edge). ``eval`` and ``pdf`` are zero (a delta lobe)."""
    import drjit as dr
    import mitsuba as mi

    F = mi.BSDFFlags
    mirror = F.DeltaReflection | F.FrontSide
    null = F.Null | F.FrontSide | F.BackSide

    class OpacityMask(mi.BSDF):
        def __init__(self, opacity, props=None):
            super().__init__(props if props is not None else mi.Properties())
            self.opacity = opacity
            self.m_components = [mirror, null]
            self.m_flags = mirror | null

        def sample(self, ctx, si, sample1, sample2, active=True):
            alpha = dr.clip(self.opacity.eval_1(si, active), 0.0, 1.0)
            passes = dr.select(alpha <= MASK_SPLIT, 1.0 - alpha, dr.select(sample1 < alpha, 0.0, 1.0))
            stops = passes <= 0.0
            bs = dr.zeros(mi.BSDFSample3f)
            bs.wo = dr.select(stops, mi.reflect(si.wi), -si.wi)
            bs.eta = 1.0
            bs.sampled_component = dr.select(stops, mi.UInt32(0), mi.UInt32(1))
            bs.sampled_type = dr.select(stops, mi.UInt32(+F.DeltaReflection), mi.UInt32(+F.Null))
            bs.pdf = 1.0
            return bs, mi.Color3f(passes)

        def eval(self, ctx, si, wo, active=True):
            return mi.Color3f(0.0)

        def pdf(self, ctx, si, wo, active=True):
            return mi.Float(0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return mi.Color3f(0.0), mi.Float(0.0)

        def eval_null_transmission(self, si, active=True):  # the mirror transmits nothing
            return mi.Color3f(1.0 - dr.clip(self.opacity.eval_1(si, active), 0.0, 1.0))

        def to_string(self):
            return "OpacityMask[]"

    assert mi.variant() == variant
    return OpacityMask
