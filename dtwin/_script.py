"""Start-up of a Snakemake script: send stderr and log records to the rule's log file.

Imported first by every script in ``scripts/`` (it imports nothing heavy), so warnings
raised while numpy or matplotlib load end up in the log too.
"""

from __future__ import annotations

import logging
import sys
from typing import Any

__all__ = ["start_rule"]


def start_rule(snakemake: Any) -> None:
    """Redirect ``sys.stderr`` to ``snakemake.log[0]`` and log INFO records there."""
    sys.stderr = open(snakemake.log[0], "w", buffering=1)  # noqa: SIM115 - lives as long as the job
    logging.basicConfig(
        stream=sys.stderr,
        level=logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    # matplotlib's PDF backend subsets fonts with fontTools, which logs every table at INFO
    logging.getLogger("fontTools").setLevel(logging.WARNING)
    logging.getLogger(__name__).info("rule %s started", getattr(snakemake, "rule", "?"))
