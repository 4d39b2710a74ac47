"""Free loopback ports."""

from __future__ import annotations

import socket

__all__ = ["free_port", "free_ports"]

_GRPC_OFFSET = 10000
"""SeaweedFS's gRPC port of a service is its port plus this."""


def free_port() -> int:
    """Return a loopback port that was free a moment ago."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def free_ports(count: int, *, grpc: bool = False) -> list[int]:
    """Return ``count`` distinct free loopback ports; with ``grpc`` each port+10000 free too."""
    ports: list[int] = []
    while len(ports) < count:
        port = free_port()
        if port in ports:
            continue
        if grpc:
            if port + _GRPC_OFFSET > 65535:
                continue
            with socket.socket() as sock:
                try:
                    sock.bind(("127.0.0.1", port + _GRPC_OFFSET))
                except OSError:
                    continue
        ports.append(port)
    return ports
