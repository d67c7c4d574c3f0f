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
