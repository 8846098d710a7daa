"""scripts/zoo.py (the generator of unseen flights) as a module, loaded once."""

import importlib.util
import sys
from pathlib import Path


def zoo():
    if "zoo" not in sys.modules:
        path = Path(__file__).resolve().parents[2] / "scripts" / "zoo.py"
        spec = importlib.util.spec_from_file_location("zoo", path)
        module = importlib.util.module_from_spec(spec)
        sys.modules["zoo"] = module  # registered before running it: its dataclasses look their module up
        spec.loader.exec_module(module)
    return sys.modules["zoo"]
