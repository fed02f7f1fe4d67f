"""Session-wide setup of the test suite: SIGINT restored, the shared real data located."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest

from tests.shared_data import shared_data_dir, shared_data_missing


def pytest_configure(config: pytest.Config) -> None:
    """Ctrl-C tests need SIGINT delivered: a shell that starts the suite in the background
    (``cmd &``, CI runners, ``nohup``) leaves SIGINT ignored, which the tests' processes would
    inherit (Python installs no KeyboardInterrupt handler for an ignored SIGINT, and
    ``_thread.interrupt_main`` does nothing). Restore Python's default handler; processes the
    tests start then get SIGINT's default disposition again."""
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The shared real data (``tests/shared_data.py`` finds it); skips, saying where it looked,
    when it is absent."""
    why = shared_data_missing()
    if why:
        pytest.skip(why)
    return shared_data_dir()
