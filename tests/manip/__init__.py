"""Tests of regrasp_cli.manip (a package so that its test modules do not clash with other test folders)."""
