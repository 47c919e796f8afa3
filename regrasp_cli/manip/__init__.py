"""Manipulation modes, the transitions between them and their solvers, and the tasks
that plan paths through them (:mod:`.modes`, :mod:`.solve`, :mod:`.tasks`)."""
