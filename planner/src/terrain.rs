//! Terrain: the 2.5-D elevation grid (under construction).
