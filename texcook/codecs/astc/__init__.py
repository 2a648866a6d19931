"""ASTC LDR: symbolic blocks, range tables, partitions, block modes, BISE,
packing and unpacking, decoding, and the encoder search."""
