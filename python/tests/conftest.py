"""Shared fixtures."""

import signal

import pytest


@pytest.fixture
def sigint_handled():
    """Python's own SIGINT handler for the test. A shell without job control starts background
    commands (`cmd &`, as a CI runner may) with SIGINT ignored, and `_thread.interrupt_main`
    then does nothing, so a test of Ctrl-C would see no interrupt at all."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)
