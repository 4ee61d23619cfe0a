"""The path tracing recorded once and replayed: Dr.Jit's ``dr.freeze`` around ``mi.render``.

Every ``mi.render`` traces the path tracer's kernel again in Python and C++ (the Python
plugins included) before it runs it; a frozen function records the kernels its first call
launches and replays them after, given new inputs. Dr.Jit finds the inputs by walking the
arguments: the scene, its plugins' device arrays (the Python plugins' attributes too) and
the sampler seed. What the recording baked in is whatever it did not find there, so the
frame's values must all be device values set before the call:

- the procedural textures' values and tables are noted and uploaded before the render
  (:meth:`~datagen.render.procedural.texture_class` ``prepare``), never made inside it;
- the per-frame values (camera, body frames, sky, air) are opaque device values made when
  set;
- every array the scene holds comes from Dr.Jit's own memory
  (:func:`datagen.render.mitsuba.scene_array`): a replay takes an array mapped from numpy
  memory at the memory it had when recording;
- the sampler seed is an opaque ``UInt32``;
- nothing Mitsuba makes on first use inside the render: the cloud layers' radiance tells
  Mitsuba it does not vary over the surface, so their emitters never ask for their mesh's
  UV parameterization, a scene of its own that Mitsuba rebuilt inside the render after
  the mesh changed (a recording then met an object its inputs did not hold and was
  refused, and a replay of an older recording read the freed scene and crashed).

A process records twice: the first frame, and the second, whose inputs' layout differs by
what Mitsuba set up in the first render; every later frame of every approach replays.
Dr.Jit evaluates the inputs' pending values (the sky's, derived from its sun and
turbidity) in a small kernel before each call, whose shape changes at a few approaches
(about 100 operations, compiled anew): with the figures on a GPU still to be taken, that
is why it is off by default. Counted by :attr:`datagen.render.renderer.Renderer.recordings`
and reported by the build.

``bench/bench_freeze.py`` compares replayed frames with traced ones per world randomizer;
``tests/test_frozen.py`` does so on three approaches with every randomizer on.
"""

from __future__ import annotations

__all__ = ["frozen_render"]


def frozen_render(spp: int):
    """A frozen ``mi.render(scene, seed=seed, spp=spp)``: call it with the scene and the seed
    as an opaque ``mi.UInt32``; ``n_recordings`` counts its recordings."""
    import drjit as dr
    import mitsuba as mi

    def render(scene, seed):
        return mi.render(scene, seed=seed, spp=spp)

    return dr.freeze(render)
