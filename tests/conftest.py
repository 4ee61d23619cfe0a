"""Test-wide settings: no per-example deadline (CI machines are slow and shared),
and the session's shared Ray cluster."""

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
