"""Uncertainty of the processed soundings.

Propagated TPU, cell uncertainty and IHO orders, and emcee depth posteriors with their waveform
model.

Like :mod:`pipeline.process`, everything here works on measured data and the
:class:`~pipeline.process.context.ProcessingContext` only; it never imports the seabed model or the
simulator (the truth-wall test checks it).
"""
