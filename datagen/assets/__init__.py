"""The objects: the rig, procedural models, mesh and feature files (read and validated), generated features."""
