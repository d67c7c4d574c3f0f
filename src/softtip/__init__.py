"""softtip: a toolkit for soft magnetic tactile fingertips.

The flow of the package follows the sensing chain: ``design`` (geometry and
materials) -> ``mechanics`` (mesh, finite elements, contact) -> ``magnetics``
(exact field of the displaced magnets) -> ``sensors`` (the chips' models, registered by name).
``twin`` composes them into the physics twin of a fingertip.
"""

__version__ = "0.1.0"
