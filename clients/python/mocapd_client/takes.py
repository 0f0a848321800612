"""Takes over mocapd's web endpoint (docs/client-protocol.md, "Takes"): list them, download one
(the raw file as recorded, or BVH / joint-angle CSV re-solved by mocapd), start, stop and
delete. Standard library only (urllib).

    takes = mc.Takes("127.0.0.1:8080", token=os.environ.get("MOCAP_TOKEN"))
    name = takes.start(notes="trial 3")
    ...
    takes.stop()
    takes.download(name, "trial3.bvh", format="bvh", subject=1)

Reading needs no token; start, stop and delete need the daemon's control token and, by
default, a loopback peer. Every refusal raises `TakeError` with the HTTP status and the
daemon's reason.
"""

from __future__ import annotations

import json
import os
import tempfile
import urllib.error
import urllib.parse
import urllib.request
from pathlib import Path

FORMATS = ("raw", "bvh", "csv")
_PAGE = 500  # takes per listing request when the daemon pages its listing


class TakeError(Exception):
    """The daemon refused a take request (`status`: 401 token, 403 not allowed, 404 no such
    take, 409 conflict, 429 throttled, 503 busy, 507 no room for the export, ...)."""

    def __init__(self, status: int, reason: str):
        super().__init__(f"HTTP {status}: {reason}")
        self.status = status
        self.reason = reason


class Takes:
    def __init__(self, http: str = "127.0.0.1:8080", token: str | None = None, timeout: float = 60.0):
        self.base = http if "://" in http else f"http://{http}"
        self.token = token
        self.timeout = timeout

    # --- reading ---------------------------------------------------------------------------
    def list(self) -> list[dict]:
        """Every take, by start time: its sidecar (name, start_us, stop_us, subjects, samples,
        samples_lost, notes, ...) plus "recording" and "raw_bytes". Follows the daemon's pages
        when it pages the listing (a reply with "total")."""
        takes: list[dict] = []
        while True:
            reply = self._json("GET", "/api/takes", {"offset": len(takes), "limit": _PAGE})
            page = reply.get("takes", [])
            takes += page
            total = reply.get("total")
            if total is None or not page or len(takes) >= total:
                return takes

    def get(self, name: str) -> dict:
        return self._json("GET", f"/api/takes/{_quote(name)}")

    def download(self, name: str, out: str | os.PathLike, format: str = "raw", *, subject: int | None = None,
                 filter: str | None = None, offline: bool = False) -> Path:
        """Writes the take to `out` and returns its path. `format`: "raw" (as recorded), "bvh"
        (one subject: `subject`, default the daemon's rule) or "csv" (every subject), the last
        two re-solved with the daemon's filter or `filter`, causally or `offline`. The file
        appears whole or not at all (written beside it, then renamed)."""
        if format not in FORMATS:
            raise ValueError(f"format must be one of {FORMATS}, not {format!r}")
        query: dict[str, object] = {"format": format}
        if subject is not None:
            query["subject"] = int(subject)
        if filter:
            query["filter"] = filter
        if offline:
            query["offline"] = 1
        out = Path(out)
        with self._open("GET", f"/api/takes/{_quote(name)}/download", query) as response:
            fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", dir=out.parent or ".")
            try:
                with os.fdopen(fd, "wb") as fh:
                    while chunk := response.read(1 << 16):
                        fh.write(chunk)
                os.replace(tmp, out)
            except BaseException:
                os.unlink(tmp)
                raise
        return out

    # --- control (token) --------------------------------------------------------------------
    def start(self, name: str | None = None, notes: str | None = None) -> str:
        """Starts a take; returns its name (the daemon's, from the start time, if none given)."""
        query = {k: v for k, v in (("name", name), ("notes", notes)) if v is not None}
        return self._json("POST", "/api/takes/start", query, control=True).get("take", "")

    def stop(self) -> str:
        """Stops the running take; returns its name."""
        return self._json("POST", "/api/takes/stop", control=True).get("take", "")

    def delete(self, name: str) -> None:
        self._json("DELETE", f"/api/takes/{_quote(name)}", control=True)

    # --- plumbing ---------------------------------------------------------------------------
    def _open(self, method: str, path: str, query: dict | None = None, control: bool = False):
        url = self.base + path + ("?" + urllib.parse.urlencode(query) if query else "")
        request = urllib.request.Request(url, method=method)
        if control:
            if not self.token:
                raise TakeError(401, "this request needs the daemon's control token (Takes(token=...))")
            request.add_header("X-Mocap-Token", self.token)
        try:
            return urllib.request.urlopen(request, timeout=self.timeout)
        except urllib.error.HTTPError as e:
            body = e.read().decode("utf-8", "replace").strip()
            e.close()
            try:
                reason = json.loads(body).get("error") or body
            except (ValueError, AttributeError):
                reason = body
            raise TakeError(e.code, reason or e.reason) from None

    def _json(self, method: str, path: str, query: dict | None = None, control: bool = False) -> dict:
        with self._open(method, path, query, control) as response:
            reply = json.loads(response.read().decode("utf-8"))
        if isinstance(reply, dict) and reply.get("ok") is False:
            raise TakeError(409, reply.get("error", "refused"))
        return reply


def _quote(name: str) -> str:
    return urllib.parse.quote(name, safe="")
