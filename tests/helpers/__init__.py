"""Builders and tools the tests share (imported as ``helpers.<module>``: tests/ is on sys.path
through tests/conftest.py)."""
