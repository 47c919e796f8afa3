"""Online planning (Saut et al. 2010, §V-B, §V-C)."""
