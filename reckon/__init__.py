"""The reckon application: the one CLI, importers, the Zenoh adapter (bus, replay, record), offline evaluation."""
