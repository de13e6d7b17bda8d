"""Shared fixtures: real Zenoh sessions on loopback (a peer hub, client spokes), rerun's
analytics state in a temporary folder. Every session is closed in teardown: an open session
with callbacks makes the interpreter hang at exit."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from fusion.io.blas import pin_blas_threads
from fusion.io.zenoh_bus import free_tcp_port, session_config

pin_blas_threads()  # see fusion/io/blas.py: multi-threaded BLAS on 4x4 matrices is 10x slower under load


@pytest.fixture(autouse=True, scope="session")
def _xdg_home(tmp_path_factory: pytest.TempPathFactory) -> None:
    home = tmp_path_factory.mktemp("xdg")
    os.environ["XDG_CONFIG_HOME"] = str(home)
    os.environ["XDG_DATA_HOME"] = str(home)


def _open_hub() -> tuple[Any, str]:
    import zenoh

    for _ in range(20):
        endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
        try:
            return zenoh.open(session_config(mode="peer", listen=[endpoint])), endpoint
        except Exception as e:  # another process took the port between probe and bind: try another
            if "in use" not in str(e).lower():
                raise
    raise RuntimeError("no free loopback port for the Zenoh hub")


@pytest.fixture
def zenoh_hub() -> Iterator[tuple[Any, str]]:
    """(session, endpoint): a peer listening on a free 127.0.0.1 port, scouting off."""
    hub, endpoint = _open_hub()
    try:
        yield hub, endpoint
    finally:
        hub.close()


@pytest.fixture
def zenoh_client(zenoh_hub: tuple[Any, str]) -> Iterator[Callable[[], Any]]:
    """A factory of client sessions connected to the hub; all closed in teardown."""
    import zenoh

    _, endpoint = zenoh_hub
    opened: list[Any] = []

    def make() -> Any:
        s = zenoh.open(session_config(mode="client", connect=[endpoint]))
        opened.append(s)
        return s

    try:
        yield make
    finally:
        for s in reversed(opened):
            s.close()
