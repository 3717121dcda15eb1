"""Analysis on top of the core: model curves, plots, evaluation, discrepancy reports."""
