"""Shared pieces of the test suite that are not fixtures: builders, scenes, fakes and waits.

`tests/` is on sys.path (tests/conftest.py is the rootdir conftest), so tests import these as
`from support.venue import write_venue`. Fixtures live in tests/conftest.py.
"""
