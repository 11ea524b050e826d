"""hybrid: the breathing human trunk, MuJoCo ribs coupled to a volume-preserving membrane."""
