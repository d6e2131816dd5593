"""What the workers of a Dask LocalCluster started by ``swarm-ros experiment`` run besides the runs.

Imported only where such a cluster starts: it loads ``distributed``.
"""

from __future__ import annotations

import asyncio
import logging

from distributed.comm.core import CommClosedError
from distributed.diagnostics.plugin import WorkerPlugin

_WORKER_LOG = "distributed.worker"
_HEARTBEAT_FAILED = "Failed to communicate with scheduler during heartbeat"


class QuietHeartbeatAtClose(WorkerPlugin):
    """Each worker drops the one error record its shut-down races into.

    Closing the cluster retires each worker at the scheduler before the worker hears it is closed. A heartbeat
    in between finds its connection closed by the scheduler, and the worker logs "Failed to communicate with
    scheduler during heartbeat." with a traceback (distributed 2026.8), after the command has already said it
    stopped. A LocalCluster's scheduler lives in the process that started it, so a connection to it closed under
    a worker means that process is closing it. Only that record is dropped: every other error a worker logs
    still shows. Given only to a LocalCluster's workers, never to those of a scheduler the user runs. The filter
    stays once the plugin is torn down: the worker's last heartbeat can come after that (the suite saw the record,
    run on three workers).
    """

    name = "swarm-ros-quiet-heartbeat-at-close"
    idempotent = True

    def setup(self, worker: object) -> None:
        logging.getLogger(_WORKER_LOG).addFilter(keep)


def keep(record: logging.LogRecord) -> bool:
    """False for a heartbeat's failure on a connection the scheduler closed, or whose handshake the worker's own
    closing cancelled (CI saw both forms, distributed 2026.8); True for any other record."""
    exc = record.exc_info[1] if record.exc_info else None
    closing = isinstance(exc, (CommClosedError, asyncio.CancelledError))
    return not (closing and str(record.msg).startswith(_HEARTBEAT_FAILED))
