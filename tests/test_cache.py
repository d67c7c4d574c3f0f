"""The on-disk cache: kept where the environment says at the moment of use, keyed by the inputs and by
the source of the code that made each entry, and trusting no entry it has not verified."""

from __future__ import annotations

import errno
import json
import os
import pwd
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import softtip.mechanics.mesh
import softtip.optimize.cache
import softtip.lab.protocols
from softtip._core.cache import (CacheEntryError, artefact_key, cache_dir, code_hash, read_entry, read_file_entry,
                                 write_entry, write_file_entry)
from softtip.calibration import PolynomialFit, load_model, save_model
from softtip.cli.main import app
from softtip.design.model import MM, load_design
from softtip.mechanics.mesh import mesh_design, mesh_key
from softtip.lab import load_protocol
from softtip.optimize.runs import Simulation


def test_the_cache_directory_is_read_at_each_call(monkeypatch, tmp_path):
    # this session's own directory (tests/conftest.py), never the user's
    assert cache_dir() == Path(os.environ["SOFTTIP_CACHE_DIR"]) != Path.home() / ".cache" / "softtip"
    monkeypatch.setenv("SOFTTIP_CACHE_DIR", str(tmp_path))
    assert cache_dir() == tmp_path
    monkeypatch.delenv("SOFTTIP_CACHE_DIR")
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    assert cache_dir() == Path.home() / ".cache" / "softtip"


def test_the_cache_follows_xdg_and_never_lands_at_the_root(monkeypatch, tmp_path):
    monkeypatch.delenv("SOFTTIP_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert cache_dir() == tmp_path / "softtip"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative")  # the XDG specification: a relative path is ignored
    monkeypatch.setenv("HOME", str(tmp_path))
    assert cache_dir() == tmp_path / ".cache" / "softtip"
    password_home = Path(pwd.getpwuid(os.getuid()).pw_dir)
    for home in ("", "relative/home"):  # as XDG readers do: the home the password database names
        monkeypatch.setenv("HOME", home)
        assert cache_dir() == password_home / ".cache" / "softtip"
    monkeypatch.setenv("HOME", "/")
    with pytest.raises(CacheEntryError, match="HOME = '/': no home folder .* set SOFTTIP_CACHE_DIR"):
        cache_dir()
    monkeypatch.setenv("HOME", "")
    monkeypatch.setattr(pwd, "getpwuid", lambda uid: {}[uid])  # a user id without an entry
    with pytest.raises(CacheEntryError, match="HOME = '': no home folder"):
        cache_dir()


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


ARRAYS = {"values": np.linspace(0.0, 1.0, 500).reshape(50, 10), "counts": np.arange(7)}


def entry_at(tmp_path, key="k1", kind="thing") -> Path:
    path = tmp_path / "entries" / f"{key}.npz"
    assert write_entry(path, key, kind, {"note": "made here"}, ARRAYS)
    return path


def one_warning(capsys, path: Path, words: str) -> None:
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and words in lines[0] and "computed again" in lines[0], lines


def test_an_entry_is_read_back_exactly_for_its_key_and_kind_only(tmp_path, capsys):
    path = entry_at(tmp_path)
    metadata, arrays = read_entry(path, "k1", "thing")
    assert metadata["note"] == "made here" and metadata["key"] == "k1" and set(arrays) == set(ARRAYS)
    for name, array in ARRAYS.items():
        np.testing.assert_array_equal(arrays[name], array)
        assert arrays[name].dtype == array.dtype
    assert read_entry(tmp_path / "absent.npz", "k1", "thing") is None and capsys.readouterr().err == ""
    assert read_entry(path, "k2", "thing") is None  # another key's valid entry under this key's name
    one_warning(capsys, path, "made for another thing (key 'k1'), not this thing (key 'k2')")
    assert read_entry(path, "k1", "other") is None
    one_warning(capsys, path, "made for another thing")


def test_every_changed_byte_of_an_entry_is_a_miss_with_one_warning(tmp_path, capsys):
    path = entry_at(tmp_path)
    content = path.read_bytes()
    for position in np.linspace(0, len(content) - 1, 300).astype(int):  # headers, arrays, metadata, directory
        damaged = bytearray(content)
        damaged[position] ^= 0x01
        path.write_bytes(bytes(damaged))
        assert read_entry(path, "k1", "thing") is None, position
        one_warning(capsys, path, "")
    for cut in (len(content) // 2, 30):  # truncated: the zip's central directory lost
        path.write_bytes(content[:cut])
        assert read_entry(path, "k1", "thing") is None
        one_warning(capsys, path, "")


def test_a_folder_fifo_or_link_in_place_of_an_entry_is_a_miss_never_followed(tmp_path, capsys):
    path = tmp_path / "entries" / "k1.npz"
    path.mkdir(parents=True)
    assert read_entry(path, "k1", "thing") is None
    one_warning(capsys, path, "a directory, not a regular file")
    assert not write_entry(path, "k1", "thing", {}, ARRAYS) and capsys.readouterr().err == ""  # said once
    path.rmdir()

    os.mkfifo(path)  # opening it to read would wait for a writer for ever
    reader = threading.Thread(target=lambda: read_entry(path, "k1", "thing"), daemon=True)
    reader.start()
    reader.join(timeout=10)
    assert not reader.is_alive()
    one_warning(capsys, path, "a FIFO, not a regular file")
    assert write_entry(path, "k1", "thing", {}, ARRAYS) and read_entry(path, "k1", "thing") is not None
    path.unlink()

    target = entry_at(tmp_path, key="k1-elsewhere")
    path.symlink_to(target)
    assert read_entry(path, "k1-elsewhere", "thing") is None
    one_warning(capsys, path, "a symbolic link, not a regular file")
    assert write_entry(path, "k1", "thing", {}, ARRAYS)  # the link replaced, its target untouched
    assert not path.is_symlink() and read_entry(target, "k1-elsewhere", "thing") is not None


def test_a_cache_that_cannot_take_an_entry_is_one_warning_not_a_failure(tmp_path, monkeypatch, capsys):
    def full_disk(descriptor):  # the disk fills as the written entry is flushed
        raise OSError(errno.ENOSPC, "No space left on device")

    path = tmp_path / "entries" / "k1.npz"
    monkeypatch.setattr(os, "fsync", full_disk)
    assert not write_entry(path, "k1", "thing", {}, ARRAYS)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and "could not be stored (No space left on device)" in lines[0]
    assert list(path.parent.iterdir()) == []  # nothing half-written left behind


FILL = """
import sys
from pathlib import Path
import numpy as np
from softtip._core.cache import read_entry, write_entry
path, seen = Path(sys.argv[1]), set()
arrays = {"values": np.sin(np.arange(200_000.0))}
for _ in range(30):
    entry = read_entry(path, "shared", "thing")
    if entry is None:
        write_entry(path, "shared", "thing", {}, arrays)
    else:
        seen.add(bool(np.array_equal(entry[1]["values"], arrays["values"])))
print(sorted(seen))
"""


def test_processes_filling_one_entry_at_once_agree(tmp_path):
    path = tmp_path / "entries" / "shared.npz"
    fillers = [subprocess.Popen([sys.executable, "-c", FILL, str(path)], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, env=os.environ | {"PYTHONPATH": os.pathsep.join(sys.path)})
               for _ in range(3)]
    outputs = [filler.communicate(timeout=120) for filler in fillers]
    assert [filler.returncode for filler in fillers] == [0, 0, 0], outputs
    assert all(out.strip() == "[True]" and err == "" for out, err in outputs), outputs  # no torn entry
    np.testing.assert_array_equal(read_entry(path, "shared", "thing")[1]["values"], np.sin(np.arange(200_000.0)))
    assert list(path.parent.iterdir()) == [path]  # no temporary file left behind


def fitted_model():
    x = np.linspace(-1.0, 1.0, 40)[:, None]
    return PolynomialFit(degree=2).fit(x, 3.0 * x[:, 0] ** 2 - x[:, 0] + 0.5)


def save(model):
    return lambda path: save_model(path, model, input_channels=["x"], input_units="1", target_names=["y"],
                                   target_units="1")


def test_a_cached_model_file_is_served_only_as_it_was_written(tmp_path, capsys):
    model = fitted_model()
    path = tmp_path / "models" / "force-k1.npz"
    write_file_entry(path, "k1", "force", save(model))
    x = np.array([[0.3], [-0.7]])
    served, _ = read_file_entry(path, "k1", "force", load_model)
    np.testing.assert_array_equal(served.predict(x), model.predict(x))
    np.testing.assert_allclose(served.predict(x), 3.0 * x[:, 0] ** 2 - x[:, 0] + 0.5, rtol=1e-9)
    assert read_file_entry(path, "k2", "force", load_model) is None  # another key's
    one_warning(capsys, path.with_name(path.name + ".entry"), "made for another force")
    assert read_file_entry(path, "k1", "state", load_model) is None  # another model's, of the same key
    one_warning(capsys, path, "made for another force")

    content = path.read_bytes()
    damaged = bytearray(content)
    damaged[len(content) // 2] ^= 0x40
    path.write_bytes(bytes(damaged))  # the model file damaged, its entry intact
    assert read_file_entry(path, "k1", "force", load_model) is None
    one_warning(capsys, path, "not the file its entry recorded")
    other = tmp_path / "other.npz"  # a valid model file of other coefficients, with no record of its key
    save(PolynomialFit(degree=1).fit(np.linspace(0, 1, 5)[:, None], np.arange(5.0)))(other)
    other.replace(path)
    assert read_file_entry(path, "k1", "force", load_model) is None
    one_warning(capsys, path, "not the file its entry recorded")

    path.unlink()
    path.mkdir()  # the file is needed by its path: a folder there is refused, naming it
    with pytest.raises(CacheEntryError, match=f"cache entry {path} is a folder where a force file belongs"):
        write_file_entry(path, "k1", "force", save(model))


def test_a_mesh_of_another_key_or_damaged_is_rebuilt(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("SOFTTIP_CACHE_DIR", str(tmp_path))
    design, wider = load_design("cylindrical-B"), load_design("cylindrical-B").with_params(**{"cavity.radius_mm": 9.5})
    fresh = mesh_design(design, 3 * MM, use_cache=False)
    mesh_design(design, 3 * MM)
    mesh_design(wider, 3 * MM)
    path, other = (tmp_path / "meshes" / f"{mesh_key(d, 3 * MM, 10)}.npz" for d in (design, wider))
    other.replace(path)  # another key's valid mesh placed under this key
    capsys.readouterr()
    rebuilt = mesh_design(design, 3 * MM)
    one_warning(capsys, path, "made for another mesh")
    np.testing.assert_array_equal(rebuilt.tets, fresh.tets)
    np.testing.assert_array_equal(rebuilt.points, fresh.points)
    content = path.read_bytes()
    path.write_bytes(content[: len(content) - 200])  # the zip's central directory cut off
    np.testing.assert_array_equal(mesh_design(design, 3 * MM).tets, fresh.tets)
    one_warning(capsys, path, "")
    assert read_entry(path, mesh_key(design, 3 * MM, 10), "mesh") is not None  # stored again, whole


def test_simulate_rebuilds_a_damaged_mesh_entry_without_a_traceback(monkeypatch, tmp_path):
    # as found by hand: a cut mesh entry raised zipfile.BadZipFile on every later run
    monkeypatch.setenv("SOFTTIP_CACHE_DIR", str(tmp_path))
    args = ["simulate", "--design", "cylindrical-B", "--mesh-size", "3", "--friction", "none", "--json"]
    first = CliRunner().invoke(app, args)
    entry = next((tmp_path / "meshes").glob("*.npz"))
    entry.write_bytes(entry.read_bytes()[:-300])
    again = CliRunner().invoke(app, args)
    assert (first.exit_code, again.exit_code) == (0, 0) and again.exception is None, again.output
    warnings = [line for line in again.stderr.splitlines() if line.startswith("softtip:")]  # not the progress lines
    assert len(warnings) == 1 and str(entry) in warnings[0] and "BadZipFile" in warnings[0], again.stderr
    fresh, rebuilt = (json.loads(result.stdout) for result in (first, again))
    assert {k: v for k, v in rebuilt.items() if k != "timings_s"} == {k: v for k, v in fresh.items()
                                                                        if k != "timings_s"}


@pytest.mark.slow  # three identifications of the wearable model (some 4 s each)
def test_a_damaged_cached_live_model_or_stream_is_rebuilt_and_served_again(monkeypatch, tmp_path, capsys):
    from softtip.systems.wearable.live import wearable_live_setup

    monkeypatch.setenv("SOFTTIP_CACHE_DIR", str(tmp_path))
    fresh = wearable_live_setup()
    stream = next((tmp_path / "models").glob("wearable-stream-*.npz"))
    for damaged in (fresh.model, stream):  # the identified model's file, then the stream's entry
        content = bytearray(damaged.read_bytes())
        content[len(content) // 3] ^= 0x04
        damaged.write_bytes(bytes(content))
        capsys.readouterr()
        rebuilt = wearable_live_setup()
        one_warning(capsys, damaged, "checksum mismatch")
        np.testing.assert_array_equal(rebuilt.readings, fresh.readings)
        assert rebuilt.validation == fresh.validation
    served = wearable_live_setup()  # stored again: a hit, no warning
    assert capsys.readouterr().err == ""
    np.testing.assert_array_equal(served.system.simulate(served.readings[:50, 0, :]),
                                  fresh.system.simulate(fresh.readings[:50, 0, :]))
