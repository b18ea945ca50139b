"""Shared fixtures of the camsim Python tests: the repository, ../shared beside it, and the
`camsim` command-line binary (built once with cargo if it is not there) for parity tests."""
import os
import pathlib
import subprocess

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
SHARED = REPO.parent / "shared"


@pytest.fixture(scope="session")
def repo():
    return REPO


@pytest.fixture(scope="session")
def shared():
    if not SHARED.is_dir():
        pytest.skip(f"{SHARED} (shared test data beside the checkout) is missing")
    return SHARED


@pytest.fixture(scope="session")
def cli():
    """Path of the camsim binary: $CAMSIM_BIN, else target/release/camsim (built if absent)."""
    env = os.environ.get("CAMSIM_BIN")
    if env:
        return pathlib.Path(env)
    exe = REPO / "target" / "release" / "camsim"
    subprocess.run(["cargo", "build", "--release", "--quiet", "--bin", "camsim"],
                   cwd=REPO, check=True)
    return exe


def run_cli(exe, *args, cwd=None):
    """Run the CLI; returns (returncode, stdout, stderr)."""
    p = subprocess.run([str(exe), *map(str, args)], cwd=cwd, capture_output=True, text=True)
    return p.returncode, p.stdout, p.stderr
