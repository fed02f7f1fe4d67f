"""A checkout named ``geosmooth`` does not shadow the installed package (issue 32 item 7).

``git clone … geosmooth`` then ``pip install -e geosmooth`` and a script beside the checkout:
the script's directory is first on ``sys.path``, and the checkout there is a directory named
``geosmooth`` without ``__init__.py``, i.e. a namespace-package portion. An editable install
made of an import hook (setuptools' ``__editable___*_finder``, appended to ``sys.meta_path``
behind the path finder) loses to it: ``import geosmooth`` gave the empty namespace package and
``geosmooth.read`` an ``AttributeError``. With ``package-dir = {"" = "."}`` (pyproject.toml) the
editable install is a plain path entry, the checkout's root, and the path finder prefers the
regular package it finds there to any namespace portion met earlier.

The test does exactly that, for real: it copies the project into ``tmp/geosmooth``, installs
it editable with pip into a throwaway prefix (no dependencies: seconds, plus pip's build of
the editable wheel in an isolated environment, which needs setuptools >= 77 from the package
index or pip's cache; skipped when pip cannot build it), then runs a script in ``tmp`` with the
prefix's site directory (its ``.pth`` processed by :func:`site.addsitedir`) and this
environment's packages behind it (not processed, so this environment's own editable install of
the repository plays no part).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

SCRIPT = "import geosmooth\nprint(geosmooth.__file__)\nprint(geosmooth.read.__name__)\n"


def _site_packages(prefix: Path) -> Path:
    purelib = sysconfig.get_path("purelib", vars={"base": str(prefix), "platbase": str(prefix)})
    return Path(purelib)


@pytest.mark.slow
def test_a_checkout_named_geosmooth_beside_a_script_does_not_shadow_the_package(
    tmp_path: Path,
) -> None:
    checkout = tmp_path / "geosmooth"
    checkout.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(REPO / name, checkout / name)
    for name in ("geosmooth", "service"):
        shutil.copytree(REPO / name, checkout / name,
                        ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))  # fmt: skip
    prefix = tmp_path / "prefix"
    install = subprocess.run(
        # --ignore-installed: pip would otherwise uninstall the project from this venv first
        [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-input",
         "--disable-pip-version-check", "--ignore-installed", "-e", str(checkout),
         "--prefix", str(prefix)],
        capture_output=True, text=True, timeout=240, check=False,
    )  # fmt: skip
    if install.returncode != 0:
        pytest.skip(f"pip could not build the editable install: {install.stderr[-400:]}")
    (tmp_path / "script.py").write_text(SCRIPT)
    ours = sysconfig.get_path("purelib")
    driver = (
        "import runpy, site, sys\n"
        f"site.addsitedir({str(_site_packages(prefix))!r})\n"
        f"sys.path.append({ours!r})\n"
        "runpy.run_path('script.py', run_name='__main__')\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONSTARTUP")}
    run = subprocess.run([sys.executable, "-S", "-c", driver], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=120, check=False)  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert run.stdout.splitlines() == [str(checkout / "geosmooth" / "__init__.py"), "read"]
    pth = [p.read_text().strip() for p in _site_packages(prefix).glob("__editable__*.pth")]
    assert pth == [str(checkout)], f"the editable install is not the checkout's path: {pth}"
