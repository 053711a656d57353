"""affcorr batch on a real local Ray cluster (issue 25): a head node without CPUs and two worker
nodes of one CPU each on 127.0.0.1 (``ray start --head``, ``ray start --address``); a worker
process is killed during the run, and every pair is still present and equal to the serial
result; with the images shipped as bytes, the workers never read the image folder and the
results are the same."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

ray = pytest.importorskip("ray", reason="the Ray executor needs ray (pip install 'affcorr[ray]')")
pytest.importorskip("h5py", reason="affcorr batch writes HDF5 through h5py")

from affcorr import batch  # noqa: E402
from test_batch import (  # noqa: E402, F401 (fixtures)
    OPTIONS,
    assert_equals_serial,
    good_pairs,
    images,
    read_matches,
    serial,
)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _node(*args: str) -> subprocess.Popen:
    # --block keeps `ray start` in the foreground: terminating its process group stops that
    # node's processes (and only them).
    ray_cli = str(Path(sys.executable).with_name("ray"))
    return subprocess.Popen(
        [ray_cli, "start", "--block", "--node-ip-address=127.0.0.1", *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
        env=dict(os.environ, RAY_USAGE_STATS_ENABLED="0"),
    )


@pytest.fixture(scope="module")
def cluster():
    """`ray start --head` (no CPUs) and two `ray start --address` nodes of one CPU each, all
    on 127.0.0.1; the driver connects to it."""
    port = _free_port()
    address = f"127.0.0.1:{port}"
    nodes = [_node("--head", f"--port={port}", "--num-cpus=0", "--include-dashboard=false")]
    try:
        deadline = time.monotonic() + 120
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                if time.monotonic() > deadline or nodes[0].poll() is not None:
                    pytest.fail("the Ray head did not start")
                time.sleep(0.5)
        ray.init(address=address, log_to_driver=False)
        # One node at a time: two raylets starting together can pick the same free port.
        for cpus in (1, 2):
            nodes.append(_node(f"--address={address}", "--num-cpus=1"))
            while ray.cluster_resources().get("CPU", 0) < cpus:
                if time.monotonic() > deadline or nodes[-1].poll() is not None:
                    pytest.fail(f"a Ray worker node did not join: {ray.cluster_resources()}")
                time.sleep(0.5)
        yield address
    finally:
        if ray.is_initialized():
            ray.shutdown()
        for p in reversed(nodes):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGTERM)
        for p in nodes:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(p.pid, signal.SIGKILL)


def test_ray_batch_survives_a_killed_worker(cluster, images, serial, tmp_path) -> None:  # noqa: F811
    folder, names = images
    pairs = good_pairs(names)
    killed: list[int] = []

    def kill_a_worker(r: dict) -> None:
        # The worker that sent the first result is running its next task by now (two tasks
        # in flight per CPU): SIGKILL it; Ray restarts it and retries the task.
        if not killed:
            pid = int(r["worker"].rsplit(":", 1)[1])
            killed.append(pid)
            os.kill(pid, signal.SIGKILL)

    s = batch.run(
        pairs, folder, tmp_path, ray_address=cluster, chunk_size=1, retries=3,
        on_result=kill_a_worker, progress=False, **OPTIONS,
    )  # fmt: skip
    assert killed
    assert (s.executor, s.workers) == ("ray", 2), s
    assert (s.matched, s.failed) == (len(pairs), 0), s
    assert set(read_matches(tmp_path)) == set(pairs)
    assert_equals_serial(tmp_path, serial)
    workers = {g["_attrs"]["worker"] for g in read_matches(tmp_path).values()}
    assert f"{socket.gethostname()}:{killed[0]}" in workers and len(workers) >= 2


def test_ray_batch_ships_images_as_bytes(cluster, images, serial, tmp_path) -> None:  # noqa: F811
    folder, names = images
    pairs = good_pairs(names)
    s = batch.run(
        pairs, folder, tmp_path, ray_address=cluster, ship_images=True, chunk_size=2,
        cache=False, progress=False, **OPTIONS,
    )  # fmt: skip
    assert (s.executor, s.matched, s.failed) == ("ray", len(pairs), 0), s
    assert set(read_matches(tmp_path)) == set(pairs)
    assert_equals_serial(tmp_path, serial)
