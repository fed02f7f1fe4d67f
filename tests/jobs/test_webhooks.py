"""Webhooks: signed deliveries to a real loopback receiver, retries, the SSRF guard."""

from __future__ import annotations

import ipaddress
import json
import time
from collections.abc import Callable

import pytest

from service.jobs import LocalQueue
from service.jobs.errors import WebhookUrlRejected
from service.jobs.queue import NewJob
from service.jobs.webhooks import (
    SIGNATURE_HEADER,
    check_webhook_url,
    deliver,
    embedded_ipv4,
    sign,
)
from service.settings import Settings
from tests.jobs.jobs_fakes import script
from tests.jobs.jobs_helpers import PARAMS, wait_finished, wait_for
from tests.jobs.jobs_receiver import HostileReceiver, Receiver, documented_verifier

MakeQueue = Callable[..., LocalQueue]
SECRET = "whsec-test-4f1c"


def _settings(**kw: object) -> Settings:
    values: dict[str, object] = {"webhook_secret": SECRET, "webhook_allow_private": True,
                                 "webhook_backoff": 0.05, "webhook_timeout": 5.0}  # fmt: skip
    values.update(kw)
    return Settings(**values)  # type: ignore[arg-type]


def test_finished_jobs_are_posted_signed_and_retried(make_queue: MakeQueue) -> None:
    verify = documented_verifier()
    with Receiver([500, 503, 200]) as hook:
        queue = make_queue(settings=_settings())
        rec = queue.submit(NewJob.check(script("ok"), "json", PARAMS, webhook_url=hook.url()))
        done = wait_finished(queue, rec.id)
        wait_for(lambda: len(hook.deliveries) == 3, timeout=10)  # 500, 503, then 200
        time.sleep(0.3)
        assert len(hook.deliveries) == 3  # delivered: no further tries
    bodies = {d.body for d in hook.deliveries}
    assert len(bodies) == 1  # the same payload each time
    last = hook.deliveries[-1]
    header = last.headers[SIGNATURE_HEADER]
    assert verify(SECRET, last.body, header)
    assert not verify("another secret", last.body, header)
    assert not verify(SECRET, last.body.replace(b"succeeded", b"failed"), header)
    stale = sign(SECRET, last.body, timestamp=int(time.time()) - 3600)
    assert not verify(SECRET, last.body, stale)  # replayed an hour later
    payload = json.loads(last.body)
    assert payload == done.public_dict()  # exactly GET /v1/jobs/{id}
    assert payload["status"] == "succeeded" and payload["report"]["iterations"] == 5
    rows = queue.store._conn().execute("SELECT webhook_state FROM jobs WHERE id = ?", (rec.id,))
    assert rows.fetchone()[0] == "delivered"


def test_cancelled_and_failed_jobs_are_posted_too(make_queue: MakeQueue) -> None:
    with Receiver() as hook:
        queue = make_queue(settings=_settings())
        failing = queue.submit(
            NewJob.check(script("core_error"), "json", PARAMS, webhook_url=hook.url("/f"))
        )
        waiting = queue.submit(NewJob.check(script("sleep", seconds=30), "json", PARAMS,
                               webhook_url=hook.url("/c")))  # fmt: skip
        wait_finished(queue, failing.id)
        queue.cancel(waiting.id)
        wait_for(lambda: len(hook.deliveries) == 2, timeout=10)
    got = {d.path: json.loads(d.body) for d in hook.deliveries}
    assert got["/f"]["status"] == "failed" and got["/f"]["error"]["code"] == "tau-out-of-range"
    assert got["/c"]["status"] == "cancelled"


def test_an_undelivered_webhook_is_redelivered_after_a_restart(make_queue: MakeQueue) -> None:
    with Receiver() as hook:
        queue = make_queue(start=False, settings=_settings())
        rec = queue.submit(NewJob.check(script("ok"), "json", PARAMS, webhook_url=hook.url()))
        # the job finished but its deliverer died before delivering (state never written)
        queue.store._conn().execute(
            "UPDATE jobs SET status = 'succeeded', finished_at = ? WHERE id = ?",
            (time.time(), rec.id),
        )
        queue.start()  # the start's sweep finds it
        wait_for(lambda: len(hook.deliveries) == 1, timeout=10)
    assert json.loads(hook.deliveries[0].body)["id"] == rec.id


@pytest.mark.parametrize(
    "url",
    [
        "http://127.0.0.1:9/x", "http://localhost/x", "http://10.1.2.3/x", "http://192.168.0.1/",
        "http://169.254.169.254/latest/meta-data", "http://[::1]/x", "http://0.0.0.0/",
        "http://100.64.0.1/", "ftp://example.org/x", "http://user:pw@93.184.216.34/",
        "http:///nohost", "http://93.184.216.34:99999/",
    ],
)  # fmt: skip
def test_the_ssrf_guard_refuses_non_public_targets(url: str) -> None:
    with pytest.raises(WebhookUrlRejected) as err:
        check_webhook_url(url, _settings(webhook_allow_private=False))
    assert err.value.status == 422 and err.value.field == "webhook_url"


#: IPv6 forms that carry a non-public IPv4 address (the packet would end up at the IPv4 one).
EMBEDDED = {
    "http://[2002:7f00:1::]/": "127.0.0.1",  # 6to4
    "http://[2002:a9fe:a9fe::1]/": "169.254.169.254",  # 6to4, cloud metadata
    "http://[64:ff9b::7f00:1]/": "127.0.0.1",  # NAT64 well-known prefix
    "http://[64:ff9b:1::a00:1]/": "10.0.0.1",  # NAT64 local-use prefix
    "http://[::ffff:127.0.0.1]/": "127.0.0.1",  # IPv4-mapped
    "http://[::ffff:0:c0a8:1]/": "192.168.0.1",  # IPv4-translated
    "http://[::127.0.0.1]/": "127.0.0.1",  # IPv4-compatible
    # Teredo: server 65.54.227.120, client 127.0.0.1 (obfuscated: XOR ffffffff)
    "http://[2001:0:4136:e378:8000:63bf:80ff:fffe]/": "127.0.0.1",
}


@pytest.mark.parametrize("url", sorted(EMBEDDED))
def test_the_ssrf_guard_checks_the_ipv4_inside_ipv6(url: str) -> None:
    with pytest.raises(WebhookUrlRejected) as err:
        check_webhook_url(url, _settings(webhook_allow_private=False))
    assert err.value.status == 422 and err.value.field == "webhook_url"
    host = ipaddress.ip_address(url.split("[", 1)[1].split("]", 1)[0])
    assert ipaddress.ip_address(EMBEDDED[url]) in embedded_ipv4(host)


def test_an_ipv6_form_of_a_public_ipv4_address_passes() -> None:
    """6to4 of 93.184.216.34 is as public as the address itself (no over-blocking)."""
    target = check_webhook_url(
        "http://[2002:5db8:d822::1]/h", _settings(webhook_allow_private=False)
    )
    assert target.address == "2002:5db8:d822::1"
    assert embedded_ipv4(ipaddress.ip_address(target.address)) == [
        ipaddress.IPv4Address("93.184.216.34")
    ]


def test_public_targets_pass_and_private_ones_when_allowed() -> None:
    target = check_webhook_url("https://93.184.216.34/hook", _settings(webhook_allow_private=False))
    assert target.address == "93.184.216.34" and target.port == 443
    assert check_webhook_url("http://127.0.0.1:8080/h", _settings()).port == 8080


def test_delivery_rechecks_the_target_and_sends_nothing_to_a_refused_one() -> None:
    with Receiver() as hook:
        ok, tries = deliver(hook.url(), {"id": "x"}, _settings(webhook_allow_private=False))
    assert (ok, tries) == (False, 1) and hook.deliveries == []


@pytest.mark.parametrize("mode", ["endless", "huge", "trickle", "silent"])
def test_a_hostile_answer_is_a_failed_try_with_bounded_memory(mode: str) -> None:
    """A receiver answering with an endless or 1 GiB body, a byte at a time, or not at all: the
    try fails (not "delivered"), the client hangs up on it (the receiver sees the connection
    cut before it ran out of answer), and the deliverer holds at most a few hundred KB."""
    import tracemalloc

    settings = _settings(webhook_timeout=1.0, webhook_max_attempts=1)
    with HostileReceiver(mode) as hook:
        tracemalloc.start()
        try:
            delivered, tries = deliver(hook.url(), {"id": "j"}, settings)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert hook.done.wait(60)
    assert (delivered, tries) == (False, 1)
    assert hook.cut.is_set()  # the client hung up: the answer was not waited out
    assert hook.sent < hook.limit
    assert peak < 1 << 20  # bytes, all Python allocations of the delivery
