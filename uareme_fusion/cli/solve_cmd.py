"""`uareme-fusion solve FILE`: bring your own normals (filled in below)."""
