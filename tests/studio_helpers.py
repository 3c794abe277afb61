"""The studio as a user runs it: ``controlmm studio`` / ``controlmm view`` in a subprocess, and a
real HTTP client (the standard library's) talking to it."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

SERVING = re.compile(r"serving (http://\S+/)")


@contextmanager
def running_server(argv: list[str], env: dict[str, str], timeout: float = 180.0) -> Iterator[str]:
    """Start ``controlmm ARGV --port 0``; yield its URL once it prints it; stop it (SIGTERM) after."""
    with tempfile.TemporaryDirectory(prefix="controlmm-studio-test-") as tmp:
        log = Path(tmp) / "server.log"
        with open(log, "w") as out:
            proc = subprocess.Popen(
                [sys.executable, "-m", "controlmm", *argv, "--port", "0"],
                stdout=out,
                stderr=subprocess.STDOUT,
                env=env,
                text=True,
            )
        try:
            end = time.monotonic() + timeout
            while True:
                match = SERVING.search(log.read_text())
                if match:
                    break
                if proc.poll() is not None or time.monotonic() > end:
                    raise RuntimeError(f"the server did not start: {log.read_text()[-2000:]}")
                time.sleep(0.1)
            yield match.group(1)
        finally:
            proc.terminate()
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def call(method: str, url: str, body: Any = None, raw: bytes | None = None) -> tuple[int, Any]:
    """One HTTP request; returns (status, parsed JSON or the raw bytes of other content)."""
    data = raw if raw is not None else (json.dumps(body).encode() if body is not None else None)
    request = urllib.request.Request(url, data=data, method=method)
    if data is not None:
        request.add_header("Content-Type", "application/json")
    try:
        with urllib.request.urlopen(request, timeout=60) as res:
            status, kind, payload = res.status, res.headers.get_content_type(), res.read()
    except urllib.error.HTTPError as exc:
        status, kind, payload = exc.code, exc.headers.get_content_type(), exc.read()
    return status, json.loads(payload) if kind == "application/json" else payload


def wait_for(url: str, predicate, timeout: float = 240.0, every: float = 0.25) -> Any:
    """GET ``url`` until ``predicate(json)`` holds; returns that JSON."""
    end = time.monotonic() + timeout
    while True:
        status, data = call("GET", url)
        if status == 200 and predicate(data):
            return data
        if time.monotonic() > end:
            raise TimeoutError(f"{url}: still {data!r:.300}")
        time.sleep(every)
