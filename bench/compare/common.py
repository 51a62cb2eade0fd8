"""Helpers shared by the comparison scripts in this folder."""

import os
import subprocess
import sys


def run(cmd, env=None):
    """Runs `cmd` and returns its standard output; exits with its error output on failure."""
    out = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if out.returncode != 0:
        sys.exit(f"failed: {' '.join(cmd)}\n{out.stderr}")
    return out.stdout


def loadavg():
    """The 1-minute load average (NaN where the platform has none)."""
    try:
        return os.getloadavg()[0]
    except OSError:
        return float("nan")
