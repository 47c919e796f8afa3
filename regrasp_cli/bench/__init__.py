"""Benchmark suites (`regrasp bench SUITE.yaml`): every (scene, planner, seed) run of the
online stage of Saut et al. 2010 (§VI, Table I) in its own process with a wall-clock
budget, one JSON record per run, and the aggregated tables and plot a comparison of
planners needs (after OMPL's benchmarking and Planner Arena).

Modules: :mod:`.suite` (the suite YAML), :mod:`.runner` (offline timing, the runs),
:mod:`.aggregate` (pure statistics over run records), :mod:`.report` (Markdown, rich,
PNG); the CLI entry is :mod:`regrasp_cli.commands.bench`.
"""
