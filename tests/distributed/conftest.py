"""The LocalCluster a module's distributed tests share (tests that kill a
worker or change the workers' environment start their own)."""

import pytest
from dask_cluster import TIMEOUT, distributed, local_cluster


@pytest.fixture(scope="module")
def client():
    with local_cluster() as cluster, distributed.Client(cluster, timeout=TIMEOUT) as c:
        c.wait_for_workers(2, timeout=TIMEOUT)
        yield c
