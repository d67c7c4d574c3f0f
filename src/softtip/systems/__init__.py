"""The systems built on softtip's toolkit, one package each, registered through the ``softtip.systems``
entry points (:mod:`softtip._core.systems`). Systems import the toolkit, never each other."""
