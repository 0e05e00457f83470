"""Diagnostic plots (matplotlib, imported only inside the plotting functions)."""
