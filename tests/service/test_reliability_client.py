"""`fusion serve -m client` with nothing listening: one line that says what the service needs
(a router or peer at that endpoint), not the hint meant for the service's own clients."""

from __future__ import annotations

from pathlib import Path

from fusion.cli.runner import Exit
from fusion.io.zenoh_bus import free_tcp_port
from tests.cli.helpers import one_error_line, run


def test_serve_in_client_mode_with_no_peer_says_what_it_needs(tmp_path: Path) -> None:
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    cfg = Path(__file__).resolve().parents[2] / "configs" / "service.toml"
    r = run("fusion", "serve", "-c", str(cfg), "-m", "client", "-e", ep, "--recordings", str(tmp_path / "rec"),
            cwd=tmp_path)
    assert r.returncode == Exit.CONNECT, r.stderr
    line = one_error_line(r)
    assert f"cannot connect to {ep}: nothing is listening there; in client mode the service needs a Zenoh router " \
           "or peer" in line, line
    assert "start the service first" not in line
    assert not (tmp_path / "rec").exists() or not list((tmp_path / "rec").iterdir()), "files left behind"
