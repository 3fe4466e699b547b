"""The scene suite: random scenes over the conditions users fly, split once into two halves.

* :mod:`pipeline.suite.generate` draws a scene (a valid TOML scene file, scene keys only) from
  a seed, and splits seeds into the *tuning* and the *held-out* half.
* :mod:`pipeline.suite.run` runs scenes with ``bathy run`` and collects their evaluations.
* :mod:`pipeline.suite.strata` pools the runs' points into strata and computes the figures.
* :mod:`pipeline.suite.report` writes ``RESULTS_suite.md`` and ``suite.csv`` with the floors.

**The held-out half is never used for tuning**: no threshold, constant or model choice of the
pipeline may be set, fitted or chosen by looking at a held-out scene's results. Tune on seeds
:func:`~pipeline.suite.generate.half` calls ``"tuning"``; report both halves side by side.
"""
