"""Every contact solver's convergence record: a load step that does not converge within its
iteration cap raises, or is reported when asked; a converged solve says so with a small residual."""

from __future__ import annotations

import pickle

import pytest

from softtip.design.model import MM, load_design
from softtip._core.errors import NotConverged
from softtip.mechanics.contact import (ContactNotConverged, FootprintBody, LoadCase, SurfaceInfluence, SurfacePatch,
                                      solve_footprint_contact, solve_hyperelastic_contact, solve_influence_contact,
                                      solve_linear_contact)
from softtip.mechanics.fe import BodyModel
from softtip.mechanics.indenters import Board, Sphere
from softtip.mechanics.mesh import mesh_design


@pytest.fixture(scope="module")
def fingertip():
    design = load_design("cylindrical-A")
    body = BodyModel.for_design(design, mesh_design(design, 2.5 * MM))
    lowest = design.height - 2 * MM  # the surface these loads reach
    influence = SurfaceInfluence.build(body, lowest)
    return body, influence, FootprintBody(SurfacePatch(body, lowest), influence.compliance_of)


# A sphere pushed 1 mm: the first contact set, its geometric overlap with the body (radius
# sqrt(2 R d)), is wider than the contact Hertz predicts (sqrt(R d)), so an active-set iteration needs
# more than one pass. One load step each, so a reported cap of 1 counts one iteration.
SPHERE = Sphere(5e-3)
CASES = {
    "solve_linear_contact": (lambda tip, load, **o: solve_linear_contact(tip[0], load, **o), "none", 0.0),
    "solve_influence_contact": (lambda tip, load, **o: solve_influence_contact(tip[1], load, **o), "none", 0.0),
    "solve_footprint_contact": (lambda tip, load, **o: solve_footprint_contact(tip[2], load, **o), "none", 0.0),
    # Coulomb's law: semi-smooth Newton, converged below a 1e-9 relative update
    "solve_footprint_contact-coulomb": (lambda tip, load, **o: solve_footprint_contact(tip[2], load, **o),
                                        "coulomb", 1e-9),
    # sticking cells: the path followed through every change of the contact set, each one iteration
    "solve_footprint_contact-stick": (lambda tip, load, **o: solve_footprint_contact(tip[2], load, **o),
                                      "stick", 0.0),
    # Newton, converged below its tolerance (1e-7) of the first residual, or sqrt of it when stalled
    "solve_hyperelastic_contact": (lambda tip, load, **o: solve_hyperelastic_contact(tip[0], load, normal_steps=1,
                                                                                     **o), "none", 3.2e-4),
}


@pytest.mark.parametrize("case", list(CASES))
def test_a_solver_stopped_by_its_iteration_cap_raises_or_reports_it(fingertip, case):
    solve, friction, converged_residual = CASES[case]
    load = LoadCase(SPHERE, 1e-3, position=(1e-3, 0.0), friction=friction)
    with pytest.raises(ContactNotConverged) as raised:
        solve(fingertip, load, max_iterations=1)
    error = raised.value
    solver = case.split("-")[0]
    assert (error.solver, error.iterations, error.step, error.steps, error.load) == (solver, 1, 1, 1, load)
    assert error.residual > converged_residual
    message = str(error)
    assert solver in message and "load step 1 of 1" in message and "1 iteration(s)" in message
    assert f"{error.residual:.3g}" in message and repr(load) in message
    # it crosses process boundaries (the reduced twin solves in worker processes) intact
    copy = pickle.loads(pickle.dumps(error))
    assert str(copy) == message and copy.residual == error.residual

    reported = solve(fingertip, load, max_iterations=1, report_unconverged=True)
    assert not reported.converged
    assert reported.iterations == 1 and reported.residual == error.residual

    converged = solve(fingertip, load)
    assert converged.converged and converged.residual <= converged_residual
    assert converged.iterations > 1  # the cap of 1 cut an iteration that was needed
    assert converged.force[2] > 0


def test_non_convergence_is_a_softtip_arithmetic_error_and_a_cap_must_be_positive(fingertip):
    assert issubclass(ContactNotConverged, NotConverged) and issubclass(NotConverged, ArithmeticError)
    body, influence, _ = fingertip
    for solve in (lambda: solve_linear_contact(body, LoadCase(Board(), 1e-3), max_iterations=0),
                  lambda: solve_influence_contact(influence, LoadCase(Board(), 1e-3), max_iterations=0)):
        with pytest.raises(ValueError, match="max_iterations = 0"):
            solve()


def test_every_load_step_counts_towards_the_record(fingertip):
    body, influence, reduced = fingertip
    # a push and a drag: 2 normal and 4 tangential steps, each at least one iteration
    load = LoadCase(Board(1.6e-3, 0.3), 1e-3, tangential=(0.5e-3, 0.2e-3), friction="stick")
    for result in (solve_linear_contact(body, load), solve_influence_contact(influence, load),
                   solve_footprint_contact(reduced, load)):
        assert result.converged and result.residual == 0.0 and result.iterations >= 6
    reported = solve_influence_contact(influence, LoadCase(SPHERE, 1e-3, tangential=(0.5e-3, 0.0)), max_iterations=1,
                                       report_unconverged=True)
    assert not reported.converged and reported.iterations == 5  # 1 normal, 4 tangential steps
    assert len(reported.path) == 5
