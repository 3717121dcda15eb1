"""Synthetic campaigns with concealed effects, to prove the discrepancy tool (kept apart from the
analysis code: it integrates its own ground truth)."""
