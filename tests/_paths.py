"""Paths the tests share, defined once: the project root, its demos/ and meshes/, and the FCLIB data.

Test modules import them (`from _paths import ROOT, DEMOS`): tests/ is on sys.path (tests/conftest.py puts it
there for every import mode). Everything is relative to this file, so the suite runs from any checkout.
"""
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEMOS = os.path.join(ROOT, "demos")
MESHES = os.path.join(ROOT, "meshes")
# The FCLIB problems are not in the repository: they live beside the project, in ../shared/data/fclib from the
# project root (CI lays shared/ there). tests/test_fclib.py fails in CI (CI=true) when they are missing and
# skips outside CI.
FCLIB = os.path.normpath(os.path.join(ROOT, "..", "shared", "data", "fclib"))
