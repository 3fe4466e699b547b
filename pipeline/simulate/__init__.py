"""Simulation stages: survey geometry (:mod:`.survey`) and the physics built on its pulses."""
