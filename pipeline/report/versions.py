"""Versions of the software that produced a run, for the report."""

from __future__ import annotations

import platform
import sys
from importlib import metadata

# distribution name -> label; opencv may be installed under any of its wheel names
_PACKAGES = (("ridgeloc", "ridgeloc"), ("numpy", "numpy"), ("scipy", "scipy"), ("opencv-python-headless", "opencv"),
             ("opencv-python", "opencv"), ("opencv-contrib-python-headless", "opencv"), ("pymap3d", "pymap3d"),
             ("matplotlib", "matplotlib"), ("pymavlink", "pymavlink"), ("rosbags", "rosbags"), ("mcap", "mcap"),
             ("pyyaml", "pyyaml"), ("tqdm", "tqdm"), ("dask", "dask"), ("distributed", "distributed"),
             ("gtsam", "gtsam"), ("pyulog", "pyulog"))


def software_versions() -> dict[str, str]:
    """{"python": ..., "platform": ..., "<package>": version} for the installed packages ridgeloc uses."""
    out = {"python": sys.version.split()[0], "platform": platform.platform()}
    for dist, label in _PACKAGES:
        if label in out:
            continue
        try:
            out[label] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            continue
    return out
