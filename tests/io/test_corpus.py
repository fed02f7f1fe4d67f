"""The fuzz corpus (tests/corpus): every malformed file gives its one-line error, nothing else."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from service.core.errors import GeosmoothError
from service.io import FormatError, read_geometry

CORPUS = Path(__file__).resolve().parents[1] / "corpus"
CASES = json.loads((CORPUS / "manifest.json").read_text())


def test_corpus_covers_every_format() -> None:
    from service.io import FORMATS

    seen = {c["file"].rsplit(".", 1)[1] for c in CASES}
    assert set(FORMATS) <= seen | {"laz"} and "laz" in seen


@pytest.mark.parametrize("case", CASES, ids=[c["file"] for c in CASES])
def test_corpus_file(case: dict[str, str]) -> None:
    path = CORPUS / "files" / case["file"]
    with pytest.raises((FormatError, GeosmoothError)) as info:
        read_geometry(path)
    err = info.value
    assert err.code == case["code"], err.message
    assert re.search(case["match"], err.message), err.message
    assert "\n" not in err.message and len(err.message) < 400
    assert str(CORPUS) not in err.message  # no server paths in messages
    assert err.to_dict()["code"] == case["code"]


@pytest.mark.parametrize("case", CASES, ids=[c["file"] for c in CASES])
def test_corpus_bytes_without_name(case: dict[str, str]) -> None:
    """The same files as uploads without a name: an error, never a crash (format may differ)."""
    data = (CORPUS / "files" / case["file"]).read_bytes()
    try:
        read_geometry(data)  # "OFFF\n3 1 0\n" without a name is a valid XYZ of one point
    except (FormatError, GeosmoothError) as exc:
        assert "\n" not in exc.message
