"""A real dask.distributed LocalCluster for the distributed tests: two worker
processes of one thread each, shared by a module's tests (tests that kill a
worker or change the workers' environment start their own)."""

import pytest

distributed = pytest.importorskip("distributed")  # the `distributed` extra; ./dev.sh test installs it

TIMEOUT = 60  # seconds any wait of these tests may take


def local_cluster(**kw):
    """A LocalCluster of two one-thread worker processes (no dashboard)."""
    kw.setdefault("n_workers", 2)
    return distributed.LocalCluster(
        threads_per_worker=1, processes=True, dashboard_address=None, worker_dashboard_address=None, **kw
    )


@pytest.fixture(scope="module")
def client():
    with local_cluster() as cluster, distributed.Client(cluster, timeout=TIMEOUT) as c:
        c.wait_for_workers(2, timeout=TIMEOUT)
        yield c
