"""Bus tests use the shared bus fixtures of tests/conftest.py."""

from tests.conftest import free_port

__all__ = ["free_port"]
