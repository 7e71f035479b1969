"""Figures (matplotlib, Agg): relation errors, map comparisons, the run report's figures."""
