"""Where the page is served, and which requests come from the page itself.

Light to import (sockets only): `dfa serve` checks its --host and --port here before it imports
the server, opens a session folder or binds anything, so bad input costs one line and a moment.

    serving_port(host, port)      the port to serve on and a note; UserError when it cannot be
    PageGuard(host).refusal(...)  why a request is not from the page ("" when it is)
"""

from __future__ import annotations

import errno
import socket
from collections.abc import Mapping
from urllib.parse import urlsplit

from sim.core import UserError

DEFAULT_PORT = 8080
PORT_TRIES = 100  # without --port: 8080, 8081, ... up to this many
LOOPBACK = ("127.0.0.1", "localhost", "::1")
ANY = ("0.0.0.0", "::")  # bind every interface
HOSTS_ACCEPTED = (
    "accepted: 127.0.0.1 (the default), localhost, ::1, 0.0.0.0 (every interface) "
    "or an address of this machine"
)


def check_port(port: int | None) -> None:
    """A port is 1..65535, or 0 for any free port; None means 8080 or the next free one."""
    if port is None:
        return
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
        raise UserError(
            f"--port {port} is not a port number; accepted: 1 to 65535, or 0 for any free port"
        )


def _addresses(host: str, port: int) -> list[tuple[int, tuple]]:
    """(family, socket address) of each address `host` names, as the server will bind them."""
    if not host or host != host.strip():
        raise UserError(f"--host {host!r} is not an address; {HOSTS_ACCEPTED}")
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except (socket.gaierror, ValueError) as e:  # ValueError: e.g. a label over 63 characters
        reason = e.strerror if isinstance(e, socket.gaierror) else "not a host name"
        raise UserError(
            f"--host {host!r} is not an address of this machine ({reason}); {HOSTS_ACCEPTED}"
        ) from None
    found: list[tuple[int, tuple]] = []
    for family, _, _, _, address in infos:
        if (family, address) not in found:
            found.append((family, address))
    return found


def _bind_error(family: int, address: tuple) -> OSError | None:
    """The error binding a listening socket to `address` gives, as the server would bind it
    (SO_REUSEADDR, IPv6 sockets IPv6-only); None when it binds."""
    try:
        sock = socket.socket(family, socket.SOCK_STREAM)
    except OSError as e:
        return e
    with sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        if family == socket.AF_INET6:
            sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
        try:
            sock.bind(address)
        except OSError as e:
            return e
    return None


def _with_port(address: tuple, port: int) -> tuple:
    return (address[0], port, *address[2:])


def _free(host: str, addresses: list[tuple[int, tuple]], port: int) -> bool:
    """True when every address of `host` can be bound on `port`; UserError for any failure
    other than the port being in use."""
    for family, address in addresses:
        e = _bind_error(family, _with_port(address, port))
        if e is None:
            continue
        if e.errno == errno.EADDRINUSE:
            return False
        raise UserError(f"cannot serve on {host} port {port} ({e.strerror})")
    return True


def serving_port(host: str, port: int | None) -> tuple[int, str]:
    """The port to serve on and a note for the user ("" when there is nothing to say).

    A port given explicitly must be free (0: the system picks one); without one, 8080 or the next
    free port after it. UserError (one line) for a port out of range, a host this machine does
    not have, or an explicit port that is busy; nothing is bound or created.
    """
    check_port(port)
    addresses = _addresses(host, 0)
    for family, address in addresses:  # does the machine have this address at all?
        e = _bind_error(family, address)
        if e is not None:
            raise UserError(
                f"--host {host!r} is not an address of this machine ({e.strerror}); "
                f"{HOSTS_ACCEPTED}"
            )
    if port is not None:
        if not _free(host, addresses, port):
            raise UserError(
                f"port {port} is busy on {host}; choose another --port, or leave --port out "
                f"to take the next free one after {DEFAULT_PORT}"
            )
        return port, ""
    for candidate in range(DEFAULT_PORT, DEFAULT_PORT + PORT_TRIES):
        if _free(host, addresses, candidate):
            note = "" if candidate == DEFAULT_PORT else moved_note(DEFAULT_PORT, candidate)
            return candidate, note
    raise UserError(
        f"ports {DEFAULT_PORT} to {DEFAULT_PORT + PORT_TRIES - 1} are all busy on {host}; "
        "choose a free one with --port (0: any free port)"
    )


def moved_note(wanted: int, got: int) -> str:
    return f"port {wanted} is busy; serving on {got}"


def url(host: str, port: int) -> str:
    """The page's URL (an IPv6 address in brackets)."""
    return f"http://[{host}]:{port}" if ":" in host else f"http://{host}:{port}"


# -- which requests come from the page ---------------------------------------------------------
def _is_local_ip(name: str) -> bool:
    """True when `name` is an IP address (not a name) that this machine has: a socket binds
    to it. No name is ever resolved here."""
    try:
        family = socket.AF_INET6 if ":" in name else socket.AF_INET
        socket.inet_pton(family, name)
    except OSError:
        return False
    return _bind_error(family, (name, 0)) is None


def _split(authority: str) -> tuple[str, int | None] | None:
    """(host name in lower case, port or None) of a Host header value; None if malformed."""
    if not authority or any(c in authority for c in "/?#@\\ \t"):
        return None
    try:
        parts = urlsplit("//" + authority)
        return (parts.hostname or "", parts.port)
    except ValueError:
        return None


class PageGuard:
    """Decides whether an HTTP request (the page's files, or the WebSocket that drives the
    session) comes from the page itself, so that no other web site open in the user's browser
    can drive a session.

    A request is the page's when
    - its Host header names the served port and a name the page is reached by, and
    - for a WebSocket upgrade, its Origin header (browsers always send one there) is
      http(s)://<such a name>:<the served port>.

    Names the page is reached by: the loopback names 127.0.0.1, localhost and [::1], the --host
    given, and, when --host binds every interface (0.0.0.0 or ::), this machine's host name and
    any IP address this machine has (a socket can be bound to it). Other names are refused even
    when they resolve to this machine: that is how DNS rebinding would reach the page, so Host
    and Origin names are compared as text and never resolved.
    """

    def __init__(self, host: str) -> None:
        self.host = host.lower()
        self.every_interface = self.host in ANY
        self.names = {*LOOPBACK, self.host}
        if self.every_interface:
            self.names.add(socket.gethostname().lower())

    def _known(self, name: str) -> bool:
        return name in self.names or (self.every_interface and _is_local_ip(name))

    def _check(self, what: str, authority: str, shown: str, port: int, default: int) -> str:
        split = _split(authority)
        if split is None:
            return f"malformed {what} {shown!r}"
        name, given = split
        if not self._known(name) or (given or default) != port:
            return f"{what} {shown!r} is not this page's address"
        return ""

    def refusal(self, headers: Mapping[str, str], port: int, *, upgrade: bool) -> str:
        """Why a request with these headers is not from the page served on `port`, in words;
        "" when it is. `upgrade`: the request opens a WebSocket."""
        host = _header(headers, "Host")
        if host is None:
            return "no Host header (or more than one)"
        why = self._check("Host", host, host, port, 80)
        if why or not upgrade:
            return why
        origin = _header(headers, "Origin")
        if origin is None:
            return "a WebSocket without an Origin header (or with more than one)"
        try:
            parts = urlsplit(origin)
        except ValueError:  # e.g. an unclosed [IPv6 address
            return f"malformed Origin {origin!r}"
        if (
            parts.scheme not in ("http", "https")
            or parts.path not in ("", "/")
            or parts.query
            or parts.fragment
        ):
            return f"Origin {origin!r} is not this page's address"
        default = 443 if parts.scheme == "https" else 80
        return self._check("Origin", parts.netloc, origin, port, default)


def _header(headers: Mapping[str, str], name: str) -> str | None:
    """The one value of a header; None when it is missing or repeated (websockets' Headers
    keeps repeated headers apart: `get_all`)."""
    get_all = getattr(headers, "get_all", None)
    if get_all is not None:
        values = list(get_all(name))
    else:
        values = [headers[name]] if name in headers else []
    return values[0] if len(values) == 1 else None
