"""Session-wide setup of the test suite."""

from __future__ import annotations

import signal

import pytest


def pytest_configure(config: pytest.Config) -> None:
    """Ctrl-C tests need SIGINT delivered: a shell that starts the suite in the background
    (``cmd &``, CI runners, ``nohup``) leaves SIGINT ignored, which the tests' processes would
    inherit (Python installs no KeyboardInterrupt handler for an ignored SIGINT, and
    ``_thread.interrupt_main`` does nothing). Restore Python's default handler; processes the
    tests start then get SIGINT's default disposition again."""
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
