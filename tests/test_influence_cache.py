"""The surface's influence matrices are computed once per design and mesh and shared through the cache:
by the studies one after another, and by processes at once (one computes, the others wait for it)."""

from __future__ import annotations

import fcntl
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from softtip._core.cache import cache_dir, computing
from softtip._core.units import MM
from softtip.design.model import load_design
from softtip.twin.influence import InfluenceEngine


@pytest.mark.slow  # two factorisations and their back-substitutions: 10.7 min on 2 cores under a load average of 22-25
def test_the_influence_matrices_are_computed_once_and_read_back_bit_for_bit(stage_names, tmp_path, monkeypatch):
    monkeypatch.setenv("SOFTTIP_CACHE_DIR", str(tmp_path))  # a cache of its own: no other test built these first
    design = load_design("rectangular")
    first, second, third = stage_names(), stage_names(), stage_names()
    built = InfluenceEngine.build(design, 3.0 * MM, 2.0 * MM, curvature_points=3, progress=first)
    served = InfluenceEngine.build(design, 3.0 * MM, 2.0 * MM, curvature_points=3, progress=second)
    assert first.names == ["unit load responses"] and second.names == []  # the back-substitutions, once
    for name in ("nodes", "node_ids", "compliance", "magnets", "magnet_centers"):
        assert np.array_equal(getattr(served.influence, name), getattr(built.influence, name))
    InfluenceEngine.build(design, 3.0 * MM, 2.5 * MM, curvature_points=3, progress=third)  # another reach
    assert third.names == ["unit load responses"]  # is computed, into an entry of its own
    assert len(list((cache_dir() / "influence").glob("*.npz"))) == 2


def test_a_process_that_needs_an_entry_being_computed_waits_for_it(tmp_path):
    entry = tmp_path / "entry.npz"
    probe = textwrap.dedent(f"""
        import fcntl, os, sys
        descriptor = os.open({str(entry) + '.lock'!r}, os.O_WRONLY)
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            sys.exit(3)
    """)
    with computing(entry):
        assert subprocess.run([sys.executable, "-c", probe]).returncode == 3  # held: another process would wait
    assert subprocess.run([sys.executable, "-c", probe]).returncode == 0  # released with the block
    descriptor = os.open(f"{entry}.lock", os.O_WRONLY)
    fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)  # and in this process too
    os.close(descriptor)


INTERRUPTED_BUILD = """
import os, signal, sys
from softtip._core.progress import Progress, Task
from softtip._core.units import MM
from softtip.design.model import load_design
from softtip.twin.influence import InfluenceEngine

class CtrlCAfter(Progress):  # the user presses Ctrl-C once this many blocks are solved
    def task(self, description, total=None):
        if description != "unit load responses":  # the mesh's and the factorisation's steps are not blocks
            return Task()
        class Blocks(Task):
            done_blocks = 0
            def advance(self, steps=1, note=None):
                Blocks.done_blocks += 1
                if Blocks.done_blocks == int(sys.argv[1]):
                    os.kill(os.getpid(), signal.SIGINT)
        return Blocks()

InfluenceEngine.build(load_design("cylindrical-D"), 3.0 * MM, 4.5 * MM, curvature_points=3, progress=CtrlCAfter())
"""


@pytest.mark.slow  # three factorisations and nine blocks of back-substitutions: 9 s at a load average of 3, 88 s at 15-20
def test_a_build_stopped_by_ctrl_c_keeps_its_finished_blocks_and_the_next_resumes_from_them(written_pieces):
    """1,299 surface unknowns: six blocks of back-substitutions; Ctrl-C after the third."""
    interrupted = subprocess.run([sys.executable, "-c", INTERRUPTED_BUILD, "3"], capture_output=True, text=True)
    assert interrupted.returncode != 0 and "KeyboardInterrupt" in interrupted.stderr
    kept = list((cache_dir() / "influence").glob("*.npz.pieces/*.npz"))
    assert len(kept) in (3, 4)  # and the block the other process was finishing, if it was stored first
    solved = written_pieces  # the blocks written in this test's process, by whichever process solved them
    design = load_design("cylindrical-D")
    resumed = InfluenceEngine.build(design, 3.0 * MM, 4.5 * MM, curvature_points=3)
    kept_blocks = {int(path.stem) for path in kept}
    # only the blocks the interrupted run had not finished, each once
    assert solved() == sorted(set(range(6)) - kept_blocks)
    assert not list((cache_dir() / "influence").glob("*.npz.pieces"))  # gone once the whole entry is stored
    whole = InfluenceEngine.build(design, 3.0 * MM, 4.5 * MM, curvature_points=3, use_cache=False)
    # to round-off against each matrix's largest entry: the interrupted blocks were solved in another process,
    # whose BLAS may sum in another order, so entries near zero may differ relatively more than 1e-10
    for name in ("compliance", "magnets"):
        resumed_matrix, whole_matrix = getattr(resumed.influence, name), getattr(whole.influence, name)
        assert np.max(np.abs(resumed_matrix - whole_matrix)) <= 1e-10 * np.max(np.abs(whole_matrix))


# a coarse fingertip factorised twice (PARDISO, SuperLU), 150 unit loads twice: 2.1 s at a load average of 3
def test_blocks_solved_by_two_forked_processes_equal_the_serial_solve_and_scipys():
    """The back-substitutions of 150 surface unknowns in five blocks: by two processes forked after the
    factorisation, as in this process, and (three of them) by SciPy's sparse solver on the stiffness."""
    from scipy.sparse.linalg import splu

    from softtip.mechanics.contact.nodal import contact_candidates
    from softtip.mechanics.fe import BodyModel
    from softtip.mechanics.linsolve import SPDSolver
    from softtip.mechanics.mesh import mesh_design

    design = load_design("cylindrical-D")
    body = BodyModel.for_design(design, mesh_design(design, 3.0 * MM, curvature_points=3))
    dofs = contact_candidates(body)[1]
    columns = dofs[(dofs >= 0).all(axis=1)].ravel()[::10][:150]
    solver = SPDSolver()
    solver.factorize(body.stiffness)
    serial = body.unit_load_responses(solver, columns, block=30, processes=1)
    forked = body.unit_load_responses(solver, columns, block=30, processes=2)
    for in_series, side_by_side in zip(serial, forked):
        assert np.max(np.abs(side_by_side - in_series)) <= 1e-12 * np.max(np.abs(in_series))
    rigid = np.arange(body.n_free, body.size)
    superlu = splu(body.stiffness.tocsc())
    for column in (0, 77, 149):
        unit = np.zeros(body.size)
        unit[columns[column]] = 1.0
        exact = superlu.solve(unit)
        assert np.max(np.abs(forked[0][:, column] - exact[columns])) <= 1e-8 * np.max(np.abs(exact[columns]))
        assert np.max(np.abs(forked[1][:, column] - exact[rigid])) <= 1e-8 * np.max(np.abs(exact[rigid]))


def test_a_piece_that_fails_in_a_worker_process_is_an_error_here():
    from softtip._core.forked import solve_in_processes

    def solve(piece: int) -> None:
        if piece == 3:
            raise ArithmeticError("piece 3 cannot be solved")

    done = []
    with pytest.raises(RuntimeError, match="worker process ended"):
        solve_in_processes(solve, range(6), done.append, processes=2)
    assert 3 not in done and set(done) <= {0, 1, 2, 4, 5}
