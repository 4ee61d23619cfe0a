"""Test-wide settings: no per-example deadline (CI machines are slow and shared)."""

from hypothesis import HealthCheck, settings

settings.register_profile("datagen", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("datagen")
