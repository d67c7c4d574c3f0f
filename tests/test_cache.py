"""The on-disk cache: kept where the environment says at the moment of use, and keyed by the inputs
and by the source of the code that made each entry."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

import softtip.mechanics.mesh
import softtip.optimize.cache
import softtip.lab.protocols
from softtip._core.cache import artefact_key, cache_dir, code_hash
from softtip.design.model import MM, load_design
from softtip.lab import load_protocol
from softtip.optimize.runs import Simulation


def test_the_cache_directory_is_read_at_each_call(monkeypatch, tmp_path):
    # this session's own directory (tests/conftest.py), never the user's
    assert cache_dir() == Path(os.environ["SOFTTIP_CACHE_DIR"]) != Path.home() / ".cache" / "softtip"
    monkeypatch.setenv("SOFTTIP_CACHE_DIR", str(tmp_path))
    assert cache_dir() == tmp_path
    monkeypatch.delenv("SOFTTIP_CACHE_DIR")
    assert cache_dir() == Path.home() / ".cache" / "softtip"


def test_the_code_hash_follows_every_byte_of_a_modules_source(monkeypatch, tmp_path):
    package = tmp_path / "hashed_package"
    (package / "sub").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "sub" / "__init__.py").write_text("")
    (package / "sub" / "kernel.py").write_text("SCALE = 1.0\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    first = code_hash("hashed_package")
    assert code_hash("hashed_package") == first and len(first) == 64
    (package / "sub" / "kernel.py").write_text("SCALE = 2.0\n")  # a nested module edited
    edited = code_hash("hashed_package")
    (package / "sub" / "shipped.toml").write_text("x = 1\n")  # data the package ships
    shipped = code_hash("hashed_package")
    (package / "notes.txt").write_text("not code")  # neither code nor shipped data
    assert len({first, edited, shipped}) == 3 and code_hash("hashed_package") == shipped
    # one module's hash is its file's: another module's edit does not touch it
    module = code_hash("hashed_package.sub.kernel")
    (package / "__init__.py").write_text("# edited\n")
    assert code_hash("hashed_package.sub.kernel") == module != code_hash("hashed_package")
    with pytest.raises(ValueError, match="no_such_module"):
        code_hash("no_such_module")


def test_an_artefact_key_changes_with_its_inputs_and_with_its_code():
    inputs = {"size": 2.5, "layer": [1.0, 0.5]}
    key = artefact_key(inputs, "code-a")
    assert key == artefact_key(dict(reversed(inputs.items())), "code-a")  # the order of keys is no input
    assert key != artefact_key(inputs | {"size": 2.6}, "code-a")
    assert key != artefact_key(inputs, "code-b")
    assert len(key) == 32 and len(artefact_key(inputs, "code-a", length=20)) == 20


@pytest.mark.parametrize("module, key_of", [
    (softtip.mechanics.mesh, lambda: softtip.mechanics.mesh.mesh_key(load_design("cylindrical-A"), 2.5 * MM, 10)),
    (softtip.optimize.cache, lambda: softtip.optimize.cache.cache_key(load_design("cylindrical-A").spec,
                                                                      Simulation(friction="none"))),
    (softtip.lab.protocols, lambda: softtip.lab.protocols.trained_model_path(load_protocol("inverter"),
                                                                                     "inverter-state").name),
])
def test_meshes_fe_results_and_models_are_keyed_by_the_code_that_made_them(monkeypatch, module, key_of):
    key = key_of()
    assert key_of() == key
    monkeypatch.setattr(module, "code_hash", lambda *modules: "other code")
    assert key_of() != key
