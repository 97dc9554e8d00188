"""CPU time of each Snakemake job, as the kernel accounts it (`make bench`, benchmarks/run.py).

benchmarks/run.py puts this folder first on ``PYTHONPATH`` and sets ``DTWIN_CPU_LOG`` to a
folder. A Python process started under it that runs a Snakemake ``script:`` job (its script
lives in ``.snakemake/scripts/``) forks at start-up: the child runs the job, and the parent
waits for it with :func:`os.wait4` and writes the child's user + system CPU seconds, peak
memory, wall seconds (interpreter start-up and shut-down included, like every child it reaped)
and end time, then exits with the child's status. The child writes its rule and wildcards (read
from the ``snakemake`` object) at exit. Any other Python process (Snakemake itself) writes its
own CPU and that of the children it reaped at exit, except a process forked from it (a child
of dtwin's job server, which runs a job's script: dtwin/_job_server.py), which writes the
job's rule and wildcards and its own usage, marked ``served``. Unlike Snakemake's
``benchmark:`` files (a sampler that stops after ~15 s and takes no sample at exit) this is
the kernel's own account.
Without ``DTWIN_CPU_LOG`` this does nothing.
"""

import atexit
import json
import os
import resource
import sys
import time

_FOLDER = os.environ.get("DTWIN_CPU_LOG")
_START = time.perf_counter()
_PID = os.getpid()
_JOB_SCRIPT = os.sep + os.path.join(".snakemake", "scripts") + os.sep


def _write(name: str, record: dict) -> None:
    with open(os.path.join(_FOLDER, name), "w", encoding="utf-8") as handle:
        handle.write(json.dumps(record) + "\n")


def _cpu(usage: resource.struct_rusage) -> float:
    return round(usage.ru_utime + usage.ru_stime, 3)


def _job_identity() -> None:
    """At the job's exit: its rule and wildcards, under its pid."""
    smk = getattr(sys.modules.get("__main__"), "snakemake", None)
    if smk is not None:
        wildcards = {key: str(value) for key, value in smk.wildcards.items()}
        _write(f"job-{os.getpid()}.json", {"rule": smk.rule, "wildcards": wildcards})


def _process_totals() -> None:
    """At a non-job process's exit: its own CPU and its reaped children's; in a child forked
    from it (a job the job server runs), the job's identity and the child's own usage."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    if os.getpid() != _PID:
        _job_identity()
        record = {"served": True, "cpu_s": _cpu(own), "max_rss_mb": round(own.ru_maxrss / 1024, 1)}
        _write(f"usage-{os.getpid()}.json", record)
        return
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    record = {"argv": sys.argv[:3], "cpu_s": _cpu(own), "children_cpu_s": _cpu(children)}
    _write(f"process-{os.getpid()}.json", record)


def _measure_job() -> None:
    """Fork; the parent reports the child's kernel-accounted usage and exits as it did."""
    pid = os.fork()
    if pid == 0:
        atexit.register(_job_identity)
        return
    _, status, usage = os.wait4(pid, 0)
    record = {
        "pid": pid,
        "cpu_s": _cpu(usage),
        "max_rss_mb": round(usage.ru_maxrss / 1024, 1),
        "wall_s": round(time.perf_counter() - _START, 3),
        "end_epoch_s": time.time(),
    }
    _write(f"usage-{pid}.json", record)
    code = os.waitstatus_to_exitcode(status)
    os._exit(code if code >= 0 else 128 - code)


if _FOLDER:
    if sys.argv and _JOB_SCRIPT in sys.argv[0]:
        _measure_job()
    else:
        atexit.register(_process_totals)
