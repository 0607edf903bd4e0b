"""Importers: vendor logs and plain CSV folders -> one session MCAP (`reckon import csv|ngimu`)."""

from reckon.importers.csv_folder import import_csv_folder
from reckon.importers.ngimu import import_ngimu_folder
from reckon.importers.report import ImportReport

__all__ = ["ImportReport", "import_csv_folder", "import_ngimu_folder"]
