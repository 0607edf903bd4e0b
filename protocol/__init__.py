"""Schemas, Zenoh keys, session descriptions and session logs: the only home of wire formats."""
