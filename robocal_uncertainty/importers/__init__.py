"""Importers of measurement tables from other tools and datasets into a Campaign."""

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

if TYPE_CHECKING:
    from robocal_uncertainty.importers.tracker_csv import read_tracker_csv

__all__ = ["read_tracker_csv"]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
