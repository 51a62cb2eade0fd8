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


def parser(doc):
    """An argument parser with the options every script here shares: --data (the shared
    data folder: $OLMAP_DATA, else ../shared/data beside the repository) and --olmap (the
    release build)."""
    import argparse

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=os.environ.get("OLMAP_DATA", os.path.join(root, "..", "shared", "data")))
    ap.add_argument("--olmap", default=os.path.join(root, "target", "release", "olmap"))
    return ap
