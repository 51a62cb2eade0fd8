"""Fixtures of the olmap Python tests: the shared real data and the olmap command line.

* ``data``: the shared data folder (``$OLMAP_DATA``, else ``../shared/data`` beside the
  repository). Tests that need it skip when it is missing, unless ``OLMAP_REQUIRE_DATA=1``
  (CI), where they fail.
* ``cli``: runs the ``olmap`` program (``$OLMAP_BIN``, else the newest of
  ``target/{debug,release}/olmap`` in the cargo target folder) and returns its JSON output.
  Missing: skip, unless ``OLMAP_REQUIRE_DATA=1``.
"""

import json
import os
import pathlib
import subprocess

import pytest

REPO = pathlib.Path(__file__).resolve().parents[3]
REQUIRED = os.environ.get("OLMAP_REQUIRE_DATA") == "1"


def _missing(what):
    if REQUIRED:
        pytest.fail(f"{what} is missing and OLMAP_REQUIRE_DATA=1")
    pytest.skip(f"{what} is missing")


@pytest.fixture(scope="session")
def data():
    root = pathlib.Path(os.environ.get("OLMAP_DATA", REPO.parent / "shared" / "data"))
    if not (root / "3dtk_dat" / "scan000.3d").is_file():
        _missing(f"the shared data folder ({root})")
    return root


def _find_cli():
    env = os.environ.get("OLMAP_BIN")
    if env:
        return pathlib.Path(env)
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    found = [p for p in (target / "debug" / "olmap", target / "release" / "olmap") if p.is_file()]
    return max(found, key=lambda p: p.stat().st_mtime) if found else None


@pytest.fixture(scope="session")
def pair(data):
    """scan001 and scan000 of the 3DTK example (valid returns), the real pair whose
    alignment the data README gives: scan001 is 1.568 m ahead."""
    import olmap

    d = data / "3dtk_dat"
    return (
        olmap.read_cloud(d / "scan001.3d", valid_3dtk=True),
        olmap.read_cloud(d / "scan000.3d", valid_3dtk=True),
    )


@pytest.fixture(scope="session")
def cli():
    binary = _find_cli()
    if binary is None or not binary.is_file():
        _missing("the olmap program (set OLMAP_BIN or build it with cargo build)")

    def run(*args, parse=True):
        out = subprocess.run(
            [str(binary), *map(str, args)],
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert out.returncode == 0, f"olmap {' '.join(map(str, args))}: {out.stderr}"
        return json.loads(out.stdout) if parse else out

    return run


#: Report fields that differ between two runs of the same computation (wall times) or
#: name where the results went.
VOLATILE = {"seconds", "files", "output", "html"}


def same_report(a, b, path="report", tol=1e-9):
    """Asserts two reports are equal: the same keys and values, numbers to ``tol``,
    ignoring the fields in ``VOLATILE``."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), f"{path}: keys {set(a) ^ set(b)}"
        for k in a:
            if k not in VOLATILE:
                same_report(a[k], b[k], f"{path}.{k}", tol)
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), f"{path}: lengths differ"
        for i, (x, y) in enumerate(zip(a, b)):
            same_report(x, y, f"{path}[{i}]", tol)
    elif isinstance(a, float) or isinstance(b, float):
        assert a is not None and b is not None and abs(a - b) <= tol, f"{path}: {a} != {b}"
    else:
        assert a == b, f"{path}: {a!r} != {b!r}"
