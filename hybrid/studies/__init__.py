"""Studies of `hybrid`: stability, work-precision, extreme cases, rigid validation."""
