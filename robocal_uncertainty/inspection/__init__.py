"""Blade-section inspection: point clouds, section algorithms and their CMM Monte Carlo."""
