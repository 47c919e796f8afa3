"""Tests of regrasp_cli.roadmap (a package so that test_build.py does not clash with tests/grasp/test_build.py)."""
