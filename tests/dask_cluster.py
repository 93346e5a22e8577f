"""A real dask.distributed LocalCluster for the distributed tests (and the
CLI's): two worker processes of one thread each, dashboards on free ports, a bound on
every wait."""

import pytest

distributed = pytest.importorskip("distributed")  # the `distributed` extra; ./dev.sh test installs it

TIMEOUT = 60  # seconds any wait of these tests may take


def local_cluster(**kw):
    """A LocalCluster of two one-thread worker processes."""
    kw.setdefault("n_workers", 2)
    return distributed.LocalCluster(
        threads_per_worker=1, processes=True, dashboard_address=":0", worker_dashboard_address=":0", **kw
    )
