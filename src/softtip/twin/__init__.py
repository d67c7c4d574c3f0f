"""The physics twin: design -> mechanics -> magnetics -> sensor, composed once.

:class:`Twin` is an engine (how the body answers loads: full finite elements, exact contact on
influence matrices, or the reduced-order networks) followed by a :class:`Readout` (the magnets'
exact field at the Hall sensors, read through the model of the design's registered chip).
"""

from softtip.twin.engines import DEFAULT_MESH_SIZE, MODELS, Engine, FiniteElementEngine, Response
from softtip.twin.readout import Readout
from softtip.twin.twin import Twin, TwinResult

__all__ = ["DEFAULT_MESH_SIZE", "MODELS", "Engine", "FiniteElementEngine", "Readout", "Response", "Twin",
           "TwinResult"]
