"""The examples in examples/python run and succeed (on the shared data and the simulator)."""

import pathlib
import subprocess
import sys

EXAMPLES = pathlib.Path(__file__).resolve().parents[3] / "examples" / "python"


def run(script, *args, cwd=None):
    out = subprocess.run(
        [sys.executable, str(EXAMPLES / script), *map(str, args)],
        capture_output=True, text=True, timeout=600, cwd=cwd,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    return out.stdout


def test_align_pair(data):
    assert "trusted" in run("align_pair.py").splitlines()[-1]


def test_build_map(data, tmp_path):
    text = run("build_map.py", data / "3dtk_dat", tmp_path / "m")
    assert (tmp_path / "m.olm").is_file() and (tmp_path / "m.bt").is_file()
    assert "scan002: (3." in text  # data README: scan002 is 3.378 m ahead of scan000


def test_team_demo():
    text = run("team_demo.py", "--robots", "2", "--scans", "3", "--world", "box-room")
    assert "scans placed" in text
