"""pytest-benchmark setup for ``pytest bench/ --benchmark-only`` (not part of the unit tests)."""
import pytest


@pytest.fixture(scope="session", autouse=True)
def taichi_runtime():
    from cdnf_ti.taichi_runtime import ensure_taichi

    return ensure_taichi("cpu")
