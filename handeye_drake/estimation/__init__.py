"""Estimation core: pure numpy/scipy, no Drake import needed."""
