"""Sim-vs-real discrepancy tool: locate the mismatch, name the missing physics, model it."""
