"""Contact of a fingertip with rigid indenters: every solver in one place, behind one interface.

Each solver takes the body, or a reduced view of it, and a :class:`LoadCase`
(+ keyword options) and returns a result that carries its :class:`Convergence`
record (``converged``, ``iterations``, ``residual``):

* :func:`solve_linear_contact` - small strain on the finite-element body,
  penalty, nodes held (:mod:`.nodal`);
* :func:`solve_hyperelastic_contact` - neo-Hookean, large deformation, on the
  finite-element body (:mod:`.nodal`);
* :func:`solve_influence_contact` - exact small-strain contact on the
  influence matrices of the surface, nodes held (:mod:`.influence`);
* :func:`solve_footprint_contact` - exact small-strain contact on cells of the
  indenter's footprint, with Coulomb friction too (:mod:`.footprint`).

The first two return the whole displacement field (:class:`ContactResult`),
the last two the magnets' rigid motion (:class:`ReducedContactResult`). A load
step that does not converge within its iteration cap raises
:class:`ContactNotConverged`, unless the caller passes
``report_unconverged=True``: then the result says ``converged=False``.
"""

from softtip.mechanics.contact.footprint import (CELL_SIZE, FootprintBody, SurfacePatch, solve_footprint_contact,
                                                 stiffness_compliance)
from softtip.mechanics.contact.influence import SurfaceInfluence, solve_influence_contact
from softtip.mechanics.contact.load import FRICTION_MODES, LoadCase
from softtip.mechanics.contact.nodal import solve_hyperelastic_contact, solve_linear_contact
from softtip.mechanics.contact.result import ContactNotConverged, ContactResult, Convergence, ReducedContactResult

__all__ = [
    "CELL_SIZE", "FRICTION_MODES", "ContactNotConverged", "ContactResult", "Convergence",
    "FootprintBody", "LoadCase", "ReducedContactResult", "SurfaceInfluence", "SurfacePatch", "solve_footprint_contact",
    "solve_hyperelastic_contact", "solve_influence_contact", "solve_linear_contact", "stiffness_compliance",
]
