"""What the package's tests are held to comes from Rust: `agp-py-reference` (tests/src/bin),
found as $AGP_PY_REFERENCE or in the repository's target/debug. The gradient test also needs
a learned AG file, $AGP_TEST_AG (the Rust test `python_package` hands it the one the other
tests learn). A test that cannot run fails and names the line to run."""

import json
import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def reference_binary() -> Path:
    path = Path(os.environ.get("AGP_PY_REFERENCE", REPO / "target" / "debug" / "agp-py-reference"))
    if not path.is_file():
        pytest.fail(f"no {path}: build it with `cargo build -p agp-tests --bins` (or set AGP_PY_REFERENCE)")
    return path


def run_reference(*args: str) -> str:
    done = subprocess.run([str(reference_binary()), *args], capture_output=True, text=True, timeout=120)
    if done.returncode != 0:
        pytest.fail(f"agp-py-reference {' '.join(args)} failed: {done.stderr.strip()}")
    return done.stdout


@pytest.fixture(scope="session")
def rust_layouts() -> dict:
    return json.loads(run_reference("layout"))


@pytest.fixture(scope="session")
def ag_file() -> Path:
    path = os.environ.get("AGP_TEST_AG")
    if not path or not Path(path).is_file():
        pytest.fail(
            "no learned AG file: set AGP_TEST_AG to one (e.g. results/triangle.ag after "
            "`target/release/agp up`), or run `cargo test -p agp-tests --test python_package`, "
            "which learns one and hands it over"
        )
    return Path(path)
