"""Files that survive faults: a byte changed anywhere in a dataset or a model file is refused in one line
naming the file; a model file whose metadata was edited and its checksum recomputed no longer loads."""

from __future__ import annotations

import hashlib
import json
import warnings
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import MinMaxScaler, StandardScaler

from softtip._core.archive import (
    ModelFileError,
    archive_digest,
    archive_format,
    canonical_json,
    read_archive,
    write_archive,
)
from softtip.calibration import LMNetwork, PolynomialFit, load_model, save_model
from softtip.data.dataset import Dataset, DatasetError, UnverifiedDatasetWarning


def flipped(path: Path, offset: int, mask: int) -> Path:
    content = bytearray(path.read_bytes())
    content[offset] ^= mask
    damaged = path.with_name("damaged" + path.suffix)
    damaged.write_bytes(bytes(content))
    return damaged


def refusals_of_every_flip(path: Path, read, error: type[Exception], mask: int) -> list[int]:
    """The offsets at which a byte of ``path`` xor ``mask`` is NOT refused by ``read`` with one ``error``
    line naming the file (a refusal of any other kind counts as not refused)."""
    missed = []
    for offset in range(path.stat().st_size):
        damaged = flipped(path, offset, mask)
        try:
            read(damaged)
        except error as refusal:
            if str(damaged) not in str(refusal) or "\n" in str(refusal):
                missed.append(offset)
        except Exception:
            missed.append(offset)
        else:
            missed.append(offset)
    return missed


# --------------------------------------------------------------------------
# Datasets
# --------------------------------------------------------------------------


def small_dataset() -> Dataset:
    return Dataset({"trial": [3, 3, 3, 8, 8], "time_s": [0.0, 0.1, 0.2, 0.0, 0.1], "s0_bz_uT": [1.5, 2.0, -3.0, 0.0, 4.0],
                    "fz_N": np.array([0.1, np.nan, 0.3, 0.0, 0.2], np.float32),
                    "state": ["air", "edge", "air", "point", "air"], "trained": [True] * 3 + [False] * 2},
                   labels={"fz_N": "N", "state": "1"}, conditions={"trained": "1"})


@pytest.mark.parametrize("mask", [0x01, 0x80, 0xFF])
def test_a_byte_changed_anywhere_in_a_dataset_file_is_refused(tmp_path, mask):
    path = small_dataset().write(tmp_path / "trials.parquet")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the file carries its checksum: no warning
        back = Dataset.read(path)
    np.testing.assert_array_equal(back.columns["fz_N"], small_dataset().columns["fz_N"])
    assert refusals_of_every_flip(path, Dataset.read, DatasetError, mask) == []


def test_dataset_pages_carry_crcs_that_any_parquet_reader_verifies(tmp_path):
    path = small_dataset().write(tmp_path / "trials.parquet")
    metadata = pq.ParquetFile(path).metadata
    column = metadata.row_group(0).column(2)
    assert column.path_in_schema == "s0_bz_uT" and column.statistics is None
    chunk_start = min(offset for offset in (column.dictionary_page_offset, column.data_page_offset) if offset)
    damaged = flipped(path, chunk_start + column.total_compressed_size - 1, 0x01)  # the last byte of its data page
    with pytest.raises(OSError, match="CRC"):
        pq.read_table(damaged, page_checksum_verification=True)
    with pytest.raises(DatasetError, match="damaged.parquet: unreadable Parquet data .*CRC"):
        Dataset.read(damaged)


def test_a_dataset_rewritten_by_another_writer_no_longer_matches_its_checksum(tmp_path):
    path = small_dataset().write(tmp_path / "trials.parquet")
    table = pq.read_table(path)
    values = table.column("s0_bz_uT").to_numpy().copy()
    values[2] = -3.5
    table = table.set_column(2, "s0_bz_uT", pa.array(values))
    pq.write_table(table.replace_schema_metadata(pq.read_schema(path).metadata), path)
    with pytest.raises(DatasetError, match=r"trials.parquet: checksum mismatch: the file was altered or damaged"):
        Dataset.read(path)


def test_a_dataset_file_without_a_checksum_reads_with_a_warning(tmp_path):
    # as softtip wrote datasets before they carried a checksum: no sha256 in the document
    path = small_dataset().write(tmp_path / "trials.parquet")
    document = json.loads(pq.read_schema(path).metadata[b"softtip"])
    del document["sha256"]
    document["softtip_version"] = "0.1.0"
    pq.write_table(pq.read_table(path).replace_schema_metadata({b"softtip": json.dumps(document).encode()}), path)
    with pytest.warns(UnverifiedDatasetWarning, match=r"trials.parquet: no checksum \(written by softtip 0.1.0"):
        back = Dataset.read(path)
    np.testing.assert_array_equal(back.X(), small_dataset().X())
    back.write(path)  # written again, it carries one
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Dataset.read(path)


# --------------------------------------------------------------------------
# Model files
# --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def training():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(60, 3))
    return x, x @ rng.normal(size=(3, 2)) + 0.1 * x**2 @ rng.normal(size=(3, 2))


def saved(tmp_path: Path, model, targets=("Fz", "Fx")) -> Path:
    return save_model(tmp_path / "model.npz", model, input_channels=["s0_bx_uT", "s0_by_uT", "s0_bz_uT"],
                      input_units="uT", target_names=list(targets), target_units="N")


@pytest.mark.parametrize("mask", [0x01, 0xFF])
def test_a_byte_changed_anywhere_in_a_model_file_is_refused(tmp_path, training, mask):
    path = saved(tmp_path, PolynomialFit().fit(*training))
    assert refusals_of_every_flip(path, load_model, ModelFileError, mask) == []


def test_an_old_model_file_without_the_seal_still_loads_by_its_content_checksum(tmp_path, training):
    model = PolynomialFit().fit(*training)
    with np.load(saved(tmp_path, model), allow_pickle=False) as archive:
        arrays = {name: archive[name] for name in archive.files}
    metadata = json.loads(str(arrays.pop("metadata")))
    del metadata["sealed"], metadata["sha256"]
    metadata["sha256"] = archive_digest(metadata, arrays)
    old = tmp_path / "old.npz"
    with old.open("wb") as handle:  # as model files were written before the seal: numpy's npz alone
        np.savez(handle, metadata=np.array(canonical_json(metadata).decode()), **arrays)
    loaded, _ = load_model(old)
    np.testing.assert_array_equal(loaded.predict(training[0]), model.predict(training[0]))
    # the seal cannot be dropped from a sealed file: its metadata says it was sealed
    sealed = saved(tmp_path, model)
    content = sealed.read_bytes()
    stripped = tmp_path / "stripped.npz"
    stripped.write_bytes(content[:-len(b"softtip-sha256:") - 64 - 2] + b"\x00\x00")  # the comment and its length
    with pytest.raises(ModelFileError, match="stripped.npz: checksum mismatch"):
        load_model(stripped)


def _edited(path: Path, edit_metadata=None, edit_arrays=None) -> Path:
    """``path`` with its metadata or arrays edited and its checksum recomputed (a consistent forgery)."""
    with np.load(path, allow_pickle=False) as archive:
        arrays = {name: archive[name] for name in archive.files}
    metadata = json.loads(str(arrays.pop("metadata")))
    del metadata["sha256"]
    if edit_metadata:
        edit_metadata(metadata)
    if edit_arrays:
        edit_arrays(arrays)
    write_archive(path, metadata, arrays)
    return path


def _steps(metadata):
    return metadata["model"]["steps"]


@pytest.mark.parametrize("edit_metadata, edit_arrays, message", [
    # a scaler's parameters that change what it does, and the arrays it does it with
    (lambda m: _steps(m)[1]["params"].__setitem__("feature_range", [0, 2]), None,
     "MinMaxScaler: its arrays do not agree with each other and its parameters"),
    (None, lambda a: a.pop("steps/0/scale_"), "StandardScaler: array 'scale_' is missing"),
    (None, lambda a: a.pop("steps/1/min_"), "MinMaxScaler: array 'min_' is missing"),
    (lambda m: _steps(m)[0]["params"].__setitem__("with_std", False), None,
     "StandardScaler: array 'var_' is not used"),
    (None, lambda a: a.__setitem__("steps/0/scale_", a["steps/0/scale_"] * 2),
     "StandardScaler: its arrays do not agree"),
    # what the metadata says that the arrays do not hold
    (None, lambda a: a.__setitem__("steps/2/spare", np.zeros(3)), "array 'steps/2/spare' is not part of the model"),
    (lambda m: _steps(m)[2]["state"].__setitem__("n_layers", 3), None, "the model description does not match"),
    (lambda m: _steps(m)[2].__setitem__("name", "network"), None, "scaling does not describe the model's steps"),
    (lambda m: m["scaling"]["lmnetwork"].__setitem__("input", "none"), None, "scaling does not describe"),
])
def test_edited_and_rehashed_model_metadata_no_longer_loads(tmp_path, training, edit_metadata, edit_arrays, message):
    x, y = training
    pipeline = make_pipeline(StandardScaler(), MinMaxScaler(), LMNetwork((3,), max_epochs=5, random_state=0))
    path = saved(tmp_path, pipeline.fit(x, y[:, 0]), targets=["Fz"])
    load_model(path)  # as written, it loads
    _edited(path, edit_metadata, edit_arrays)
    with pytest.raises(ModelFileError, match=message) as refusal:
        load_model(path)
    assert str(path) in str(refusal.value) and "\n" not in str(refusal.value)


def test_the_model_checksum_covers_each_arrays_shape():
    metadata, weights = {"format": "softtip-model"}, np.arange(6.0)
    # the reference, by hand: canonical metadata, then name NUL dtype NUL shape NUL and the bytes
    reference = hashlib.sha256(b'{"format":"softtip-model"}' + b"w\0<f8\0(6,)\0" + weights.tobytes()).hexdigest()
    assert archive_digest(metadata, {"w": weights}) == reference
    # the same bytes in another shape: only the shape term tells them apart
    assert archive_digest(metadata, {"w": weights.reshape(2, 3)}) != reference
    assert archive_digest(metadata, {"w": weights.reshape(2, 3)}) == hashlib.sha256(
        b'{"format":"softtip-model"}' + b"w\0<f8\0(2, 3)\0" + weights.tobytes()).hexdigest()


def test_canonical_json_sorts_keys_at_every_level_and_refuses_nan():
    # by hand: sorted keys at every level, no spaces
    assert canonical_json({"b": 1, "a": {"d": [1.5, "x"], "c": None}}) == b'{"a":{"c":null,"d":[1.5,"x"]},"b":1}'
    with pytest.raises(ValueError, match="not JSON compliant"):
        canonical_json({"gain": float("nan")})


def test_read_archive_refuses_object_arrays_and_a_metadata_entry_that_is_not_one_text(tmp_path):
    metadata = {"format": "softtip-model", "schema_version": 1}
    stated = metadata | {"sha256": archive_digest(metadata, {})}
    path = tmp_path / "model.npz"  # as numpy alone writes an archive: no seal, its content checksum right
    np.savez(path, metadata=np.array(canonical_json(stated).decode()), w=np.array([1.0, "a"], dtype=object))
    # an object array is pickled: never unpickled, refused for what numpy says
    with pytest.raises(ModelFileError, match=r"model.npz is truncated or unreadable \(ValueError: Object arrays "
                                             r"cannot be loaded when allow_pickle=False\)"):
        read_archive(path, "softtip-model", 1, "model", ModelFileError)
    # the metadata as a list of one text rather than one text
    np.savez(path, metadata=np.array([canonical_json(stated).decode()]))
    with pytest.raises(ModelFileError, match=r"model.npz is not a softtip model file \(no metadata entry\)"):
        read_archive(path, "softtip-model", 1, "model", ModelFileError)
    np.savez(path, metadata=np.array(canonical_json(stated).decode()))  # the same text as one: it reads
    assert read_archive(path, "softtip-model", 1, "model", ModelFileError) == (stated, {})


def test_archive_format_names_the_format_of_a_readable_archive_and_nothing_else(tmp_path):
    written = write_archive(tmp_path / "model.npz", {"format": "softtip-model", "schema_version": 1},
                            {"w": np.arange(3.0)})
    assert archive_format(written) == "softtip-model"
    other = tmp_path / "other.npz"
    np.savez(other, metadata=np.array('{"format": "made-by-numpy"}'))  # no checksum, no seal: read all the same
    assert archive_format(other) == "made-by-numpy"
    # the same text pickled as an object array: never unpickled, so no format
    np.savez(other, metadata=np.array('{"format": "made-by-numpy"}', dtype=object))
    assert archive_format(other) is None
    for metadata in ("[1, 2]", "{}", "not JSON"):  # not an object, no format, no JSON
        np.savez(other, metadata=np.array(metadata))
        assert archive_format(other) is None, metadata
    np.savez(other, w=np.zeros(2))  # no metadata entry
    assert archive_format(other) is None
    for content in (b"not an archive", written.read_bytes()[:200]):  # not a zip; cut inside its first entry
        other.write_bytes(content)
        assert archive_format(other) is None


def test_a_dataset_whose_metadata_is_rewritten_as_compact_json_is_refused(tmp_path):
    # compact JSON moves the checksum's entry out of the place the seal looks for: that is a refusal,
    # not a file taken as sealed
    path = small_dataset().write(tmp_path / "trials.parquet")
    document = json.loads(pq.read_schema(path).metadata[b"softtip"])
    document["description"] = "another dataset"
    compact = json.dumps(document, separators=(",", ":")).encode()
    assert b'"sha256":"' in compact
    pq.write_table(pq.read_table(path).replace_schema_metadata({b"softtip": compact}), path)
    with pytest.raises(DatasetError, match=r"trials.parquet: checksum mismatch: the file was altered or damaged"):
        Dataset.read(path)
    # as it was, value unchanged but compact: refused too (the checksum's place is part of the seal)
    document["description"] = small_dataset().metadata.description
    pq.write_table(pq.read_table(path).replace_schema_metadata(
        {b"softtip": json.dumps(document, separators=(",", ":")).encode()}), path)
    with pytest.raises(DatasetError, match="checksum mismatch"):
        Dataset.read(path)
