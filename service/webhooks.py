"""Webhook targets that are safe to post to, and the signature on every delivery.

**Targets.** A webhook URL is ``http`` or ``https``, carries no user name or password, and its
host resolves (:func:`socket.getaddrinfo`, every address it returns) to public addresses only.
A URL is refused when any address is loopback, link-local (``169.254.0.0/16``, where cloud
metadata services answer, and ``fe80::/10``), private, shared (``100.64.0.0/10``),
multicast, unspecified (``0.0.0.0``, ``::``) or reserved, IPv4-mapped, 6to4 and NAT64 IPv6
addresses judged by the IPv4 address inside. Integer and octal/hex spellings of IPv4
(``2130706433``, ``0x7f.1``) resolve to the address they stand for and are judged by it.
The administrator names internal targets that are wanted anyway in ``LOCEVAL_WEBHOOK_ALLOW``
(:class:`AllowList`): host names (``hooks.internal``, or ``.internal`` for every name under
it) and addresses or networks (``10.1.2.3``, ``10.0.0.0/8``, ``::1``).

URLs are checked when a schedule is created or changed (a refusal is a 422 problem) and
again before each delivery (a refusal is recorded on the run and not retried). Delivery
resolves the name once, checks the addresses and connects to those very addresses
(:func:`post`), so a name that re-resolves in between (DNS rebinding) cannot redirect the
connection; HTTPS keeps the name for SNI and certificate checks, and the ``Host`` header
names the host of the URL. Redirects are never followed: a 3xx answer is a failed attempt.
Proxy variables (``HTTPS_PROXY``) are not used; the service posts directly.

Residual risk: the resolver's answer is trusted for the addresses it returns, so an
allow-listed *name* may point anywhere its DNS says; allow-list addresses or networks, not
names, where that matters.

**Signature.** Each schedule has its own secret (``secrets.token_urlsafe``), shown once when
the schedule is created and when it is rotated (``POST /api/v1/schedules/{id}/secret``).
Each delivery carries::

    X-Loceval-Timestamp: <unix seconds when the attempt was sent>
    X-Loceval-Signature: sha256=<hex HMAC-SHA256(secret, timestamp + "." + body)>

where ``secret`` is the secret's text as UTF-8 bytes and ``body`` the exact request body
bytes. A receiver recomputes the HMAC over the raw body, compares it in constant time, and
refuses timestamps older than a few minutes (:data:`SIGNATURE_TOLERANCE_S`) so a recorded
delivery cannot be replayed later; :func:`verify_signature` does all three.
"""

from __future__ import annotations

import hashlib
import hmac
import http.client
import ipaddress
import re
import secrets
import socket
import ssl
import time
import urllib.parse
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Final

from service.errors import WebhookRefusedError, WebhookUnresolvedError

__all__ = [
    "ALLOW_SETTING",
    "SIGNATURE_HEADER",
    "SIGNATURE_TOLERANCE_S",
    "TIMESTAMP_HEADER",
    "AllowList",
    "WebhookRefusedError",
    "WebhookTarget",
    "WebhookUnresolvedError",
    "check_webhook_url",
    "new_secret",
    "post",
    "resolve_addresses",
    "sign",
    "signature_headers",
    "verify_signature",
]

ALLOW_SETTING: Final = "LOCEVAL_WEBHOOK_ALLOW"
"""The environment variable of the allow-list, as messages name it."""
SIGNATURE_HEADER: Final = "X-Loceval-Signature"
TIMESTAMP_HEADER: Final = "X-Loceval-Timestamp"
SIGNATURE_TOLERANCE_S: Final = 300
"""How old a signed timestamp :func:`verify_signature` accepts, in seconds."""
_FIELD: Final = "webhook_url"
_WHAT_TO_DO: Final = f"use a public address, or ask the administrator to add it to {ALLOW_SETTING}."
_HOST_NAME: Final = re.compile(r"^\.?(?=.{1,253}$)[a-z0-9_](?:[a-z0-9_.-]*[a-z0-9_])?$")
_CONTROL: Final = re.compile(r"[\x00-\x20\x7f]")
_URL_SAFE: Final = "!#$%&'()*+,/:;=?@[]~"
"""Kept as they are in the request's path and query; other non-ASCII bytes are %-encoded."""
_NAT64: Final = ipaddress.IPv6Network("64:ff9b::/96")
_SHARED: Final = ipaddress.IPv4Network("100.64.0.0/10")

_Address = ipaddress.IPv4Address | ipaddress.IPv6Address
_Network = ipaddress.IPv4Network | ipaddress.IPv6Network


def new_secret() -> str:
    """Return a new signing secret for a schedule (43 URL-safe characters, 256 bits)."""
    return secrets.token_urlsafe(32)


# --- the allow-list ----------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class AllowList:
    """Internal webhook targets the administrator lets through.

    Attributes:
        hosts: host names allowed whatever they resolve to; one starting with ``.`` allows
            every name under it (``.internal`` allows ``hooks.internal``).
        networks: addresses and networks allowed (an address is a one-address network).
    """

    hosts: frozenset[str] = frozenset()
    networks: tuple[_Network, ...] = ()

    @classmethod
    def parse(cls, text: str) -> AllowList:
        """Read a comma-separated list of host names, addresses and CIDR networks.

        Raises:
            ValueError: an entry is neither (the message names it).
        """
        hosts: set[str] = set()
        networks: list[_Network] = []
        for raw in text.split(","):
            entry = raw.strip().lower().strip("[]").rstrip(".")
            if not entry:
                continue
            try:
                networks.append(ipaddress.ip_network(entry, strict=False))
                continue
            except ValueError:
                pass
            if not _HOST_NAME.match(entry) or "/" in entry:
                msg = (
                    f"{ALLOW_SETTING}: {raw.strip()!r} is neither a host name nor an address or "
                    "CIDR network; give e.g. 'hooks.internal,10.0.0.0/8,127.0.0.1'."
                )
                raise ValueError(msg)
            hosts.add(entry)
        return cls(frozenset(hosts), tuple(networks))

    def allows_host(self, host: str) -> bool:
        """Return whether a host name (lower case, no trailing dot) is allowed by name."""
        return host in self.hosts or any(h.startswith(".") and host.endswith(h) for h in self.hosts)

    def allows_address(self, address: _Address) -> bool:
        """Return whether an address lies in an allowed network (IPv4 inside IPv6 too)."""
        forms = [address, *([] if (inner := _embedded_ipv4(address)) is None else [inner])]
        return any(a in n for a in forms for n in self.networks if a.version == n.version)


# --- checking a URL ----------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class WebhookTarget:
    """A checked webhook URL and the addresses it may be posted to.

    Attributes:
        url: the URL as given.
        https: whether the scheme is ``https``.
        host: the host name or literal address (lower case, IPv6 without brackets).
        port: the port (80 or 443 unless the URL names one).
        target: the path and query to request (``/`` when the URL has none).
        addresses: the checked addresses, in the resolver's order; :func:`post` connects
            to these and nothing else.
    """

    url: str
    https: bool
    host: str
    port: int
    target: str
    addresses: tuple[str, ...]


def resolve_addresses(host: str, port: int) -> list[str]:
    """Return every address a host resolves to for TCP (literal addresses included).

    Raises:
        OSError: the name does not resolve (:class:`socket.gaierror`).
        UnicodeError: the name cannot be encoded for DNS.
    """
    infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, proto=socket.IPPROTO_TCP)
    seen: dict[str, None] = {}
    for _family, _type, _proto, _canonname, sockaddr in infos:
        seen.setdefault(str(sockaddr[0]).split("%", 1)[0], None)
    return list(seen)


def _embedded_ipv4(address: _Address) -> ipaddress.IPv4Address | None:
    """Return the IPv4 address inside an IPv4-mapped, 6to4 or NAT64 IPv6 address."""
    if isinstance(address, ipaddress.IPv4Address):
        return None
    if address.ipv4_mapped is not None:
        return address.ipv4_mapped
    if address.sixtofour is not None:
        return address.sixtofour
    if address in _NAT64:
        return ipaddress.IPv4Address(int(address) & 0xFFFFFFFF)
    return None


def _internal_kind(address: _Address) -> str | None:
    """Return what makes an address internal (``"a loopback address"``...), or None."""
    inner = _embedded_ipv4(address)
    if inner is not None:
        kind = _internal_kind(inner)
        return None if kind is None else f"an IPv6 form of {kind}"
    checks = (
        (address.is_unspecified, "an unspecified address"),
        (address.is_loopback, "a loopback address"),
        (address.is_link_local, "a link-local address (where cloud metadata services answer)"),
        (address.is_multicast, "a multicast address"),
        (address in _SHARED, "a shared (carrier-grade NAT) address"),
        (address.is_private, "a private address"),
        (address.is_reserved, "a reserved address"),
        (not address.is_global, "an address that is not public"),
    )
    return next((kind for internal, kind in checks if internal), None)


def _split(url: str) -> tuple[bool, str, int, str]:
    """Return ``(https, host, port, target)`` of a URL, or refuse its form."""
    if _CONTROL.search(url):
        msg = f"{_FIELD}: the URL contains spaces or control characters; percent-encode them."
        raise WebhookRefusedError(msg)
    try:
        parts = urllib.parse.urlsplit(url)
        port = parts.port
    except ValueError as err:
        msg = f"{_FIELD}: {url!r} is not a valid URL ({err}); give e.g. 'https://example.com/hook'."
        raise WebhookRefusedError(msg) from None
    scheme = parts.scheme.lower()
    if scheme not in {"http", "https"}:
        msg = f"{_FIELD}: the scheme {parts.scheme!r} is not allowed; use an https:// URL."
        raise WebhookRefusedError(msg)
    if parts.username is not None or parts.password is not None:
        msg = (
            f"{_FIELD}: the URL carries a user name or password; remove it, and check "
            "deliveries with their X-Loceval-Signature header instead."
        )
        raise WebhookRefusedError(msg)
    host = (parts.hostname or "").rstrip(".")
    if not host:
        msg = f"{_FIELD}: {url!r} names no host; give e.g. 'https://example.com/hook'."
        raise WebhookRefusedError(msg)
    target = urllib.parse.quote(parts.path or "/", safe=_URL_SAFE)
    if parts.query:
        target += "?" + urllib.parse.quote(parts.query, safe=_URL_SAFE)
    return scheme == "https", host, port or (443 if scheme == "https" else 80), target


def check_webhook_url(
    url: str, allow: AllowList, *, addresses: Sequence[str] | None = None
) -> WebhookTarget:
    """Check a webhook URL and return it with the addresses it may be posted to.

    Args:
        url: the URL.
        allow: the internal targets the administrator allows.
        addresses: the host's addresses, if already resolved (tests); by default
            :func:`resolve_addresses` resolves them now.

    Raises:
        WebhookUnresolvedError: the host does not resolve (may be temporary).
        WebhookRefusedError: the URL's form is not allowed, or one of the host's addresses
            is internal and not allowed (the message says which kind, and what to do).
    """
    https, host, port, target = _split(url)
    by_name = allow.allows_host(host)
    if _is_localhost(host) and not by_name:  # loopback by definition, whatever DNS says
        msg = (
            f"{_FIELD}: the host {host!r} is a loopback address, which webhooks may not "
            f"reach; {_WHAT_TO_DO}"
        )
        raise WebhookRefusedError(msg)
    if addresses is None:
        try:
            addresses = resolve_addresses(host, port)
        except (OSError, UnicodeError, ValueError):
            if _is_localhost(host):  # allowed by name: RFC 6761's loopback, with no hosts file
                addresses = ["127.0.0.1"]
                return WebhookTarget(url, https, host, port, target, tuple(addresses))
            msg = (
                f"{_FIELD}: the host {host!r} does not resolve; check the name, or use a "
                "public address."
            )
            raise WebhookUnresolvedError(msg) from None
    if not addresses:
        msg = f"{_FIELD}: the host {host!r} resolves to no address; check the name."
        raise WebhookUnresolvedError(msg)
    literal = _is_literal(host)
    for text in addresses:
        address = ipaddress.ip_address(text)
        kind = _internal_kind(address)
        if kind is None or by_name or allow.allows_address(address):
            continue
        where = f"the address {host!r} is" if literal else f"the host {host!r} resolves to"
        msg = f"{_FIELD}: {where} {kind}, which webhooks may not reach; {_WHAT_TO_DO}"
        raise WebhookRefusedError(msg)
    return WebhookTarget(url, https, host, port, target, tuple(addresses))


def _is_localhost(host: str) -> bool:
    """Return whether a name is ``localhost`` or under it (RFC 6761: always loopback)."""
    name = host.lower().rstrip(".")
    return name == "localhost" or name.endswith(".localhost")


def _is_literal(host: str) -> bool:
    try:
        ipaddress.ip_address(host)
    except ValueError:
        return False
    return True


# --- signing -----------------------------------------------------------------------------


def sign(secret: str, timestamp: int, body: bytes) -> str:
    """Return the signature header's value: ``sha256=`` and the hex HMAC of ``ts.body``."""
    mac = hmac.new(secret.encode("utf-8"), f"{timestamp}.".encode("ascii") + body, hashlib.sha256)
    return f"sha256={mac.hexdigest()}"


def signature_headers(secret: str, body: bytes, *, now: float | None = None) -> dict[str, str]:
    """Return the timestamp and signature headers of one delivery of ``body``."""
    timestamp = int(time.time() if now is None else now)
    return {TIMESTAMP_HEADER: str(timestamp), SIGNATURE_HEADER: sign(secret, timestamp, body)}


def verify_signature(
    secret: str,
    headers: Mapping[str, str],
    body: bytes,
    *,
    now: float | None = None,
    tolerance_s: float = SIGNATURE_TOLERANCE_S,
) -> bool:
    """Return whether a received delivery is signed with ``secret`` and recent.

    Args:
        secret: the schedule's secret, as shown when it was created or rotated.
        headers: the request's headers (exact names, or any mapping such as
            :class:`email.message.Message` that looks them up case-insensitively).
        body: the raw request body, before any JSON parsing.
        now: the current time in Unix seconds (default: the clock).
        tolerance_s: the largest accepted age (and clock skew) of the timestamp.
    """
    stamp = headers.get(TIMESTAMP_HEADER)
    given = headers.get(SIGNATURE_HEADER)
    if stamp is None or given is None or not stamp.isdigit():
        return False
    current = time.time() if now is None else now
    if abs(current - int(stamp)) > tolerance_s:
        return False
    return hmac.compare_digest(sign(secret, int(stamp), body), given)


# --- posting -----------------------------------------------------------------------------


def _connect_to(addresses: Iterable[str], port: int, timeout: float | None) -> socket.socket:
    """Open a TCP connection to the first of the checked addresses that answers."""
    error: OSError = OSError("no address to connect to")
    for address in addresses:
        try:
            return socket.create_connection((address, port), timeout)
        except OSError as err:
            error = err
    raise error


class _PinnedHTTPConnection(http.client.HTTPConnection):
    """HTTP to the checked addresses only (the name is used for the Host header)."""

    def __init__(self, target: WebhookTarget, timeout: float) -> None:
        super().__init__(target.host, target.port, timeout=timeout)
        self._addresses = target.addresses

    def connect(self) -> None:
        """Connect to a checked address, never to a fresh lookup of the name."""
        self.sock = _connect_to(self._addresses, self.port, self.timeout)


class _PinnedHTTPSConnection(http.client.HTTPSConnection):
    """HTTPS to the checked addresses only; SNI and the certificate check use the name."""

    def __init__(self, target: WebhookTarget, timeout: float, tls: ssl.SSLContext) -> None:
        super().__init__(target.host, target.port, timeout=timeout)
        self._addresses = target.addresses
        self._tls = tls

    def connect(self) -> None:
        """Connect to a checked address, then speak TLS to it as the URL's host."""
        raw = _connect_to(self._addresses, self.port, self.timeout)
        self.sock = self._tls.wrap_socket(raw, server_hostname=self.host)


def post(
    target: WebhookTarget,
    body: bytes,
    headers: Mapping[str, str],
    *,
    timeout: float,
    tls: ssl.SSLContext | None = None,
) -> tuple[int, str | None]:
    """Post ``body`` once to a checked target; return the status and any ``Location``.

    Redirects are not followed: a 3xx comes back as it is.

    Args:
        target: the checked URL; the connection goes to one of its addresses.
        body: the request body.
        headers: the request headers (``Host`` is the URL's host and port).
        timeout: seconds for the connection and for each read.
        tls: the TLS settings of an https target (default: the system's certificate
            authorities, with host name checks).

    Raises:
        OSError: the connection failed or timed out (:class:`ssl.SSLError` included).
        http.client.HTTPException: the answer is not HTTP.
    """
    connection: http.client.HTTPConnection = (
        _PinnedHTTPSConnection(target, timeout, tls or ssl.create_default_context())
        if target.https
        else _PinnedHTTPConnection(target, timeout)
    )
    try:
        connection.request("POST", target.target, body=body, headers=dict(headers))
        response = connection.getresponse()
        response.read(65536)
        return response.status, response.getheader("Location")
    finally:
        connection.close()
