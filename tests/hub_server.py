"""A Hugging Face hub on 127.0.0.1 for the model manager's tests (stdlib http.server in a thread).

It serves model repositories the test makes ({repo id: {path: bytes}}, one commit each) through the
endpoints huggingface_hub calls: a revision's info (/api/models/ID/revision/REV), its file tree
(/api/models/ID/tree/REV), and files (/ID/resolve/REV/PATH, HEAD and GET, with ETag, X-Repo-Commit
and Range). Every request is recorded (method, path, Range) so a test can see what was fetched again.
"""
from __future__ import annotations

import hashlib
import json
import re
import threading
import time
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from urllib.parse import unquote, urlsplit

_API = re.compile(r"^/api/models/(?P<repo>[^/]+/[^/]+)(?:/(?P<kind>revision|tree)/(?P<rev>[^/]+))?/?$")
_RESOLVE = re.compile(r"^/(?P<repo>[^/]+/[^/]+)/resolve/(?P<rev>[^/]+)/(?P<path>.+)$")
_RANGE = re.compile(r"^bytes=(\d+)-$")


@dataclass
class HubServer:
    repos: dict[str, dict[str, bytes]]
    requests: list[dict] = field(default_factory=list)   # {"method", "path", "range"}
    bytes_sent: int = 0
    seconds_per_mib: float = 0.0   # a slow link, so a test can stop a download half-way from another thread
    # a hostile or broken hub: the ETag answered for a file ({path: etag}), the commit answered for a repository
    etags: dict[str, str] = field(default_factory=dict)
    commits: dict[str, str] = field(default_factory=dict)

    def commit(self, repo: str) -> str:
        return self.commits.get(repo, hashlib.sha1(repo.encode()).hexdigest())

    @staticmethod
    def etag(data: bytes) -> str:
        return hashlib.sha256(data).hexdigest()

    def start(self) -> "HubServer":
        hub = self

        class Handler(BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"

            def log_message(self, *args) -> None:
                pass

            def handle(self) -> None:
                try:
                    super().handle()
                except ConnectionResetError:   # a client that stopped (a cancel) closed its connection
                    pass

            def do_HEAD(self) -> None:
                self._answer(body=False)

            def do_GET(self) -> None:
                self._answer(body=True)

            def _answer(self, body: bool) -> None:
                path = unquote(urlsplit(self.path).path)
                hub.requests.append({"method": self.command, "path": path, "range": self.headers.get("Range")})
                api, resolve = _API.match(path), _RESOLVE.match(path)
                if api and api["repo"] in hub.repos:
                    return self._json(hub._api(api["repo"], api["kind"]), body)
                if resolve and resolve["repo"] in hub.repos and resolve["path"] in hub.repos[resolve["repo"]]:
                    return self._file(resolve["repo"], resolve["path"], body)
                self._json({"error": "Repository Not Found"}, body, status=404)

            def _json(self, payload, body: bool, status: int = 200) -> None:
                data = json.dumps(payload).encode()
                self.send_response(status)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(data)))
                if status == 404:
                    self.send_header("X-Error-Code", "RepoNotFound")
                self.end_headers()
                if body:
                    self.wfile.write(data)

            def _file(self, repo: str, name: str, body: bool) -> None:
                data, start = hub.repos[repo][name], 0
                asked = _RANGE.match(self.headers.get("Range") or "")
                if asked and body:
                    start = int(asked[1])
                self.send_response(206 if start else 200)
                self.send_header("ETag", f'"{hub.etags.get(name, hub.etag(data))}"')
                self.send_header("X-Repo-Commit", hub.commit(repo))
                self.send_header("Accept-Ranges", "bytes")
                self.send_header("Content-Length", str(len(data) - start))
                if start:
                    self.send_header("Content-Range", f"bytes {start}-{len(data) - 1}/{len(data)}")
                self.end_headers()
                if body:
                    step = 1 << 20
                    for at in range(start, len(data), step):
                        try:
                            self.wfile.write(data[at:at + step])
                        except (BrokenPipeError, ConnectionResetError):   # the client stopped reading (a cancel)
                            return
                        hub.bytes_sent += len(data[at:at + step])
                        time.sleep(hub.seconds_per_mib)

        self._server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self._server.daemon_threads = True
        self._thread = threading.Thread(target=self._server.serve_forever, daemon=True)
        self._thread.start()
        return self

    def _api(self, repo: str, kind: str | None):
        files = self.repos[repo]
        if kind == "tree":
            return [{"type": "file", "oid": hashlib.sha1(data).hexdigest(), "size": len(data), "path": path}
                    for path, data in sorted(files.items())]
        return {"id": repo, "modelId": repo, "sha": self.commit(repo), "private": False,
                "siblings": [{"rfilename": path} for path in sorted(files)]}

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self._server.server_address[1]}"

    def stop(self) -> None:
        self._server.shutdown()
        self._server.server_close()
