"""The campaign's LocalCluster: no dashboard unless asked for, so no busy-port warning.

Dask's scheduler serves HTTP on port 8787 by default even without a dashboard, and
warns "Port 8787 is already in use" when another cluster (or anything else) holds it.
Here the port is held and two clusters start: neither warns.
"""

import socket

import pytest

from fahv.cluster import dask_client

DEFAULT_PORT = 8787  # Dask's default dashboard port


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _http_port(cluster) -> int:
    return cluster.scheduler.http_server.port


@pytest.fixture
def busy_default_port():
    """Port 8787 held for the test (or already held by another program)."""
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", DEFAULT_PORT))
            s.listen()
        except OSError:  # in use already: busy either way
            pass
        yield


def test_two_local_clusters_start_without_the_port_in_use_warning(busy_default_port, recwarn):
    started = [dask_client(workers=1) for _ in range(2)]
    try:
        ports = [_http_port(cluster) for _, cluster in started]
    finally:
        for client, cluster in started:
            client.close()
            cluster.close()
    busy = [str(w.message) for w in recwarn if "already in use" in str(w.message)]
    assert busy == []
    assert DEFAULT_PORT not in ports and min(ports) > 0 and ports[0] != ports[1]


def test_the_dashboard_is_served_where_the_user_asks(recwarn):
    port = _free_port()
    client, cluster = dask_client(workers=1, dashboard=f"127.0.0.1:{port}")
    try:
        assert _http_port(cluster) == port
        assert client.dashboard_link == f"http://127.0.0.1:{port}/status"
    finally:
        client.close()
        cluster.close()
    assert not [w for w in recwarn if "already in use" in str(w.message)]
