"""softtip as a user installs it: every file the code reads is in the installed package."""

from __future__ import annotations

from pathlib import Path

import pytest

import softtip
from softtip._core.systems import systems

SOURCE = Path(__file__).parents[1] / "src" / "softtip"
INSTALLED = Path(softtip.__file__).parent


@pytest.mark.skipif(INSTALLED == SOURCE, reason="softtip is installed editable: its files are the source tree's")
def test_the_installed_package_holds_every_data_file_of_the_source_tree():
    data = sorted(path.relative_to(SOURCE) for path in SOURCE.rglob("*")
                  if path.is_file() and path.suffix not in (".py", ".pyc") and "__pycache__" not in path.parts)
    assert data, "the source tree ships data files (designs, protocols, published tables)"
    missing = [str(path) for path in data if not (INSTALLED / path).is_file()]
    assert not missing, f"not in the installed package: {missing}"


def test_every_registered_system_reads_its_files_from_its_package():
    for system in systems().values():
        published = system.published()
        assert published is None or published.is_file()
        for name in system.protocols:
            assert system.protocol_file(name).is_file(), (system.name, name)
        for path in system.designs().values():
            assert path.is_file()
