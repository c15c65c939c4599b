"""Lets the tests run from the source tree too: the installed package is used when there is
one (as CI installs it), else the one beside these tests."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

if importlib.util.find_spec("tacmesh") is None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
