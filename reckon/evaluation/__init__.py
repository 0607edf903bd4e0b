"""Offline evaluation (`reckon eval`): run estimators over a session log and score them against truth."""
