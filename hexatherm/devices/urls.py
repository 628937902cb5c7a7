"""Device URLs: ``symetrie://HOST[:PORT]``, ``pi://HOST[:PORT]`` and
``symetrie-pmac://HOST[:PORT]`` (Symétrie's gpascii over telnet) to a controller driver.

A module of its own so that the protocol (:mod:`hexatherm.devices.controller`) does not
import its drivers, which import it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from urllib.parse import urlsplit

from hexatherm.core.hexapod import Hexapod
from hexatherm.devices.controller import LogCallback, SocketController
from hexatherm.devices.pi import PIController
from hexatherm.devices.symetrie import SymetrieController
from hexatherm.devices.symetriepmac import SymetriePmacController
from hexatherm.errors import ControllerError


def controller_from_url(
    url: str,
    *,
    hexapod: Hexapod | None = None,
    convention: str | None = None,
    reply_timeout_s: float = 5.0,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
    log: LogCallback | None = None,
) -> SocketController:
    """A driver (not yet connected) for ``symetrie://HOST[:PORT]`` or ``pi://HOST[:PORT]``.

    The port defaults to the dialect's (Symétrie API v2: 61559, PI GCS: 50000). Keyword
    arguments go to the driver (see :class:`SocketController`).

    >>> controller_from_url("pi://192.168.0.10").url
    'pi://192.168.0.10:50000'
    >>> controller_from_url("symetrie://hexa:61559").dialect
    'Symetrie API v2'
    >>> controller_from_url("symetrie-pmac://zonda").url
    'symetrie-pmac://zonda:23'
    >>> controller_from_url("modbus://hexa")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    hexatherm.errors.ControllerError: unknown controller URL scheme 'modbus' ...
    """
    drivers: dict[str, type[SocketController]] = {
        SymetrieController.scheme: SymetrieController,
        PIController.scheme: PIController,
        SymetriePmacController.scheme: SymetriePmacController,
    }
    parts = urlsplit(url)
    scheme = parts.scheme.lower()
    if scheme not in drivers:
        raise ControllerError(
            f"unknown controller URL scheme {parts.scheme!r} in {url!r}; expected "
            "symetrie://HOST:61559, pi://HOST:50000 or symetrie-pmac://HOST:23"
        )
    if parts.path not in ("", "/") or parts.query or parts.fragment or parts.username:
        raise ControllerError(f"controller URL {url!r} must be SCHEME://HOST[:PORT], no more")
    try:
        port = parts.port
    except ValueError as exc:
        raise ControllerError(f"bad port in controller URL {url!r}: {exc}") from exc
    if not parts.hostname:
        raise ControllerError(f"no host in controller URL {url!r}")
    return drivers[scheme](
        parts.hostname,
        port,
        hexapod=hexapod,
        convention=convention,
        reply_timeout_s=reply_timeout_s,
        clock=clock,
        sleep=sleep,
        log=log,
    )
