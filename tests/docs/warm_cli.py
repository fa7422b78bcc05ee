"""A ``hybridev`` command for the docs tests that does not import torch for every call.

A page of the docs is run as a bash script that calls ``hybridev`` several times;
each call in a new interpreter pays about 4 CPU-seconds of imports (torch,
scikit-learn, scipy, pandas, matplotlib) and a second to load the compiled
physics kernel, which is most of what a small fit costs. In the default suite
the ``hybridev`` on the script's ``PATH`` is instead a thin client of one
*warm* server process (started by the test, with those modules imported):
for every call the server forks, and the child runs
``hybridev.cli.main(argv)`` with the caller's working directory, environment,
stdin, stdout and stderr (the client's file descriptors, passed over a Unix
socket), and the server hands the child's exit status back to the client, which
exits with it. A page's python blocks (``"$HYBRIDEV_PYTHON" -`` with the program
on stdin) run the same way, with the program compiled and run as ``__main__`` in the
forked child (its imports still have to be written: the server's modules are
loaded, not in the program's namespace). The scripts themselves run verbatim; only the interpreter's
start-up is shared. The slow tests (``test_page_runs_as_written``, the guide on
the real trips) and ``tests/cli`` keep running the real console command in a
fresh process.

The server's children are waited for, so their CPU time is counted in the
server's, and the server's in the test process's when it is stopped.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

__all__ = ["WarmCli", "client_argv", "client_main", "hybridev_bin", "serve"]

_MAX_MSG = 1 << 22


def _recv_all(conn: socket.socket) -> bytes:
    chunks = []
    while True:
        data = conn.recv(65536)
        if not data:
            return b"".join(chunks)
        chunks.append(data)


def serve(sock_path: str) -> None:
    """Import the heavy modules, then run one forked ``main(argv)`` per connection."""
    import tempfile

    import matplotlib

    matplotlib.use("Agg")
    import hybridev.apps.demo  # the apps and their plotting
    import hybridev.learning.model  # noqa: F401  (torch, scikit-learn, scipy)
    from hybridev import make_trips, trip_stats
    from hybridev.cli.main import main

    trip_stats(make_trips(2, seed=0), n_steps=20)  # loads the compiled kernel
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    srv.bind(sock_path)
    srv.listen(4)
    sys.stdout.write("ready\n")
    sys.stdout.flush()
    while True:
        conn, _ = srv.accept()
        msg, fds, _, _ = socket.recv_fds(conn, _MAX_MSG, 3)
        request = json.loads(msg)
        if request.get("stop"):
            for fd in fds:
                os.close(fd)
            conn.close()
            break
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:  # the child: become the caller's process, run the command
            srv.close()
            conn.close()
            for target, fd in enumerate(fds):
                os.dup2(fd, target)
                os.close(fd)
            os.chdir(request["cwd"])
            os.environ.clear()
            os.environ.update(request["env"])
            tempfile.tempdir = None  # TMPDIR is the caller's
            try:
                if request.get("python"):  # ``python -``: the program is on stdin
                    sys.argv = ["-"]
                    sys.path[0] = ""
                    code = compile(sys.stdin.read(), "<stdin>", "exec")
                    exec(code, {"__name__": "__main__", "__builtins__": __builtins__})
                    rc = 0
                else:
                    sys.argv = ["hybridev", *request["argv"]]
                    rc = main(request["argv"])
            except SystemExit as exc:
                rc = exc.code
            except BaseException:
                import traceback

                traceback.print_exc()
                rc = 1
            if rc is None:
                rc = 0
            elif not isinstance(rc, int):
                print(rc, file=sys.stderr)
                rc = 1
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(rc)
        for fd in fds:
            os.close(fd)
        _, status = os.waitpid(pid, 0)
        rc = os.waitstatus_to_exitcode(status)
        conn.sendall(str(rc if rc >= 0 else 128 - rc).encode())
        conn.close()
    srv.close()


def client_main(sock_path: str, argv: list[str], python: bool = False) -> int:
    """Send ``argv``, the working directory, the environment and fds 0-2; return the exit code.

    ``python``: run the program on stdin (``python -``) instead of ``hybridev argv``.
    """
    conn = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    conn.connect(sock_path)
    msg = json.dumps({"argv": argv, "cwd": os.getcwd(), "env": dict(os.environ),
                      "python": python}).encode()
    socket.send_fds(conn, [msg], [0, 1, 2])
    conn.shutdown(socket.SHUT_WR)
    answer = _recv_all(conn)
    conn.close()
    return int(answer) if answer else 1


def _default_signals() -> None:
    """SIGINT and SIGTERM as in an interactive shell (a background job ignores SIGINT)."""
    import signal

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_DFL)


def client_argv(warm: WarmCli, argv: list[str], python: bool = False) -> list[str]:
    """The command line of one call of ``hybridev argv`` (or ``python -``) through ``warm``."""
    return [sys.executable, "-S", "-E", __file__, "python" if python else "client", warm.sock,
            *argv]


def hybridev_bin(workdir: Path, warm: WarmCli | None = None) -> Path:
    """``workdir/bin`` holding a ``hybridev`` command for ``PATH``: a fresh interpreter per
    call, or the client of the warm server ``warm``."""
    bin_dir = workdir / "bin"
    bin_dir.mkdir()
    if warm is None:
        shim = bin_dir / "hybridev"
        shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m hybridev.cli "$@"\n')
        shim.chmod(0o755)
    else:
        warm.write_shim(bin_dir)
    return bin_dir


class WarmCli:
    """The warm server (a child process) and the ``hybridev`` client script for a ``PATH``."""

    def __init__(self, folder: Path, env: dict[str, str]):
        folder.mkdir(parents=True, exist_ok=True)
        self.sock = str(folder / "hybridev.sock")
        self.proc = subprocess.Popen(  # the signals' default actions, as a terminal gives
            [sys.executable, __file__, "serve", self.sock], env=env, stdout=subprocess.PIPE,
            text=True, preexec_fn=_default_signals)
        line = self.proc.stdout.readline()
        if line.strip() != "ready":
            self.proc.wait(timeout=60)
            raise RuntimeError(f"the warm hybridev server did not start: {line!r}")

    def write_shim(self, bin_dir: Path) -> None:
        """``bin_dir/hybridev``: the client, in an interpreter without site imports."""
        shim = bin_dir / "hybridev"
        shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" -S -E "{__file__}" client '
                        f'"{self.sock}" "$@"\n')
        shim.chmod(0o755)

    def write_python(self, bin_dir: Path) -> Path:
        """``bin_dir/python-warm``: ``python -`` (a program on stdin) run by the server."""
        shim = bin_dir / "python-warm"
        shim.write_text(f'#!/bin/sh\n[ "$#" = 1 ] && [ "$1" = - ] || exec "{sys.executable}" "$@"\n'
                        f'exec "{sys.executable}" -S -E "{__file__}" python "{self.sock}"\n')
        shim.chmod(0o755)
        return shim

    def close(self) -> None:
        if self.proc.poll() is None:
            conn = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            conn.connect(self.sock)
            socket.send_fds(conn, [json.dumps({"stop": True}).encode()], [0, 1, 2])
            conn.close()
            deadline = time.monotonic() + 30
            while self.proc.poll() is None and time.monotonic() < deadline:
                time.sleep(0.05)
            if self.proc.poll() is None:
                self.proc.kill()
        self.proc.wait()
        self.proc.stdout.close()


if __name__ == "__main__":
    if sys.argv[1] == "serve":
        serve(sys.argv[2])
    else:
        sys.exit(client_main(sys.argv[2], sys.argv[3:], python=sys.argv[1] == "python"))
