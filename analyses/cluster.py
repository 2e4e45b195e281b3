"""Running a study's simulations on a Dask cluster.

``coherence report``, ``paper`` and ``whatif`` take ``--dask ADDRESS``: the
runs (or grid points) become tasks on that scheduler, and each task reads the
trace from the trace cache where it runs, so the cache folder (``--cache``)
must be on storage every worker can reach under the same path. Results are
the same as a local run's.
"""
from __future__ import annotations

from contextlib import contextmanager


@contextmanager
def dask_executor(address):
    """A :class:`concurrent.futures.Executor` on a Dask scheduler, or None.

    Parameters
    ----------
    address : str, distributed.Client or None
        ``tcp://host:8786`` (a client is opened and closed here), a client
        (used as it is), or None (yields None: run locally).
    """
    if address is None:
        yield None
        return
    from distributed import Client

    client = address if isinstance(address, Client) else Client(address)
    try:
        yield client.get_executor(pure=False)
    finally:
        if client is not address:
            client.close()
