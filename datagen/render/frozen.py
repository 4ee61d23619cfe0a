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
- the sampler seed is an opaque ``UInt32``.

A change Dr.Jit can see that alters the kernels' shape (a literal that changed, an array
of another width class) makes it record again, and so does a failed dry run of the replay,
measured at most approach boundaries (a new recording compiles kernels: why it is off by
default); counted by :attr:`datagen.render.renderer.Renderer.recordings` and reported by
the build.
``bench/bench_freeze.py`` compares replayed frames with traced ones per world randomizer;
``tests/test_frozen.py`` does so on two approaches with every randomizer on.
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
