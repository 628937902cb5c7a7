"""A threaded TCP server on 127.0.0.1 whose connections are tracked, so that a
simulated machine can drop them (a pulled cable) and close cleanly: the plumbing the
simulated controller and thermocouple logger share."""

from __future__ import annotations

import socket
import socketserver
import threading


class _Server(socketserver.ThreadingTCPServer):
    daemon_threads = True
    allow_reuse_address = True


class TcpService:
    """Serve every connection with ``self._serve(sock)`` (a subclass's), on a thread.

    Subclasses call :meth:`_start` once their state is ready, and in ``_serve`` wrap
    the connection in :meth:`_accepted` and :meth:`_finished`.

    Attributes
    ----------
    connections : int
        Connections accepted so far.
    """

    connections: int
    _lock: threading.Lock
    _live: set[socket.socket]
    _server: _Server
    _thread: threading.Thread

    def _start(self, host: str, port: int) -> None:
        self.connections = 0
        self._lock = threading.Lock()
        self._live = set()
        outer = self

        class Handler(socketserver.BaseRequestHandler):
            def handle(self) -> None:
                outer._serve(self.request)

        self._server = _Server((host, port), Handler)
        self._thread = threading.Thread(
            target=self._server.serve_forever, kwargs={"poll_interval": 0.02}, daemon=True
        )
        self._thread.start()

    def _serve(self, sock: socket.socket) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    @property
    def port(self) -> int:
        """The TCP port the server listens on."""
        return int(self._server.server_address[1])

    @property
    def host(self) -> str:
        """The address the server listens on."""
        return str(self._server.server_address[0])

    def _accepted(self, sock: socket.socket) -> int:
        """Count and track a new connection; its number (1, 2, ...)."""
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        with self._lock:
            self.connections += 1
            self._live.add(sock)
            return self.connections

    def _finished(self, sock: socket.socket) -> None:
        """Forget a connection and close it."""
        with self._lock:
            self._live.discard(sock)
        try:
            sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        sock.close()

    def drop(self) -> int:
        """Drop every connection and go on listening (a pulled cable); how many."""
        with self._lock:
            live = list(self._live)
        for sock in live:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        return len(live)

    def close(self) -> None:
        """Stop serving and drop every connection (a machine that goes away)."""
        self._server.shutdown()
        self._server.server_close()
        self.drop()
        self._thread.join(timeout=10)

    def __enter__(self) -> TcpService:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
