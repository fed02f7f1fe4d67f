"""One client shape: sync and async results expose the same attributes (issue 25.6)."""

from __future__ import annotations

import inspect

from geosmooth_client.result import AsyncResult, Result


def _public(cls: type) -> dict[str, object]:
    return {n: inspect.getattr_static(cls, n) for n in dir(cls) if not n.startswith("_")}


def test_same_members_same_kinds() -> None:
    sync, async_ = _public(Result), _public(AsyncResult)
    assert set(sync) == set(async_) - {"create"}
    for name, member in sync.items():
        other = async_[name]
        if isinstance(member, property):  # attributes stay attributes (report, id)
            assert isinstance(other, property), name
        else:  # methods that talk to the service are awaited in the async client
            assert inspect.iscoroutinefunction(other), name
            assert not inspect.iscoroutinefunction(member), name
    assert isinstance(async_["report"], property)
