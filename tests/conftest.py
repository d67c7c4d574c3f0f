"""Every test session keeps its cache to itself."""

from __future__ import annotations

import collections
import itertools
import textwrap

import pytest

from softtip._core.progress import Progress, Task


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


# The files whose tests take longest (pytest --durations): the reduced twin of the default size (some
# 850 s in one process, a file of its own), every study's report in a browser (about 270 s), two studies
# reproduced serially and in a pool, the S4 system's study runs, the CLI's sweep of bad values, the
# wearable's study, a later session of a unit, the demo, the firmware in simavr, then test_rom.py's
# smaller twins, pooled trials and the tolerance ranking. pytest-xdist hands a worker one file at a time
# in the order below (pyproject: --no-loadscope-reorder): longest first, so that none starts near the end
# and runs on alone while the other workers idle; the rest by their number of tests, most first.
LONGEST_FILES = ("test_rom_default_size.py", "test_report_browser.py", "test_reproduce_parallel.py",
                 "test_cilia_system.py", "test_cli_sweep.py", "test_wearable_study.py", "test_drift.py",
                 "test_fingertip_demo.py", "test_firmware_sim.py", "test_rom.py", "test_lab_trials.py",
                 "test_fingertip_tolerance.py", "test_studies.py", "test_insertion.py", "test_mechanics.py")


def pytest_collection_modifyitems(items):
    for item in items:
        if SLOW_FIXTURES.get(item.path.name, set()) & set(item.fixturenames):
            item.add_marker(pytest.mark.slow)
    tests_in = collections.Counter(item.path for item in items)
    rank = {name: place for place, name in enumerate(LONGEST_FILES)}
    # a stable sort: each file's tests keep their order
    items.sort(key=lambda item: (rank.get(item.path.name, len(rank)), -tests_in[item.path], str(item.path)))


# The fewest conditions that still exercise every part of a study (its default has hundreds of trials)
FEWER_CONDITIONS = {"contact-states": """
    phi_deg = [20.0]
    psi_deg = [10.0]
    untrained_phi_deg = [25.0]
    untrained_psi_deg = [12.0]
    approach_inclines_deg = [45.0]
    positions_mm = [[0.0, 0.0], [5.0, 5.0]]
""", "wearable": """
    participants = 2
    runs = 2
"""}


@pytest.fixture(scope="session")
def coarse_protocol(tmp_path_factory):
    """Write a protocol file for ``name`` on ``design`` with a coarse mesh (and, with ``fewer``, the fewest
    conditions of :data:`FEWER_CONDITIONS`); returns its path."""
    directory = tmp_path_factory.mktemp("protocols")
    numbers = itertools.count()

    def write(name: str, design: str, mesh: float = 3.0, extra: str = "", seed: int = 2, fewer: bool = False):
        from dataclasses import fields

        from softtip.lab.protocols import bench_of

        path = directory / f"{name}-{next(numbers)}.toml"
        # a bench built from a design (the Hall fingertip's) takes it and a coarse mesh; others have neither
        designed = "design" in {item.name for item in fields(bench_of(name).protocol_file)}
        fixture = f'design = "{design}"\n[parameters]\nmesh_size_mm = {mesh}\n' if designed else "[parameters]\n"
        path.write_text(f'protocol = "{name}"\nseed = {seed}\n' + fixture + textwrap.dedent(extra)
                        + textwrap.dedent(FEWER_CONDITIONS.get(name, "") if fewer else ""))
        return path

    return write


@pytest.fixture(scope="session")
def install_package():
    """Writes a package of a lab's own on a folder beside its dist-info, as pip would install it:
    ``install(root, name, files, systems)`` with ``files`` its modules' text by path within the package
    and ``systems`` its ``softtip.systems`` entry points ("name = module:attribute" lines)."""

    def install(root, name: str, files: dict[str, str], systems: str, version: str = "0.1") -> None:
        for path, text in files.items():
            target = root / name / path
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(textwrap.dedent(text).lstrip())
        info = root / f"{name}-{version}.dist-info"
        info.mkdir()
        (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n")
        (info / "entry_points.txt").write_text(f"[softtip.systems]\n{textwrap.dedent(systems).strip()}\n")

    return install


class StageNames(Progress):
    """The stages a job announces, in order, shown nowhere."""

    def __init__(self) -> None:
        self.names: list[str] = []

    def task(self, description: str, total: float | None = None) -> Task:
        self.names.append(description)
        return Task()


@pytest.fixture
def stage_names() -> type[StageNames]:
    """Makes a progress that records the names of the stages a job runs."""
    return StageNames


@pytest.fixture
def written_pieces(tmp_path, monkeypatch):
    """From here on, every cache piece written (:class:`softtip._core.cache.EntryPieces`) is logged, by this
    process or one it forks; returns what reads the log: the pieces' indices, sorted."""
    from softtip._core.cache import EntryPieces

    log, write = tmp_path / "written-pieces", EntryPieces.write

    def write_and_log(self, index, arrays):
        with open(log, "a") as file:
            file.write(f"{index}\n")
        write(self, index, arrays)

    monkeypatch.setattr(EntryPieces, "write", write_and_log)
    return lambda: sorted(map(int, log.read_text().split())) if log.exists() else []
