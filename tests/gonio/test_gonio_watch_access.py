"""The live view lets in only whoever holds its key, and no client can tie it up: the attack
of issue 34 (curl's POST to /control/abort without the key, as root and as `nobody`) leaves
the scan measuring; the key by query and by its cookie (HttpOnly, SameSite=Strict); framing
errors answered at once; idle connections beyond the cap cost no thread and keep no keyed
client out; a slow request closed at its deadline; accept errors (out of descriptors) back
off without a traceback; every token hint passes the token on stdin or in a file."""

import http.client
import json
import os
import re
import socket
import subprocess
import sys
import threading
from urllib.parse import urlsplit

import pytest
from gonio_testkit import ROOT, gonio_cli, one_line_error
from waiting import wait_until
from watch_testkit import plan_file, scanning

from gonio.runner import new_scan
from gonio.store import open_run
from gonio_watch.gate import Limits
from gonio_watch.viewer import serving

NOBODY = 65534
TOKEN_AS_ARGUMENT = re.compile(r"--token(=|\s+)(?!-(\s|$))\S")  # `--token T`, as ps shows it


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """A completed all-emulated run (instant motion) for the viewer to serve."""
    folder = tmp_path_factory.mktemp("access")
    result = new_scan(plan_file(folder), sim=True, out=folder / "runs", progress=False)
    assert result.outcome.status == "completed"
    return result.path


def request(port, path, method="GET", headers=(), body=None):
    """(status, headers, body) of one plain HTTP request to 127.0.0.1:port."""
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    conn.request(method, path, body=body, headers=dict(headers))
    reply = conn.getresponse()
    out = reply.status, reply.headers, reply.read()
    conn.close()
    return out


def raw(port, data: bytes) -> tuple[bytes, bytes]:
    """Send bytes on a new connection: (what came back until the server closed it, and what
    a read after that gives: b"" once it is closed)."""
    with socket.create_connection(("127.0.0.1", port), timeout=30) as sock:
        sock.sendall(data)
        reply = b""
        while chunk := sock.recv(65536):
            reply += chunk
        return reply, sock.recv(1)


def curl_abort(url: str, as_nobody: bool = False) -> int:
    """The attack, as issue 34 gives it: curl's plain JSON POST to /control/abort without the
    key; the HTTP status it got."""
    parts = urlsplit(url)
    done = subprocess.run(
        ["curl", "-s", "-o", "/dev/null", "-w", "%{http_code}", "-X", "POST",
         "-H", "Content-Type: application/json", "-d", "{}",
         f"http://{parts.netloc}/control/abort"],
        capture_output=True, text=True, timeout=60,
        preexec_fn=(lambda: (os.setgroups([]), os.setgid(NOBODY), os.setuid(NOBODY)))
        if as_nobody else None)
    return int(done.stdout)


def watched_scan_survives(tmp_path, as_nobody: bool) -> None:
    """A `gonio scan --watch` attacked through its viewer without the key: 401, and the scan
    completes every planned reading; its token hint teaches stdin or a file only."""
    with scanning(plan_file(tmp_path, 15.0), tmp_path / "runs", "--watch") as scan:
        line = wait_until(lambda: [ln for ln in scan.stderr
                                   if ln.startswith("gonio scan: watch ")],
                          what="the viewer's URL line")[0]
        url = line.split()[-1]
        parts = urlsplit(url)
        keyed = f"/status.json?{parts.query}"
        wait_until(lambda: request(parts.port, keyed)[0] == 200, what="the viewer")
        doc = json.loads(request(parts.port, keyed)[2])
        assert doc["control"]["enabled"] and doc["readings"] < doc["planned"]
        assert curl_abort(url, as_nobody) == 401
        assert request(parts.port, "/status.json")[0] == 401
        assert scan.proc.wait(timeout=120) == 0
    run = open_run(scan.run_dir)
    assert run.meta["status"] == "completed" and len(run) == run.meta["planned"]
    hints = [ln for ln in scan.stderr if "--token" in ln]
    assert hints and all("--token -" in ln and not TOKEN_AS_ARGUMENT.search(ln)
                         for ln in hints), hints


def test_the_attack_without_the_key_leaves_the_scan_measuring(tmp_path):
    watched_scan_survives(tmp_path, as_nobody=False)


@pytest.mark.skipif(os.geteuid() != 0, reason="another user's attack needs root to become "
                                               "`nobody` (uid 65534) for curl")
def test_another_users_attack_leaves_the_scan_measuring(tmp_path):
    watched_scan_survives(tmp_path, as_nobody=True)


def test_the_key_by_query_then_by_its_cookie(run_dir):
    with serving(run_dir) as server:
        port, access = server.port, server.access
        for path in ("/", "/status.json", "/data.json", "/model.json?keys=0|reflection",
                     "/nothing", f"/status.json?key={access.key[:-1]}"):
            status, headers, body = request(port, path)
            assert status == 401 and "Set-Cookie" not in headers, path
            assert "its key" in json.loads(body)["error"]
        for asset in ("/watch.js", "/plot.js", "/watch.css"):
            assert request(port, asset)[0] == 200  # nothing of the run in them
        status, headers, page = request(port, urlsplit(server.keyed_url).path + "?"
                                        + urlsplit(server.keyed_url).query)
        assert status == 200 and b'id="readings"' in page
        cookie = headers["Set-Cookie"]
        attributes = {a.strip() for a in cookie.split(";")[1:]}
        assert attributes == {"HttpOnly", "SameSite=Strict", "Path=/"}
        pair = cookie.split(";")[0]
        assert pair == f"{access.cookie_name}={access.key}"
        for path in ("/", "/status.json", "/data.json?since=3"):
            status, headers, _ = request(port, path, headers=[("Cookie", f"a=b; {pair}")])
            assert status == 200 and "Set-Cookie" not in headers, path
        other = f"gonio_watch_{port + 1}={access.key}"  # another viewer's cookie name
        assert request(port, "/status.json", headers=[("Cookie", other)])[0] == 401
        json_post = [("Content-Type", "application/json")]
        assert request(port, "/control/abort", "POST", json_post, "{}")[0] == 401
        status, _, body = request(port, "/control/abort", "POST",
                                  [*json_post, ("Cookie", pair)], "{}")
        assert status == 403 and "--token -" in json.loads(body)["error"]  # keyed, no token


@pytest.mark.parametrize("length, status", [
    ("-1", 400), ("abc", 400), ("99999999999999999999", 413), ("5000", 413), (None, 411)])
def test_a_bad_content_length_is_answered_at_once(run_dir, length, status):
    with serving(run_dir) as server:
        threads = set(threading.enumerate())  # another test's thread may end meanwhile
        head = (f"POST /control/abort?key={server.access.key} HTTP/1.1\r\n"
                f"Host: 127.0.0.1:{server.port}\r\nContent-Type: application/json\r\n"
                + (f"Content-Length: {length}\r\n" if length is not None else "") + "\r\n")
        reply, after = raw(server.port, head.encode())
        assert reply.startswith(f"HTTP/1.1 {status} ".encode()) and after == b""
        assert server.gate.counts["refused"] == 1 and server.gate.counts["answered"] == 0
        assert set(threading.enumerate()) <= threads  # no thread was ever held for it


def test_idle_connections_beyond_the_cap_keep_no_keyed_client_out(run_dir):
    cap = 8
    with serving(run_dir, limits=Limits(connections=cap, request_s=600.0)) as server:
        threads = set(threading.enumerate())  # another test's thread may end meanwhile
        idle = [socket.create_connection(("127.0.0.1", server.port)) for _ in range(6 * cap)]
        try:
            wait_until(lambda: server.gate.counts["accepted"] == len(idle),
                       what="every idle connection accepted")
            assert set(threading.enumerate()) <= threads  # a connection costs no thread
            assert server.gate.counts["evicted"] == len(idle) - cap
            status, _, body = request(server.port, f"/status.json?key={server.access.key}")
            assert status == 200 and json.loads(body)["status"] == "completed"
        finally:
            for sock in idle:
                sock.close()


def test_a_request_that_never_completes_is_closed_at_its_deadline(run_dir):
    with serving(run_dir, limits=Limits(request_s=0.2)) as server:
        reply, after = raw(server.port, b"GET /status.json HTTP/1.1\r\nHost: 127.0.0.1")
        assert reply.startswith(b"HTTP/1.1 408 ") and after == b""
        assert server.gate.counts["expired"] == 1


OUT_OF_DESCRIPTORS = r"""
import json, os, resource, sys
sys.path.insert(0, sys.argv[2])
from waiting import wait_until
from gonio_watch.viewer import serving

with serving(sys.argv[1]) as server:
    gate = server.gate
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (len(os.listdir("/proc/self/fd")) + 8, hard))
    spare = []
    try:
        while True:
            spare.append(os.open(os.devnull, os.O_RDONLY))
    except OSError:
        pass
    print(server.port, server.access.key, flush=True)
    wait_until(lambda: gate.counts["accept_errors"] >= 6, what="six accept errors")
    stuck = dict(gate.counts)
    for fd in spare:
        os.close(fd)
    wait_until(lambda: gate.counts["answered"] >= 1, what="the waiting client answered")
    print(json.dumps(stuck), flush=True)
"""


def test_accept_errors_back_off_without_a_traceback(run_dir):
    proc = subprocess.Popen([sys.executable, "-c", OUT_OF_DESCRIPTORS, str(run_dir),
                             str(ROOT / "tests")], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    port, key = proc.stdout.readline().split()
    status, _, body = request(int(port), f"/status.json?key={key}")  # waits in the backlog
    stuck = json.loads(proc.stdout.readline())
    assert proc.wait(timeout=60) == 0
    err = proc.stderr.read()
    assert status == 200 and json.loads(body)["status"] == "completed"
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    assert "cannot accept a connection (Too many open files)" in err
    # each error rested the listener, twice as long as the last (0.01 s up to 1 s): the
    # script, looking every 2 ms, sees the sixth error, not the thousands a spinning loop makes
    # by then; and the gate woke a few times per error, no more
    assert 6 <= stuck["accept_errors"] <= 12, stuck
    assert stuck["rounds"] <= 3 * stuck["accept_errors"] + 5, stuck


def test_the_token_is_taken_only_from_stdin_or_a_private_file(run_dir, tmp_path):
    given = gonio_cli("watch", run_dir, "--token", "0123456789abcdef")
    assert given.returncode == 2 and "visible to every user in ps" in given.stderr
    assert "0123456789abcdef" not in given.stderr
    token = tmp_path / "token"
    token.write_text("t0ken\n")
    token.chmod(0o644)
    shared = gonio_cli("watch", run_dir, "--token-file", token)
    assert shared.returncode == 2 and "chmod 600" in one_line_error(shared.stderr)
    token.chmod(0o600)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "gonio_cli", "watch", str(run_dir),
                             "--token-file", str(token), "--until-eof"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    url = proc.stdout.readline().strip()
    assert re.fullmatch(r"http://127\.0\.0\.1:\d+/\?key=[\w-]{43}", url), url
    parts = urlsplit(url)
    doc = json.loads(request(parts.port, f"/status.json?{parts.query}")[2])
    assert doc["control"]["why"] != "" and "--token" not in doc["control"]["why"]  # a token
    proc.stdin.close()
    assert proc.wait(timeout=30) == 0 and "t0ken" not in proc.stderr.read()


def test_a_token_file_that_is_a_fifo_is_one_error_not_a_hang(run_dir, tmp_path):
    """The attack: `--token-file FIFO` waited forever for a writer (the subprocess timeout
    only guards against that hang)."""
    fifo = tmp_path / "token"
    os.mkfifo(fifo, 0o600)
    done = gonio_cli("watch", run_dir, "--token-file", fifo, timeout=60)
    assert done.returncode == 2
    assert f"{fifo}: token file must be a regular file, not a FIFO" in one_line_error(done.stderr)


@pytest.mark.skipif(os.geteuid() != 0, reason="making a file another user's needs root")
def test_a_token_file_another_user_owns_is_refused(run_dir, tmp_path):
    token = tmp_path / "token"
    token.write_text("t0ken\n")
    token.chmod(0o600)
    os.chown(token, NOBODY, NOBODY)
    done = gonio_cli("watch", run_dir, "--token-file", token)
    assert done.returncode == 2 and f"owned by uid {NOBODY}" in one_line_error(done.stderr)


def test_open_gives_the_browser_no_key_on_its_command_line(run_dir, tmp_path):
    seen = tmp_path / "browser.txt"
    browser = tmp_path / "browser.py"  # a stand-in browser: records its arguments and the page
    browser.write_text("import pathlib, stat, sys\n"
                       "page = pathlib.Path(sys.argv[1].removeprefix('file://'))\n"
                       f"pathlib.Path({str(seen)!r}).write_text(' '.join(sys.argv[1:]) + '\\n'"
                       " + oct(stat.S_IMODE(page.stat().st_mode)) + '\\n' + page.read_text())\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT), "BROWSER": f"{sys.executable} {browser} %s"}
    proc = subprocess.Popen([sys.executable, "-m", "gonio_cli", "watch", str(run_dir), "--open",
                             "--until-eof"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True, env=env)
    url = proc.stdout.readline().strip()
    arguments, mode, page = wait_until(lambda: seen.exists() and seen.read_text().count("\n")
                                       >= 2 and seen.read_text().split("\n", 2),
                                       what="the browser's record")
    key = urlsplit(url).query.removeprefix("key=")
    assert key not in arguments and arguments.startswith("file://") and mode == "0o600"
    assert f'url={url}"' in page
    proc.stdin.close()
    assert proc.wait(timeout=30) == 0
    assert not os.path.exists(arguments.removeprefix("file://"))  # gone with the viewer
