"""In-hand manipulation by finger gaiting (Saut, Sahbani, Perdereau, seed 003): contacts
and their force closure, contact paths on the object's surface, the fingers that follow
them, and the GS_n roadmap."""
