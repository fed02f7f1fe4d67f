"""Session-wide setup of the test suite: SIGINT restored, the shared real data located, and the
placement of tests on pytest-xdist's workers (``make test`` runs ``-n auto --dist loadgroup``).

Parallel runs: every live server, redis-server and browser the tests start binds a free port of
its own (and takes another if a parallel test took it first), every file goes to a pytest
temporary directory, so any two tests may run at once. Session fixtures are per worker (each
worker starts its own live servers and browser when its first test needs one); tests that must
share one worker can say so with ``@pytest.mark.xdist_group(name)``. Tests marked ``serial``
(they load the whole machine, e.g. a flood of 20,000 connections) run in a second, serial pass
after the parallel one.
"""

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
