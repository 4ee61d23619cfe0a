"""Test-wide settings: no per-example deadline (CI machines are slow and shared),
Mitsuba's memory freed after each test, and the session's shared Ray cluster."""

import gc
import sys

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile("datagen", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("datagen")


@pytest.fixture(scope="session")
def ray_cluster():
    """One small real local Ray cluster (2 CPUs) shared by every test that needs it."""
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()


@pytest.fixture(autouse=True)
def release_renderers():
    """A test's Mitsuba scenes and Dr.Jit memory freed after it, where it loaded Mitsuba: they
    sit in reference cycles until a collection, and the render tests that followed ran up
    to 3x slower (test_render.py: 362 s, 208 s with this)."""
    yield
    if "drjit" in sys.modules:
        import drjit as dr

        gc.collect()
        dr.sync_thread()
        dr.flush_malloc_cache()
