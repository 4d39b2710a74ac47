"""Webhooks reach public addresses only, are not redirected, and every delivery is signed.

The receivers are real HTTP servers on 127.0.0.1, which the service may post to only when
``webhook_allow`` names it; runs select no recordings, so a run is its (empty) report and
the webhook. Jobs run inside the requests (``queue_url="immediate"``).
"""

from __future__ import annotations

import hashlib
import hmac
import shutil
import socket
import ssl
import subprocess
import threading
from collections.abc import Callable, Iterator
from http.server import BaseHTTPRequestHandler, HTTPServer
from pathlib import Path
from typing import Any

import pytest
import sqlalchemy as sa
from alembic import command
from alembic.config import Config
from fastapi.testclient import TestClient
from pydantic import ValidationError

from service import db, webhooks
from service.auth import create_key
from service.db import create_db_engine, migrate
from service.main import create_app
from service.settings import Settings
from service.webhooks import SIGNATURE_HEADER, TIMESTAMP_HEADER, verify_signature

BAD_URLS = [
    "http://169.254.169.254/latest/meta-data/",
    "http://localhost/hook",
    "http://[::1]/hook",
    "http://0.0.0.0/hook",
    "http://2130706433/hook",
    "http://10.0.0.1/hook",
    "http://0x7f.1/hook",
    "http://017700000001/hook",
    "http://[::ffff:127.0.0.1]/hook",
    "http://[::ffff:169.254.169.254]/hook",
    "http://[fe80::1]/hook",
    "http://224.0.0.1/hook",
    "http://192.168.1.10:8080/hook",
    "https://172.16.0.1/hook",
    "http://100.64.0.1/hook",
]
"""Internal targets, spelled in ways a resolver accepts: every one must be refused."""


def _schedule_body(**overrides: Any) -> dict[str, Any]:
    body: dict[str, Any] = {
        "name": "Nightly",
        "cron": "0 3 * * *",
        "selection": {"tags": ["none"]},
        "template": {"reference": {"selector": "/gt"}, "estimates": [{"selector": "/est"}]},
        # the HTML summary only: a webhook test needs no PDF (nor pango to lay one out)
        "produce": {"summary_formats": ["summary.html"]},
    }
    body.update(overrides)
    return body


@pytest.fixture
def make_client(tmp_path: Path) -> Iterator[Callable[[str], TestClient]]:
    """Open clients of fresh services with a given ``webhook_allow``; closed after the test."""
    opened: list[TestClient] = []

    def make(allow: str = "") -> TestClient:
        settings = Settings(
            data_dir=tmp_path / f"data{len(opened)}", queue_url="immediate", webhook_allow=allow
        )
        app = create_app(settings)
        with app.state.runtime.sessions() as session:
            key = create_key(session, "site")
        client = TestClient(app, headers={"Authorization": f"Bearer {key}"})
        client.__enter__()
        opened.append(client)
        return client

    yield make
    for client in opened:
        client.__exit__(None, None, None)


class Receiver:
    """A local HTTP server that keeps each request's headers and raw body."""

    def __init__(self, status: int = 204, location: str | None = None) -> None:
        self.requests: list[tuple[dict[str, str], bytes]] = []
        receiver = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                body = self.rfile.read(int(self.headers["Content-Length"]))
                receiver.requests.append((dict(self.headers.items()), body))
                self.send_response(status)
                if location is not None:
                    self.send_header("Location", location)
                self.send_header("Content-Length", "0")
                self.end_headers()

            def log_message(self, *_args: object) -> None:
                return

        self.server = HTTPServer(("127.0.0.1", 0), Handler)
        self.port = self.server.server_port
        self.url = f"http://127.0.0.1:{self.port}/hook"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture
def receiver() -> Iterator[Receiver]:
    hook = Receiver()
    yield hook
    hook.close()


def _run(client: TestClient, schedule_id: str) -> dict[str, Any]:
    """Trigger a run (it finishes inside the request) and return it as recorded."""
    run = client.post(f"/api/v1/schedules/{schedule_id}/run").json()
    assert run["status"] == "succeeded", run
    recorded: dict[str, Any] = client.get(
        f"/api/v1/schedules/{schedule_id}/runs/{run['id']}"
    ).json()
    return recorded


def _assert_refused(response: Any) -> None:
    assert response.status_code == 422, response.text
    assert response.headers["content-type"].startswith("application/problem+json")
    problem = response.json()
    assert problem["detail"].startswith("webhook_url: ")
    assert "LOCEVAL_WEBHOOK_ALLOW" in problem["detail"] or "password" in problem["detail"]


# --- refused targets ---------------------------------------------------------------------


@pytest.mark.parametrize("url", [*BAD_URLS, "http://user:secret@example.com/hook"])
def test_internal_targets_are_refused_at_create(make_client, url: str):
    """Loopback, link-local (metadata), private, multicast... as any spelling: 422, nothing kept."""
    client = make_client()
    _assert_refused(client.post("/api/v1/schedules", json=_schedule_body(webhook_url=url)))
    assert client.get("/api/v1/schedules").json()["count"] == 0


def test_internal_targets_are_refused_at_patch(make_client):
    """PATCH checks a new webhook URL as create does and keeps the old one on refusal."""
    client = make_client()
    schedule = client.post("/api/v1/schedules", json=_schedule_body()).json()
    path = f"/api/v1/schedules/{schedule['id']}"
    for url in BAD_URLS:
        _assert_refused(client.patch(path, json={"webhook_url": url}))
    assert client.get(path).json()["webhook_url"] is None
    assert client.patch(path, json={"paused": True}).status_code == 200  # others still change


def test_the_metadata_address_is_named_in_the_problem(make_client):
    """The problem says what kind of address it is and what to do."""
    response = make_client().post(
        "/api/v1/schedules", json=_schedule_body(webhook_url="http://169.254.169.254/")
    )
    detail = response.json()["detail"]
    assert "link-local" in detail
    assert "cloud metadata" in detail
    assert "use a public address" in detail


def test_the_allow_list_lets_named_internal_targets_through(make_client, receiver):
    """Addresses, networks and names in webhook_allow are accepted; others stay refused."""
    by_address = make_client("127.0.0.1")
    created = by_address.post("/api/v1/schedules", json=_schedule_body(webhook_url=receiver.url))
    assert created.status_code == 201, created.text
    _assert_refused(
        by_address.post("/api/v1/schedules", json=_schedule_body(webhook_url="http://10.0.0.1/"))
    )
    by_network = make_client("10.0.0.0/8, 127.0.0.0/8")
    for url in ("http://10.0.0.1/hook", "http://2130706433/hook", receiver.url):
        response = by_network.post("/api/v1/schedules", json=_schedule_body(webhook_url=url))
        assert response.status_code == 201, response.text
    by_name = make_client("localhost")
    url = f"http://localhost:{receiver.port}/hook"
    assert by_name.post("/api/v1/schedules", json=_schedule_body(webhook_url=url)).is_success


def test_localhost_names_are_loopback_whatever_dns_says(
    make_client: Callable[[str], TestClient], monkeypatch: pytest.MonkeyPatch
) -> None:
    """RFC 6761: localhost and names under it are loopback, even where no hosts file says so."""

    def no_resolver(host: str, _port: int) -> list[str]:
        raise socket.gaierror(socket.EAI_NONAME, host)

    monkeypatch.setattr(webhooks, "resolve_addresses", no_resolver)
    client = make_client("")
    for url in ("http://localhost/hook", "http://LOCALHOST./hook", "http://api.localhost/h"):
        problem = client.post("/api/v1/schedules", json=_schedule_body(webhook_url=url)).json()
        assert problem["status"] == 422, problem
        assert "loopback" in problem["detail"], problem
    allowed = make_client("localhost")
    url = "http://localhost:8080/hook"
    assert allowed.post("/api/v1/schedules", json=_schedule_body(webhook_url=url)).is_success


@pytest.mark.parametrize(
    ("url", "match"),
    [
        ("ftp://example.com/hook", "scheme 'ftp'"),
        ("https://example.com/a\x01b", "control characters"),
        ("https://example.com@10.0.0.1/hook", "user name or password"),
        ("https://[::1/hook", "not a valid URL"),
    ],
)
def test_the_form_of_a_url_is_checked_before_any_lookup(url: str, match: str):
    """Scheme, control characters, credentials and syntax are refused without resolving."""
    with pytest.raises(webhooks.WebhookRefusedError, match=match):
        webhooks.check_webhook_url(url, webhooks.AllowList(), addresses=["93.184.216.34"])


def test_a_public_target_keeps_its_path_and_query_encoded():
    """A public address passes; non-ASCII in the path and query is percent-encoded."""
    target = webhooks.check_webhook_url(
        "https://Hooks.Example.com./häk?team=ü", webhooks.AllowList(), addresses=["93.184.216.34"]
    )
    assert (target.host, target.port, target.https) == ("hooks.example.com", 443, True)
    assert target.target == "/h%C3%A4k?team=%C3%BC"
    assert target.addresses == ("93.184.216.34",)


def test_a_bad_allow_list_entry_stops_the_settings():
    """An entry that is neither a name nor an address or network is named at start."""
    with pytest.raises(ValidationError, match=r"LOCEVAL_WEBHOOK_ALLOW: 'not a host'"):
        Settings(webhook_allow="127.0.0.1, not a host")


# --- signed deliveries -------------------------------------------------------------------


def test_a_delivery_is_signed_with_the_secret_shown_once(make_client, receiver):
    """The create answer's secret verifies the delivery's HMAC; GET and lists never show it."""
    client = make_client("127.0.0.1")
    created = client.post("/api/v1/schedules", json=_schedule_body(webhook_url=receiver.url))
    assert created.status_code == 201
    secret = created.json()["webhook_secret"]
    assert len(secret) >= 40
    schedule_id = created.json()["id"]
    assert "webhook_secret" not in client.get(f"/api/v1/schedules/{schedule_id}").json()
    assert "webhook_secret" not in client.get("/api/v1/schedules").json()["items"][0]
    assert secret not in client.get(f"/api/v1/schedules/{schedule_id}").text

    recorded = _run(client, schedule_id)
    assert recorded["webhook"]["delivered"] is True
    ((headers, body),) = receiver.requests
    stamp = headers[TIMESTAMP_HEADER]
    expected = hmac.new(secret.encode(), stamp.encode() + b"." + body, hashlib.sha256)
    assert headers[SIGNATURE_HEADER] == f"sha256={expected.hexdigest()}"
    assert headers["Host"] == f"127.0.0.1:{receiver.port}"
    assert verify_signature(secret, headers, body)
    assert not verify_signature(secret, headers, body + b" ")  # the exact bytes are signed
    assert not verify_signature("another secret", headers, body)
    assert not verify_signature(secret, headers, body, now=int(stamp) + 3600)  # a replay
    assert secret not in body.decode()


def test_rotating_the_secret_shows_a_new_one_and_signs_with_it(make_client, receiver):
    """POST .../secret answers a new secret once; deliveries no longer verify with the old."""
    client = make_client("127.0.0.1")
    created = client.post("/api/v1/schedules", json=_schedule_body(webhook_url=receiver.url))
    old = created.json()["webhook_secret"]
    rotated = client.post(f"/api/v1/schedules/{created.json()['id']}/secret")
    assert rotated.status_code == 200
    new = rotated.json()["webhook_secret"]
    assert new != old
    _run(client, created.json()["id"])
    ((headers, body),) = receiver.requests
    assert verify_signature(new, headers, body)
    assert not verify_signature(old, headers, body)
    other = make_client("127.0.0.1")
    assert other.post(f"/api/v1/schedules/{created.json()['id']}/secret").status_code == 404


# --- at delivery -------------------------------------------------------------------------


def test_a_redirect_is_not_followed(make_client, receiver):
    """A 3xx answer is one failed attempt naming the status; its target gets nothing."""
    redirecting = Receiver(status=302, location=receiver.url)
    try:
        client = make_client("127.0.0.1")
        body = _schedule_body(webhook_url=redirecting.url)
        schedule = client.post("/api/v1/schedules", json=body).json()
        recorded = _run(client, schedule["id"])
    finally:
        redirecting.close()
    assert len(redirecting.requests) == 1  # not retried: the answer would be the same
    assert receiver.requests == []
    record = recorded["webhook"]
    assert record["delivered"] is False
    (attempt,) = record["attempts"]
    assert attempt["status"] == 302
    assert "302" in attempt["error"]
    assert "not followed" in attempt["error"]


def test_a_name_that_turns_internal_is_refused_at_delivery(make_client, receiver, monkeypatch):
    """Public at create, loopback at delivery (DNS rebinding): refused, recorded, not retried."""
    answers = {"hooks.example.com": ["93.184.216.34"]}
    monkeypatch.setattr(webhooks, "resolve_addresses", lambda host, _port: answers[host])
    client = make_client()
    url = f"http://hooks.example.com:{receiver.port}/hook"
    created = client.post("/api/v1/schedules", json=_schedule_body(webhook_url=url))
    assert created.status_code == 201, created.text
    answers["hooks.example.com"] = ["93.184.216.34", "127.0.0.1"]  # any internal one is enough
    recorded = _run(client, created.json()["id"])
    assert receiver.requests == []
    record = recorded["webhook"]
    assert record["delivered"] is False
    assert record["refused"] is True
    (attempt,) = record["attempts"]
    assert "loopback" in attempt["error"]
    assert "status" not in attempt


def test_a_delivery_connects_to_the_checked_address(make_client, receiver, monkeypatch):
    """The name is resolved once; the connection goes to that address with the name as Host."""
    lookups: list[str] = []

    def resolve(host: str, _port: int) -> list[str]:
        lookups.append(host)
        return ["127.0.0.1"]

    monkeypatch.setattr(webhooks, "resolve_addresses", resolve)
    client = make_client("hooks.example.com")
    url = f"http://hooks.example.com:{receiver.port}/hook"
    schedule = client.post("/api/v1/schedules", json=_schedule_body(webhook_url=url)).json()
    lookups.clear()
    recorded = _run(client, schedule["id"])
    assert recorded["webhook"]["delivered"] is True
    assert lookups == ["hooks.example.com"]  # one lookup per delivery, none by the connection
    ((headers, _body),) = receiver.requests
    assert headers["Host"] == f"hooks.example.com:{receiver.port}"


def test_a_name_that_stops_resolving_is_retried(make_client, monkeypatch):
    """A lookup failure at delivery may be temporary: tried three times, not marked refused."""
    monkeypatch.setattr(webhooks, "resolve_addresses", lambda _h, _p: ["93.184.216.34"])
    client = make_client()
    url = "https://hooks.example.com/hook"
    schedule = client.post("/api/v1/schedules", json=_schedule_body(webhook_url=url)).json()

    def fail(_host: str, _port: int) -> list[str]:
        msg = "Name or service not known"
        raise OSError(msg)

    monkeypatch.setattr(webhooks, "resolve_addresses", fail)
    record = _run(client, schedule["id"])["webhook"]
    assert record["delivered"] is False
    assert "refused" not in record
    assert len(record["attempts"]) == 3
    assert all("does not resolve" in a["error"] for a in record["attempts"])


# --- the migration -----------------------------------------------------------------------


def test_the_migration_gives_existing_schedules_their_own_secret(tmp_path: Path):
    """Schedules made before 0003 get distinct secrets; new rows cannot lack one."""
    engine = create_db_engine(f"sqlite:///{tmp_path / 'old.db'}")
    config = Config()
    config.set_main_option("script_location", str(Path(db.__file__).parent / "migrations"))
    with engine.begin() as connection:
        config.attributes["connection"] = connection
        command.upgrade(config, "0002")
        connection.execute(
            sa.text("INSERT INTO projects (id, name, created_at) VALUES ('p', 'site', :now)"),
            {"now": "2026-01-01 00:00:00.000000"},
        )
        for k in range(3):
            connection.execute(
                sa.text(
                    "INSERT INTO schedules (id, project_id, name, cron, timezone, paused, "
                    "selection, template, produce, created_at, updated_at) VALUES "
                    "(:id, 'p', 'old', '0 7 * * mon', 'UTC', 0, '{}', '{}', '{}', :now, :now)"
                ),
                {"id": f"s{k}", "now": "2026-01-01 00:00:00.000000"},
            )
    migrate(engine)
    with engine.connect() as connection:
        secrets = connection.execute(sa.text("SELECT webhook_secret FROM schedules")).scalars()
        found = list(secrets)
        columns = {c["name"]: c for c in sa.inspect(connection).get_columns("schedules")}
    assert len(found) == 3
    assert len(set(found)) == 3
    assert all(isinstance(s, str) and len(s) >= 40 for s in found)
    assert columns["webhook_secret"]["nullable"] is False
    engine.dispose()


def test_https_connects_to_the_checked_address_with_the_name_for_tls(tmp_path: Path):
    """SNI and the certificate check use the URL's name; the socket goes to the address."""
    if shutil.which("openssl") is None:
        pytest.skip("openssl is needed to make the test certificate")
    cert, key = tmp_path / "cert.pem", tmp_path / "key.pem"
    subprocess.run(
        ["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1",
         "-keyout", str(key), "-out", str(cert), "-subj", "/CN=hooks.example.com",
         "-addext", "subjectAltName=DNS:hooks.example.com"],
        check=True, capture_output=True,
    )  # fmt: skip
    server_tls = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    server_tls.load_cert_chain(cert, key)
    names: list[str | None] = []

    def keep_name(_sock: ssl.SSLObject, name: str | None, _ctx: ssl.SSLContext) -> None:
        names.append(name)

    server_tls.sni_callback = keep_name
    hook = Receiver(status=200)
    hook.server.socket = server_tls.wrap_socket(hook.server.socket, server_side=True)
    client_tls = ssl.create_default_context(cafile=str(cert))
    try:
        url = f"https://hooks.example.com:{hook.port}/hook?team=a"
        target = webhooks.check_webhook_url(
            url, webhooks.AllowList.parse("127.0.0.1"), addresses=["127.0.0.1"]
        )
        status, _location = webhooks.post(target, b"{}", {}, timeout=5, tls=client_tls)
        with pytest.raises(ssl.SSLCertVerificationError):  # the name is checked, not skipped
            webhooks.post(target, b"{}", {}, timeout=5, tls=ssl.create_default_context())
    finally:
        hook.close()
    assert status == 200
    assert names[0] == "hooks.example.com"
    ((headers, body),) = hook.requests
    assert headers["Host"] == f"hooks.example.com:{hook.port}"
    assert body == b"{}"
