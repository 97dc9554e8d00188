"""The warm job server (dtwin/_job_server.py) with small scripts in place of Snakemake jobs.

A job script here does what ``dtwin._script.start_rule`` does first (``hand_over``), then its
work; the server preloads numpy only. The workflow's own byte-identity check (a run through the
server against one without it) is tests/workflow/test_workflow.py's
test_rerun_gives_byte_identical_tables_and_figures.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from dtwin import _job_server
from tests.conftest import REPO

#: The start of every job script: hand over to the server, or go on here.
HAND_OVER = (
    "import sys\n"
    "from dtwin import _job_server\n"
    "status = _job_server.hand_over()\n"
    "if status is not None:\n"
    "    raise SystemExit(status)\n"
)
#: A job that says where it ran and draws from numpy's global random state.
REPORT = (
    "import os, numpy\n"
    "print('served' if _job_server._SERVED else 'own process', os.getcwd(), sys.argv[1:])\n"
    "print('draw', numpy.random.random())\n"
)


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """A running server (numpy preloaded) and the environment its jobs get."""
    before = dict(os.environ)
    os.environ["PYTHONPATH"] = str(REPO)
    try:
        path = _job_server.start_server(["numpy"])
        deadline = time.monotonic() + 120
        while not os.path.exists(path):
            assert time.monotonic() < deadline, "the job server did not start"
            time.sleep(0.05)
        env = {**os.environ, **dict.fromkeys(_job_server.THREAD_ENV, "1")}
        yield path, env
    finally:
        _job_server.stop_server()
        os.environ.clear()
        os.environ.update(before)
    assert not os.path.exists(os.path.dirname(path)), "the server's folder is left behind"


def run_job(folder: Path, body: str, env: dict, *args: str) -> subprocess.CompletedProcess:
    """Run a job script (``HAND_OVER`` + ``body``) in ``folder`` with ``env``."""
    script = folder / "job.py"
    script.write_text(HAND_OVER + body)
    return subprocess.run(
        [sys.executable, str(script), *args],
        cwd=folder,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_a_served_job_runs_in_its_folder_with_its_argv_and_output(server, tmp_path):
    _, env = server
    done = run_job(tmp_path, REPORT, env, "a", "b")
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(f"served {tmp_path} ['a', 'b']\n")


def test_two_jobs_at_once_each_get_their_own_random_state(server, tmp_path):
    _, env = server
    folders = [tmp_path / "one", tmp_path / "two"]
    results: dict[int, subprocess.CompletedProcess] = {}

    def job(index: int) -> None:
        folders[index].mkdir()
        body = REPORT + "import time; time.sleep(1)\n"
        results[index] = run_job(folders[index], body, env)

    threads = [threading.Thread(target=job, args=(i,)) for i in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    lines = [results[i].stdout.splitlines() for i in range(2)]
    assert [line[0].split()[0] for line in lines] == ["served", "served"]
    assert lines[0][1] != lines[1][1], "forked jobs share numpy's global random state"


def test_a_failing_job_fails_with_its_traceback(server, tmp_path):
    _, env = server
    done = run_job(tmp_path, "print('before')\n1 / 0\n", env)
    assert done.returncode == 1
    assert done.stdout == "before\n"
    assert "Traceback" in done.stderr and "ZeroDivisionError: division by zero" in done.stderr
    assert 'job.py", line 7' in done.stderr  # the script's own file and line
    assert run_job(tmp_path, "sys.exit(3)\n", env).returncode == 3
    killed = run_job(tmp_path, "import os, signal\nos.kill(os.getpid(), signal.SIGKILL)\n", env)
    assert killed.returncode == -signal.SIGKILL


def test_atexit_handlers_of_a_served_job_run(server, tmp_path):
    _, env = server
    body = "import atexit\natexit.register(print, 'at exit')\nprint('work')\n"
    assert run_job(tmp_path, body, env).stdout == "work\nat exit\n"


def test_without_a_server_or_when_refused_the_job_runs_in_its_own_process(server, tmp_path):
    path, env = server
    refused = {**env, "OPENBLAS_NUM_THREADS": "2"}  # a rule with threads: 2
    missing = {**env, _job_server.SOCKET_ENV: path + ".missing"}
    off = {k: v for k, v in env.items() if k != _job_server.SOCKET_ENV}
    for other in (refused, missing, off):
        done = run_job(tmp_path, REPORT, other)
        assert done.returncode == 0, done.stderr
        assert done.stdout.startswith("own process")


def test_the_server_stops_with_the_process_that_started_it(tmp_path):
    starter = (
        "import os, time\n"
        "from dtwin import _job_server\n"
        "path = _job_server.start_server(['json'])\n"
        "print(path, _job_server._SERVER.pid, flush=True)\n"
        "while not os.path.exists(path):\n"
        "    time.sleep(0.05)\n"
        "print('ready', flush=True)\n"
        "time.sleep(60)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    process = subprocess.Popen(
        [sys.executable, "-c", starter], env=env, stdout=subprocess.PIPE, text=True
    )
    path, pid = process.stdout.readline().split()
    assert process.stdout.readline() == "ready\n"
    process.kill()
    process.wait()
    deadline = time.monotonic() + 10
    while os.path.exists(os.path.dirname(path)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not os.path.exists(os.path.dirname(path)), "the server's folder is left behind"
    while is_running(int(pid)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not is_running(int(pid)), "the server outlived the process that started it"


def is_running(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
    return "\nState:\tZ" not in status
