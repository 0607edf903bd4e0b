"""The reckon application: one CLI, evaluation, importers."""
