"""Tests of regrasp_cli.plan (a package so that its test modules do not clash with other test folders)."""
