"""meshcat's server, started by us, bound to one host, stopped with us.

``meshcat.Visualizer()`` starts ``meshcat.servers.zmqserver``, whose web server
listens on every interface (0.0.0.0 and [::]). :func:`start_server` runs the same
bridge in a child process (``python -m manip_id.viz.meshcat_server HTTP_HOST PARENT``)
with its ZeroMQ command socket on 127.0.0.1 always and its web server on
``HTTP_HOST`` only (127.0.0.1 unless asked otherwise). The child ends when the parent
dies, whatever the signal (Linux ``PR_SET_PDEATHSIG``, and a watchdog on the parent's
pid elsewhere); :meth:`MeshcatServer.stop` ends it explicitly.
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import ipaddress
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import webbrowser
from dataclasses import dataclass, field
from typing import Any

import umsgpack

from ..errors import InputError, ManipIdError

LOOPBACK = "127.0.0.1"


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and 'localhost'."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_host(host: str) -> str:
    """``host`` if it is an IP address or a name that resolves, else :class:`InputError`."""
    if not isinstance(host, str) or not host or any(c.isspace() for c in host):
        raise InputError(f"--host must be an IP address or a host name, got {host!r}")
    try:
        socket.getaddrinfo(host, None)
    except (socket.gaierror, UnicodeError) as exc:
        raise InputError(f"--host {host!r} does not resolve to an address") from exc
    return host


@dataclass
class MeshcatServer:
    """A running meshcat bridge: ``zmq_url`` (127.0.0.1), ``web_url`` (its host)."""

    process: subprocess.Popen
    zmq_url: str
    web_url: str
    host: str
    _stopped: bool = field(default=False, repr=False)

    def stop(self, timeout: float = 3.0) -> None:
        """Terminate the server process (then kill it) and wait for it."""
        if self._stopped:
            return
        self._stopped = True
        proc = self.process
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        for stream in (proc.stdout, proc.stderr):
            if stream is not None:
                stream.close()

    def __enter__(self) -> MeshcatServer:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def start_server(host: str = LOOPBACK, timeout: float = 30.0) -> MeshcatServer:
    """Start the bridge in a child process; its web server listens on ``host`` only."""
    check_host(host)
    cmd = [sys.executable, "-u", "-m", __name__, host, str(os.getpid())]
    proc = subprocess.Popen(
        cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL
    )
    lines: list[str] = []

    def read():
        assert proc.stdout is not None
        for raw in proc.stdout:
            lines.append(raw.decode("utf-8", "replace").strip())
            if len(lines) >= 2:
                return

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(timeout)
    urls = dict(line.split("=", 1) for line in lines if "=" in line)
    if "zmq_url" not in urls or "web_url" not in urls:
        proc.kill()
        proc.wait()
        raise ManipIdError(
            f"the meshcat server did not start within {timeout:g} s on {host} "
            f"(exit status {proc.poll()})"
        )
    return MeshcatServer(proc, urls["zmq_url"], urls["web_url"], host)


def webbrowser_open(url: str) -> None:  # pragma: no cover - interactive
    webbrowser.open(url, new=2)


@dataclass
class LiveView:
    """A scene replayed into a running meshcat server (see :meth:`RobotScene.serve`)."""

    visualizer: Any  # meshcat.Visualizer
    server: MeshcatServer

    @property
    def url(self) -> str:
        """The viewer's address, on the server's host."""
        return self.server.web_url

    def stop(self) -> None:
        """Close the connection and stop the server process."""
        try:
            self.visualizer.window.zmq_socket.close(linger=0)
        finally:
            self.server.stop()

    def __enter__(self) -> LiveView:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def replay(commands, host: str = LOOPBACK, open_browser: bool = False) -> LiveView:
    """Start a server on ``host`` (:func:`start_server`) and replay the packed meshcat
    ``commands`` into it; returns the :class:`LiveView` (stop it when done)."""
    import meshcat  # optional heavy library: only for a live view

    server = start_server(host)
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # meshcat prints its URL
            vis = meshcat.Visualizer(zmq_url=server.zmq_url)
        for packed in commands:
            data = umsgpack.unpackb(packed)
            vis.window.zmq_socket.send_multipart(
                [data["type"].encode(), data.get("path", "").encode(), packed]
            )
            vis.window.zmq_socket.recv()
    except BaseException:
        server.stop()
        raise
    view = LiveView(vis, server)
    if open_browser:
        webbrowser_open(view.url)
    return view


def _die_with_parent(parent: int) -> None:
    """End this process when ``parent`` ends (PR_SET_PDEATHSIG, plus a watchdog)."""
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, signal.SIGTERM, 0, 0, 0)  # PR_SET_PDEATHSIG = 1
        except (OSError, AttributeError):  # pragma: no cover
            pass
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(0)

    def watch():
        while True:
            time.sleep(1.0)
            if os.getppid() != parent:
                os._exit(0)

    threading.Thread(target=watch, daemon=True).start()


def _serve(http_host: str, parent: int) -> None:  # pragma: no cover - runs in the child
    _die_with_parent(parent)
    signal.signal(signal.SIGTERM, lambda *_: os._exit(0))
    from meshcat.servers.zmqserver import ZMQWebSocketBridge  # meshcat: heavy, the child only

    class Bridge(ZMQWebSocketBridge):
        """The ZeroMQ socket on 127.0.0.1 (self.host); the web server on ``http_host``."""

        def make_app(self):
            app = super().make_app()
            listen = app.listen

            def listen_on_host(port, *args, **kwargs):
                kwargs.setdefault("address", http_host)
                return listen(port, *args, **kwargs)

            app.listen = listen_on_host
            return app

    bridge = Bridge(host=LOOPBACK)
    shown = f"[{http_host}]" if ":" in http_host else http_host
    print(f"zmq_url={bridge.zmq_url}", flush=True)
    print(f"web_url=http://{shown}:{bridge.fileserver_port}/static/", flush=True)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)  # nobody reads our stdout any more
    bridge.run()


if __name__ == "__main__":  # pragma: no cover
    _serve(sys.argv[1], int(sys.argv[2]))
