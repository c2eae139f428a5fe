"""A local HTTP mirror for download tests: serves one folder on 127.0.0.1, logs the paths asked
for, and can cut a file short. Tests start it through the ``serve`` fixture of conftest."""

from __future__ import annotations

import http.server
import threading
import urllib.parse
from pathlib import Path


class Handler(http.server.BaseHTTPRequestHandler):
    """Serves the files below ``root``, logs the paths asked for, and can cut a file short.

    Settings live on a per-server subclass (see :class:`Server`).
    """

    root: Path
    cut_once: set[str]
    log: list[str]

    def do_GET(self) -> None:
        path = urllib.parse.unquote(self.path.split("?", 1)[0])
        self.log.append(path)
        target = self.root / path.lstrip("/")
        if not target.is_file():
            self.send_error(404)
            return
        data = target.read_bytes()
        self.send_response(200)
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        if path in self.cut_once:
            # Announce the full length, send half, hang up: a connection lost mid-download.
            self.cut_once.discard(path)
            self.wfile.write(data[: len(data) // 2])
            self.close_connection = True
            return
        self.wfile.write(data)

    def log_message(self, fmt: str, *args: object) -> None:
        pass


class Server:
    """A threaded HTTP server on 127.0.0.1 serving one folder."""

    def __init__(self, root: Path) -> None:
        self.log: list[str] = []
        self.cut_once: set[str] = set()
        handler = type(
            "Handler",
            (Handler,),
            {"root": root.resolve(), "cut_once": self.cut_once, "log": self.log},
        )
        self.httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}"
        self.thread = threading.Thread(target=self.httpd.serve_forever, args=(0.05,), daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()
        self.thread.join()
