"""A warm job server: a run's Snakemake jobs forked from one preloaded process.

A ``script:`` job starts a fresh interpreter that imports numpy, pandas, matplotlib, scipy and
dtwin and loads the compiled EM kernels from numba's cache before it does its work: 0.4-1.4
CPU-s a job, a third of the paper DAG's CPU time. The server pays that once per run. The
Snakefile's ``onstart`` starts it (:func:`start_server`: a process that listens on a Unix
socket in a private folder, ``mkdtemp``, mode 0700, named by :data:`SOCKET_ENV` in the
environment the jobs inherit, and meanwhile imports the modules the run's scripts import and
runs their ``warm_up``: the compiled kernels loaded, a figure drawn); ``onsuccess`` and
``onerror`` stop it (:func:`stop_server`), and it stops by itself when the Snakemake process
that started it dies.

Each job still starts as Snakemake starts it, ``python .snakemake/scripts/tmp<random>.<rule>.py``
(the copy of the script Snakemake writes under a random name).
The first thing the script does (``dtwin._script.start_rule``) is :func:`hand_over`: it sends
its argv, working folder and environment and passes its stdin, stdout and stderr (SCM_RIGHTS)
to the server, which forks. The child takes over those descriptors, the folder, the
environment and argv, and runs the same script file as ``__main__`` (the preamble, then the
script, which now goes on past ``start_rule``); an uncaught exception prints its traceback to
``sys.stderr`` (the rule's log) and exits 1, as the interpreter does, and the atexit handlers
run. The server reaps the child and sends its wait status; the job process exits with it (or
dies of the same signal), so Snakemake sees what a plain run would have shown.

When the job runs exactly as it would without the server:

- no server (cluster jobs, dry runs, ``job_server: false``, a platform without ``fork``), or
  it cannot be reached, or it refuses a job: the job runs in its own process as before
  (:func:`hand_over` returns None);
- the server refuses a job whose interpreter or environment differs from its own on anything
  but :data:`PER_JOB_ENV` (per-job temporary folders and what the shell sets): what was
  imported at preload cannot then be what the job would import (another ``threads:`` count
  gives other BLAS thread variables, a conda environment another Python);
- the server is single-threaded and its BLAS runs on one thread (it sets Snakemake's thread
  variables to 1, as Snakemake does for a ``threads: 1`` job), so forking is safe; numpy's
  legacy global random state is reseeded from the OS in each child, as a fresh process seeds
  it (dtwin draws only from Generators seeded by the config); Python's ``random`` reseeds
  itself on fork;
- if the job process is killed, the child follows: SIGTERM, SIGINT and SIGHUP are forwarded
  to it and the job process waits for its end; on SIGKILL the child sees the connection close
  and kills itself.

Not the same: Snakemake's ``benchmark:`` sampler sees only the job process, not the child
that does the work (its files undercount further; benchmarks/run.py measures the children).
"""

from __future__ import annotations

import contextlib
import gc
import importlib
import json
import os
import selectors
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
from collections.abc import Sequence
from typing import Any

__all__ = [
    "PER_JOB_ENV",
    "SOCKET_ENV",
    "THREAD_ENV",
    "hand_over",
    "serve",
    "served",
    "start_server",
    "stop_server",
]

#: Environment variable that names the running server's socket.
SOCKET_ENV = "DTWIN_JOB_SERVER"
#: Variables Snakemake sets to a job's ``threads`` (snakemake.shell); the server's are 1.
THREAD_ENV = (
    "OMP_NUM_THREADS",
    "GOTO_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
)
#: Variables that may differ between a job and the server: Snakemake's per-job temporary
#: folder and what the job's shell sets. The child takes the job's values of all of them.
PER_JOB_ENV = frozenset({"TMPDIR", "TMP", "TEMP", "TEMPDIR", "PWD", "OLDPWD", "SHLVL", "_"})

_SOCKET_NAME = "jobs.sock"
_LENGTH = struct.Struct("!Q")
_FORWARDED = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)
#: The running server of this (Snakemake) process, if :func:`start_server` started one.
_SERVER: subprocess.Popen | None = None
#: True in a job's process once the server has forked it: it runs the script itself.
_SERVED = False


# --- the Snakemake side -------------------------------------------------------------------


def start_server(modules: Sequence[str], warm_up: Sequence[str] = ()) -> str | None:
    """Start the job server for this run and name its socket in ``os.environ``.

    Parameters
    ----------
    modules : sequence of str
        Modules to preload (what the run's scripts import), in the order the jobs need them.
    warm_up : sequence of str
        Of those, the modules whose ``warm_up()`` runs right after their import (compiled
        kernels loaded, caches filled).

    Returns
    -------
    str or None
        The socket's path (it appears as soon as the server runs; jobs that start before run
        in their own process), or None where processes cannot fork (not POSIX).
    """
    global _SERVER
    if not hasattr(os, "fork") or _SERVER is not None:
        return None
    folder = tempfile.mkdtemp(prefix="dtwin-jobs-")
    path = os.path.join(folder, _SOCKET_NAME)
    env = {**os.environ, **dict.fromkeys(THREAD_ENV, "1")}
    env.pop(SOCKET_ENV, None)
    args = [sys.executable, "-m", "dtwin._job_server", path, ",".join(modules), ",".join(warm_up)]
    _SERVER = subprocess.Popen(args, env=env, stdin=subprocess.DEVNULL)
    os.environ[SOCKET_ENV] = path
    return path


def stop_server(timeout_s: float = 10.0) -> None:
    """Stop the server :func:`start_server` started (its running jobs are killed) and reap it."""
    global _SERVER
    server, _SERVER = _SERVER, None
    path = os.environ.pop(SOCKET_ENV, None)
    if server is None:
        return
    server.terminate()
    try:
        server.wait(timeout_s)
    except subprocess.TimeoutExpired:
        server.kill()
        server.wait()
    if path:
        with contextlib.suppress(OSError):
            os.unlink(path)
        with contextlib.suppress(OSError):
            os.rmdir(os.path.dirname(path))


# --- the job side -------------------------------------------------------------------------


def hand_over() -> int | None:
    """Run this job's script in a child of the job server; the child's exit status, or None.

    None when there is no server (or not yet), it cannot be reached or it refuses the job: the
    caller goes on in its own process. If the child died of a signal, this process dies of the
    same signal.
    """
    path = os.environ.get(SOCKET_ENV)
    if _SERVED or not path or not hasattr(socket, "send_fds"):
        return None
    request = {
        "argv": sys.argv,
        "cwd": os.getcwd(),
        "env": dict(os.environ),
        "executable": sys.executable,
    }
    try:
        connection = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        connection.connect(path)
        payload = json.dumps(request).encode()
        sys.stdout.flush()
        sys.stderr.flush()
        socket.send_fds(connection, [_LENGTH.pack(len(payload))], [0, 1, 2])
        connection.sendall(payload)
        replies = connection.makefile("rb")
        first = json.loads(replies.readline() or b'{"refused": "no answer"}')
    except OSError:
        return None
    if "pid" not in first:
        return None
    return _wait_for_child(first["pid"], replies)


def served() -> bool:
    """Whether this process is a job the server forked (it runs the job's script)."""
    return _SERVED


def _wait_for_child(pid: int, replies: Any) -> int:
    """Forward signals to the child ``pid`` until the server reports its end; its status."""

    def forward(signum: int, _frame: object) -> None:
        with contextlib.suppress(OSError):
            os.kill(pid, signum)

    for signum in _FORWARDED:
        signal.signal(signum, forward)
    line = b""
    while not line:
        try:
            line = replies.readline() or b'{"status": 256}'
        except InterruptedError:
            continue
    status = json.loads(line)["status"]
    if os.WIFSIGNALED(status):
        signum = os.WTERMSIG(status)
        with contextlib.suppress(OSError, ValueError):  # SIGKILL and SIGSTOP have no handler
            signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)
    return os.waitstatus_to_exitcode(status)


# --- the server ---------------------------------------------------------------------------


def serve(path: str, modules: Sequence[str], warm_up: Sequence[str]) -> None:
    """Serve jobs: fork one child per job until told to stop, preloading meanwhile.

    The socket is in place from the start (bound under a temporary name and renamed, so a job
    never finds it half set up). The modules are imported one at a time, in the order given
    (the order the run's jobs need them), each of ``warm_up`` followed by its ``warm_up()``;
    after each step the server takes the jobs that are waiting, so a job that starts during
    the preload is forked with what is loaded by then and imports the rest itself, as its own
    process would. Stops on SIGTERM, SIGINT or when its parent process dies (then its running
    children are killed).
    """
    parent = os.getppid()
    for signum in _FORWARDED:
        signal.signal(signum, _stop)
    _die_with_parent()
    running: dict[int, socket.socket] = {}
    try:
        baseline = _comparable(os.environ)
        listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        listener.bind(path + ".tmp")
        listener.listen(64)
        os.rename(path + ".tmp", path)
        selector = selectors.DefaultSelector()
        selector.register(listener, selectors.EVENT_READ)
        for name in modules:
            module = importlib.import_module(name)
            _take_jobs(listener, baseline, running, selector, timeout_s=0.0)
            if name in warm_up:
                module.warm_up()
                _take_jobs(listener, baseline, running, selector, timeout_s=0.0)
        gc.freeze()  # objects the children inherit are never collected: fewer copied pages
        while os.getppid() == parent:
            _take_jobs(listener, baseline, running, selector, timeout_s=1.0)
    except _StopError:
        pass
    finally:
        _shut_down(path, running)


def _take_jobs(
    listener: socket.socket, baseline: dict, running: dict, selector: Any, timeout_s: float
) -> None:
    """Accept the jobs that are waiting and report the children that ended (up to ``timeout_s``)."""
    for key, _ in selector.select(timeout=timeout_s):
        if key.fileobj is listener:
            _accept(listener, baseline, running, selector)
        else:
            _reap(key, running, selector)


def _shut_down(path: str, running: dict[int, socket.socket]) -> None:
    """Kill the running children and remove the socket and its folder (signals ignored)."""
    for signum in _FORWARDED:
        signal.signal(signum, signal.SIG_IGN)
    for pid in running:
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)
    for remove, name in (
        (os.unlink, path),
        (os.unlink, path + ".tmp"),
        (os.rmdir, os.path.dirname(path)),
    ):
        with contextlib.suppress(OSError):
            remove(name)


class _StopError(Exception):
    """Raised in the server by SIGTERM, SIGINT or SIGHUP."""


def _stop(_signum: int, _frame: object) -> None:
    raise _StopError


def _die_with_parent() -> None:
    """Ask Linux to send SIGTERM when the parent exits (prctl PR_SET_PDEATHSIG)."""
    with contextlib.suppress(OSError, AttributeError):
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM))


def _receive(connection: socket.socket) -> tuple[dict, list[int]]:
    """Read a job's request and its three descriptors."""
    head, fds, _, _ = socket.recv_fds(connection, _LENGTH.size, 3)
    (length,) = _LENGTH.unpack(head)
    payload = bytearray()
    while len(payload) < length:
        chunk = connection.recv(length - len(payload))
        if not chunk:
            raise OSError("the job closed its connection")
        payload += chunk
    return json.loads(payload), fds


def _comparable(env: Any) -> dict[str, str]:
    """Return the variables of ``env`` a job must share with the server."""
    return {k: v for k, v in env.items() if k not in PER_JOB_ENV and k != SOCKET_ENV}


def _refusal(request: dict, baseline: dict) -> str | None:
    """Why the server cannot run this job as its own process would, or None."""
    if request["executable"] != sys.executable:
        return f"another interpreter ({request['executable']})"
    differing = set(_comparable(request["env"]).items()) ^ set(baseline.items())
    if differing:
        return "another environment: " + ", ".join(sorted({key for key, _ in differing}))
    return None


def _accept(listener: socket.socket, baseline: dict, running: dict, selector: Any) -> None:
    """Take one job: refuse it, or fork its child and watch for the child's end.

    ``baseline``: the server's environment before it imported anything (without
    :data:`PER_JOB_ENV`), which a job's must equal; the child adds the variables the imports
    so far have set (scikit-learn's ``KMP_*``: a job importing them sets them).
    """
    connection, _ = listener.accept()
    fds: list[int] = []
    try:
        connection.settimeout(10.0)
        request, fds = _receive(connection)
        reason = _refusal(request, baseline)
        if reason is None and len(fds) != 3:
            reason = "stdin, stdout and stderr not received"
        if reason is not None:
            connection.sendall(json.dumps({"refused": reason}).encode() + b"\n")
            connection.close()
            return
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            for other in [*running.values(), listener]:
                other.close()
            for other in selector.get_map().values():
                if isinstance(other.fileobj, int):
                    os.close(other.fileobj)
            selector.close()
            added = {k: v for k, v in os.environ.items() if k not in baseline}
            added.pop(SOCKET_ENV, None)
            request["env"] = {**added, **request["env"]}
            _run_child(connection, request, fds)  # never returns
        connection.sendall(json.dumps({"pid": pid}).encode() + b"\n")
    except OSError:
        connection.close()
        return
    finally:
        for fd in fds:
            os.close(fd)
    running[pid] = connection
    selector.register(os.pidfd_open(pid), selectors.EVENT_READ, pid)


def _reap(key: Any, running: dict, selector: Any) -> None:
    """Send a finished child's wait status to its job."""
    selector.unregister(key.fileobj)
    os.close(key.fileobj)
    _, status = os.waitpid(key.data, 0)
    connection = running.pop(key.data)
    with contextlib.suppress(OSError):
        connection.sendall(json.dumps({"status": status}).encode() + b"\n")
    connection.close()


# --- the child ----------------------------------------------------------------------------


def _run_child(connection: socket.socket, request: dict, fds: list[int]) -> None:
    """In the forked child: become the job's process, run its script, exit with its status."""
    global _SERVED
    _SERVED = True
    for signum in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    for target, fd in enumerate(fds):
        os.dup2(fd, target)
    for fd in fds:
        if fd > 2:
            os.close(fd)
    os.chdir(request["cwd"])
    os.environ.clear()
    os.environ.update(request["env"])
    tempfile.tempdir = None
    sys.argv = list(request["argv"])
    sys.path[0] = os.path.dirname(os.path.abspath(sys.argv[0]))
    if "numpy" in sys.modules:
        sys.modules["numpy"].random.seed()
    connection.settimeout(None)
    threading.Thread(target=_die_with_job, args=(connection,), daemon=True).start()
    status = _run_main(sys.argv[0])
    os._exit(status)


def _die_with_job(connection: socket.socket) -> None:
    """Kill this child when its job process is gone (its end of the connection closed)."""
    with contextlib.suppress(OSError):
        while connection.recv(1):
            pass
    os.kill(os.getpid(), signal.SIGKILL)


def _run_main(path: str) -> int:
    """Run the file ``path`` as ``__main__`` as the interpreter would; the exit status."""
    import atexit
    import builtins
    import types

    main = types.ModuleType("__main__")
    main.__file__ = path
    main.__builtins__ = builtins
    sys.modules["__main__"] = main
    try:
        with open(path, "rb") as handle:
            code = compile(handle.read(), path, "exec")
        exec(code, main.__dict__)
        status = 0
    except SystemExit as stop:
        status = _exit_status(stop)
    except BaseException:
        sys.excepthook(*sys.exc_info())
        status = 1
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    return status


def _exit_status(stop: SystemExit) -> int:
    """Return the status the interpreter exits with on an uncaught ``SystemExit``."""
    if stop.code is None:
        return 0
    if isinstance(stop.code, int):
        return stop.code & 0xFF
    print(stop.code, file=sys.stderr)
    return 1


def main(argv: Sequence[str]) -> None:
    """``python -m dtwin._job_server SOCKET MODULE,... WARM_UP_MODULE,...``: :func:`serve`."""
    path, modules, warm_up = argv
    serve(path, [m for m in modules.split(",") if m], [m for m in warm_up.split(",") if m])


if __name__ == "__main__":
    # through the imported module, so that the children's dtwin._job_server is this one
    from dtwin import _job_server

    _job_server.main(sys.argv[1:])
