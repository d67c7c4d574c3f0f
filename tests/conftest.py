"""Every test session keeps its cache to itself."""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True, scope="session")
def private_cache_dir(tmp_path_factory):
    """Meshes, FE results and trained models are made in this session, by the code under test, in a
    directory of its own: the user's cache is never read or written (worker processes inherit it)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("SOFTTIP_CACHE_DIR", str(tmp_path_factory.mktemp("softtip-cache")))
        yield


# Module fixtures that take over 10 s to build (a mesh and the influence matrices of its surface, or a
# reduced twin): every test that needs one is slow, and leaves the quick suite (-m "not slow").
SLOW_FIXTURES = {"test_footprint.py": {"coarse"}, "test_lab.py": {"coarse_rectangular"},
                 "test_rom.py": {"coarse", "tiny_twin"}}


def pytest_collection_modifyitems(items):
    for item in items:
        if SLOW_FIXTURES.get(item.path.name, set()) & set(item.fixturenames):
            item.add_marker(pytest.mark.slow)
