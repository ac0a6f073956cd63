"""Importers of measurement tables from other tools and datasets into a Campaign."""

from robocal_uncertainty.importers.tracker_csv import read_tracker_csv

__all__ = ["read_tracker_csv"]
