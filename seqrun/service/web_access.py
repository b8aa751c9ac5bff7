"""Which web requests may reach a face of the arm at all: the Host and Origin rules.

The console (:mod:`seqrun.console.guard`) and the Foxglove server
(:mod:`seqrun.foxglove.gate`) both apply :func:`foreign`, so a web page of another site
open in the operator's browser reaches neither:

- **Host** (a face on 127.0.0.1): the Host header must name this machine, so a page cannot
  reach the face through a DNS name of its own that resolves to 127.0.0.1;
- **Origin**: a browser request from another site's page (its Origin is not the face's own
  address; ``null`` too, a file:// page) is refused. A client that sends no Origin (a tool,
  a desktop app) passes these rules.
"""

from __future__ import annotations

from collections.abc import Mapping
from urllib.parse import urlsplit

LOCAL_HOSTS = frozenset({"127.0.0.1", "localhost", "::1", "[::1]"})


def host_name(host: str) -> str:
    """``127.0.0.1:8765`` -> ``127.0.0.1``, ``[::1]:8765`` -> ``[::1]``."""
    if host.startswith("["):
        return host[:host.find("]") + 1]
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


def foreign(headers: Mapping[str, str], *, local_only: bool,
            server: str = "the console") -> str | None:
    """Why a request is refused by the Host and Origin rules (None: it passes).
    ``headers``: names in lower case; ``local_only``: the Host must name this machine;
    ``server``: what the request would reach, for the message."""
    host = headers.get("host", "")
    if local_only and host_name(host) not in LOCAL_HOSTS:
        return f"host '{host}' refused: {server} answers on 127.0.0.1 only"
    origin = headers.get("origin")
    if origin is not None and urlsplit(origin).netloc != host:  # "null" too (file://)
        return f"origin '{origin}' refused: a page of another site may not reach {server}"
    return None


__all__ = ["LOCAL_HOSTS", "foreign", "host_name"]
