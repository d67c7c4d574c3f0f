"""What every stage of softtip shares, each concept in one module.

- :mod:`~softtip._core.config`: the TOML reader and declarative schemas with one-line errors;
- :mod:`~softtip._core.files`: replacing a file atomically;
- :mod:`~softtip._core.progress`: reporting the progress of long jobs;
- :mod:`~softtip._core.units`: unit constants (SI internally);
- :mod:`~softtip._core.channels`: the names of the sensor channels;
- :mod:`~softtip._core.network`: the run-time of the tanh networks (calibration models, reduced twin);
- :mod:`~softtip._core.signals`: signal metrics shared by the physics and the calibration metrics;
- :mod:`~softtip._core.errors`: errors of computations that did not converge;
- :mod:`~softtip._core.cache`: the on-disk cache, keys tied to the code that made an entry, and entries
  verified on every read (a damaged or misplaced one is a miss);
- :mod:`~softtip._core.threads`: a named daemon thread that runs until it is asked to stop.
"""
