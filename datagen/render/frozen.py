"""The path tracing recorded once and replayed: Dr.Jit's ``dr.freeze`` around ``mi.render``
(the frame's, and the target pass's merged into it: :mod:`datagen.render.target`), and around
the geometry pass's ray cast.

Every ``mi.render`` traces the path tracer's kernel again in Python and C++ (the Python
plugins included) before it runs it; a frozen function records the kernels its first call
launches and replays them after, given new inputs. Dr.Jit finds the inputs by walking the
arguments: the scene, its plugins' device arrays (the Python plugins' attributes too) and
the sampler seed. What the recording baked in is whatever it did not find there, so the
frame's values must all be device values set before the call:

- the procedural textures' values and tables are noted and uploaded before the render
  (:meth:`~datagen.render.procedural.texture_class` ``prepare``), never made inside it, and
  reach the frozen function as an argument of their own (each texture's ``inputs``): the
  walk over the scene meets a texture once for every object that holds it (each of an
  aircraft's parts), so the textures keep their attributes where that walk passes at once;
- the per-frame values (camera, body frames, sky, air) are opaque device values made when
  set;
- every array the scene holds comes from Dr.Jit's own memory
  (:func:`datagen.render.mitsuba.scene_array`): a replay takes an array mapped from numpy
  memory at the memory it had when recording;
- the sampler seeds are opaque ``UInt32``, and so is the target pass's window (its
  sensor's principal point, the merge's offsets);
- nothing Mitsuba makes on first use inside the render: the cloud layers' radiance tells
  Mitsuba it does not vary over the surface, so their emitters never ask for their mesh's
  UV parameterization, a scene of its own that Mitsuba rebuilt inside the render after
  the mesh changed (a recording then met an object its inputs did not hold and was
  refused, and a replay of an older recording read the freed scene and crashed);
- no value still pending when the render is called: Dr.Jit evaluates a frozen function's
  pending inputs before the call, all of them in one kernel, whose shape then depends on
  which were pending (a new scene's hose, a new sky's sun angles) and compiled anew at some
  frames; :func:`settle` evaluates them where they are made, always in the same groups;
- the same inputs' layout from the first frame on: the sensors' films are prepared, and the
  films' and samplers' literals settled, when the scene is built (a first render leaves
  arrays where they held literals, and the second frame recorded again).

The geometry pass's ray cast is frozen the same way (:func:`frozen_cast`): its rays, the
state they start from and the cloud layers' opacity textures are its inputs, and it reads
nothing back to the host between passes.

A renderer records once, at its first frame, and compiles nothing after it; every later
frame of every approach replays (the default: ``render.frozen``); a scene built anew after
another renderer's replays the recording or records once more (measured: wingcam55 and
podcam15 replay, dashcam75 beside podcam15 records again). Counted by
:attr:`datagen.render.renderer.Renderer.recordings`; a build reports recordings after a
worker's first frame, if any. A recording Dr.Jit refuses traces its frame instead
(:attr:`~datagen.render.renderer.Renderer.refused_recordings`).

``bench/bench_freeze.py`` compares replayed frames with traced ones per world randomizer;
``tests/test_frozen.py`` does so on three approaches with every randomizer on.
"""

from __future__ import annotations

__all__ = ["Frozen", "frozen_cast", "frozen_render", "refused", "settle"]


def frozen_render(render):
    """``render`` (the renderer's path tracing: :meth:`datagen.render.renderer.Renderer.trace`)
    frozen: call it with the scene and its other inputs as opaque device values (the seeds as
    ``mi.UInt32``); ``n_recordings`` counts its recordings."""
    import drjit as dr

    return dr.freeze(render)


def frozen_cast(cast):
    """``cast`` (:func:`datagen.render.raycast.cast_kernel`) frozen: the geometry pass's ray
    cast, recorded once per input layout and replayed (its inputs are all device arrays or
    Mitsuba objects, and a key of the Python values it bakes in)."""
    import drjit as dr

    return dr.freeze(cast, limit=CAST_LAYOUTS)


class Frozen:
    """A frozen function (``make()``: a ``dr.freeze``) that traces its call instead where
    Dr.Jit refuses to record it, or to record it again after a failed dry run of a replay:
    the call is made by ``traced``, and a new frozen function (:attr:`function`) replaces the
    one whose cache may hold the refused entry. Measured before the cloud layers' radiance
    stopped asking for their mesh's UV parameterization
    (procedural.FieldTexture.is_spatially_varying): a recording met an object Mitsuba makes
    on first use inside the render; the traced call makes it, and the next one records."""

    def __init__(self, make) -> None:
        self._make = make
        self.function = make()
        self.refused = 0  # refusals (those calls traced)
        self._dropped = 0  # recordings of the functions replaced after a refusal

    @property
    def recordings(self) -> int:
        """How many times it recorded, the replaced functions' recordings included."""
        return self._dropped + self.function.n_recordings

    def __call__(self, traced, *args):
        """``function(*args)``, or ``traced(*args)`` where Dr.Jit refuses to record it; any
        other error is raised."""
        try:
            return self.function(*args)
        except RuntimeError as error:
            if not refused(error):
                raise
            self.refused += 1
            self._dropped += self.function.n_recordings
            self.function = self._make()
        return traced(*args)


def refused(error: BaseException) -> bool:
    """Whether ``error`` (or an error it was raised from) is Dr.Jit refusing to record or to
    record again a frozen function (``record(): ...``, ``replay(): ... re-recording ...``)."""
    cause: BaseException | None = error
    while cause is not None:
        if "record()" in str(cause) or "re-recording" in str(cause):
            return True
        cause = cause.__cause__
    return False


def settle(obj, *, literals: bool = False) -> None:
    """Evaluate now every value ``obj`` (a Mitsuba object, a Python plugin, the scene) holds
    that is still pending, as Dr.Jit evaluates a frozen function's inputs; with
    ``literals``, its literal values (a ``dr.zeros``, say) become arrays in memory too.

    Mitsuba leaves some values a plugin derives in its ``parameters_changed`` pending
    (measured, Mitsuba 3.9: the sun's angles of ``sunsky``, a new mesh's buffers); a frozen
    render evaluates them before replaying, in one kernel whatever else is pending, so that
    kernel's shape changes from frame to frame and compiles anew. Settled where they are
    made, they are evaluated in the same groups every frame. A film before its first render
    holds a literal image, after it an array: the inputs' layout differs, and the second
    frame records again unless the film is prepared and its literals settled.

    Each kind of object (its type, with or without ``literals``) has a no-op frozen function
    of its own, which keeps its last :data:`SETTLE_LAYOUTS` input layouts."""
    import drjit as dr
    import mitsuba as mi

    key = (type(obj).__name__, bool(literals))
    if key not in _settlers:
        _settlers[key] = dr.freeze(lambda _obj: None, backend=dr.backend_v(mi.Float), auto_opaque=not literals,
                                   limit=SETTLE_LAYOUTS, warn_after=1_000_000)
    _settlers[key](obj)


#: How many input layouts each of :func:`settle`'s no-op frozen functions keeps (a new scene
#: is a new layout; the oldest is dropped).
SETTLE_LAYOUTS = 4

#: How many input layouts the frozen ray cast keeps (a frame with more lights than the rays
#: padded for is another layout; a scene built anew, another).
CAST_LAYOUTS = 4

#: The no-op frozen functions whose input evaluation :func:`settle` uses.
_settlers: dict = {}
