"""The package's lazy exports resolve to the right objects in any import order."""

from __future__ import annotations

import subprocess
import sys

import pytest

ORDERS = [
    "import service.core.pipeline\nfrom service.core import smooth",
    "from service.core import *",
    "from service.core import smooth",
    "import service.jobs.runner\nfrom service.core import smooth",
]


@pytest.mark.parametrize("code", ORDERS)
def test_smooth_is_the_function(code: str) -> None:
    check = code + "\nimport inspect\nassert inspect.isfunction(smooth), smooth\n"
    done = subprocess.run(
        [sys.executable, "-c", check], capture_output=True, text=True, check=False
    )
    assert done.returncode == 0, done.stderr


def test_params_import_does_not_load_the_solver() -> None:
    code = (
        "import sys\nimport service.core.params\n"
        "assert 'scipy.sparse' not in sys.modules\n"
        "assert 'service.core.linalg.solver' not in sys.modules"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
