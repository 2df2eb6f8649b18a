"""Shared fixtures: the repository root, the CLI binary, a local Ray cluster."""

from __future__ import annotations

import os
import pathlib
import shutil
import subprocess
import tempfile

import pytest

os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")

ROOT = pathlib.Path(__file__).resolve().parents[3]


@pytest.fixture(scope="session")
def root() -> pathlib.Path:
    return ROOT


@pytest.fixture(scope="session")
def cli() -> list:
    """The command that runs the chiaro CLI: a built binary if there is one
    (release preferred), else `cargo run`."""
    for profile in ("release", "debug"):
        exe = ROOT / "target" / profile / "chiaro"
        if exe.is_file() and os.access(exe, os.X_OK):
            return [str(exe)]
    cargo = shutil.which("cargo")
    if cargo is None:
        pytest.fail("no chiaro CLI binary under target/ and no cargo to build one")
    return [cargo, "run", "--quiet", "-p", "chiaro-cli", "--manifest-path", str(ROOT / "Cargo.toml"), "--"]


@pytest.fixture(scope="session")
def ray_cluster():
    """A real local Ray cluster on loopback with two CPUs, for the session.
    The temp dir is short because Ray's Unix socket paths must fit in 107 bytes."""
    ray = pytest.importorskip("ray")
    tmp = tempfile.mkdtemp(prefix="cr", dir="/tmp")
    ray.init(
        num_cpus=2,
        include_dashboard=False,
        _temp_dir=tmp,
        log_to_driver=False,
        _node_ip_address="127.0.0.1",
    )
    try:
        yield ray
    finally:
        ray.shutdown()
        shutil.rmtree(tmp, ignore_errors=True)


def run(cmd: list, **kw) -> subprocess.CompletedProcess:
    """Runs a command, failing the test with its output if it fails."""
    r = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if r.returncode != 0:
        pytest.fail(f"{cmd} exited {r.returncode}\nstdout:\n{r.stdout}\nstderr:\n{r.stderr}")
    return r
