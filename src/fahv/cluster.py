"""The Dask cluster long computations run on: a LocalCluster, or a scheduler's address.

Campaigns (`fahv.campaign.engine`) and designs (`fahv.design.pipeline`) spread
independent work over Dask distributed workers: by default an embedded `LocalCluster`
of one single-threaded worker process per core, started and stopped by the command;
with a scheduler address (`dask scheduler` and `dask worker ADDRESS` started
elsewhere), an existing cluster.
"""

from __future__ import annotations

import logging
import os

#: HTTP address of a LocalCluster without dashboard: a free port of this host. The
#: scheduler always serves HTTP (health and metrics routes); on Dask's default port
#: 8787 every campaign started beside another cluster would warn that it is in use.
NO_DASHBOARD = "127.0.0.1:0"


def dask_client(scheduler: str | None = None, workers: int | None = None,
                dashboard: str | None = None):  # fmt: skip
    """A Dask client: of the cluster at `scheduler`, or of a new LocalCluster.

    Parameters
    ----------
    scheduler : str, optional
        Address of an existing Dask scheduler (`tcp://host:8786`).
    workers : int, optional
        Worker processes of the LocalCluster (one thread each; default: the cores).
    dashboard : str, optional
        Address of the LocalCluster's dashboard (`":8787"`, `"127.0.0.1:0"`);
        default: no dashboard, the scheduler's HTTP server on `NO_DASHBOARD`.
        Ignored with `scheduler` (that cluster serves its own).

    Returns
    -------
    (distributed.Client, distributed.LocalCluster or None)
        The client and the cluster started here (None with `scheduler`); the
        caller closes both.
    """
    from dask.distributed import Client, LocalCluster

    if scheduler:
        return Client(scheduler), None
    cluster = LocalCluster(
        n_workers=workers or os.cpu_count() or 1,
        threads_per_worker=1,
        processes=True,
        silence_logs=logging.ERROR,
        dashboard_address=dashboard or NO_DASHBOARD,
        scheduler_kwargs={"dashboard": dashboard is not None},
    )
    return Client(cluster), cluster


def active_client():
    """The default Dask distributed client of this process, or None.

    Returns
    -------
    distributed.Client or None
        The client a command started (`fahv design`, `fahv campaign`) or the caller
        made current; None in a plain library call.
    """
    try:
        from distributed import default_client
    except ImportError:  # pragma: no cover - distributed is a dependency
        return None
    try:
        return default_client()
    except ValueError:  # no client
        return None
