"""Helpers the test modules share. A test module imports from here, never from another test
module (tests/core/test_layout.py checks it)."""
