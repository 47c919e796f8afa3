"""Tasks: each a way of choosing a path through manipulation modes and the key
configurations where its transitions meet.  ``handover``: Saut et al. 2010 (seed 000)."""
