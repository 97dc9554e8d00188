"""Start-up of a Snakemake script: hand the job to the job server, or log to the rule's log.

Imported first by every script in ``scripts/`` (it imports nothing heavy), so warnings
raised while numpy or matplotlib load end up in the log too, and a job the run's job server
(:mod:`dtwin._job_server`) takes over has loaded nothing the server had preloaded.
"""

from __future__ import annotations

import logging
import sys
from typing import Any

from dtwin._job_server import hand_over, served

__all__ = ["start_rule"]


def start_rule(snakemake: Any) -> None:
    """Redirect ``sys.stderr`` to ``snakemake.log[0]`` and log INFO records there.

    If the run's job server takes the job, its forked child runs this script from the top and
    this process exits with the child's status (``SystemExit``) instead of returning.
    """
    status = hand_over()
    if status is not None:
        raise SystemExit(status)
    sys.stderr = open(snakemake.log[0], "w", buffering=1)  # noqa: SIM115 - lives as long as the job
    logging.basicConfig(
        stream=sys.stderr,
        level=logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    # matplotlib's PDF backend subsets fonts with fontTools, which logs every table at INFO
    logging.getLogger("fontTools").setLevel(logging.WARNING)
    where = " (forked from the job server)" if served() else ""
    logging.getLogger(__name__).info("rule %s started%s", getattr(snakemake, "rule", "?"), where)
