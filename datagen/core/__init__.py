"""Pure numpy, no I/O: the conventions, transforms, camera, feature table, labels and the trainer's view of a label."""
